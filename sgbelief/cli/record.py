"""``sgbelief record EVENTS --vocab VOCAB --operator comod --out map.rrd``: replay a log into a rerun recording."""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

from sgbelief.cli import _console as console

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("events", type=Path, help="events.jsonl evidence log")
    p.add_argument("--vocab", required=True, help="vocabulary YAML (subsumption table) or a shipped name: scannet, kitti360")
    p.add_argument("--operator", default="comod", help="fusion operator (default: %(default)s)")
    p.add_argument("--out", type=Path, default=Path("map.rrd"), help="rerun recording to write (default: %(default)s)")
    p.add_argument("--truth", type=Path, default=None,
                   help="truth.json {node: {predicate: 0|1}}: print the replay's scores as `sgbelief replay` does "
                        "(default: no scores)")
    p.add_argument("--nodes", type=Path, default=None,
                   help="nodes.json with the objects' boxes, tracks and the ego trajectory (default: nodes.json beside "
                        "the events file, when there is one)")
    p.add_argument("--config", type=Path, default=None, help="operator config YAML (default: sgbelief/configs/operators/default.yaml)")
    p.add_argument("--tau", type=float, default=0.5,
                   help="commit threshold of the box labels and scores: committed when P > tau (default: %(default)s)")
    p.add_argument("--skip-bad-lines", action="store_true",
                   help="skip (and count) malformed lines instead of stopping (default: stop at the first)")
    p.add_argument("--allow-unknown-predicates", action="store_true",
                   help="accept predicates the vocabulary does not define (default: an error)")
    p.add_argument("--save-graph", type=Path, default=None,
                   help="also save the final graph under DIR (for `sgbelief show`; default: not saved)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: a bar on stderr when it is a terminal)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.eval.formats import ReadStats, iter_events, read_truth
    from sgbelief.eval.replay import format_table, make_runs, require_events, score_run
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.viz.rerun_log import MapLogger, require_rerun

    rr = require_rerun()  # before any work: a missing extra is said at once
    vocab = SubsumptionTable.resolve(args.vocab)
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    truth = read_truth(args.truth) if args.truth is not None else None
    (run_,) = make_runs([args.operator], vocab, config, strict=not args.allow_unknown_predicates)
    graph = run_.graph
    nodes_file = args.nodes if args.nodes is not None else args.events.with_name("nodes.json")
    ego: list[tuple[int, float, float, float]] = []
    if args.nodes is not None or nodes_file.is_file():
        ego = _add_geometry(graph, nodes_file)
    else:
        log.warning("no nodes.json beside %s: objects have no boxes in the recording, only belief series "
                    "(--nodes gives one)", args.events)

    args.out.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(f"sgbelief {args.operator}", recording_id=f"{args.events}:{args.operator}")
    tmp = args.out.with_name(f".{args.out.name}.tmp")
    rec.save(str(tmp))
    logger = MapLogger(rec, tau=args.tau, predicates=vocab.predicates)
    logger.log_setup()
    if ego:
        logger.log_ego_track([p[1:] for p in ego])
    stats = ReadStats()
    progress = console.progress(desc="record", unit="ev", quiet=args.no_progress)
    try:
        _replay_into(logger, run_, iter_events(args.events, skip_bad_lines=args.skip_bad_lines, stats=stats), stats,
                     args.events, ego, progress)
        require_events(stats, args.events)
        rec.flush()
    except BaseException:
        rec.disconnect()
        tmp.unlink(missing_ok=True)
        raise
    finally:
        progress.close()
    rec.disconnect()
    tmp.replace(args.out)
    refused = dict(getattr(run_.operator, "stats", {}) or {}).get("refused", 0)
    print(f"{stats.events} events replayed from {args.events} through {run_.name}"
          + (f" ({stats.skipped} bad lines skipped)" if stats.skipped else ""))
    print(f"wrote {args.out}: {len(graph)} objects, {len(graph.provenance)} belief series, {refused} refused claims "
          f"(open it with: rerun {args.out})")
    if truth is not None:
        preds = [p for p in vocab.predicates if any(p in row for row in truth.values())]
        print(format_table({run_.name: score_run(run_, truth, preds, tau=args.tau)}, preds))
    if args.save_graph is not None:
        print(f"wrote {graph.save(args.save_graph)}")
    return 0


def _add_geometry(graph: Any, path: Path) -> list[tuple[int, float, float, float]]:
    """Add the nodes.json nodes (boxes, tracks, attributes) to ``graph``; returns the ego track
    (t, x, y, z) of the log's scene when there is exactly one."""
    from sgbelief.eval.formats import node_attributes, read_nodes

    doc = read_nodes(path)
    for nid, info in doc.nodes.items():
        graph.add_node(nid, **node_attributes(info))
    tracks = [sc.ego_track for sc in doc.scenes.values() if sc.ego_track]
    return [(int(p[0]), float(p[1]), float(p[2]), float(p[3])) for p in tracks[0]] if len(tracks) == 1 else []


def _replay_into(logger: Any, run_: Any, records: Any, stats: Any, source: Path, ego: list, progress: Any) -> None:
    """Every record through the run's operator, event by event (with reports: the verdicts and
    actions are logged); at each new time step the objects and beliefs touched at the last one."""
    from sgbelief.errors import FormatError, SgbeliefError
    from sgbelief.eval.replay import to_event
    from sgbelief.fusion.protocol import Action
    from sgbelief.viz.map_state import object_view

    perf = time.perf_counter
    op, graph = run_.operator, run_.graph
    ego_at = {p[0]: p[1:] for p in ego}
    touched: dict[Any, None] = {}
    pairs: dict[tuple[Any, str], None] = {}
    last_t: int | None = None

    def flush(t: int) -> None:
        logger.log_nodes(graph, touched, t, pairs)
        if t in ego_at:
            logger.log_ego(ego_at[t])
        touched.clear()
        pairs.clear()

    n = 0
    for rec in records:
        n += 1
        line = stats.lines
        if last_t is not None and rec.t < last_t:
            raise FormatError(f"event times must not decrease; t goes back from {last_t} to {rec.t}", path=source, line=line)
        if last_t is not None and rec.t != last_t:
            flush(last_t)
        last_t = rec.t
        ev, labels = to_event(rec, f"line{line}")
        t0 = perf()
        try:
            report = op.update(graph, ev, labels)
        except SgbeliefError as exc:
            raise FormatError(f"event {ev.id!r} rejected by {run_.name}: {exc}", path=source, line=line) from exc
        run_.seconds += perf() - t0  # the operator's own time (events/s in the scores), logging apart
        run_.events += 1
        logger.set_time(rec.t)
        for out in report.targets:
            if out.action is Action.BELOW_THRESHOLD:
                continue
            touched[out.node] = None
            pairs[(out.node, rec.predicate)] = None
            if out.action is Action.REFUSED:
                geo = rec.geometric.get(out.node)
                logger.log_refusal(object_view(graph, out.node, logger.tau), out.node, rec.predicate, rec.t,
                                   f" (c = {rec.confidence:.2f}, {rec.context}; geometry: {geo}; verdict {out.verdict.symbol})")
        for res in report.resolutions:
            logger.log_text(f"{res.kind}: {res.node} {res.predicate} (event {res.event_id}, t = {res.t})")
            if res.node in graph:
                touched[res.node] = None
                pairs[(res.node, res.predicate)] = None
        progress.update(1)
    if last_t is not None:
        flush(last_t)

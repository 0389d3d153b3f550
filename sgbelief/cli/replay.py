"""``sgbelief replay EVENTS --truth TRUTH --vocab VOCAB``: several operators on one logged stream."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from sgbelief.cli import _console as console
from sgbelief.fusion.registry import OPERATOR_NAMES

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("events", type=Path, nargs="+",
                   help="events.jsonl evidence log; several logs = several scenes (unique node ids), pooled")
    p.add_argument("--truth", type=Path, required=True, help="truth.json {node: {predicate: 0|1}}")
    p.add_argument("--vocab", required=True, help="vocabulary YAML (subsumption table) or a shipped name: scannet, kitti360")
    p.add_argument("--operators", default=",".join(OPERATOR_NAMES), help="comma-separated operator names (default: %(default)s)")
    p.add_argument("--config", type=Path, default=None, help="operator config YAML (default: sgbelief/configs/operators/default.yaml)")
    p.add_argument("--json", type=Path, default=None, dest="json_out", help="write metrics per operator as JSON (default: none)")
    p.add_argument("--save-graph", type=Path, default=None, help="save each operator's final graph under DIR/<operator>/ (default: not saved)")
    p.add_argument("--nodes", type=Path, default=None,
                   help="nodes.json whose geometry and attributes the saved graphs carry (default: nodes.json beside "
                        "the events file, when there is one; the simulator and bench write it)")
    p.add_argument("--graph-format", choices=["json", "npz"], default="json",
                   help="format of the saved graphs: json (graph.json, default) or npz (graph.npz, the binary layout "
                        "for large maps)")
    p.add_argument("--skip-bad-lines", action="store_true",
                   help="skip (and count) malformed lines instead of stopping (default: stop at the first)")
    p.add_argument("--tau", type=float, default=0.5,
                   help="commit threshold for the metrics: committed when P > tau (default: %(default)s)")
    p.add_argument("--allow-unknown-predicates", action="store_true", help="accept predicates the vocabulary does not define (default: an error)")
    p.add_argument("--predicates", default=None,
                   help="comma-separated predicates to score; mIoU is their unweighted mean (default: every "
                        "predicate of the vocabulary that the truth file mentions; bench's tables use each suite's "
                        "three evaluated predicates, e.g. is_car,is_pedestrian,is_traffic_sign outdoors)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: a bar on stderr when it is a terminal)")
    p.add_argument("--engine", choices=["streaming", "batched", "auto"], default="streaming",
                   help="streaming (event by event, the log read incrementally), batched (majority, naive_bayes and "
                        "overwrite through the vectorised engine: same maps bit for bit, 12.7x faster than streaming "
                        "(5.7x with building the columns; docs/usage.md has the command), the log held in memory, times must not decrease; other operators stream) or auto (batched when possible); "
                        "default: %(default)s")
    p.add_argument("--workers", type=int, default=1,
                   help="replay several scenes in parallel processes (default: %(default)s)")
    p.add_argument("--executor", choices=["local", "ray"], default="local",
                   help="local process pool, or a Ray cluster (pip install 'sgbelief[ray]'; RAY_ADDRESS; "
                        "default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.errors import ConfigError
    from sgbelief.eval.formats import ReadStats, iter_events, read_truth
    from sgbelief.eval.replay import evidence_nodes, format_table, make_runs, replay, require_events, score_run
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.graph.persistence import atomic_write_text

    from sgbelief.fusion.compatibility import SubsumptionTable

    vocab = SubsumptionTable.resolve(args.vocab)
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    names = [n.strip() for n in args.operators.split(",") if n.strip()]
    if not names:
        raise ConfigError("--operators: give at least one operator name")
    truth = read_truth(args.truth)
    if len(args.events) > 1 or args.workers > 1 or args.executor != "local":
        return _run_scenes(args, names, truth, vocab, config)
    runs = make_runs(names, vocab, config, strict=not args.allow_unknown_predicates)
    args.events = args.events[0]
    stats = ReadStats()
    progress = console.progress(desc="replay", unit="ev", quiet=args.no_progress)
    try:
        replay(iter_events(args.events, skip_bad_lines=args.skip_bad_lines, stats=stats), runs,
               line_of=stats, source=args.events, progress=None if progress.disable else progress,
               engine=args.engine)
    finally:
        progress.close()
    require_events(stats, args.events)  # an empty log: an error, and no saved graph overwritten
    log_nodes = evidence_nodes(runs)
    coverage = _truth_coverage(truth, log_nodes, args.truth, args.events)
    attrs = _nodes_for_saving(args, log_nodes) if args.save_graph else None
    preds = _predicates(vocab, truth, args.predicates)
    scores = {r.name: score_run(r, truth, preds, tau=args.tau) for r in runs}
    print(f"{stats.events} events replayed from {args.events}" + (f" ({stats.skipped} bad lines skipped)" if stats.skipped else ""))
    print(coverage)
    print(format_table(scores, preds))
    print(_miou_note(preds, scores))
    if args.json_out:
        doc = {name: sc.as_dict() for name, sc in scores.items()}
        for d in doc.values():
            d["skipped_lines"] = stats.skipped
        atomic_write_text(args.json_out, json.dumps(doc, indent=2, allow_nan=True))
    if args.save_graph:
        for r in runs:
            if attrs is not None:
                for node, a in attrs.items():
                    r.graph.add_node(node, **a)
            r.graph.save(args.save_graph / r.name, format=args.graph_format)
    return 0


def _truth_coverage(truth, log_nodes: set, truth_path: Path, events: object) -> str:
    """Check that the truth file describes the log's nodes (none: an error; some: a warning) and
    say how much of the truth the log reaches."""
    from sgbelief.eval.replay import check_coverage

    scored = check_coverage("truth file", truth, log_nodes, path=truth_path, log=events,
                            missing_means="they are not scored")
    rest = len(truth) - scored
    return (f"truth: {scored} of the {len(truth)} nodes of {truth_path} have evidence in the log"
            + (f"; the other {rest} stay at the prior (not committed: a miss where the truth says 1)" if rest else ""))


def _nodes_for_saving(args: argparse.Namespace, log_nodes: set) -> dict[str, dict] | None:
    """The node attributes the saved graphs carry: --nodes, else nodes.json beside the log (None:
    neither, said as a warning). A nodes file that names none of the log's nodes is an error, one
    that misses some a warning."""
    from sgbelief.eval.replay import check_coverage

    nodes_file = args.nodes if args.nodes is not None else Path(args.events).with_name("nodes.json")
    if args.nodes is None and not nodes_file.is_file():
        log.warning("no nodes.json beside %s: the saved graphs carry no geometry, so geometric and named "
                    "queries on them find nothing (--nodes gives one)", args.events)
        return None
    attrs = _node_attributes(nodes_file)
    check_coverage("nodes file", attrs, log_nodes, path=nodes_file, log=args.events,
                   missing_means="the saved graphs carry no geometry for them, so geometric queries cannot retrieve them")
    return attrs


def _node_attributes(path: Path) -> dict[str, dict]:
    """node id -> scene-graph attributes, from a nodes.json (errors name the file)."""
    from sgbelief.eval.formats import node_attributes, read_nodes

    return {nid: node_attributes(info) for nid, info in read_nodes(path).nodes.items()}


def _predicates(vocab, truth, chosen: str | None = None) -> list[str]:
    """The scored predicates: ``--predicates`` (checked against the truth), else all the truth mentions."""
    from sgbelief.errors import ConfigError

    known = [p for p in vocab.predicates if any(p in row for row in truth.values())]
    known += sorted({p for row in truth.values() for p in row} - set(known))
    if chosen is None:
        return known
    preds = [p.strip() for p in chosen.split(",") if p.strip()]
    missing = [p for p in preds if p not in known]
    if missing or not preds:
        raise ConfigError(f"--predicates: {', '.join(missing) or '(none given)'} not in the truth file; "
                          f"it has {', '.join(known)}")
    return preds


def _miou_note(preds: list[str], scores) -> str:
    from sgbelief.eval.replay import no_positives_note

    counted = preds
    if no_positives_note(scores, preds):
        first = next(iter(scores.values()))
        counted = [p for p in preds if first.per_predicate[p].has_positives]
    return f"mIoU: unweighted mean IoU over these {len(counted)} predicates ({', '.join(counted) or 'none'})"


def _run_scenes(args: argparse.Namespace, names: list[str], truth, vocab, config) -> int:
    """Several scenes: each replayed independently (serial, process pool or Ray), metrics pooled."""
    from sgbelief.eval.parallel import run_scenes
    from sgbelief.eval.replay import SceneJob, format_table, pool_scene_scores, replay_scene
    from sgbelief.graph.persistence import atomic_write_text

    jobs = [SceneJob(str(e), tuple(names), str(args.vocab), config.model_dump(), not args.allow_unknown_predicates,
                     args.skip_bad_lines, str(args.save_graph) if args.save_graph else None, args.graph_format,
                     args.engine)
            for e in args.events]
    results = run_scenes(replay_scene, jobs, workers=args.workers, executor=args.executor)
    log_nodes = {node for r in results for pairs in r.evidence_pairs.values() for node, _ in pairs}
    coverage = _truth_coverage(truth, log_nodes, args.truth, ", ".join(map(str, args.events)))
    preds = _predicates(vocab, truth, args.predicates)
    scores = pool_scene_scores(results, truth, preds, tau=args.tau)
    n = sum(r.n_events for r in results)
    skipped = sum(r.skipped for r in results)
    print(f"{n} events replayed from {len(results)} scenes" + (f" ({skipped} bad lines skipped)" if skipped else ""))
    print(coverage)
    print(format_table(scores, preds))
    print(_miou_note(preds, scores))
    if args.json_out:
        doc = {name: sc.as_dict() for name, sc in scores.items()}
        for d in doc.values():
            d["skipped_lines"] = skipped
            d["scenes"] = len(results)
        atomic_write_text(args.json_out, json.dumps(doc, indent=2, allow_nan=True))
    return 0

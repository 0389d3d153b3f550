"""``sgbelief replay EVENTS --truth TRUTH --vocab VOCAB``: several operators on one logged stream."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sgbelief.fusion.registry import OPERATOR_NAMES


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("events", type=Path, help="events.jsonl evidence log")
    p.add_argument("--truth", type=Path, required=True, help="truth.json {node: {predicate: 0|1}}")
    p.add_argument("--vocab", required=True, help="vocabulary YAML (subsumption table) or a shipped name: scannet, kitti360")
    p.add_argument("--operators", default=",".join(OPERATOR_NAMES), help="comma-separated operator names")
    p.add_argument("--config", type=Path, default=None, help="operator config YAML (default: configs/operators/default.yaml)")
    p.add_argument("--json", type=Path, default=None, dest="json_out", help="write metrics per operator as JSON")
    p.add_argument("--save-graph", type=Path, default=None, help="save each operator's final graph under DIR/<operator>/")
    p.add_argument("--skip-bad-lines", action="store_true", help="skip (and count) malformed lines instead of stopping")
    p.add_argument("--tau", type=float, default=0.5, help="commit threshold for the metrics")
    p.add_argument("--allow-unknown-predicates", action="store_true", help="accept predicates the vocabulary does not define")
    p.add_argument("--no-progress", action="store_true")


def load_vocab(spec: str):
    from sgbelief.fusion.compatibility import SubsumptionTable

    path = Path(spec)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return SubsumptionTable.from_yaml(path)
    return SubsumptionTable.shipped(spec)


def run(args: argparse.Namespace) -> int:
    from sgbelief.errors import ConfigError
    from sgbelief.eval.formats import ReadStats, iter_events, read_truth
    from sgbelief.eval.replay import format_table, make_runs, replay, score_run
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.graph.persistence import atomic_write_text

    vocab = load_vocab(args.vocab)
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    names = [n.strip() for n in args.operators.split(",") if n.strip()]
    if not names:
        raise ConfigError("--operators: give at least one operator name")
    truth = read_truth(args.truth)
    runs = make_runs(names, vocab, config, strict=not args.allow_unknown_predicates)
    stats = ReadStats()
    progress = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        progress = tqdm(desc="replay", unit="ev", file=sys.stderr)
    try:
        replay(iter_events(args.events, skip_bad_lines=args.skip_bad_lines, stats=stats), runs,
               line_of=stats, source=args.events, progress=progress)
    finally:
        if progress is not None:
            progress.close()
    preds = [p for p in vocab.predicates if any(p in row for row in truth.values())]
    preds += sorted({p for row in truth.values() for p in row} - set(preds))
    scores = {r.name: score_run(r, truth, preds, tau=args.tau) for r in runs}
    print(f"{stats.events} events replayed from {args.events}" + (f" ({stats.skipped} bad lines skipped)" if stats.skipped else ""))
    print(format_table(scores, preds))
    if args.json_out:
        doc = {name: sc.as_dict() for name, sc in scores.items()}
        for d in doc.values():
            d["skipped_lines"] = stats.skipped
        atomic_write_text(args.json_out, json.dumps(doc, indent=2, allow_nan=True))
    if args.save_graph:
        for r in runs:
            r.graph.save(args.save_graph / r.name)
    return 0

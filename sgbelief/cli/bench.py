"""``sgbelief bench``: the simulated suites + real detector confidences, in the paper's table layout."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sgbelief.fusion.registry import OPERATOR_NAMES


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--suite", choices=["outdoor", "indoor", "all"], default="all",
                   help="simulated suite(s) to run: outdoor (KITTI-360-like), indoor (ScanNet-like) or all "
                        "(default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulated suites (default: %(default)s)")
    p.add_argument("--out", type=Path, default=Path("results/bench"),
                   help="output directory (default: %(default)s): results.json, results.md, the figures (PNG), and "
                        "the reusable evidence logs data/<suite>/events.jsonl, truth.json, nodes.json (input for "
                        "'sgbelief replay' and 'sgbelief retrieval --suite')")
    p.add_argument("--operators", default=",".join(OPERATOR_NAMES),
                   help="comma-separated fusion operators (default: %(default)s)")
    p.add_argument("--config", type=Path, default=None,
                   help="operator config YAML (default: configs/operators/default.yaml)")
    p.add_argument("--fm-source", choices=["parametric", "detector_records"], default=None,
                   help="draw the foundation-model channel's (score, correct) pairs from real detector records "
                        "(default: the suite config's choice, parametric)")
    p.add_argument("--scale", type=float, default=None,
                   help="scale the suites' size (e.g. 4 for a bigger run; default: 1, the paper's size)")
    p.add_argument("--no-retrieval", action="store_true", help="skip the compound-query retrieval table (default: run it)")
    p.add_argument("--no-real", action="store_true",
                   help="skip the real detector-confidence calibration report (default: run it)")
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr (default: show it)")
    p.add_argument("--workers", type=int, default=1, help="run the suites in parallel processes (default: %(default)s)")
    p.add_argument("--executor", choices=["local", "ray"], default="local",
                   help="local process pool or a Ray cluster (default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from sgbelief.eval.benchmark import run_bench
    from sgbelief.fusion.config import OperatorConfig

    suites = ["outdoor", "indoor"] if args.suite == "all" else [args.suite]
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    ops = [o.strip() for o in args.operators.split(",") if o.strip()]
    steps = 7 * len(suites) + (0 if args.no_real else 1) + 1
    bar = tqdm(total=steps, desc="bench", unit="step", file=sys.stderr, disable=args.quiet)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg[:60])
        bar.update(1)

    try:
        results = run_bench(suites, seed=args.seed, out=args.out, operators=ops, config=config, fm_source=args.fm_source,
                            scale=args.scale, retrieval=not args.no_retrieval, real_data=not args.no_real, progress=progress,
                            workers=args.workers, executor=args.executor)
    finally:
        bar.close()
    print((args.out / "results.md").read_text())
    print(f"wrote {args.out / 'results.json'}, {args.out / 'results.md'} and {', '.join(results['figures'])} in {args.out}")
    return 0

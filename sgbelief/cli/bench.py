"""``sgbelief bench``: the simulated suites + real detector confidences, in the paper's table layout."""

from __future__ import annotations

import argparse
from pathlib import Path

from sgbelief.cli import _console as console
from sgbelief.fusion.registry import OPERATOR_NAMES


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--suite", choices=["outdoor", "indoor", "realistic", "all"], default="all",
                   help="simulated suite(s) to run: outdoor (KITTI-360-like), indoor (ScanNet-like), realistic "
                        "(real COCO detector records over ScanNet-like rooms: detector x channel {mesh, segmenter, "
                        "none} x confidence {c, c**3}) or all (bench: outdoor and indoor; --grid: all three) "
                        "(default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the simulated suites (default: %(default)s)")
    p.add_argument("--out", type=Path, default=Path("results/bench"),
                   help="output directory (default: %(default)s): results.json, results.md, the figures (PNG), and "
                        "the reusable evidence logs data/<suite>/events.jsonl, truth.json, nodes.json (input for "
                        "'sgbelief replay' and 'sgbelief retrieval --suite')")
    p.add_argument("--operators", default=",".join(OPERATOR_NAMES),
                   help="comma-separated fusion operators (default: %(default)s)")
    p.add_argument("--config", type=Path, default=None,
                   help="operator config YAML (default: sgbelief/configs/operators/default.yaml)")
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
    p.add_argument("--grid", action="store_true",
                   help="run the robustness grid instead: suite x profile {vlm_a, vlm_b} x confidence source "
                        "{parametric, rfcn, ssd} x channel {oracle, segmenter}, every operator, over --seeds; "
                        "writes grid.md and grid.json (default: off)")
    p.add_argument("--seeds", default="100-104",
                   help="with --grid: seeds as a list or range, e.g. 0-2 (development) or 100-104 (held out, the default)")


def parse_seeds(text: str) -> list[int]:
    """``"100-104"`` or ``"0,1,2"`` -> a list of seeds."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            out += list(range(int(lo), int(hi) + 1)) if sep else [int(lo)]
        except ValueError:
            raise SystemExit(f"sgbelief bench: --seeds: {part!r} is not a seed or a range like 100-104") from None
    if not out:
        raise SystemExit("sgbelief bench: --seeds names no seed")
    return out


def run_grid_command(args: argparse.Namespace) -> int:
    import json

    from sgbelief.eval.grid import grid_cells, render_grid, run_grid, summarize
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.graph.persistence import atomic_write_text

    seeds = parse_seeds(args.seeds)
    suites = ["outdoor", "indoor", "realistic"] if args.suite == "all" else [args.suite]
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    cells = grid_cells(suites)
    n_jobs = len({(c.suite, c.source) for c in cells}) * len(seeds)
    bar = console.progress(n_jobs, desc="grid", unit="sim", quiet=args.quiet)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg[:60])
        bar.update(1)

    try:
        rows = run_grid(seeds, cells=cells, config=config, scale=args.scale, workers=args.workers,
                        executor=args.executor, progress=progress)
    finally:
        bar.close()
    summary = summarize(rows)
    note = f"`{args.config}`" if args.config else "the shipped default (sgbelief/configs/operators/default.yaml)"
    md = "# sgbelief robustness grid\n\n" + render_grid(summary, seeds=seeds, config_note=note)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out / "grid.md", md)
    atomic_write_text(args.out / "grid.json", json.dumps({"seeds": seeds, "rows": rows, "summary": summary}, indent=1))
    print(md)
    print(f"wrote {args.out / 'grid.md'} and {args.out / 'grid.json'}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.grid:
        return run_grid_command(args)
    if args.suite == "realistic":
        return run_realistic_command(args)
    from sgbelief.eval.benchmark import run_bench
    from sgbelief.fusion.config import OperatorConfig

    suites = ["outdoor", "indoor"] if args.suite == "all" else [args.suite]
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    ops = [o.strip() for o in args.operators.split(",") if o.strip()]
    steps = 7 * len(suites) + (0 if args.no_real else 1) + 1
    bar = console.progress(steps, desc="bench", unit="step", quiet=args.quiet)

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


def run_realistic_command(args: argparse.Namespace) -> int:
    """``sgbelief bench --suite realistic``: every cell of the realistic suite at ``--seed``."""
    import json

    from sgbelief.eval.realistic_report import render_realistic, run_realistic, summarize_realistic
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.graph.persistence import atomic_write_text

    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    ops = [o.strip() for o in args.operators.split(",") if o.strip()]
    bar = console.progress(12, desc="realistic", unit="cell", quiet=args.quiet)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg[:60])
        bar.update(1)

    try:
        rows = run_realistic([args.seed], ops, transforms=("c", "c3"), config=config, scale=args.scale,
                             progress=progress)
    finally:
        bar.close()
    note = f"`{args.config}`" if args.config else "the shipped default (sgbelief/configs/operators/default.yaml)"
    md = (f"# sgbelief bench: realistic suite (seed {args.seed})\n\nOperator configuration: {note}.\n\n"
          + render_realistic(summarize_realistic(rows), seeds=[args.seed]))
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out / "realistic.md", md)
    atomic_write_text(args.out / "realistic.json", json.dumps({"seed": args.seed, "rows": rows}, indent=1))
    print(md)
    print(f"wrote {args.out / 'realistic.md'} and {args.out / 'realistic.json'}")
    return 0

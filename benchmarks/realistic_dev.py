"""The realistic suite in a developer's loop: one table per (detector, channel, transform).

    python benchmarks/realistic_dev.py --seeds 0-2 --operators majority,refined,cal,comod
    python benchmarks/realistic_dev.py --seeds 0-2 --config my_operators.yaml --transforms c,c3
    python benchmarks/realistic_dev.py --seeds 0 --detectors ssd --channels none --json

Each table gives, per operator, the mean IoU over the eight classes (mean over seeds), the commit
precision per class (pooled over seeds) and where the false commits sit: on nodes whose claims
came with a channel label that decides the predicate (adjudicable), with labels only that do not
(ambiguous), or with no label (unseen). The development seeds (0-2) are the default; report on
100-104. Suite: sgbelief/configs/sim/realistic.yaml (docs/simulation.md, "The realistic suite").
To run operators directly on one cell: ``sgbelief.eval.realistic.realistic_cell(seed, detector,
channel, transform)`` gives ``.events`` (for ``replay``), ``.pairs()`` (for ``op.update_many``),
``.truth``, ``.table`` and ``.predicates``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sgbelief.cli.bench import parse_seeds  # noqa: E402
from sgbelief.eval.realistic_report import render_realistic, run_realistic, summarize_realistic  # noqa: E402
from sgbelief.fusion.config import OperatorConfig  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", default="0-2", help="seeds, e.g. 0-2 (development, default) or 100-104")
    p.add_argument("--operators", default="majority,refined,cal,comod", help="comma-separated operator names")
    p.add_argument("--config", type=Path, default=None, help="operator config YAML (default: the shipped default)")
    p.add_argument("--suite-config", type=Path, default=None,
                   help="realistic suite config YAML (default: sgbelief/configs/sim/realistic.yaml)")
    p.add_argument("--detectors", default="rfcn,ssd", help="detector keys (default: %(default)s)")
    p.add_argument("--channels", default="mesh,segmenter,none", help="channels (default: %(default)s)")
    p.add_argument("--transforms", default="c", help="confidence transforms, e.g. c,c3 (default: %(default)s)")
    p.add_argument("--scale", type=float, default=None, help="multiply the rooms per seed (default: 1)")
    p.add_argument("--json", action="store_true", help="print the per-seed rows as one JSON line at the end")
    args = p.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    config = OperatorConfig.from_yaml(args.config) if args.config else OperatorConfig.default()
    split = lambda s: [x.strip() for x in s.split(",") if x.strip()]  # noqa: E731
    t0 = time.perf_counter()
    rows = run_realistic(seeds, split(args.operators), detectors=split(args.detectors), channels=split(args.channels),
                         transforms=split(args.transforms), config=config, suite_config=args.suite_config,
                         scale=args.scale)
    seconds = time.perf_counter() - t0
    print(render_realistic(summarize_realistic(rows), seeds=seeds))
    print(f"{len(rows)} rows in {seconds:.1f} s ({seconds / len(seeds):.1f} s per seed); operator config: "
          f"{args.config or 'shipped default'}")
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

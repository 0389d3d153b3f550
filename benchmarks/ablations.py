"""Ablations of the calibrated operators (docs/method.md): one mechanism changed at a time.

    python benchmarks/ablations.py --seeds 0-2 --out benchmarks/ablations.md
    python benchmarks/ablations.py --support-table     # docs/method.md §2: commits by support
    python benchmarks/ablations.py --cold-start        # docs/method.md §4: beliefs after n claims

Each row is ``comod`` (or ``cal``) with the shipped default configuration and one setting changed,
on both simulated suites, vlm_a, with the oracle and the segmenter channel; mean IoU over the
suite's evaluated predicates and Brier over pairs with evidence, averaged over the seeds.
The development seeds (0-2) are the default: the held-out seeds are for the grid only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from sgbelief.cli.bench import parse_seeds
from sgbelief.eval.benchmark import SUITES, _run
from sgbelief.eval.simulate import simulate
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig

#: (row label, operator, top-level overrides, calibration overrides)
ABLATIONS: list[tuple[str, str, dict[str, Any], dict[str, Any]]] = [
    ("default comod", "comod", {}, {}),
    ("Eq. 2 reference: slice base rate (paper)", "comod", {}, {"lr_reference": "slice"}),
    ("no support strata (paper taxonomy)", "comod", {}, {"support_strata": 1}),
    ("support strata 2 (first claim vs later)", "comod", {}, {"support_strata": 2}),
    ("support strata 8", "comod", {}, {"support_strata": 8}),
    ("no geometric evidence (refusal only, paper)", "comod", {"geometric_evidence": "none"}, {}),
    ("kappa_hat pooled over levels", "comod", {}, {"kappa_pooling": "pooled"}),
    ("no kappa_hat shrinkage (kappa_min 1)", "comod", {}, {"kappa_min": 1.0}),
    ("target size 10", "comod", {}, {"target_size": 10}),
    ("target size 200", "comod", {}, {"target_size": 200}),
    ("no revision quarantine (tau_rev = 1e9)", "comod", {"tau_rev": 1e9}, {}),
    ("strict revision quarantine (tau_rev = 0.05)", "comod", {"tau_rev": 0.05}, {}),
    ("cold start neutral", "comod", {}, {"cold_start": "neutral"}),
    ("tau_T 0.05", "comod", {"tau_t": 0.05}, {}),
    ("tau_T 0.3", "comod", {"tau_t": 0.3}, {}),
    ("no refusal, no geometric evidence (cal)", "cal", {}, {}),
    ("paper settings (comod_paper)", "comod_paper", {}, {}),
]


def variant(base: OperatorConfig, top: dict[str, Any], cal: dict[str, Any]) -> OperatorConfig:
    return base.model_copy(update={**top, "calibration": base.calibration.model_copy(update=cal)})


def support_table(seed: int = 0) -> str:
    """Committed pairs by the number of claims they received (outdoor, vlm_a, oracle channel)."""
    from collections import Counter

    from sgbelief.eval.replay import graph_probabilities, make_runs, replay

    suite = simulate("outdoor", seed)
    spec = SUITES["outdoor"]
    table = SubsumptionTable.shipped(spec.vocab)
    preds = list(spec.predicates)
    events = suite.events_for("vlm_a", "oracle")
    config = OperatorConfig.default()
    runs = make_runs(["majority", "refined", "cal_paper", "comod_paper", "cal", "comod"], table, config)
    replay(events, runs)
    probs = {r.name: graph_probabilities(r.graph, suite.truth) for r in runs}
    n: Counter[tuple[str, str]] = Counter()
    for e in events:
        if e.predicate in preds:
            for v, m in e.targets.items():
                if m > config.tau_t:
                    n[(v, e.predicate)] += 1
    lines = ["| claims at the pair | pairs | true | " + " | ".join(f"{r.name} TP / FP" for r in runs) + " |",
             "|---" * (len(runs) + 3) + "|"]
    for lo, hi, label in ((1, 1, "1"), (2, 2, "2"), (3, 5, "3-5"), (6, 10, "6-10"), (11, 10**9, "11+")):
        keys = [k for k in n if lo <= n[k] <= hi]
        row = f"| {label} | {len(keys)} | {sum(suite.truth[k[0]][k[1]] for k in keys)} |"
        for r in runs:
            tp = sum(1 for k in keys if probs[r.name][k[0]][k[1]] > config.tau and suite.truth[k[0]][k[1]] == 1)
            fp = sum(1 for k in keys if probs[r.name][k[0]][k[1]] > config.tau and suite.truth[k[0]][k[1]] == 0)
            row += f" {tp} / {fp} |"
        lines.append(row)
    return "\n".join(lines) + "\n"


def cold_start_table() -> str:
    """Beliefs of an always-confirmed detector (c = 0.9, 20 elements in turn) after n claims."""
    from sgbelief import EvidenceEvent, SceneGraph, make_operator
    from sgbelief.fusion import FrameLabels

    vocab = SubsumptionTable.shipped("kitti360")
    lines = ["| operator | first element after 1 / 2 / 3 claims | new element after 60 verified claims: 1 / 2 / 3 |",
             "|---|---|---|"]
    for label, name, cfg in (("comod", "comod", None), ("cal", "cal", None),
                             ("cal, kappa_pooling: pooled", "cal", {"calibration": {"kappa_pooling": "pooled"}}),
                             ("comod_paper", "comod_paper", None)):
        op = make_operator(name, cfg, vocab)
        g = SceneGraph(vocabulary=vocab)
        first = []
        for t in range(60):
            node = f"n{t % 20}"
            op.update(g, EvidenceEvent({node: 1.0}, "is_car", 0.9, "vlm", t), FrameLabels({node: "car"}))
            if t % 20 == 0:
                first.append(g.probability("n0", "is_car"))
        new = []
        for k in range(3):
            op.update(g, EvidenceEvent({"new": 1.0}, "is_car", 0.9, "vlm", 100 + k), FrameLabels({"new": "car"}))
            new.append(g.probability("new", "is_car"))
        lines.append(f"| {label} | " + " / ".join(f"{p:.3f}" for p in first) + " | "
                     + " / ".join(f"{p:.3f}" for p in new) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-2", help="seeds (default: the development seeds 0-2)")
    ap.add_argument("--scale", type=float, default=None, help="scale the suites (smaller: faster, noisier)")
    ap.add_argument("--out", type=Path, default=None, help="write the markdown table here too")
    ap.add_argument("--support-table", action="store_true", help="print docs/method.md's support table (seed 0) and stop")
    ap.add_argument("--cold-start", action="store_true", help="print docs/method.md's cold-start table and stop")
    args = ap.parse_args(argv)
    if args.support_table:
        print(support_table())
        return 0
    if args.cold_start:
        print(cold_start_table())
        return 0
    seeds = parse_seeds(args.seeds)
    base = OperatorConfig.default()
    channels = ("oracle", "segmenter")
    scores: dict[str, dict[tuple[str, str], list[tuple[float, float]]]] = {label: {} for label, *_ in ABLATIONS}
    for suite_name in ("outdoor", "indoor"):
        spec = SUITES[suite_name]
        table = SubsumptionTable.shipped(spec.vocab)
        preds = list(spec.predicates)
        for seed in seeds:
            suite = simulate(suite_name, seed, scale=args.scale)
            for channel in channels:
                events = suite.events_for("vlm_a", channel)
                for label, op, top, cal in ABLATIONS:
                    sc = _run(events, [op], table, suite.truth, preds, variant(base, top, cal))[op]
                    scores[label].setdefault((suite_name, channel), []).append((sc.mean_iou, sc.brier))
            print(f"{suite_name} seed {seed} done", file=sys.stderr, flush=True)
    cols = [(s, c) for s in ("outdoor", "indoor") for c in channels]
    lines = [f"Ablations on seeds {', '.join(map(str, seeds))} (vlm_a): mean IoU / Brier, mean over seeds.", "",
             "| configuration | " + " | ".join(f"{s} {c}" for s, c in cols) + " | mean IoU |",
             "|---" * (len(cols) + 2) + "|"]
    for label, *_ in ABLATIONS:
        cells, ious = [], []
        for col in cols:
            arr = np.array(scores[label][col])
            iou, brier = float(arr[:, 0].mean()), float(arr[:, 1].mean())
            ious.append(iou)
            cells.append(f"{iou:.3f} / {brier:.3f}")
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {np.mean(ious):.3f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out is not None:
        args.out.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

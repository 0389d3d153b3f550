"""Scoring the realistic suite: per cell and operator, mean IoU, per-class precision, and where the
false commits sit (docs/simulation.md, "The realistic suite").

A false commit is a (node, predicate) whose end-of-stream probability exceeds tau while the truth
is 0. It sits where the channel
- **adjudicable**: some claim of that predicate on that node came with a channel label that decides
  the predicate (the vocabulary's outcome is 0 or 1): the channel could have said no;
- **ambiguous**: the channel labelled the node in some claim, but no label decided the predicate
  (otherprop, otherfurniture, otherstructure, shelves, books, box, ...);
- **unseen**: the channel gave no label in any of those claims (or there is no channel).

A second breakdown looks at the node's own NYU40 label, whatever the channel reported: it
**decides** the predicate, is **silent** on it (otherprop, otherfurniture, ...), or the node is
**unannotated**.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from sgbelief.eval.realistic import CHANNELS, RealisticCell, generate_world
from sgbelief.eval.realistic_config import RealisticConfig, load_realistic_config
from sgbelief.eval.replay import make_runs, replay, score_run
from sgbelief.fusion.config import OperatorConfig

__all__ = ["STATUSES", "OBJECT_LABELS", "evidence_status", "score_cell", "run_realistic", "summarize_realistic",
           "render_realistic", "realistic_grid_rows"]

STATUSES = ("adjudicable", "ambiguous", "unseen")
OBJECT_LABELS = ("decides", "silent", "unannotated")


def evidence_status(cell: RealisticCell) -> dict[tuple[str, str], str]:
    """(node, predicate) -> where the channel stood on its claims (one of :data:`STATUSES`)."""
    rank = {"unseen": 0, "ambiguous": 1, "adjudicable": 2}
    out: dict[tuple[str, str], str] = {}
    outcome = cell.table.outcome
    for rec in cell.events:
        for node in rec.targets:
            lab = rec.geometric.get(node)
            s = "unseen" if lab is None else ("ambiguous" if outcome(rec.predicate, lab) is None else "adjudicable")
            key = (node, rec.predicate)
            if rank[s] > rank[out.get(key, "unseen")] or key not in out:
                out[key] = s
    return out


def score_cell(cell: RealisticCell, operators: Sequence[str], config: OperatorConfig | None = None,
               ) -> list[dict[str, Any]]:
    """Replay the cell under each operator; one row per operator (the grid's row shape plus
    ``false_commits``: counts per status, and per true NYU40 label of the node)."""
    config = config or OperatorConfig.default()
    runs = make_runs(list(operators), cell.table, config)
    replay(cell.events, runs)
    status = evidence_status(cell)
    rows = []
    for run in runs:
        sc = score_run(run, cell.truth, cell.predicates, tau=config.tau)
        where: Counter[str] = Counter()
        labels: Counter[str] = Counter()
        per_pred: Counter[str] = Counter()
        own: Counter[str] = Counter()
        prov = run.graph.provenance
        for node, pred in prov.pairs():
            if pred not in cell.predicates or cell.truth.get(node, {}).get(pred, 0) == 1:
                continue
            if prov.mean(node, pred) > config.tau:
                where[status.get((node, pred), "unseen")] += 1
                lab = cell.labels.get(node)
                labels[str(lab)] += 1
                per_pred[pred] += 1
                own["unannotated" if lab is None else "silent" if cell.table.outcome(pred, lab) is None
                    else "decides"] += 1
        rows.append({
            "suite": "realistic", "seed": cell.seed, "profile": cell.transform, "source": cell.detector,
            "channel": cell.channel, "operator": run.name, "mean_iou": sc.mean_iou, "brier": sc.brier,
            "per_predicate": {p: {"iou": s.iou, "precision": s.precision, "recall": s.recall, "tp": s.tp, "fp": s.fp,
                                  "fn": s.fn} for p, s in sc.per_predicate.items()},
            "false_commits": {"total": sum(where.values()), **{k: where.get(k, 0) for k in STATUSES},
                              "by_label": dict(labels.most_common()), "by_predicate": dict(per_pred),
                              "object_label": {k: own.get(k, 0) for k in OBJECT_LABELS}},
            "events": len(cell.events),
        })
    return rows


def run_realistic(
    seeds: Iterable[int], operators: Sequence[str], *, detectors: Sequence[str] | None = None,
    channels: Sequence[str] = CHANNELS, transforms: Sequence[str] = ("c",), config: OperatorConfig | None = None,
    suite_config: RealisticConfig | str | None = None, scale: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Rows for every (seed, detector, channel, transform, operator); one world per seed."""
    cfg = suite_config if isinstance(suite_config, RealisticConfig) else load_realistic_config(
        suite_config or "realistic")
    if scale is not None:
        cfg = cfg.model_copy(update={"scale": scale})
    rows: list[dict[str, Any]] = []
    for seed in seeds:
        world = generate_world(seed, cfg)
        for det in detectors or list(cfg.detection.records):
            for ch in channels:
                for tr in transforms:
                    if progress is not None:
                        progress(f"realistic seed {seed} {det} {ch} {tr}")
                    rows += score_cell(world.cell(det, ch, tr), operators, config)
    return rows


def realistic_grid_rows(seed: int, transforms: Sequence[str], sources: Sequence[str], channels: Sequence[str],
                        operators: Sequence[str], config: dict[str, Any], scale: float | None) -> list[dict[str, Any]]:
    """The grid's job for the realistic suite (profile = confidence transform, source = detector)."""
    return run_realistic([seed], operators, detectors=sources, channels=channels, transforms=transforms,
                         config=OperatorConfig.from_mapping(config), scale=scale)


def _mean(xs: list[float]) -> float:
    xs = [x for x in xs if not math.isnan(x)]
    return float(np.mean(xs)) if xs else math.nan


def summarize_realistic(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, str, str], dict[str, dict[str, Any]]]:
    """(detector, channel, transform) -> operator -> means over seeds: mean IoU, per-class
    precision (pooled tp / (tp + fp) over seeds), false commits summed over seeds."""
    acc: dict[tuple[str, str, str], dict[str, list[dict[str, Any]]]] = {}
    for r in rows:
        acc.setdefault((r["source"], r["channel"], r["profile"]), {}).setdefault(r["operator"], []).append(r)
    out: dict[tuple[str, str, str], dict[str, dict[str, Any]]] = {}
    for key, ops in acc.items():
        out[key] = {}
        for op, rs in ops.items():
            preds = list(rs[0]["per_predicate"])
            prec = {}
            for p in preds:
                tp = sum(r["per_predicate"][p]["tp"] for r in rs)
                fp = sum(r["per_predicate"][p]["fp"] for r in rs)
                prec[p] = tp / (tp + fp) if tp + fp else math.nan
            fc = {k: sum(r["false_commits"][k] for r in rs) for k in ("total", *STATUSES)}
            fc.update({k: sum(r["false_commits"]["object_label"][k] for r in rs) for k in OBJECT_LABELS})
            labels: Counter[str] = Counter()
            for r in rs:
                labels.update(r["false_commits"]["by_label"])
            out[key][op] = {"mean_iou": _mean([r["mean_iou"] for r in rs]), "precision": prec,
                            "false_commits": fc, "false_commit_labels": dict(labels.most_common(5)),
                            "seeds": len(rs), "events": _mean([r["events"] for r in rs])}
    return out


def _f(x: float, d: int = 3) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{d}f}"


def render_realistic(summary: dict[tuple[str, str, str], dict[str, dict[str, Any]]], *, seeds: Sequence[int]) -> str:
    """Markdown: one table per (detector, channel, transform)."""
    lines = [f"Realistic suite, seeds {', '.join(map(str, seeds))}: mean IoU over the eight classes (mean over "
             "seeds), commit precision per class (pooled over seeds; – = nothing committed), and the false "
             "commits (summed over seeds) by where the channel stood on their claims (adjudicable / ambiguous / "
             "unseen) and by the node's own label (decides the predicate / silent on it / unannotated).", ""]
    for (det, ch, tr), ops in summary.items():
        first = next(iter(ops.values()))
        preds = list(first["precision"])
        short = [p.removeprefix("is_").replace("table_or_desk", "table").replace("refrigerator", "fridge")
                 for p in preds]
        lines += [f"### {det} / channel {ch} / confidence {tr} ({first['events']:.0f} events per seed)", "",
                  "| operator | mean IoU | " + " | ".join(f"P {s}" for s in short)
                  + " | false commits | adjudicable / ambiguous / unseen | label decides / silent / none "
                  "| top labels of false commits |",
                  "|---|---|" + "---|" * len(short) + "---|---|---|---|"]
        best = max(ops, key=lambda o: ops[o]["mean_iou"])
        for op, s in ops.items():
            fc = s["false_commits"]
            top = ", ".join(f"{k} {v}" for k, v in s["false_commit_labels"].items())
            name = f"**{op}**" if op == best else op
            lines.append(f"| {name} | {_f(s['mean_iou'])} | " + " | ".join(_f(s["precision"][p], 2) for p in preds)
                         + f" | {fc['total']} | {fc['adjudicable']} / {fc['ambiguous']} / {fc['unseen']} | "
                         f"{fc['decides']} / {fc['silent']} / {fc['unannotated']} | {top} |")
        lines.append("")
    return "\n".join(lines)

"""The robustness grid: suite x model profile x confidence source x geometric channel x seed.

``run_grid(seeds)`` simulates each (suite, seed, confidence source) once and replays every operator
on each of its (profile, channel) views; :func:`summarize` averages the seeds per cell and checks
the method's targets (docs/method.md); :func:`render_grid` writes the tables. Seeds 0-2 are the
development seeds; :data:`HELD_OUT_SEEDS` (100-104) are the ones reported.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.registry import OPERATOR_NAMES, PAPER_OPERATOR_NAMES

__all__ = ["GridCell", "SOURCES", "DEV_SEEDS", "HELD_OUT_SEEDS", "BASELINES", "run_grid", "summarize", "render_grid",
           "grid_cells"]

#: confidence source -> (sim ``fm_source``, detector record file or None)
SOURCES: dict[str, tuple[str, str | None]] = {
    "parametric": ("parametric", None),
    "rfcn": ("detector_records", "rfcn-resnet-101-iou-0.60"),
    "ssd": ("detector_records", "ssd-resnet-50-v1-iou-0.60"),
}
PROFILES = ("vlm_a", "vlm_b")
CHANNELS = ("oracle", "segmenter")
DEV_SEEDS = (0, 1, 2)
HELD_OUT_SEEDS = (100, 101, 102, 103, 104)
BASELINES = ("overwrite", "majority", "naive_bayes", "refined")
#: the predicate whose commit precision the paper reports (0.997 with the panoptic oracle)
PRECISION_PREDICATE = {"outdoor": "is_car", "indoor": "is_chair", "realistic": "is_chair"}
#: the realistic suite's axes (sgbelief.eval.realistic): profile = confidence transform, source = detector
REALISTIC_PROFILES = ("c", "c3")
REALISTIC_SOURCES = ("rfcn", "ssd")
REALISTIC_CHANNELS = ("mesh", "segmenter", "none")


@dataclass(frozen=True, order=True)
class GridCell:
    """One cell of the grid (seeds are averaged within a cell)."""

    suite: str
    profile: str
    source: str
    channel: str

    @property
    def label(self) -> str:
        return f"{self.suite} / {self.profile} / {self.source} / {self.channel}"


def grid_cells(suites: Sequence[str] = ("outdoor", "indoor"), profiles: Sequence[str] = PROFILES,
               sources: Sequence[str] = tuple(SOURCES), channels: Sequence[str] = CHANNELS) -> list[GridCell]:
    """The cells of ``suites``; the realistic suite has its own axes (REALISTIC_*)."""
    sim = [s for s in suites if s != "realistic"]
    cells = [GridCell(*c) for c in itertools.product(sim, profiles, sources, channels)]
    if "realistic" in suites:
        cells += [GridCell("realistic", *c) for c in itertools.product(REALISTIC_PROFILES, REALISTIC_SOURCES,
                                                                        REALISTIC_CHANNELS)]
    return cells


@dataclass(frozen=True)
class _Job:
    suite: str
    seed: int
    source: str
    profiles: tuple[str, ...]
    channels: tuple[str, ...]
    operators: tuple[str, ...]
    config: dict[str, Any]
    scale: float | None


def _run_job(job: _Job) -> list[dict[str, Any]]:
    """Simulate one (suite, seed, source) and score every operator on each (profile, channel) view."""
    if job.suite == "realistic":
        from sgbelief.eval.realistic_report import realistic_grid_rows

        return realistic_grid_rows(job.seed, job.profiles, (job.source,), job.channels, job.operators, job.config,
                                   job.scale)
    from sgbelief.eval.benchmark import SUITES, score_operators
    from sgbelief.eval.sim_config import load_sim_config
    from sgbelief.eval.simulate import simulate
    from sgbelief.fusion.compatibility import SubsumptionTable

    fm_source, records = SOURCES[job.source]
    overrides: dict[str, Any] = {"fm_source": fm_source}
    if records is not None:
        overrides["detector_records"] = records
    if job.scale is not None:
        overrides["scale"] = job.scale
    suite = simulate(load_sim_config(job.suite, **overrides), job.seed)
    spec = SUITES[job.suite]
    table = SubsumptionTable.shipped(spec.vocab)
    preds = list(spec.predicates)
    config = OperatorConfig.from_mapping(job.config)
    rows = []
    for profile, channel in itertools.product(job.profiles, job.channels):
        scores = score_operators(suite.events_for(profile, channel), list(job.operators), table, suite.truth, preds, config)
        for op, sc in scores.items():
            rows.append({
                "suite": job.suite, "seed": job.seed, "profile": profile, "source": job.source, "channel": channel,
                "operator": op, "mean_iou": sc.mean_iou, "brier": sc.brier,
                "per_predicate": {p: {"iou": s.iou, "precision": s.precision, "recall": s.recall}
                                  for p, s in sc.per_predicate.items()},
            })
    return rows


def run_grid(
    seeds: Sequence[int] = HELD_OUT_SEEDS,
    *,
    cells: Sequence[GridCell] | None = None,
    operators: Sequence[str] = OPERATOR_NAMES + PAPER_OPERATOR_NAMES,
    config: OperatorConfig | None = None,
    scale: float | None = None,
    workers: int = 1,
    executor: str = "local",
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """One row per (cell, seed, operator): mean IoU over the suite's evaluated predicates, Brier
    over pairs with evidence, per-predicate IoU / precision / recall."""
    from sgbelief.eval.parallel import run_scenes

    cells = list(cells) if cells is not None else grid_cells()
    config = config or OperatorConfig.default()
    groups: dict[tuple[str, str], tuple[set[str], set[str]]] = {}
    for c in cells:
        prof, chan = groups.setdefault((c.suite, c.source), (set(), set()))
        prof.add(c.profile)
        chan.add(c.channel)
    jobs = [_Job(suite, seed, source, tuple(sorted(prof)), tuple(sorted(chan)), tuple(operators), config.model_dump(), scale)
            for (suite, source), (prof, chan) in groups.items() for seed in seeds]
    wanted = set(cells)
    rows: list[dict[str, Any]] = []
    if workers <= 1 and executor == "local":
        for job in jobs:
            if progress is not None:
                progress(f"{job.suite} seed {job.seed} {job.source}")
            rows += _run_job(job)
    else:
        for out in run_scenes(_run_job, jobs, workers=workers, executor=executor):
            rows += out
            if progress is not None:
                progress("cell done")
    return [r for r in rows if GridCell(r["suite"], r["profile"], r["source"], r["channel"]) in wanted]


def _mean(xs: list[float]) -> float:
    xs = [x for x in xs if not math.isnan(x)]
    return float(np.mean(xs)) if xs else math.nan


def summarize(rows: Sequence[dict[str, Any]], method: str = "comod") -> dict[str, Any]:
    """Per-cell means over seeds and the targets of docs/method.md for ``method``."""
    cells: dict[GridCell, dict[str, dict[str, list[float]]]] = {}
    for r in rows:
        cell = GridCell(r["suite"], r["profile"], r["source"], r["channel"])
        d = cells.setdefault(cell, {}).setdefault(r["operator"], {"mean_iou": [], "brier": [], "precision": []})
        d["mean_iou"].append(r["mean_iou"])
        d["brier"].append(r["brier"])
        d["precision"].append(r["per_predicate"][PRECISION_PREDICATE[r["suite"]]]["precision"])
    table = {cell: {op: {k: _mean(v) for k, v in d.items()} for op, d in ops.items()} for cell, ops in sorted(cells.items())}
    operators = sorted({op for ops in table.values() for op in ops}, key=lambda o: (OPERATOR_NAMES + PAPER_OPERATOR_NAMES).index(o)
                       if o in OPERATOR_NAMES + PAPER_OPERATOR_NAMES else 99)
    six = [o for o in OPERATOR_NAMES if o in operators]
    # a tie counts as the highest (cal and comod often reach the same map)
    wins = {cell.label: all(ops[method]["mean_iou"] >= ops[o]["mean_iou"] for o in six) for cell, ops in table.items()
            if method in ops}
    over = {op: _mean([ops[op]["mean_iou"] for ops in table.values() if op in ops]) for op in operators}
    baselines = [b for b in BASELINES if b in over]
    best_baseline = max(baselines, key=lambda b: over[b]) if baselines else None
    precision = {cell.label: ops[method]["precision"] for cell, ops in table.items()
                 if method in ops and cell.channel == "oracle" and cell.suite == "outdoor"}
    shifts: dict[str, dict[str, float]] = {}
    for cell, ops in table.items():
        if cell.profile != "vlm_a":
            continue
        other = table.get(GridCell(cell.suite, "vlm_b", cell.source, cell.channel))
        if other is None:
            continue
        key = f"{cell.suite} / {cell.source} / {cell.channel}"
        shifts[key] = {op: other[op]["brier"] - ops[op]["brier"] for op in ops if op in other}
    shift_ok = {k: all(abs(v[o]) <= 0.01 for o in ("cal", method) if o in v)
                and all(abs(v[b]) > max(abs(v.get("cal", 0.0)), abs(v.get(method, 0.0))) for b in BASELINES if b in v)
                for k, v in shifts.items()}
    return {
        "method": method,
        "cells": {cell.label: ops for cell, ops in table.items()},
        "operators": operators,
        "mean_over_cells": over,
        "best_baseline": best_baseline,
        "margin": over.get(method, math.nan) - over[best_baseline] if best_baseline else math.nan,
        "wins": wins,
        "commit_precision": precision,
        "brier_shift": shifts,
        "targets": {
            "highest_mean_iou_in_every_cell": bool(wins) and all(wins.values()),
            "mean_margin_over_best_baseline_ge_0.10": bool(best_baseline) and over.get(method, -1) - over[best_baseline] >= 0.10,
            "is_car_commit_precision_ge_0.95": (all(p >= 0.95 for p in precision.values()) if precision else None),
            "calibrated_brier_shift_le_0.01_and_baselines_move_more": bool(shift_ok) and all(shift_ok.values()),
        },
        "shift_ok": shift_ok,
    }


def render_grid(summary: dict[str, Any], *, seeds: Sequence[int], config_note: str) -> str:
    """Markdown: mean IoU per cell and operator (best of the six in bold), the targets, the Brier shifts."""
    ops = summary["operators"]
    six = [o for o in OPERATOR_NAMES if o in ops]
    lines = [f"Seeds {', '.join(map(str, seeds))}; operator configuration: {config_note}.", "",
             "Mean IoU over the suite's evaluated predicates (mean over seeds; best of the six operators in bold).", "",
             "| cell | " + " | ".join(ops) + " |", "|---" * (len(ops) + 1) + "|"]
    for label, row in summary["cells"].items():
        best = max(six, key=lambda o: row[o]["mean_iou"]) if six else None
        cells = [(f"**{row[o]['mean_iou']:.3f}**" if o == best else f"{row[o]['mean_iou']:.3f}") if o in row else "–" for o in ops]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    over = summary["mean_over_cells"]
    lines.append("| **mean over cells** | " + " | ".join(f"{over[o]:.3f}" for o in ops) + " |")
    lines += ["", f"Targets for `{summary['method']}` (best baseline over cells: `{summary['best_baseline']}`, "
              f"margin {summary['margin']:+.3f}):", ""]
    for name, ok in summary["targets"].items():
        verdict = "n/a (no outdoor oracle cell)" if ok is None else "met" if ok else "NOT met"
        lines.append(f"- {name.replace('_', ' ')}: **{verdict}**")
    if summary["commit_precision"]:
        lo = min(summary["commit_precision"].values())
        lines.append(f"- lowest `is_car` commit precision over the outdoor oracle cells: {lo:.3f}")
    lines += ["", "Brier shift under vlm_a → vlm_b (Δ = Brier vlm_b − Brier vlm_a):", "",
              "| suite / source / channel | " + " | ".join(ops) + " |", "|---" * (len(ops) + 1) + "|"]
    for key, v in summary["brier_shift"].items():
        lines.append(f"| {key} | " + " | ".join(f"{v[o]:+.4f}" if o in v else "–" for o in ops) + " |")
    return "\n".join(lines) + "\n"

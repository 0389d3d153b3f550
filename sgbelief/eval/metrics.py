"""Evaluation metrics (pure functions, no operator knowledge).

Conventions on empty sets (chosen so that a class with nothing to find is not scored at all, and
an operator that commits nothing on a class with positives scores 0, as in the paper's tables):

* no positives (R = ∅): IoU, recall and F1 are undefined (nan, shown "n/a"), whatever was
  committed; precision is 0.0 if something was committed (C ≠ ∅), else nan. A mean over classes
  (:func:`mean_iou`) leaves such a class out, so it can neither inflate nor deflate the mean.
* IoU = |C ∩ R| / |C ∪ R|.
* precision = |C ∩ R| / |C|; 0.0 when C = ∅ (and R ≠ ∅).
* recall = |C ∩ R| / |R|.
* F1 = 2PR / (P + R); 0.0 when P + R = 0.

Here C is the committed / retrieved set and R the relevant (true) set.  Calibration metrics share
one binning engine (:func:`reliability_bins`), so the ECE number and the reliability diagram drawn
from the same bins always agree.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "SetScores",
    "ReliabilityBins",
    "CoverageResult",
    "binarize",
    "set_scores",
    "per_predicate_scores",
    "mean_iou",
    "without_positives",
    "brier_score",
    "brier_over_pairs",
    "reliability_bins",
    "expected_calibration_error",
    "conformal_quantile",
    "nll_prediction_sets",
    "conformal_coverage",
    "emission_rate",
    "retrieval_f1",
    "segmentation_iou",
]


@dataclass(frozen=True)
class SetScores:
    """IoU / precision / recall / F1 of a committed set C against a relevant set R."""

    iou: float
    precision: float
    recall: float
    f1: float
    tp: int
    fp: int
    fn: int

    @property
    def has_positives(self) -> bool:
        """Whether the relevant set is non-empty (else IoU, recall and F1 are nan: n/a)."""
        return self.tp + self.fn > 0

    def as_dict(self) -> dict[str, float | int]:
        """Plain dict (JSON-ready; nan where a score is undefined)."""
        return {"iou": self.iou, "precision": self.precision, "recall": self.recall, "f1": self.f1,
                "tp": self.tp, "fp": self.fp, "fn": self.fn}


def _scores(tp: int, fp: int, fn: int) -> SetScores:
    if tp + fn == 0:  # no positives: nothing to find, so no IoU, recall or F1
        precision = 0.0 if fp else math.nan
        return SetScores(math.nan, precision, math.nan, math.nan, tp, fp, fn)
    iou = tp / (tp + fp + fn)
    precision = 0.0 if tp + fp == 0 else tp / (tp + fp)
    recall = tp / (tp + fn)
    f1 = 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)
    return SetScores(iou, precision, recall, f1, tp, fp, fn)


def binarize(probabilities: Mapping[Hashable, float], tau: float = 0.5) -> set[Hashable]:
    """Committed set {v : p(v) > tau} (strict, as the map's commit rule)."""
    return {v for v, p in probabilities.items() if p > tau}


def set_scores(committed: Iterable[Hashable], relevant: Iterable[Hashable]) -> SetScores:
    """IoU, precision, recall and F1 of committed set C against relevant set R (module conventions)."""
    c, r = set(committed), set(relevant)
    tp = len(c & r)
    return _scores(tp, len(c) - tp, len(r) - tp)


def per_predicate_scores(
    probabilities: Mapping[str, Mapping[str, float]],
    truth: Mapping[str, Mapping[str, int]],
    predicates: Sequence[str],
    *,
    tau: float = 0.5,
    prior: float = 0.5,
) -> dict[str, SetScores]:
    """Per-predicate scores of the threshold-binarised map against truth.

    ``probabilities[node][predicate]`` is the end-of-stream posterior mean (missing = ``prior``);
    ``truth[node][predicate]`` in {0, 1}.  The universe of predicate φ is the set of nodes with a
    truth entry for φ; C_φ = {v : p(v, φ) > tau}, R_φ = {v : y(v, φ) = 1}.
    """
    out: dict[str, SetScores] = {}
    for pred in predicates:
        tp = fp = fn = 0
        for node, row in truth.items():
            if pred not in row:
                continue
            p = probabilities.get(node, {}).get(pred, prior)
            committed = p > tau
            y = row[pred] == 1
            if committed and y:
                tp += 1
            elif committed:
                fp += 1
            elif y:
                fn += 1
        out[pred] = _scores(tp, fp, fn)
    return out


def mean_iou(scores: Mapping[str, SetScores]) -> float:
    """Unweighted mean of the per-predicate IoU over the predicates with positives (a class with
    none has no IoU and is left out; nan when no predicate has positives)."""
    vals = [s.iou for s in scores.values() if s.has_positives]
    return float(np.mean(vals)) if vals else math.nan


def without_positives(scores: Mapping[str, SetScores]) -> list[str]:
    """The predicates whose relevant set is empty: IoU n/a, left out of :func:`mean_iou`."""
    return [p for p, s in scores.items() if not s.has_positives]


def brier_score(probabilities: ArrayLike, outcomes: ArrayLike) -> float:
    """Brier score mean((p - y)^2); nan for empty input."""
    p = np.asarray(probabilities, dtype=float)
    y = np.asarray(outcomes, dtype=float)
    if p.shape != y.shape:
        raise ValueError(f"shape mismatch: probabilities {p.shape} vs outcomes {y.shape}")
    return float(np.mean((p - y) ** 2)) if p.size else math.nan


def brier_over_pairs(
    probabilities: Mapping[str, Mapping[str, float]],
    truth: Mapping[str, Mapping[str, int]],
    pairs: Iterable[tuple[str, str]],
    *,
    prior: float = 0.5,
) -> float:
    """Brier score over (node, predicate) pairs that have a truth value (others are ignored)."""
    ps: list[float] = []
    ys: list[int] = []
    for node, pred in pairs:
        y = truth.get(node, {}).get(pred)
        if y is None:
            continue
        ps.append(probabilities.get(node, {}).get(pred, prior))
        ys.append(y)
    return brier_score(ps, ys)


@dataclass(frozen=True)
class ReliabilityBins:
    """Equal-width reliability bins on [0, 1]; empty bins have nan mean confidence / accuracy."""

    edges: NDArray[np.float64]  # (n_bins + 1,)
    centres: NDArray[np.float64]  # (n_bins,)
    mean_confidence: NDArray[np.float64]  # (n_bins,)
    accuracy: NDArray[np.float64]  # (n_bins,) empirical frequency of y = 1
    counts: NDArray[np.int64]  # (n_bins,)

    @property
    def ece(self) -> float:
        """ECE = sum_b (n_b / N) |acc_b - conf_b| over non-empty bins (nan if N = 0)."""
        n = int(self.counts.sum())
        if n == 0:
            return math.nan
        m = self.counts > 0
        return float(np.sum(self.counts[m] / n * np.abs(self.accuracy[m] - self.mean_confidence[m])))


def reliability_bins(confidences: ArrayLike, outcomes: ArrayLike, n_bins: int = 10) -> ReliabilityBins:
    """Bin predictions by confidence into ``n_bins`` equal-width bins (bin b = [b/n, (b+1)/n), last closed).

    Returns per-bin mean confidence, accuracy (mean outcome) and count.
    """
    if n_bins < 1:
        raise ValueError("n_bins must be >= 1")
    c = np.asarray(confidences, dtype=float).ravel()
    y = np.asarray(outcomes, dtype=float).ravel()
    if c.shape != y.shape:
        raise ValueError(f"shape mismatch: confidences {c.shape} vs outcomes {y.shape}")
    if c.size and (not np.all(np.isfinite(c)) or c.min() < 0.0 or c.max() > 1.0):
        raise ValueError("confidences must be finite and in [0, 1]")
    edges = np.linspace(0.0, 1.0, n_bins + 1)
    idx = np.minimum((c * n_bins).astype(np.int64), n_bins - 1)
    counts = np.bincount(idx, minlength=n_bins).astype(np.int64)
    sum_c = np.bincount(idx, weights=c, minlength=n_bins)
    sum_y = np.bincount(idx, weights=y, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_c = np.where(counts > 0, sum_c / np.maximum(counts, 1), np.nan)
        acc = np.where(counts > 0, sum_y / np.maximum(counts, 1), np.nan)
    return ReliabilityBins(edges, (edges[:-1] + edges[1:]) / 2, mean_c, acc, counts)


def expected_calibration_error(confidences: ArrayLike, outcomes: ArrayLike, n_bins: int = 10) -> float:
    """ECE from :func:`reliability_bins` (same bins as the reliability diagram)."""
    return reliability_bins(confidences, outcomes, n_bins).ece


def conformal_quantile(scores: ArrayLike, alpha: float) -> float:
    """Split-conformal threshold: the ceil((n+1)(1-alpha))-th smallest score (inf if that exceeds n).

    Same rule as the operators use (:func:`sgbelief.calibration.conformal.conformal_quantile`).
    """
    from sgbelief.calibration.conformal import conformal_quantile as _quantile

    return _quantile(np.sort(np.asarray(scores, dtype=float).ravel()), alpha)


def nll_prediction_sets(probabilities: ArrayLike, qhat: float, eps: float = 1e-12) -> list[frozenset[int]]:
    """Binary prediction sets {y in {0,1} : -log p(y) <= qhat} for the NLL nonconformity score."""
    p = np.clip(np.asarray(probabilities, dtype=float).ravel(), eps, 1.0 - eps)
    s1, s0 = -np.log(p), -np.log1p(-p)
    return [frozenset(y for y, s in ((0, a), (1, b)) if s <= qhat) for a, b in zip(s0, s1)]


@dataclass(frozen=True)
class CoverageResult:
    """Empirical coverage of prediction sets."""

    coverage: float  # fraction of sets containing the outcome
    mean_set_size: float
    n: int
    empty_fraction: float  # fraction of empty sets


def conformal_coverage(prediction_sets: Sequence[Collection[int]], outcomes: ArrayLike) -> CoverageResult:
    """Coverage P(y in C) and mean |C| over paired prediction sets and outcomes (nan if empty)."""
    y = np.asarray(outcomes).ravel()
    if len(prediction_sets) != y.size:
        raise ValueError(f"{len(prediction_sets)} prediction sets vs {y.size} outcomes")
    if y.size == 0:
        return CoverageResult(math.nan, math.nan, 0, math.nan)
    hits = sum(int(yy) in s for s, yy in zip(prediction_sets, y.tolist()))
    sizes = [len(s) for s in prediction_sets]
    return CoverageResult(hits / y.size, float(np.mean(sizes)), int(y.size), sizes.count(0) / y.size)


def emission_rate(emitted: int, total: int) -> float:
    """Rate of ⊥ emissions (or any event count) per opportunity; 0.0 when total = 0."""
    if emitted < 0 or total < 0:
        raise ValueError("counts must be non-negative")
    return emitted / total if total else 0.0


def retrieval_f1(retrieved: Iterable[Hashable], relevant: Iterable[Hashable]) -> SetScores:
    """Compound-query retrieval scores (set-based precision / recall / F1; module conventions)."""
    return set_scores(retrieved, relevant)


def segmentation_iou(
    true_labels: Sequence[str | None],
    pred_labels: Sequence[str | None],
    classes: Iterable[str] | None = None,
) -> tuple[float, dict[str, float]]:
    """Per-class IoU and mIoU of a labeller over paired observations.

    Observations whose true label is None are ignored; a None prediction is a miss (FN for the
    true class).  IoU_c = TP_c / (TP_c + FP_c + FN_c); mIoU averages over ``classes`` (default:
    classes present in the truth).
    """
    if len(true_labels) != len(pred_labels):
        raise ValueError("true_labels and pred_labels differ in length")
    tp: dict[str, int] = {}
    fp: dict[str, int] = {}
    fn: dict[str, int] = {}
    for t, p in zip(true_labels, pred_labels):
        if t is None:
            continue
        if p == t:
            tp[t] = tp.get(t, 0) + 1
        else:
            fn[t] = fn.get(t, 0) + 1
            if p is not None:
                fp[p] = fp.get(p, 0) + 1
    cls = list(classes) if classes is not None else sorted(set(tp) | set(fn))
    per = {}
    for c in cls:
        denom = tp.get(c, 0) + fp.get(c, 0) + fn.get(c, 0)
        per[c] = tp.get(c, 0) / denom if denom else math.nan
    vals = [v for v in per.values() if not math.isnan(v)]
    return (float(np.mean(vals)) if vals else math.nan), per

"""The shift between a detector's scores and its accuracy, learned from agreement without ground truth.

sgbelief reads a claim's confidence c as the probability that its class is right (Eq. 2's cold
start, log Lambda = logit c). With no geometric channel there is never an outcome to correct that
reading, and many detectors' scores are not on that scale: open-vocabulary detectors report
0.2-0.5 for detections that are mostly right, so every claim counts against its class, and
others are over-confident. A detector's scores often order its detections well while their level
is off: the reading is right up to a shift in log-odds. One parameter per detector context
learns that shift from the map itself, from how often claims on the same element agree:

    p_i = sigmoid(logit c_i + a_w)                                   (claim i's reading, context w)
    P(l_i | z_v = z) = p_i if l_i = z;  (1 - p_i) / (K - 1) otherwise     (errors spread over the K classes)
    log q_v(z) = log pi_z + sum_{i at v} m_i log P(l_i | z) + const       (E-step)
    sum_{i in w} m_i (q_{v_i}(l_i) - p_i) = 0;   pi_z = mean_v q_v(z)     (M-step: a_w by Newton)

q_v is the posterior class of element v given every claim on it, K the classes claimed in the
map, m_i the claim's targeting mass T(v). The M-step equation is the score equation of an
intercept-only logistic regression of the soft outcomes q_v(l_i) on the offsets logit c_i. The
model is Dawid–Skene's with a symmetric ("one-coin") confusion whose accuracy follows the claim's
confidence (:mod:`sgbelief.calibration.dawid_skene`), reduced to one free parameter per context,
which a map of tens of objects identifies. A full confusion, or an isotonic map per cell, does
not identify on such a map (docs/method.md §8, docs/conceptgraphs.md). Only elements with at
least two claims enter the fit: a lone claim agrees or disagrees with nothing.

The reading applies the shift upward only, a_w^+ = max(0, a_w). A per-predicate Beta belief
reads a claim with p < 1/2 as evidence against its class. Among K exclusive classes, the same
claim favours its class over any single rival whenever p > 1/K, since its likelihood ratio
p (K - 1) / (1 - p) is then above 1. Raising a deflated detector's readings brings them closer to
that; lowering an over-confident detector's readings below 1/2 would turn claims that favour their
class into claims counted against it. Measured in ConceptGraphs' own loop with no channel (harness,
main, 10 seeds): the two-sided shift cost 0.03 of label accuracy with uninformative scores, and with
R-FCN's scores it changed nothing (0.756 both ways). docs/method.md §8 has the figures. An over-confident
detector therefore keeps the raw reading; :attr:`ShiftCalibration.readings_` still holds the
fitted a_w, for the summary.

The reading keeps the order of the scores (a strictly increasing map of c). A calibrated
detector's reading stays put (a near 0), and a deflated detector's moves up.

**Scores that say nothing.** Weighing claims by their scores pays only when the scores carry
information about which claims are right. A detector whose scores are unrelated to its accuracy
(an uncalibrated head, a constant-ish score, a score from another task) turns a weighted count into
a count with noise added to every weight: worse than ConceptGraphs' plain vote. Whether the scores
say anything is itself testable on the map. For each claim on an element with other claims, it
agrees when its class is the plurality of the others' (mass-weighted; others tied: left out). If
a context's scores carry information, its agreeing claims score higher than its disagreeing ones:

    H0: the scores of agreeing and disagreeing claims have one distribution
    H1: agreeing claims score stochastically higher                 (one-sided Mann-Whitney U, level alpha)

When the test rejects H0, the context's claims are read as above. When it does not, they are read
at one common level, the same model with the offsets logit c_i replaced by 0: the M-step's root is
then sigmoid(a_w) = sum m_i q_v(l_i) / sum m_i, the context's agreement rate. Every claim of the
context weighs the same, so the map counts claims, as the vote does. As with the shift, that level
never reads the detector below what it states: the reading is max(a_w, mean_i logit c_i) in
log-odds. The test's power grows with the map: in ConceptGraphs' own loop with R-FCN's or SSD's
scores it rejected on all 20 maps of 150 frames, and on 7-9 of 10 maps of 60 frames per branch
(docs/conceptgraphs.md). A map too small to show that its scores mean something is counted.

:class:`ShiftCalibration` answers the same queries as
:class:`~sgbelief.calibration.consensus.ConsensusCalibration` (``likelihood_ratio``,
``likelihood_ratios``, ``fitted``), so the map's consensus (``calibration.consensus.method:
agreement_shift``, :mod:`sgbelief.fusion.consensus`) refits it in batches and weighs silent
claims with it.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import expit
from scipy.stats import mannwhitneyu

from sgbelief.calibration.mondrian import cold_start_log_lr

__all__ = ["ContextReading", "ShiftCalibration", "agreement_rank_test", "fit_agreement_shift",
           "level_log_lr", "shifted_log_lr"]

_exp = math.exp
#: confidences are clipped to [_C_EPS, 1 - _C_EPS] before logit (as the cold start does)
_C_EPS = 1e-6


def shifted_log_lr(c: float, shift: float, log_lr_max: float) -> float:
    """log Lambda of the shifted reading: logit(c) + a, c clipped to [1e-6, 1 - 1e-6] and the result
    to [-log_lr_max, log_lr_max] (the cold start's raw rule, :func:`cold_start_log_lr`, when a = 0)."""
    lo = cold_start_log_lr(c, "raw", math.inf) + shift
    return log_lr_max if lo > log_lr_max else -log_lr_max if lo < -log_lr_max else lo


def level_log_lr(level: float, stated: float, log_lr_max: float) -> float:
    """log Lambda of every claim of a context read at one level (module docstring): max(a_w, mean logit c),
    clipped to [-log_lr_max, log_lr_max]."""
    lo = level if level > stated else stated
    return log_lr_max if lo > log_lr_max else -log_lr_max if lo < -log_lr_max else lo


def agreement_rank_test(tasks: NDArray[np.intp], labels: NDArray[np.intp], confidences: NDArray[np.float64],
                        contexts: NDArray[np.intp], *, weights: NDArray[np.float64] | None = None
                        ) -> dict[int, tuple[float, int, int]]:
    """Per context, whether its scores predict agreement (module docstring): {context: (p-value,
    agreeing claims, disagreeing claims)}.

    A claim on a task with other claims agrees when its label is the plurality of the others' labels,
    each other claim counted with its weight (default 1); claims whose others tie, or whose task has
    no other claim, are left out. The p-value is the one-sided Mann-Whitney U test (scipy, asymptotic
    with continuity correction) that the agreeing claims' confidences are stochastically larger than
    the disagreeing ones'; 1.0 when either group is empty."""
    t = np.asarray(tasks, dtype=np.intp)
    if len(t) == 0:
        return {}
    lab = np.asarray(labels, dtype=np.intp)
    ctx = np.asarray(contexts, dtype=np.intp)
    m = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=np.float64)
    c = np.asarray(confidences, dtype=np.float64)
    _, t = np.unique(t, return_inverse=True)
    _, lab = np.unique(lab, return_inverse=True)
    n_t, k = int(t.max()) + 1, int(lab.max()) + 1
    total = np.zeros((n_t, k))
    np.add.at(total, (t, lab), m)
    agree = np.zeros(len(t), dtype=bool)
    decided = np.zeros(len(t), dtype=bool)
    for lo in range(0, len(t), 4096):  # the others' totals, a block of claims at a time
        sl = slice(lo, lo + 4096)
        rows = np.arange(len(t[sl]))
        others = total[t[sl]]
        others[rows, lab[sl]] -= m[sl]
        top = others.argmax(axis=1)
        best = others[rows, top]
        others[rows, top] = -np.inf
        scale = np.maximum(best, 1.0)
        decided[sl] = (best > 1e-9 * scale) & (best - others.max(axis=1) > 1e-9 * scale)
        agree[sl] = top == lab[sl]
    out = {}
    for w in np.unique(ctx).tolist():
        mine = decided & (ctx == w)
        yes, no = c[mine & agree], c[mine & ~agree]
        p = float(mannwhitneyu(yes, no, alternative="greater").pvalue) if len(yes) and len(no) else 1.0
        out[int(w)] = (p, len(yes), len(no))
    return out


def fit_agreement_shift(tasks: NDArray[np.intp], labels: NDArray[np.intp], confidences: NDArray[np.float64],
                        contexts: NDArray[np.intp], *, weights: NDArray[np.float64] | None = None,
                        n_iter: int = 100, tol: float = 1e-6, bound: float = math.log(1000.0),
                        level_contexts: Collection[int] = ()) -> dict[int, tuple[float, int]]:
    """The shift a_w of each context by EM (module docstring): {context: (a_w, claims in the fit)}.
    For the contexts in ``level_contexts``, a_w is their common level instead: the same EM with their
    offsets logit c_i replaced by 0.

    ``tasks``, ``labels`` (class codes), ``confidences``, ``contexts`` and ``weights`` (the masses
    m_i, default 1) have one entry per claim. Claims on tasks with fewer than two claims are left
    out; a context left with no claim, or whose soft outcomes are all 0 or all 1, gets no shift
    (it is absent from the result, or at ``-bound`` / ``bound``). EM starts from the initial reading
    (a = 0) and stops when no posterior moves by more than ``tol``.
    """
    table = _fit_table(tasks, labels, confidences, contexts, weights, level_contexts)
    if table is None:
        return {}
    n_w = len(table.codes)
    if table.n_classes < 2:  # one class claimed: every claim agrees; no level to learn
        a = np.zeros(n_w)
    else:
        a = _em_shifts(table, n_iter, tol, bound)
    n = np.bincount(table.contexts, minlength=n_w)
    return {int(w): (float(a[j]), int(n[j])) for j, w in enumerate(table.codes)}


def _em_shifts(table: _FitTable, n_iter: int, tol: float, bound: float) -> NDArray[np.float64]:
    """The EM of :func:`fit_agreement_shift` (module docstring) on a table of two classes or more:
    a_w per context, in the order of ``table.codes``."""
    t, lab, ci, m, x = table.tasks, table.labels, table.contexts, table.masses, table.offsets
    n_t, k, n_w = table.n_tasks, table.n_classes, len(table.codes)
    a = np.zeros(n_w)
    cell = t * k + lab  # claim i's entry (v_i, l_i) of the flattened posterior table
    q = np.zeros((n_t, k))
    np.add.at(q.reshape(-1), cell, m)  # initial posterior: the weighted vote
    q /= q.sum(axis=1, keepdims=True)
    at_least, at_most = np.maximum, np.minimum  # np.clip in two calls (docs/performance.md)
    for _ in range(n_iter):
        a = _intercepts(x, q.reshape(-1)[cell], m, ci, n_w, a, bound)  # M-step: a_w
        pi = q.sum(axis=0) / n_t  # M-step: pi_z = mean_v q_v(z)
        p = at_most(at_least(expit(x + a[ci]), 1e-12), 1.0 - 1e-12)
        # E-step: log q_v(z) = log pi_z + sum_i m_i log P(l_i | z), every claim first counted wrong
        log_wrong = m * np.log((1.0 - p) / (k - 1))
        log_lik = np.bincount(t, weights=log_wrong, minlength=n_t)[:, None] + np.log(at_least(pi, 1e-300))
        np.add.at(log_lik.reshape(-1), cell, m * np.log(p) - log_wrong)  # then right where z = l_i
        log_lik -= log_lik.max(axis=1, keepdims=True)
        q_new = np.exp(log_lik)
        q_new /= q_new.sum(axis=1, keepdims=True)
        delta = float(np.abs(q_new - q).max())
        q = q_new
        if delta <= tol:
            break
    return _intercepts(x, q.reshape(-1)[cell], m, ci, n_w, a, bound)


@dataclass(frozen=True)
class _FitTable:
    """The claims that enter the EM (those on tasks with at least two claims), re-coded 0..n-1."""

    tasks: NDArray[np.intp]
    labels: NDArray[np.intp]
    #: each claim's context, as an index into ``codes``
    contexts: NDArray[np.intp]
    masses: NDArray[np.float64]
    #: logit c_i, or 0 for a context read at one level
    offsets: NDArray[np.float64]
    #: the context codes, in order
    codes: NDArray[np.intp]
    n_tasks: int
    n_classes: int


def _fit_table(tasks: NDArray[np.intp], labels: NDArray[np.intp], confidences: NDArray[np.float64],
               contexts: NDArray[np.intp], weights: NDArray[np.float64] | None, level_contexts: Collection[int]
               ) -> _FitTable | None:
    """:func:`fit_agreement_shift`'s claims as the EM reads them; None when none is on a task with
    two claims or more."""
    t = np.asarray(tasks, dtype=np.intp)
    lab = np.asarray(labels, dtype=np.intp)
    ctx = np.asarray(contexts, dtype=np.intp)
    m = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=np.float64)
    c = np.clip(np.asarray(confidences, dtype=np.float64), _C_EPS, 1.0 - _C_EPS)
    if len(t) == 0:
        return None
    keep = np.bincount(t)[t] >= 2
    t, lab, ctx, m, c = t[keep], lab[keep], ctx[keep], m[keep], c[keep]
    if len(t) == 0:
        return None
    _, t = np.unique(t, return_inverse=True)
    _, lab = np.unique(lab, return_inverse=True)
    ctx_codes, ci = np.unique(ctx, return_inverse=True)
    x = np.log(c / (1.0 - c))
    if level_contexts:
        x[np.isin(ctx_codes[ci], np.fromiter(level_contexts, dtype=np.intp))] = 0.0
    return _FitTable(t, lab, ci, m, x, ctx_codes, int(t.max()) + 1, int(lab.max()) + 1)


def _intercepts(x: NDArray[np.float64], y: NDArray[np.float64], m: NDArray[np.float64], ci: NDArray[np.intp],
                n_w: int, a0: NDArray[np.float64], bound: float, steps: int = 50) -> NDArray[np.float64]:
    """Per context j, the root a_j in [-bound, bound] of sum_{i in j} m_i (y_i - sigmoid(x_i + a_j)),
    by Newton from ``a0`` (the left side decreases in a_j: one root, or a bound)."""
    at_least, at_most = np.maximum, np.minimum  # np.clip in two calls (docs/performance.md)
    a = at_most(at_least(np.asarray(a0, dtype=np.float64), -bound), bound)
    target = np.bincount(ci, weights=m * y, minlength=n_w)
    for _ in range(steps):
        p = expit(x + a[ci])
        mp = m * p
        g = target - np.bincount(ci, weights=mp, minlength=n_w)
        h = np.bincount(ci, weights=mp * (1.0 - p), minlength=n_w)
        step = at_most(at_least(g / at_least(h, 1e-12), -1.0), 1.0)
        a = at_most(at_least(a + step, -bound), bound)
        if np.abs(step).max() < 1e-10:
            break
    return a


@dataclass(frozen=True)
class ContextReading:
    """How one detector context's confidences are read, from the last fit (module docstring)."""

    #: the fitted a_w: the log-odds shift when the scores are read, the common level otherwise
    fitted: float
    #: claims in the fit (on elements with at least two claims)
    claims: int
    #: whether the scores are read (the rank test rejected at the configured level, or no test)
    reads_scores: bool
    #: the rank test's one-sided p-value (nan when no test ran)
    p_value: float = math.nan
    #: mean logit c of the claims in the fit: the level the detector states
    stated: float = 0.0

    @property
    def applied_shift(self) -> float:
        """The shift a reading of the scores applies: max(0, a_w), upward only (module docstring)."""
        return self.fitted if self.fitted > 0.0 else 0.0

    def log_lr(self, c: float, log_lr_max: float) -> float:
        """log Lambda of a claim at confidence ``c``: :func:`shifted_log_lr` with :attr:`applied_shift`,
        or :func:`level_log_lr`."""
        if self.reads_scores:
            return shifted_log_lr(c, self.applied_shift, log_lr_max)
        return level_log_lr(self.fitted, self.stated, log_lr_max)


class ShiftCalibration:
    """Each context's reading of its confidences (module docstring), queried like
    :class:`~sgbelief.calibration.consensus.ConsensusCalibration`.

    Parameters
    ----------
    kappa_min : float
        The kappa_hat every answer carries: the cold start's, since no outcome backs the reading.
    lr_max : float
        Lambda_hat is clipped to [1 / lr_max, lr_max] (and the shift to [-log lr_max, log lr_max]).
    test_level : float or None
        Level alpha of the rank test that a context's scores predict agreement
        (:func:`agreement_rank_test`); a context whose test does not reject is read at one level.
        None reads every context's scores (the shift alone).
    """

    def __init__(self, kappa_min: float = 0.05, lr_max: float = 1000.0, test_level: float | None = None) -> None:
        self.kappa_min = kappa_min
        self.log_lr_max = math.log(lr_max)
        self.test_level = test_level
        #: context code -> its reading
        self.readings_: dict[int, ContextReading] = {}

    def fit(self, tasks: NDArray[np.intp], labels: NDArray[np.intp], confidences: NDArray[np.float64],
            contexts: NDArray[np.intp], weights: NDArray[np.float64] | None = None) -> ShiftCalibration:
        """Refit every context's reading on the whole claim table: the rank test
        (:func:`agreement_rank_test`, unless ``test_level`` is None), then :func:`fit_agreement_shift`
        with the contexts the test did not show informative read at one level."""
        t = np.asarray(tasks, dtype=np.intp)
        many = np.bincount(t)[t] >= 2 if len(t) else np.zeros(0, dtype=bool)
        ctx = np.asarray(contexts, dtype=np.intp)
        c = np.clip(np.asarray(confidences, dtype=np.float64), _C_EPS, 1.0 - _C_EPS)
        tests: dict[int, tuple[float, int, int]] = {}
        if self.test_level is not None:
            tests = agreement_rank_test(t[many], np.asarray(labels)[many], c[many], ctx[many],
                                        weights=None if weights is None else np.asarray(weights)[many])
        level = {w for w, (p, _, _) in tests.items() if not p < self.test_level}  # type: ignore[operator]
        fits = fit_agreement_shift(t, labels, c, ctx, weights=weights, bound=self.log_lr_max, level_contexts=level)
        x = np.log(c / (1.0 - c))
        readings = {}
        for w, (a, n) in fits.items():
            mine = many & (ctx == w)
            readings[w] = ContextReading(a, n, w not in level, tests[w][0] if w in tests else math.nan,
                                         float(x[mine].mean()) if mine.any() else 0.0)
        self.readings_ = readings
        return self

    def shift(self, context: int) -> float:
        """The shift the reading applies for a context code whose scores are read: max(0, a_w) (module
        docstring); 0, the raw reading, for a context not fitted or read at one level."""
        found = self.readings_.get(context)
        return found.applied_shift if found is not None and found.reads_scores else 0.0

    def likelihood_ratio(self, c: float, keys: Sequence[int]) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) of a claim with confidence ``c``; ``keys[-1]`` is its context code
        (the coarsest of the consensus' levels)."""
        found = self.readings_.get(keys[-1])
        if found is None:
            return _exp(shifted_log_lr(c, 0.0, self.log_lr_max)), self.kappa_min
        return _exp(found.log_lr(c, self.log_lr_max)), self.kappa_min

    def likelihood_ratios(self, c: np.ndarray, keys: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`likelihood_ratio` of many claims at once."""
        cc = np.clip(np.asarray(c, dtype=np.float64), _C_EPS, 1.0 - _C_EPS)
        codes, inv = np.unique(np.asarray(keys[-1], dtype=np.intp), return_inverse=True)
        shift = np.zeros(len(codes))
        level = np.full(len(codes), np.nan)  # the common level of a context read at one level
        for j, w in enumerate(codes.tolist()):
            found = self.readings_.get(w)
            if found is None:
                continue
            if found.reads_scores:
                shift[j] = found.applied_shift
            else:
                level[j] = level_log_lr(found.fitted, found.stated, math.inf)
        lv = level[inv]
        log_lr = np.where(np.isnan(lv), np.log(cc / (1.0 - cc)) + shift[inv], lv)
        log_lr = np.clip(log_lr, -self.log_lr_max, self.log_lr_max)
        return np.exp(log_lr), np.full(len(cc), self.kappa_min)

    @property
    def fitted(self) -> bool:
        """Whether any context's reading has been fitted."""
        return bool(self.readings_)

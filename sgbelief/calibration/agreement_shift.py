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
detector therefore keeps the raw reading; :attr:`ShiftCalibration.shifts_` still holds the fitted
a_w, for the summary.

The reading keeps the order of the scores (a strictly increasing map of c). A calibrated
detector's reading stays put (a near 0), and a deflated detector's moves up.

:class:`ShiftCalibration` answers the same queries as
:class:`~sgbelief.calibration.consensus.ConsensusCalibration` (``likelihood_ratio``,
``likelihood_ratios``, ``fitted``), so the map's consensus (``calibration.consensus.method:
agreement_shift``, :mod:`sgbelief.fusion.consensus`) refits it in batches and weighs silent
claims with it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import expit

from sgbelief.calibration.mondrian import cold_start_log_lr

__all__ = ["ShiftCalibration", "fit_agreement_shift", "shifted_log_lr"]

_exp = math.exp
#: confidences are clipped to [_C_EPS, 1 - _C_EPS] before logit (as the cold start does)
_C_EPS = 1e-6


def shifted_log_lr(c: float, shift: float, log_lr_max: float) -> float:
    """log Lambda of the shifted reading: logit(c) + a, c clipped to [1e-6, 1 - 1e-6] and the result
    to [-log_lr_max, log_lr_max] (the cold start's raw rule, :func:`cold_start_log_lr`, when a = 0)."""
    lo = cold_start_log_lr(c, "raw", math.inf) + shift
    return log_lr_max if lo > log_lr_max else -log_lr_max if lo < -log_lr_max else lo


def fit_agreement_shift(tasks: NDArray[np.intp], labels: NDArray[np.intp], confidences: NDArray[np.float64],
                        contexts: NDArray[np.intp], *, weights: NDArray[np.float64] | None = None,
                        n_iter: int = 100, tol: float = 1e-6, bound: float = math.log(1000.0)
                        ) -> dict[int, tuple[float, int]]:
    """The shift a_w of each context by EM (module docstring): {context: (a_w, claims in the fit)}.

    ``tasks``, ``labels`` (class codes), ``confidences``, ``contexts`` and ``weights`` (the masses
    m_i, default 1) have one entry per claim. Claims on tasks with fewer than two claims are left
    out; a context left with no claim, or whose soft outcomes are all 0 or all 1, gets no shift
    (it is absent from the result, or at ``-bound`` / ``bound``). EM starts from the initial reading
    (a = 0) and stops when no posterior moves by more than ``tol``.
    """
    t = np.asarray(tasks, dtype=np.intp)
    lab = np.asarray(labels, dtype=np.intp)
    ctx = np.asarray(contexts, dtype=np.intp)
    m = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=np.float64)
    c = np.clip(np.asarray(confidences, dtype=np.float64), _C_EPS, 1.0 - _C_EPS)
    if len(t) == 0:
        return {}
    keep = np.bincount(t)[t] >= 2
    t, lab, ctx, m, c = t[keep], lab[keep], ctx[keep], m[keep], c[keep]
    if len(t) == 0:
        return {}
    _, t = np.unique(t, return_inverse=True)
    _, lab = np.unique(lab, return_inverse=True)
    ctx_codes, ci = np.unique(ctx, return_inverse=True)
    n_t, k, n_w = int(t.max()) + 1, int(lab.max()) + 1, len(ctx_codes)
    x = np.log(c / (1.0 - c))
    a = np.zeros(n_w)
    if k < 2:  # one class claimed: every claim agrees; no level to learn
        return {int(w): (0.0, int(np.sum(ci == j))) for j, w in enumerate(ctx_codes)}
    q = np.zeros((n_t, k))
    np.add.at(q, (t, lab), m)  # initial posterior: the weighted vote
    q /= q.sum(axis=1, keepdims=True)
    for _ in range(n_iter):
        y = q[t, lab]
        a = _intercepts(x, y, m, ci, n_w, a, bound)
        pi = q.mean(axis=0)
        p = expit(x + a[ci])
        p = np.clip(p, 1e-12, 1.0 - 1e-12)
        log_wrong = m * np.log((1.0 - p) / (k - 1))
        log_lik = np.tile(np.log(np.maximum(pi, 1e-300)), (n_t, 1))
        log_lik += np.bincount(t, weights=log_wrong, minlength=n_t)[:, None]
        np.add.at(log_lik, (t, lab), m * np.log(p) - log_wrong)
        log_lik -= log_lik.max(axis=1, keepdims=True)
        q_new = np.exp(log_lik)
        q_new /= q_new.sum(axis=1, keepdims=True)
        delta = float(np.max(np.abs(q_new - q)))
        q = q_new
        if delta <= tol:
            break
    a = _intercepts(x, q[t, lab], m, ci, n_w, a, bound)
    n = np.bincount(ci, minlength=n_w)
    return {int(w): (float(a[j]), int(n[j])) for j, w in enumerate(ctx_codes)}


def _intercepts(x: NDArray[np.float64], y: NDArray[np.float64], m: NDArray[np.float64], ci: NDArray[np.intp],
                n_w: int, a0: NDArray[np.float64], bound: float, steps: int = 50) -> NDArray[np.float64]:
    """Per context j, the root a_j in [-bound, bound] of sum_{i in j} m_i (y_i - sigmoid(x_i + a_j)),
    by Newton from ``a0`` (the left side decreases in a_j: one root, or a bound)."""
    a = np.clip(np.asarray(a0, dtype=np.float64).copy(), -bound, bound)
    target = np.bincount(ci, weights=m * y, minlength=n_w)
    for _ in range(steps):
        p = expit(x + a[ci])
        g = target - np.bincount(ci, weights=m * p, minlength=n_w)
        h = np.bincount(ci, weights=m * p * (1.0 - p), minlength=n_w)
        step = np.clip(g / np.maximum(h, 1e-12), -1.0, 1.0)
        a = np.clip(a + step, -bound, bound)
        if np.max(np.abs(step)) < 1e-10:
            break
    return a


class ShiftCalibration:
    """Each context's shifted reading of its confidences (module docstring), queried like
    :class:`~sgbelief.calibration.consensus.ConsensusCalibration`.

    Parameters
    ----------
    kappa_min : float
        The kappa_hat every answer carries: the cold start's, since no outcome backs the reading.
    lr_max : float
        Lambda_hat is clipped to [1 / lr_max, lr_max] (and the shift to [-log lr_max, log lr_max]).
    """

    def __init__(self, kappa_min: float = 0.05, lr_max: float = 1000.0) -> None:
        self.kappa_min = kappa_min
        self.log_lr_max = math.log(lr_max)
        #: context code -> (shift a_w, claims in its fit)
        self.shifts_: dict[int, tuple[float, int]] = {}

    def fit(self, tasks: NDArray[np.intp], labels: NDArray[np.intp], confidences: NDArray[np.float64],
            contexts: NDArray[np.intp], weights: NDArray[np.float64] | None = None) -> ShiftCalibration:
        """Refit every context's shift on the whole claim table (:func:`fit_agreement_shift`)."""
        self.shifts_ = fit_agreement_shift(tasks, labels, confidences, contexts, weights=weights,
                                           bound=self.log_lr_max)
        return self

    def shift(self, context: int) -> float:
        """The shift the reading applies for a context code: max(0, a_w) (module docstring); 0, the
        raw reading, for a context not fitted."""
        found = self.shifts_.get(context)
        return max(0.0, found[0]) if found is not None else 0.0

    def likelihood_ratio(self, c: float, keys: Sequence[int]) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) of a claim with confidence ``c``; ``keys[-1]`` is its context code
        (the coarsest of the consensus' levels)."""
        return _exp(shifted_log_lr(c, self.shift(keys[-1]), self.log_lr_max)), self.kappa_min

    def likelihood_ratios(self, c: np.ndarray, keys: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`likelihood_ratio` of many claims at once."""
        cc = np.clip(np.asarray(c, dtype=np.float64), _C_EPS, 1.0 - _C_EPS)
        shift = np.array([self.shift(int(w)) for w in np.asarray(keys[-1]).tolist()], dtype=np.float64)
        log_lr = np.clip(np.log(cc / (1.0 - cc)) + shift, -self.log_lr_max, self.log_lr_max)
        return np.exp(log_lr), np.full(len(cc), self.kappa_min)

    @property
    def fitted(self) -> bool:
        """Whether any context's shift has been fitted."""
        return bool(self.shifts_)

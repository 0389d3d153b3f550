"""The isotonic calibrator p_hat(y = 1 | c) of one Mondrian slice and the likelihood ratio of Eq. 2 (§4.1).

A slice's outcomes (c, y) are held by an :class:`IsotonicStore`: the last ``capacity`` of them in
arrival order, and the isotonic fit on them as knots (ascending confidences, calibrated
probabilities; p_hat between knots is the linear interpolation, :func:`interpolate`). Two stores
give the same knots:

- :class:`RefitIsotonic` (the reference, the default): every fit is a fresh fit of an
  :class:`IsotonicEstimator` on the held outcomes, by default scikit-learn's
  ``IsotonicRegression(y_min=0, y_max=1, out_of_bounds="clip")`` (:class:`ScikitLearnIsotonic`);
- the incremental merge of :mod:`sgbelief._fast.isotonic`, which the fast engine injects
  (``MondrianCalibrator(..., isotonic=IncrementalIsotonic)``); it is proven equal to the reference
  by hypothesis (:func:`sgbelief.testing.check_isotonic_matches_reference`).

Eq. 2 turns p_hat into a likelihood ratio with Bayes' rule (:func:`calibrated_log_lr`), p_hat and
the base rate clipped to [eps, 1 - eps] with eps = 1 / (2 (n + 1)) (:func:`probability_clip`).
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_right
from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = [
    "IsotonicEstimator",
    "IsotonicStore",
    "IsotonicStoreFactory",
    "RefitIsotonic",
    "ScikitLearnIsotonic",
    "base_rate_log_odds",
    "calibrated_log_lr",
    "interpolate",
    "probability_clip",
]

_log = math.log


# ------------------------------------------------------------------------------- Eq. 2
def calibrated_log_lr(p_hat: float, eps: float, log_reference_odds: float) -> float:
    """Eq. 2: the calibrated likelihood ratio, as log Lambda_hat, from the isotonic calibrator.

    Eq. 2 is Lambda_hat(e) = p_hat(c | y = 1) / p_hat(c | y = 0). The conditional densities are
    recovered by Bayes' rule from the isotonic calibrated probability p_hat = p_hat(y = 1 | c) and
    the class base rate pi, the probability of y = 1 before the claim's confidence is seen::

        Lambda_hat = [p_hat / (1 - p_hat)] * [(1 - pi) / pi]
        log Lambda_hat = log(p_hat / (1 - p_hat)) - log_reference_odds

    with p_hat clipped to [eps, 1 - eps], so the ratio is always finite and positive.

    Parameters
    ----------
    p_hat : float
        The calibrated probability at the claim's confidence (:func:`interpolate`).
    eps : float
        The clip of p_hat (:func:`probability_clip`).
    log_reference_odds : float
        log(pi / (1 - pi)): the slice's base rate among claims (the paper's reading,
        ``lr_reference: slice``, :func:`base_rate_log_odds`) or 0, the odds of the Beta(1, 1) prior
        (``uniform``, the default; derivation in docs/method.md).

    Returns
    -------
    float
        log Lambda_hat, finite.
    """
    if p_hat < eps:
        p_hat = eps
    elif p_hat > 1.0 - eps:
        p_hat = 1.0 - eps
    return _log(p_hat / (1.0 - p_hat)) - log_reference_odds


def probability_clip(n: int) -> float:
    """eps = 1 / (2 (n + 1)): the clip of p_hat and of the base rate in Eq. 2 for a fit on n outcomes
    (half an outcome's worth of probability, so log-odds stay finite on a pure slice)."""
    return 0.5 / (n + 1)


def base_rate_log_odds(n_pos: int, n: int, eps: float) -> float:
    """log(pi / (1 - pi)) of the base rate pi = n_pos / n clipped to [eps, 1 - eps] (Eq. 2's
    reference odds with ``lr_reference: slice``)."""
    pi = min(max(n_pos / n, eps), 1.0 - eps)
    return _log(pi / (1.0 - pi))


def interpolate(kx: Sequence[float], ky: Sequence[float], c: float) -> float:
    """p_hat(c) from the knots of an isotonic fit: linear between knots, constant beyond them
    (scikit-learn's ``predict`` with ``out_of_bounds="clip"``); bisection, O(log n)."""
    i = bisect_right(kx, c)
    if i == 0:
        return ky[0]
    if i >= len(kx):
        return ky[-1]
    x0, x1 = kx[i - 1], kx[i]
    if x1 == x0:
        return ky[i]
    return ky[i - 1] + (ky[i] - ky[i - 1]) * (c - x0) / (x1 - x0)


# ------------------------------------------------------------------- the estimator
@runtime_checkable
class IsotonicEstimator(Protocol):
    """An isotonic (non-decreasing) regression of y in {0, 1} on the confidences c, as knots."""

    def fit_knots(self, c: np.ndarray, y: np.ndarray) -> tuple[list[float], list[float]]:
        """Fit on outcomes in any order; return the knots (ascending confidences, fitted values in [0, 1])."""
        ...


class ScikitLearnIsotonic:
    """The default :class:`IsotonicEstimator`: ``sklearn.isotonic.IsotonicRegression`` with
    ``y_min=0, y_max=1, out_of_bounds="clip"``, its ``X_thresholds_`` / ``y_thresholds_`` as knots.

    scikit-learn pools confidences less than its float resolution (1e-15) apart into one point and
    runs scipy's pool-adjacent-violators (``scipy.optimize.isotonic_regression``) on the distinct
    points, weighted by their counts.
    """

    __slots__ = ()

    def fit_knots(self, c: np.ndarray, y: np.ndarray) -> tuple[list[float], list[float]]:
        from sklearn.isotonic import IsotonicRegression  # imported when first fitted (import time)

        iso = IsotonicRegression(increasing=True, y_min=0.0, y_max=1.0, out_of_bounds="clip")
        iso.fit(np.asarray(c, dtype=np.float64), np.asarray(y, dtype=np.float64))
        return iso.X_thresholds_.tolist(), iso.y_thresholds_.tolist()


# ----------------------------------------------------------------------- the store
@runtime_checkable
class IsotonicStore(Protocol):
    """The outcomes one slice's isotonic fit rests on, and that fit.

    A store holds the last ``capacity`` outcomes merged (all of them when ``capacity`` is None).
    Implementations must give the same knots for the same held outcomes.
    """

    capacity: int | None

    def merge(self, c: array, y: array) -> None:
        """Add a batch of outcomes (confidences ``array("d")``, labels ``array("b")``, arrival order),
        then keep the last ``capacity``."""
        ...

    def clear(self) -> None:
        """Forget every outcome held."""
        ...

    def knots(self) -> tuple[list[float], list[float]]:
        """The isotonic fit p_hat(y = 1 | c) on the held outcomes, as knots."""
        ...

    @property
    def n(self) -> int:
        """Outcomes held."""
        ...

    @property
    def n_pos(self) -> int:
        """Positive outcomes (y = 1) held."""
        ...

    def window(self) -> tuple[Sequence[float], Sequence[int]]:
        """The held outcomes in arrival order: (confidences, labels)."""
        ...

    def sorted_by_label(self, label: int) -> np.ndarray:
        """The held confidences of outcomes y = ``label``, ascending."""
        ...


#: what a slice is given to make its store: ``factory(capacity)``
IsotonicStoreFactory = Callable[[int | None], IsotonicStore]


class RefitIsotonic:
    """The reference :class:`IsotonicStore`: the held outcomes in arrival order, refitted from
    scratch by an :class:`IsotonicEstimator` (default :class:`ScikitLearnIsotonic`) at every fit.

    Parameters
    ----------
    capacity : int or None
        Outcomes kept (the most recent); None keeps all.
    estimator : IsotonicEstimator, optional
        The isotonic regression.
    """

    __slots__ = ("capacity", "estimator", "_c", "_y")

    def __init__(self, capacity: int | None = None, estimator: IsotonicEstimator | None = None) -> None:
        self.capacity = capacity
        self.estimator: IsotonicEstimator = estimator if estimator is not None else ScikitLearnIsotonic()
        self._c = np.empty(0, dtype=np.float64)
        self._y = np.empty(0, dtype=np.int8)

    def merge(self, c: array, y: array) -> None:
        cs = np.concatenate((self._c, np.frombuffer(c, dtype=np.float64)))
        ys = np.concatenate((self._y, (np.frombuffer(y, dtype=np.int8) != 0).astype(np.int8)))
        if self.capacity is not None and len(cs) > self.capacity:
            cs, ys = cs[-self.capacity :], ys[-self.capacity :]
        self._c, self._y = cs, ys

    def clear(self) -> None:
        self._c = np.empty(0, dtype=np.float64)
        self._y = np.empty(0, dtype=np.int8)

    def knots(self) -> tuple[list[float], list[float]]:
        if not len(self._c):
            return [], []
        return self.estimator.fit_knots(self._c, self._y)

    @property
    def n(self) -> int:
        return len(self._c)

    @property
    def n_pos(self) -> int:
        return int(np.count_nonzero(self._y))

    def window(self) -> tuple[list[float], list[int]]:
        return self._c.tolist(), self._y.tolist()

    def sorted_by_label(self, label: int) -> np.ndarray:
        return np.sort(self._c[self._y == (1 if label else 0)])

"""One Mondrian slice of the calibration buffer C: its outcomes, p_hat(y = 1 | c) and Eq. 1's scores (§4.1)."""

from __future__ import annotations

from array import array
from bisect import bisect_right
from collections.abc import Sequence

import numpy as np

from sgbelief.calibration.conformal import ConformalSlice, nonconformity
from sgbelief.calibration.isotonic import (
    IsotonicStore,
    IsotonicStoreFactory,
    RefitIsotonic,
    base_rate_log_odds,
    calibrated_log_lr,
    interpolate,
    probability_clip,
)

__all__ = ["CalibrationSlice"]


class CalibrationSlice:
    """One slice of the calibration buffer: outcomes (c, y), the isotonic fit and the conformal scores.

    New outcomes wait in ``c`` / ``y`` (their scores, Eq. 1, in ``conformal.pending``).
    :meth:`refit` commits them: ``n_fit``, the clip ``eps`` of Eq. 2 and the gap to the next refit
    change at once, while the isotonic fit is computed when next read (``kx``, ``ky``, ``log_lr``,
    ``base_rate``, ...), every batch committed since merged into the store in one go. The fit
    depends on the held outcomes only, so this equals a fit per batch, and a slice nobody reads
    (a pool behind a full-weight slice) costs O(1) per outcome.

    Parameters
    ----------
    alpha : float
        The conformal miscoverage level (the adaptive level alpha_t starts there).
    capacity : int or None
        Outcomes kept, the most recent (a sliding window); None keeps all.
    min_refit, refit_growth : int, float
        Refit once the pending outcomes reach max(min_refit, refit_growth * n_fit): O(log n) fits.
    isotonic : IsotonicStoreFactory
        Makes the store of the outcomes and the fit, ``isotonic(capacity)``: the reference
        :class:`~sgbelief.calibration.isotonic.RefitIsotonic` (default) or the fast engine's
        incremental merge.
    """

    __slots__ = (
        "c", "y", "pending_scores", "batches", "n_batch", "store", "capacity", "n_fit", "n_seen_fit", "stale",
        "_kx", "_ky", "_base_rate", "_log_prior_odds", "eps", "conformal", "min_refit", "refit_growth", "refit_gap",
    )

    def __init__(
        self,
        alpha: float,
        capacity: int | None = None,
        *,
        min_refit: int = 8,
        refit_growth: float = 0.1,
        isotonic: IsotonicStoreFactory = RefitIsotonic,
    ) -> None:
        self.c = array("d")
        self.y = array("b")
        self.conformal = ConformalSlice(alpha, capacity)
        #: the pending scores (Eq. 1), ``conformal.pending``
        self.pending_scores: array = self.conformal.pending
        #: batches (c, y) committed by ``refit`` and not merged into the store yet, and their total size
        self.batches: list[tuple[array, array]] = []
        self.n_batch = 0
        #: the outcomes the fit rests on, and the fit
        self.store: IsotonicStore = isotonic(capacity)
        self.capacity = capacity
        #: outcomes in the fitted window (committed) and outcomes ever committed
        self.n_fit = 0
        self.n_seen_fit = 0
        #: committed batches wait to be merged (the fit below is out of date)
        self.stale = False
        self._kx: list[float] = []
        self._ky: list[float] = []
        self._base_rate = 0.5
        self._log_prior_odds = 0.0
        #: clip of p_hat and of the base rate in Eq. 2 (``probability_clip(n_fit)``)
        self.eps = 0.5
        self.min_refit = min_refit
        self.refit_growth = refit_growth
        #: refit once ``n - n_fit >= refit_gap`` = max(min_refit, refit_growth * n_fit) (0: never fitted)
        self.refit_gap: float = 0

    # ------------------------------------------------------------ counters
    @property
    def n(self) -> int:
        """Outcomes held (the fitted window plus those waiting for the next refit)."""
        return self.n_fit + len(self.c)

    @property
    def n_seen(self) -> int:
        """Outcomes ever added (held or slid out)."""
        return self.n_seen_fit + len(self.c)

    @property
    def n_pos(self) -> int:
        """Positive outcomes held (fitted window plus pending)."""
        if self.stale:
            self.fit()
        return self.store.n_pos + sum(self.y)

    # ------------------------------------------------------ the fit (lazy)
    @property
    def kx(self) -> list[float]:
        """Knots of p_hat: confidences, ascending."""
        if self.stale:
            self.fit()
        return self._kx

    @property
    def ky(self) -> list[float]:
        """Knots of p_hat: calibrated probabilities."""
        if self.stale:
            self.fit()
        return self._ky

    @property
    def base_rate(self) -> float:
        """Share of positive outcomes in the fitted window."""
        if self.stale:
            self.fit()
        return self._base_rate

    @property
    def log_prior_odds(self) -> float:
        """log(pi / (1 - pi)), pi the base rate clipped to [eps, 1 - eps]."""
        if self.stale:
            self.fit()
        return self._log_prior_odds

    @property
    def window_confidences(self) -> Sequence[float]:
        """The fitted window's confidences in arrival order."""
        if self.stale:
            self.fit()
        return self.store.window()[0]

    @property
    def window_labels(self) -> Sequence[int]:
        """The fitted window's labels in arrival order."""
        if self.stale:
            self.fit()
        return self.store.window()[1]

    @property
    def sorted_negatives(self) -> np.ndarray:
        """Fitted confidences of outcomes y = 0, ascending."""
        if self.stale:
            self.fit()
        return self.store.sorted_by_label(0)

    @property
    def sorted_positives(self) -> np.ndarray:
        """Fitted confidences of outcomes y = 1, ascending."""
        if self.stale:
            self.fit()
        return self.store.sorted_by_label(1)

    # ---------------------------------------------------------------- data
    def add(self, c: float, y: int) -> None:
        """Append one outcome (committed by the next :meth:`refit`), with its score of Eq. 1."""
        self.add_scored(c, y, nonconformity(c, y), refit=False)

    def add_scored(self, c: float, y: int, score: float, *, refit: bool = True) -> None:
        """Append one outcome and its score ``nonconformity(c, y)``; with ``refit``, refit once the
        pending outcomes reach the refit gap (the calibrator's schedule)."""
        cs = self.c
        cs.append(c)
        self.y.append(y)
        self.pending_scores.append(score)
        if refit and len(cs) >= self.refit_gap:
            self.refit()

    def refit(self) -> None:
        """Commit the pending outcomes; the isotonic fit p_hat(y = 1 | c) on the whole slice is
        computed when next read."""
        cs = self.c
        if cs:
            self.batches.append((cs, self.y))
            self.n_batch += len(cs)
            self.c = array("d")
            self.y = array("b")
            self.n_seen_fit += len(cs)
            n = self.n_fit + len(cs)
            cap = self.capacity
            if cap is not None:
                if n > cap:
                    n = cap
                if self.n_batch >= cap:  # the committed batches alone fill the window: the merged outcomes all slide out
                    self.store.clear()
                    batches = self.batches
                    while self.n_batch - len(batches[0][0]) >= cap:
                        self.n_batch -= len(batches.pop(0)[0])
            self.n_fit = n
            self.stale = True
        else:  # nothing new: the same fit
            n = self.n_fit
            if not n:
                raise ZeroDivisionError("division by zero: refit of an empty calibration slice")
        self.conformal.refresh()
        self.refit_gap = max(self.min_refit, self.refit_growth * n)
        self.eps = probability_clip(n)

    def fit(self) -> None:
        """Merge the committed batches into the store; read its knots and the base rate."""
        batches = self.batches
        if batches:
            cs, ys = batches[0]
            for c2, y2 in batches[1:]:
                cs += c2
                ys += y2
            self.batches = []
            self.n_batch = 0
            store = self.store
            store.merge(cs, ys)
            self._kx, self._ky = store.knots()
            n, n_pos = self.n_fit, store.n_pos
            self._base_rate = n_pos / n
            self._log_prior_odds = base_rate_log_odds(n_pos, n, self.eps)
        self.stale = False

    # ------------------------------------------------------------- queries
    def p_hat(self, c: float) -> float:
        """Isotonic calibrated probability at c (:func:`~sgbelief.calibration.isotonic.interpolate`)."""
        if self.stale:
            self.fit()
        return interpolate(self._kx, self._ky, c)

    def log_lr(self, c: float, reference: bool = True) -> float:
        """log Lambda_hat(c) of Eq. 2 (:func:`~sgbelief.calibration.isotonic.calibrated_log_lr`)
        against the slice's base rate; ``reference=False`` keeps the calibrated posterior odds
        (the base rate not divided out: odds against the uniform Beta(1, 1) prior)."""
        if self.stale:
            self.fit()
        kx, ky = self._kx, self._ky
        i = bisect_right(kx, c)  # interpolate(kx, ky, c), inlined: this runs once per claim and level
        if i == 0:
            p = ky[0]
        elif i >= len(kx):
            p = ky[-1]
        else:
            x0, x1 = kx[i - 1], kx[i]
            p = ky[i] if x1 == x0 else ky[i - 1] + (ky[i] - ky[i - 1]) * (c - x0) / (x1 - x0)
        return calibrated_log_lr(p, self.eps, self._log_prior_odds if reference else 0.0)

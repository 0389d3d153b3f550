"""Calibration from agreement: p_hat(y = 1 | c) fitted on consensus outcomes where the channel is silent.

Where the geometric channel cannot adjudicate a claim (no label at (v, t), or a label such as
``otherprop`` that neither corroborates nor contradicts the predicate), §4.1's calibration has no
outcome y. The claims it does adjudicate are a biased sample: elements the channel labels decisively
are the well-observed ones, and claims on them are right far more often than claims on clutter
nobody can adjudicate. Calibrating the silent claims on the adjudicated ones over-trusts them.

Here the outcome of a silent claim of phi at v is the map-wide consensus instead: the posterior
q_v(phi) that v is of class phi under a Dawid–Skene model fitted on every claim of the map and
every label the channel gave (:class:`~sgbelief.calibration.dawid_skene.DawidSkene`). Given the
consensus outcomes, the calibration is §4.1's, cell by cell:

    p_hat_cell(c) = isotonic regression of q on c over the claims of the cell        (soft targets)
    log Lambda_hat(c) = logit p_hat(c)                        (Eq. 2, uniform reference, docs/method.md)

shrunk from the finest level toward coarser ones and finally the cold-start rule exactly as the
Mondrian calibrator does (:mod:`sgbelief.calibration.mondrian`), with l = min(1, n / target_size)::

    log Lambda = l_1 log L_1 + (1 - l_1) [l_2 log L_2 + (1 - l_2) log L_cold]

The levels, finest first, are the claim's Mondrian cell (context, support stratum, adjudication
status, standing among the exclusive classes claimed at v; ``sgbelief.fusion.rules.consensus_cell``)
per predicate, the same cell pooled over predicates, and every silent claim of the context. The fit is a batch computation over the claim table,
repeated on a geometric schedule by the operator (``sgbelief.fusion.consensus``), never per event.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import isotonic_regression

from sgbelief.calibration.isotonic import calibrated_log_lr, interpolate, probability_clip
from sgbelief.calibration.mondrian import cold_start_log_lr

__all__ = ["ConsensusCalibration", "fit_cell"]

_exp = math.exp


def fit_cell(c: np.ndarray, q: np.ndarray, w: np.ndarray | None = None) -> tuple[list[float], list[float]]:
    """Isotonic regression of the soft outcomes ``q`` on the confidences ``c`` (weights ``w``), as knots.

    The weighted least-squares isotonic fit of targets in [0, 1] is the maximum-likelihood
    non-decreasing p(c) for Bernoulli outcomes with those expectations (scipy's public
    pool-adjacent-violators, ``scipy.optimize.isotonic_regression``). Equal confidences are pooled
    first (their weighted mean target), so the knots are strictly increasing in c.
    """
    order = np.argsort(c, kind="stable")
    cs, qs = c[order], q[order]
    ws = np.ones_like(cs) if w is None else w[order]
    x, start = np.unique(cs, return_index=True)
    wsum = np.add.reduceat(ws, start)
    ymean = np.add.reduceat(ws * qs, start) / wsum
    fitted = isotonic_regression(ymean, weights=wsum, increasing=True).x  # targets in [0, 1]: so is the fit
    return x.tolist(), fitted.tolist()


class ConsensusCalibration:
    """Per-cell isotonic calibrators fitted on consensus outcomes, queried like the Mondrian calibrator.

    Parameters
    ----------
    target_size : int
        A level's shrinkage weight is l = min(1, n / target_size) (n: claims in its cell).
    kappa_min : float
        Floor of kappa_hat (the pooled share of the estimate resting on fitted cells).
    lr_max : float
        Lambda_hat is clipped to [1 / lr_max, lr_max].
    cold_start : {"raw", "neutral"}
        The rule the coarsest level shrinks toward (:func:`~sgbelief.calibration.mondrian.cold_start_log_lr`).
    """

    def __init__(self, target_size: int = 50, kappa_min: float = 0.05, lr_max: float = 1000.0,
                 cold_start: str = "raw") -> None:
        self.target_size = target_size
        self.kappa_min = kappa_min
        self.log_lr_max = math.log(lr_max)
        self.cold_start = cold_start
            #: (level, cell key) -> (knots x, knots y, n, eps)
        self.fits_: dict[tuple[int, int], tuple[list[float], list[float], int, float]] = {}
        self.n_fit_ = 0

    def fit(self, levels: Sequence[np.ndarray], c: np.ndarray, q: np.ndarray,
            w: np.ndarray | None = None) -> ConsensusCalibration:
        """Refit every cell from scratch. ``levels[l][i]`` is claim i's integer cell key at level l
        (finest level first, e.g. cell and predicate, cell, context); ``c`` the confidences, ``q`` the
        consensus outcomes, ``w`` optional weights. A fit is stored under (l, key)."""
        c = np.asarray(c, dtype=np.float64)
        q = np.asarray(q, dtype=np.float64)
        w = np.ones_like(c) if w is None else np.asarray(w, dtype=np.float64)
        fits = {}
        for lvl, keys in enumerate(levels):
            keys = np.asarray(keys, dtype=np.int64)
            order = np.argsort(keys, kind="stable")
            uniq, starts = np.unique(keys[order], return_index=True)
            ends = np.append(starts[1:], len(order))
            for key, a, b in zip(uniq.tolist(), starts.tolist(), ends.tolist()):
                ix = order[a:b]
                kx, ky = fit_cell(c[ix], q[ix], w[ix])
                fits[(lvl, key)] = (kx, ky, b - a, probability_clip(b - a))
        self.fits_ = fits
        self.n_fit_ = int(c.shape[0])
        return self

    def likelihood_ratio(self, c: float, keys: Sequence[int]) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) of a claim with confidence ``c`` whose cell keys are ``keys`` (one per level, finest first)."""
        log_lr = cold_start_log_lr(c, self.cold_start, self.log_lr_max)
        kappa = 0.0
        fits = self.fits_
        for lvl in range(len(keys) - 1, -1, -1):  # coarsest first: each finer level shrinks toward the coarser ones
            fit = fits.get((lvl, keys[lvl]))
            if fit is None:
                continue
            kx, ky, n, eps = fit
            level = min(1.0, n / self.target_size)
            lo = calibrated_log_lr(interpolate(kx, ky, c), eps, 0.0)
            log_lr = level * lo + (1.0 - level) * log_lr
            kappa = level + (1.0 - level) * kappa
        log_lr = min(max(log_lr, -self.log_lr_max), self.log_lr_max)
        return _exp(log_lr), max(self.kappa_min, kappa)

    def likelihood_ratios(self, c: np.ndarray, keys: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`likelihood_ratio` of many claims at once: confidences ``c``, one key array per level
        (finest first). The same shrinkage level by level, with numpy's linear interpolation between
        each cell's knots (equal to the scalar call up to rounding; tests/test_consensus.py)."""
        c = np.asarray(c, dtype=np.float64)
        if self.cold_start == "neutral":
            log_lr = np.zeros_like(c)
        else:
            cc = np.clip(c, 1e-6, 1.0 - 1e-6)
            log_lr = np.clip(np.log(cc / (1.0 - cc)), -self.log_lr_max, self.log_lr_max)
        kappa = np.zeros_like(c)
        fits = self.fits_
        for lvl in range(len(keys) - 1, -1, -1):  # coarsest first, as likelihood_ratio
            k = np.asarray(keys[lvl], dtype=np.int64)
            order = np.argsort(k, kind="stable")
            uniq, starts = np.unique(k[order], return_index=True)
            ends = np.append(starts[1:], len(order))
            for key, a, b in zip(uniq.tolist(), starts.tolist(), ends.tolist()):
                fit = fits.get((lvl, key))
                if fit is None:
                    continue
                kx, ky, n, eps = fit
                ix = order[a:b]
                level = min(1.0, n / self.target_size)
                p = np.clip(np.interp(c[ix], kx, ky), eps, 1.0 - eps)  # Eq. 2, uniform reference
                log_lr[ix] = level * np.log(p / (1.0 - p)) + (1.0 - level) * log_lr[ix]
                kappa[ix] = level + (1.0 - level) * kappa[ix]
        log_lr = np.clip(log_lr, -self.log_lr_max, self.log_lr_max)
        return np.exp(log_lr), np.maximum(self.kappa_min, kappa)

    @property
    def fitted(self) -> bool:
        """Whether any cell has been fitted."""
        return bool(self.fits_)

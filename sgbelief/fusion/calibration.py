"""Per-class (Mondrian) calibration of foundation-model confidences against the geometric channel (§4.1).

Outcomes (c, y) enter a streaming buffer whenever the geometric channel is decisive for the
claimed predicate (y = 1: its label is in phi's positive set, y = 0: in the negative set). The
buffer is sliced per (kappa, phi) and pooled per phi and globally. For each slice:

- an isotonic calibrator p_hat(y = 1 | c) (scikit-learn ``IsotonicRegression``), refitted only when
  the slice has grown by ``refit_growth`` (amortised O(log n) per outcome); a query is a bisection
  over the fitted knots plus linear interpolation, O(log n);
- the calibrated likelihood ratio of Eq. 2, recovered with Bayes' rule from p_hat and the slice's
  base rate pi::

      Lambda_hat(c) = p(c | y=1) / p(c | y=0) = [p_hat / (1 - p_hat)] * [(1 - pi) / pi]

  with p_hat and pi clipped to [eps, 1 - eps] (eps = 1 / (2 (n + 1))) and Lambda_hat clipped to
  [1 / lr_max, lr_max], so it is always finite and positive;
- nonconformity scores (Eq. 1) for split and adaptive conformal sets (conformal.py).

Shrinkage: log Lambda = l_s log L_slice + (1 - l_s) [l_p log L_phi + (1 - l_p) log L_global] with
l = min(1, n / target_size) per level; kappa_hat(e) = clip(n_slice / target_size, kappa_min, 1).
Cold start (no outcome at any level): Lambda = c / (1 - c) ("raw", the model taken at its word,
at the minimal weight kappa_min) or Lambda = 1 ("neutral").
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_right
from typing import Any

import numpy as np

from sgbelief.fusion.config import CalibrationConfig
from sgbelief.fusion.conformal import (
    ConformalSlice,
    PredictionSet,
    merge_sorted,
    no_coverage,
    nonconformity,
    prediction_set,
    remove_sorted,
    slide_window,
)

_GLOBAL = ("*", "*")


def _isotonic_knots(x_sorted: np.ndarray, y_sorted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The knots scikit-learn's ``IsotonicRegression(y_min=0, y_max=1).fit`` keeps, for data
    already sorted by x, without its per-call validation overhead.

    Same steps as ``IsotonicRegression._build_y``: average y over duplicate x (sklearn's own
    ``_make_unique``), weighted pool-adjacent-violators (``scipy.optimize.isotonic_regression``,
    which scikit-learn itself calls), clip to [0, 1], drop interior points of constant runs.
    Falls back to the public estimator if those internals move.
    """
    try:
        from scipy.optimize import isotonic_regression
        from sklearn._isotonic import _make_unique
    except ImportError:  # pragma: no cover - other library versions
        from sklearn.isotonic import IsotonicRegression

        iso = IsotonicRegression(increasing=True, y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(x_sorted, y_sorted)
        return iso.X_thresholds_, iso.y_thresholds_
    ux, uy, uw = _make_unique(x_sorted, y_sorted, np.ones_like(x_sorted))
    fit = np.asarray(isotonic_regression(uy, weights=uw, increasing=True).x, dtype=np.float64)
    np.clip(fit, 0.0, 1.0, fit)
    keep = np.ones(len(fit), dtype=bool)
    keep[1:-1] = np.logical_or(np.not_equal(fit[1:-1], fit[:-2]), np.not_equal(fit[1:-1], fit[2:]))
    return ux[keep], fit[keep]


class CalibrationSlice:
    """The outcomes of one Mondrian slice and its current isotonic fit.

    Outcomes added since the last fit wait in ``c`` / ``y`` (arrival order); a refit merges them
    into the sorted confidence arrays ``sx0`` (outcomes y = 0) and ``sx1`` (y = 1): one sort of
    the new outcomes plus a linear merge, so a refit costs O(n + k log k) instead of re-sorting
    the whole buffer. With a ``capacity`` the slice is a sliding window over its most recent
    ``capacity`` outcomes (``fc`` / ``fy`` keep them in arrival order; the oldest are removed
    from the sorted arrays at the refit that pushes them out), so memory stays bounded.
    """

    __slots__ = (
        "c", "y", "sx0", "sx1", "fc", "fy", "capacity", "n", "n_pos", "n_fit", "n_seen",
        "kx", "ky", "base_rate", "log_prior_odds", "conformal", "min_refit", "refit_growth", "refit_gap",
    )

    def __init__(
        self, alpha: float, capacity: int | None = None, *, min_refit: int = 8, refit_growth: float = 0.1
    ) -> None:
        self.c = array("d")
        self.y = array("b")
        self.sx0: np.ndarray = np.empty(0, dtype=np.float64)
        self.sx1: np.ndarray = np.empty(0, dtype=np.float64)
        self.fc: np.ndarray = np.empty(0, dtype=np.float64)
        self.fy: np.ndarray = np.empty(0, dtype=np.int8)
        self.capacity = capacity
        #: outcomes held (the fitted window plus those waiting for the next refit)
        self.n = 0
        self.n_pos = 0
        self.n_fit = 0
        #: outcomes ever added (held or evicted)
        self.n_seen = 0
        self.kx: list[float] = []
        self.ky: list[float] = []
        self.base_rate = 0.5
        self.log_prior_odds = 0.0
        self.conformal = ConformalSlice(alpha, capacity)
        self.min_refit = min_refit
        self.refit_growth = refit_growth
        #: refit once ``n - n_fit >= refit_gap`` = max(min_refit, refit_growth * n_fit) (0: never fitted)
        self.refit_gap: float = 0

    def add(self, c: float, y: int) -> None:
        self.c.append(c)
        self.y.append(y)
        self.n += 1
        self.n_seen += 1
        self.n_pos += y
        self.conformal.pending.append(nonconformity(c, y))

    def refit(self) -> None:
        """Fit p_hat(y=1 | c) by isotonic regression on the whole slice (= scikit-learn's fit)."""
        if self.c:
            new_c = np.frombuffer(self.c, dtype=np.float64)
            new_y = np.frombuffer(self.y, dtype=np.int8)
            self.c = array("d")
            self.y = array("b")
            if self.capacity is not None:
                self.fc, old_c, new_c, self.fy, old_y, new_y = slide_window(
                    self.fc, new_c, self.capacity, (self.fy, new_y)
                )
                if len(old_c):
                    pos = old_y.astype(bool)
                    self.sx0 = remove_sorted(self.sx0, old_c[~pos])
                    self.sx1 = remove_sorted(self.sx1, old_c[pos])
            pos = new_y.astype(bool)
            self.sx0 = merge_sorted(self.sx0, new_c[~pos])  # type: ignore[assignment]
            self.sx1 = merge_sorted(self.sx1, new_c[pos])  # type: ignore[assignment]
            self.n = len(self.sx0) + len(self.sx1)
            self.n_pos = len(self.sx1)
        x = np.concatenate((self.sx0, self.sx1))
        yv = np.concatenate((np.zeros(len(self.sx0)), np.ones(len(self.sx1))))
        order = np.argsort(x, kind="stable")  # two sorted runs: a linear merge
        kx, ky = _isotonic_knots(x[order], yv[order])
        self.kx = kx.tolist()
        self.ky = ky.tolist()
        self.n_fit = self.n
        self.refit_gap = max(self.min_refit, self.refit_growth * self.n_fit)
        eps = 0.5 / (self.n + 1)
        pi = min(max(self.n_pos / self.n, eps), 1.0 - eps)
        self.base_rate = self.n_pos / self.n
        self.log_prior_odds = math.log(pi / (1.0 - pi))
        self.conformal.refresh()

    def p_hat(self, c: float) -> float:
        """Isotonic calibrated probability at c: bisection + linear interpolation, O(log n)."""
        kx = self.kx
        i = bisect_right(kx, c)
        if i == 0:
            return self.ky[0]
        if i >= len(kx):
            return self.ky[-1]
        x0, x1 = kx[i - 1], kx[i]
        y0, y1 = self.ky[i - 1], self.ky[i]
        if x1 == x0:
            return y1
        return y0 + (y1 - y0) * (c - x0) / (x1 - x0)

    def log_lr(self, c: float, reference: bool = True) -> float:
        """log Lambda_hat(c) of Eq. 2; ``reference=False`` keeps the calibrated posterior odds
        (base rate not divided out: odds against the uniform Beta(1, 1) prior)."""
        kx, ky = self.kx, self.ky
        i = bisect_right(kx, c)  # p_hat(c), inlined (hot path)
        if i == 0:
            p = ky[0]
        elif i >= len(kx):
            p = ky[-1]
        else:
            x0, x1 = kx[i - 1], kx[i]
            p = ky[i] if x1 == x0 else ky[i - 1] + (ky[i] - ky[i - 1]) * (c - x0) / (x1 - x0)
        eps = 0.5 / (self.n_fit + 1)
        if p < eps:
            p = eps
        elif p > 1.0 - eps:
            p = 1.0 - eps
        lo = math.log(p / (1.0 - p))
        return lo - self.log_prior_odds if reference else lo


class MondrianCalibrator:
    """Streaming calibration buffer C, sliced per (kappa, phi), with per-phi and global pooling."""

    def __init__(self, config: CalibrationConfig | None = None, alpha: float = 0.1) -> None:
        self.config = config or CalibrationConfig()
        self.alpha = alpha
        self.slices: dict[tuple[str, str], CalibrationSlice] = {}
        self._log_lr_max = math.log(self.config.lr_max)
        self._ref = self.config.lr_reference == "slice"
        self._gamma = self.config.adaptive_gamma
        #: (slice, predicate pool, global pool) per (context, predicate)
        self._levels: dict[tuple[str, str], tuple[CalibrationSlice, ...]] = {}
        self.frozen = False

    # ------------------------------------------------------------------ data
    def _slice(self, key: tuple[str, str]) -> CalibrationSlice:
        s = self.slices.get(key)
        if s is None:
            cfg = self.config
            s = self.slices[key] = CalibrationSlice(
                self.alpha, cfg.buffer_size, min_refit=cfg.min_refit, refit_growth=cfg.refit_growth
            )
        return s

    def add(self, context: str, predicate: str, c: float, y: int) -> None:
        """Append one verification outcome to its slice, its predicate pool and the global pool.

        The adaptive conformal level of the slice is updated first with this outcome (was y
        in the set the slice would have produced for c?), as in Alg. 1's outcome loop.
        """
        if self.frozen:
            return
        levels = self._levels.get((context, predicate))
        if levels is None:
            keys = ((context, predicate), ("*", predicate), _GLOBAL)
            levels = self._levels[(context, predicate)] = tuple(self._slice(k) for k in keys)
        score = nonconformity(c, y)  # Eq. 1, the same for the three levels
        first = levels[0]
        if first.n_fit > 0 and context != "*":
            conf = first.conformal
            q = conf.threshold(conf.alpha_t) if conf.alpha_t > 0 else math.inf
            err = 0 if score <= q else 1
            conf.n_seen += 1
            conf.n_err += err
            conf.alpha_t += self._gamma * (self.alpha - err)
        for s in levels:
            s.c.append(c)
            s.y.append(y)
            s.n += 1
            s.n_seen += 1
            s.n_pos += y
            s.conformal.pending.append(score)
            if s.n - s.n_fit >= s.refit_gap:
                s.refit()

    def refit_all(self) -> None:
        for s in self.slices.values():
            if s.n and s.n_fit != s.n:
                s.refit()

    def n_outcomes(self, context: str = "*", predicate: str = "*", *, seen: bool = False) -> int:
        """Outcomes held in a slice (``seen=True``: ever added, including those slid out)."""
        s = self.slices.get((context, predicate))
        if s is None:
            return 0
        return s.n_seen if seen else s.n

    # --------------------------------------------------------------- queries
    def likelihood_ratio(self, c: float, context: str, predicate: str) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) for a claim with raw confidence c (Eq. 2 with shrinkage)."""
        cfg = self.config
        slices = self.slices
        target = cfg.target_size
        s = slices.get((context, predicate))
        p = slices.get(("*", predicate))
        g = slices.get(_GLOBAL)
        n_s = s.n_fit if s is not None else 0
        n_p = p.n_fit if p is not None else 0
        n_g = g.n_fit if g is not None else 0
        if n_g == 0:
            kappa = cfg.kappa_min
            if cfg.cold_start == "neutral":
                return 1.0, kappa
            cc = min(max(c, 1e-6), 1.0 - 1e-6)
            lam = cc / (1.0 - cc)
            lo = 1.0 / cfg.lr_max
            return (lo if lam < lo else cfg.lr_max if lam > cfg.lr_max else lam), kappa
        ref = self._ref
        # a level with full weight (n >= target_size) makes the coarser ones irrelevant:
        # 1 * x + 0 * y == x, so they are not evaluated
        if n_s >= target:
            log_lr = s.log_lr(c, ref)  # type: ignore[union-attr]
        else:
            if n_p >= target:
                log_lr = p.log_lr(c, ref)  # type: ignore[union-attr]
            else:
                log_lr = g.log_lr(c, ref)  # type: ignore[union-attr]
                if n_p:
                    lp = n_p / target
                    log_lr = lp * p.log_lr(c, ref) + (1.0 - lp) * log_lr  # type: ignore[union-attr]
            if n_s:
                ls = n_s / target
                log_lr = ls * s.log_lr(c, ref) + (1.0 - ls) * log_lr  # type: ignore[union-attr]
        m = self._log_lr_max
        if log_lr > m:
            log_lr = m
        elif log_lr < -m:
            log_lr = -m
        kappa = n_s / target
        if kappa > 1.0:
            kappa = 1.0
        elif kappa < cfg.kappa_min:
            kappa = cfg.kappa_min
        return math.exp(log_lr), kappa

    def calibrated_probability(self, c: float, context: str, predicate: str) -> float:
        """p_hat(y=1 | c) of the most specific fitted slice (slice, then predicate, then global)."""
        for key in ((context, predicate), ("*", predicate), _GLOBAL):
            s = self.slices.get(key)
            if s is not None and s.n_fit:
                return s.p_hat(c)
        return c

    def in_regime(self, context: str, predicate: str) -> bool:
        """(phi, kappa) is calibratable: at least one verification outcome in its slice (Property 1)."""
        s = self.slices.get((context, predicate))
        return s is not None and s.n_fit > 0

    def prediction_set(self, c: float, context: str, predicate: str, *, adaptive: bool = False) -> PredictionSet:
        """Event-level (1 - alpha) set over {0, 1} for a claim (c, kappa, phi), or no coverage claim."""
        s = self.slices.get((context, predicate))
        if s is None or s.n_fit == 0:
            return no_coverage(f"no verification outcome yet for context {context!r}, predicate {predicate!r}")
        conf = s.conformal
        level = conf.alpha_t if adaptive else self.alpha
        q = conf.threshold(level) if level > 0 else math.inf
        return PredictionSet(prediction_set(c, q), 1.0 - self.alpha, conf.n_sorted)

    def summary(self) -> dict[str, Any]:
        return {
            f"{k[0]}|{k[1]}": {"n": s.n, "n_seen": s.n_seen, "base_rate": s.base_rate, "knots": len(s.kx), "alpha_t": s.conformal.alpha_t}
            for k, s in sorted(self.slices.items())
        }

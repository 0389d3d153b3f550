"""Per-class (Mondrian) calibration of foundation-model confidences against the geometric channel (§4.1).

Outcomes (c, y) enter a streaming buffer whenever the geometric channel is decisive for the
claimed predicate (y = 1: its label is in phi's positive set, y = 0: in the negative set). The
buffer is sliced per (kappa, phi) and pooled per phi and globally. For each slice:

- an isotonic calibrator p_hat(y = 1 | c) (the fit of scikit-learn's ``IsotonicRegression``),
  refitted only when the slice has grown by ``refit_growth`` (amortised O(log n) per outcome);
  a query is a bisection over the fitted knots plus linear interpolation, O(log n);
- the calibrated likelihood ratio of Eq. 2, recovered with Bayes' rule from p_hat and the slice's
  base rate pi::

      Lambda_hat(c) = p(c | y=1) / p(c | y=0) = [p_hat / (1 - p_hat)] * [(1 - pi) / pi]

  with p_hat and pi clipped to [eps, 1 - eps] (eps = 1 / (2 (n + 1))) and Lambda_hat clipped to
  [1 / lr_max, lr_max], so it is always finite and positive;
- nonconformity scores (Eq. 1) for split and adaptive conformal sets (conformal.py).

Shrinkage: log Lambda = l_s log L_slice + (1 - l_s) [l_p log L_phi + (1 - l_p) log L_global] with
l = min(1, n / target_size) per level; kappa_hat(e) = clip(n_slice / target_size, kappa_min, 1)
(``kappa_pooling: slice``, the paper) or clip(l_s + (1 - l_s) [l_p + (1 - l_p) l_g], kappa_min, 1)
(``pooled``: the share of the shrunk estimate that rests on fitted data).
Cold start (no outcome at any level): Lambda = c / (1 - c) ("raw", the model taken at its word,
at the minimal weight kappa_min) or Lambda = 1 ("neutral"); the hierarchy ends there, so a global
level with n_g < target_size outcomes is itself shrunk toward it with weight l_g = n_g / target_size.
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_left, bisect_right
from typing import Any

import numpy as np

from sgbelief.fusion.config import CalibrationConfig
from sgbelief.fusion.rules import calibrated_log_lr
from sgbelief.fusion.conformal import (
    _EPS,
    _ONE_MINUS_EPS,
    SMALL,
    ConformalSlice,
    PredictionSet,
    _no_nan,
    no_coverage,
    nonconformity,
    prediction_set,
    slide_window,
)

_GLOBAL = ("*", "*")
#: scikit-learn's ``_make_unique`` pools a sorted x into the current point while x - x_first < this
_RES = float(np.finfo(np.float64).resolution)
_INF = math.inf
_log = math.log
_exp = math.exp
_ceil = math.ceil

try:  # scipy's PAVA kernel, the one ``scipy.optimize.isotonic_regression`` (and scikit-learn) run
    from scipy.optimize._pava_pybind import pava as _pava
except ImportError:  # pragma: no cover - other library versions
    _pava = None


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


def _pav(uy: np.ndarray, uw: np.ndarray) -> np.ndarray:
    """``scipy.optimize.isotonic_regression(uy, weights=uw).x`` (its PAVA kernel, called directly;
    overwrites ``uy`` and ``uw``)."""
    if _pava is None:  # pragma: no cover - other library versions
        from scipy.optimize import isotonic_regression

        return np.asarray(isotonic_regression(uy, weights=uw, increasing=True).x, dtype=np.float64)
    return _pava(uy, uw, np.full(len(uy) + 1, -1, dtype=np.intp))[0]


def _expand(ux: np.ndarray, cnt: np.ndarray, npos: np.ndarray, nan_n: int, nan_p: int) -> tuple[np.ndarray, np.ndarray]:
    """The sorted (x, y) sequence the counts stand for (NaN last, as numpy sorts)."""
    neg = cnt - npos
    reps = np.empty(2 * len(ux), dtype=np.int64)
    reps[0::2] = neg
    reps[1::2] = npos
    x = np.repeat(np.repeat(ux, 2), reps)
    y = np.repeat(np.tile(np.array([0.0, 1.0]), len(ux)), reps)
    if nan_n:
        x = np.concatenate((x, np.full(nan_n, np.nan)))
        y = np.concatenate((y, np.zeros(nan_n - nan_p), np.ones(nan_p)))
    return x, y


def _knots_counts(ux: np.ndarray, cnt: np.ndarray, npos: np.ndarray, nan_n: int, nan_p: int) -> tuple[list[float], list[float]]:
    """``_isotonic_knots`` of the outcomes given as distinct confidences ``ux`` (ascending) with their
    counts ``cnt`` and positives ``npos`` (plus ``nan_n`` NaN confidences, ``nan_p`` of them positive).

    sklearn's ``_make_unique`` starts a new point at x when x - x_first >= eps (eps = 1e-15, x_first
    the first x of the current point) and averages y over the point. When consecutive distinct
    confidences are all >= eps apart (always, unless they differ by ~1e-15), its points are the
    distinct confidences: weight = count, y = positives / count, both exact, so the fit is
    PAVA(npos / cnt, cnt) with no pass over the outcomes. Otherwise (or with NaN) ``_make_unique``
    itself is run on the expanded outcomes.
    """
    u = len(ux)
    if nan_n or (u > 1 and not np.all(ux[1:] - ux[:-1] >= _RES)):
        kx, ky = _isotonic_knots(*_expand(ux, cnt, npos, nan_n, nan_p))
        return kx.tolist(), ky.tolist()
    uw = cnt.astype(np.float64)
    fit = _pav(npos / uw, uw)
    np.clip(fit, 0.0, 1.0, fit)
    if u > 2:
        keep = np.ones(u, dtype=bool)
        keep[1:-1] = np.logical_or(np.not_equal(fit[1:-1], fit[:-2]), np.not_equal(fit[1:-1], fit[2:]))
        return ux[keep].tolist(), fit[keep].tolist()
    return ux.tolist(), fit.tolist()


def _knots_counts_small(ux: list[float], cnt: list[int], npos: list[int]) -> tuple[list[float], list[float]]:
    """``_knots_counts`` for short Python lists (no NaN): same points and weights, scipy's PAVA
    kernel, clip and trim in Python (the same float operations)."""
    for a, b in zip(ux, ux[1:]):
        if not b - a >= _RES:  # near-ties: sklearn's own grouping
            return _knots_counts(np.array(ux), np.array(cnt, dtype=np.int64), np.array(npos, dtype=np.int64), 0, 0)
    fit = _pav(np.array([p / w for p, w in zip(npos, cnt)]), np.array(cnt, dtype=np.float64)).tolist()
    fit = [0.0 if v < 0.0 else 1.0 if v > 1.0 else v for v in fit]
    u = len(fit)
    if u <= 2:
        return list(ux), fit
    kx = [ux[0]]
    ky = [fit[0]]
    prev, cur = fit[0], fit[1]
    for i in range(1, u - 1):
        nxt = fit[i + 1]
        if cur != prev or cur != nxt:
            kx.append(ux[i])
            ky.append(cur)
        prev, cur = cur, nxt
    kx.append(ux[-1])
    ky.append(fit[-1])
    return kx, ky


def _distinct(c: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """A batch of outcomes as (distinct confidences ascending, counts, positives, NaN count, NaN positives).
    (Equal confidences are one value; of +0.0 and -0.0, the one the sort puts first stands for both.)"""
    o = np.argsort(c)
    v = c[o]
    lab = y[o]
    k = len(v)
    nan_n = nan_p = 0
    if k and v[-1] != v[-1]:  # NaN sort last
        first = int(np.flatnonzero(v != v)[0])
        nan_n, nan_p = k - first, int(np.count_nonzero(lab[first:]))
        v, lab, k = v[:first], lab[:first], first
    brk = np.empty(k, dtype=bool)
    brk[:1] = True
    np.not_equal(v[1:], v[:-1], out=brk[1:])
    starts = np.flatnonzero(brk)
    if len(starts) == k:
        return v, np.ones(k, dtype=np.int64), lab.astype(np.int64), nan_n, nan_p
    ends = np.empty(len(starts), dtype=np.intp)
    ends[:-1] = starts[1:]
    ends[-1:] = k
    cum = np.zeros(k + 1, dtype=np.int64)
    np.cumsum(lab, dtype=np.int64, out=cum[1:])
    return v[starts], ends - starts, cum[ends] - cum[starts], nan_n, nan_p


class CalibrationSlice:
    """One Mondrian slice: its outcomes and the isotonic fit p_hat(y = 1 | c) (= scikit-learn's).

    Pending outcomes wait in ``c`` / ``y`` (their scores, Eq. 1, in ``conformal.pending``).
    ``refit`` commits them (``n_fit``, ``refit_gap``, ``eps`` at once); the fit is computed when next
    read (``kx``, ``ky``, ``log_lr``, ``base_rate``, ...), all committed batches in one merge, so an
    unread slice (a pool behind a full-weight slice) costs O(1) per outcome. The fit depends on the
    held outcomes only: it equals a refit per batch. They are kept as distinct confidences ``ux``
    with counts ``cnt`` and positives ``npos``; p_hat = PAVA(npos / cnt, weights cnt) over them
    (``_knots_counts``), O(u + k log k) per merge of k outcomes. Up to ``SMALL`` outcomes these are
    Python lists, beyond numpy arrays. With a ``capacity``: a sliding window over the most recent
    outcomes (``fc`` / ``fy`` in arrival order), bounded memory.
    """

    __slots__ = (
        "c", "y", "sc", "batches", "n_batch", "ux", "cnt", "npos", "nan_n", "nan_p", "n_merged", "wc", "wy",
        "capacity", "n_fit", "n_pos_fit", "n_seen_fit", "stale", "_kx", "_ky", "_base_rate", "_log_prior_odds",
        "eps", "conformal", "min_refit", "refit_growth", "refit_gap",
    )

    def __init__(
        self, alpha: float, capacity: int | None = None, *, min_refit: int = 8, refit_growth: float = 0.1
    ) -> None:
        self.c = array("d")
        self.y = array("b")
        self.conformal = ConformalSlice(alpha, capacity)
        #: the pending scores (Eq. 1), ``conformal.pending``
        self.sc: array = self.conformal.pending
        #: batches (c, y) committed by ``refit`` and not merged into the fit yet, and their total size
        self.batches: list[tuple[array, array]] = []
        self.n_batch = 0
        self.ux: list[float] | np.ndarray = []
        self.cnt: list[int] | np.ndarray = []
        self.npos: list[int] | np.ndarray = []
        #: NaN confidences merged (they sort after every number) and how many of them are positive
        self.nan_n = 0
        self.nan_p = 0
        #: outcomes merged into ux / cnt / npos (+ NaN)
        self.n_merged = 0
        #: the merged outcomes in arrival order (kept only with a capacity)
        self.wc: list[float] | np.ndarray = []
        self.wy: list[int] | np.ndarray = []
        self.capacity = capacity
        #: outcomes in the fitted window (committed), positives among the merged ones, outcomes ever committed
        self.n_fit = 0
        self.n_pos_fit = 0
        self.n_seen_fit = 0
        #: committed batches wait to be merged (the fit below is out of date)
        self.stale = False
        self._kx: list[float] = []
        self._ky: list[float] = []
        self._base_rate = 0.5
        self._log_prior_odds = 0.0
        #: clip of p_hat: [eps, 1 - eps], eps = 1 / (2 (n_fit + 1))
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
        """Outcomes ever added (held or evicted)."""
        return self.n_seen_fit + len(self.c)

    @property
    def n_pos(self) -> int:
        if self.stale:
            self.fit()
        return self.n_pos_fit + sum(self.y)

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
    def fc(self) -> list[float] | np.ndarray:
        """The fitted window's confidences in arrival order (kept only with a capacity)."""
        if self.stale:
            self.fit()
        return self.wc

    @property
    def fy(self) -> list[int] | np.ndarray:
        """The fitted window's labels in arrival order (kept only with a capacity)."""
        if self.stale:
            self.fit()
        return self.wy

    def _sorted_by_label(self, label: int) -> np.ndarray:
        if self.stale:
            self.fit()
        cnt = np.asarray(self.cnt, dtype=np.int64)
        npos = np.asarray(self.npos, dtype=np.int64)
        x = np.repeat(np.asarray(self.ux, dtype=np.float64), npos if label else cnt - npos)
        nan = self.nan_p if label else self.nan_n - self.nan_p
        return np.concatenate((x, np.full(nan, np.nan))) if nan else x

    @property
    def sx0(self) -> np.ndarray:
        """Fitted confidences of outcomes y = 0, ascending."""
        return self._sorted_by_label(0)

    @property
    def sx1(self) -> np.ndarray:
        """Fitted confidences of outcomes y = 1, ascending."""
        return self._sorted_by_label(1)

    # ---------------------------------------------------------------- data
    def add(self, c: float, y: int) -> None:
        self.c.append(c)
        self.y.append(y)
        self.sc.append(nonconformity(c, y))

    def refit(self) -> None:
        """Refit p_hat(y=1 | c) by isotonic regression on the whole slice (= scikit-learn's fit):
        commit the pending outcomes; the fit is computed when next read."""
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
                    self._reset_merged()
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
        self.eps = 0.5 / (n + 1)

    def _reset_merged(self) -> None:
        self.ux, self.cnt, self.npos, self.wc, self.wy = [], [], [], [], []
        self.nan_n = self.nan_p = self.n_merged = self.n_pos_fit = 0

    def fit(self) -> None:
        """Merge the committed batches and fit p_hat (the isotonic knots) and the base rate."""
        batches = self.batches
        if batches:
            cs, ys = batches[0]
            for c2, y2 in batches[1:]:
                cs += c2
                ys += y2
            self.batches = []
            self.n_batch = 0
            if type(self.ux) is list and self.n_merged + len(cs) <= SMALL and _no_nan(cs):
                self._merge_small(cs, [1 if v else 0 for v in ys])
                self._kx, self._ky = _knots_counts_small(self.ux, self.cnt, self.npos)  # type: ignore[arg-type]
            else:
                self._merge_numpy(np.frombuffer(cs, dtype=np.float64), (np.frombuffer(ys, dtype=np.int8) != 0).view(np.int8))
                self._kx, self._ky = _knots_counts(self.ux, self.cnt, self.npos, self.nan_n, self.nan_p)  # type: ignore[arg-type]
            n = self.n_fit
            eps = self.eps
            n_pos = self.n_pos_fit
            pi = min(max(n_pos / n, eps), 1.0 - eps)
            self._base_rate = n_pos / n
            self._log_prior_odds = math.log(pi / (1.0 - pi))
        self.stale = False

    def _merge_small(self, cs: array, labs: list[int]) -> None:
        ux, cnt, npos = self.ux, self.cnt, self.npos
        n_pos = self.n_pos_fit
        held = self.n_merged + len(cs)
        cap = self.capacity
        if cap is not None:
            fc, fy = self.wc, self.wy
            drop = len(fc) + len(cs) - cap
            if drop > 0:
                drop_old = min(drop, len(fc))
                for v, lab in zip(fc[:drop_old], fy[:drop_old]):
                    i = bisect_left(ux, v)  # type: ignore[arg-type]
                    if i >= len(ux) or ux[i] != v or not (npos[i] if lab else cnt[i] - npos[i]):  # type: ignore[operator]
                        raise ValueError("remove_sorted: values are not a sub-multiset of the sorted buffer")
                    if cnt[i] == 1:  # type: ignore[operator]
                        del ux[i], cnt[i], npos[i]  # type: ignore[arg-type]
                    else:
                        cnt[i] -= 1  # type: ignore[operator,index]
                        npos[i] -= lab  # type: ignore[operator,index]
                    n_pos -= lab
                drop_new = max(drop - len(fc), 0)
                cs, labs = cs[drop_new:], labs[drop_new:]
                fc, fy = fc[drop_old:], fy[drop_old:]
                held -= drop
            fc.extend(cs)  # type: ignore[union-attr]
            fy.extend(labs)  # type: ignore[union-attr]
            self.wc, self.wy = fc, fy
        for v, lab in zip(cs, labs):
            i = bisect_left(ux, v)  # type: ignore[arg-type]
            if i < len(ux) and ux[i] == v:
                cnt[i] += 1  # type: ignore[index]
                npos[i] += lab  # type: ignore[index]
            else:
                ux.insert(i, v)  # type: ignore[union-attr]
                cnt.insert(i, 1)  # type: ignore[union-attr]
                npos.insert(i, lab)  # type: ignore[union-attr]
            n_pos += lab
        self.n_pos_fit = n_pos
        self.n_merged = held

    def _merge_numpy(self, new_c: np.ndarray, new_y: np.ndarray) -> None:
        ux, cnt, npos = self.ux, self.cnt, self.npos
        if type(ux) is list:
            ux = np.array(ux, dtype=np.float64)
            cnt = np.array(cnt, dtype=np.int64)
            npos = np.array(npos, dtype=np.int64)
        n_pos = self.n_pos_fit
        held = self.n_merged + len(new_c)
        if self.capacity is not None:
            fc, fy = self.wc, self.wy
            if type(fc) is list:
                fc, fy = np.array(fc, dtype=np.float64), np.array(fy, dtype=np.int8)
            self.wc, old_c, new_c, self.wy, old_y, new_y = slide_window(fc, new_c, self.capacity, (fy, new_y))  # type: ignore[arg-type]
            held = len(self.wc)
            if len(old_c):
                ov, oc, op, on, onp = _distinct(old_c, old_y)
                pos = np.searchsorted(ux, ov)  # type: ignore[arg-type]
                if len(ov) and (pos[-1] >= len(ux) or not np.array_equal(ux[pos], ov)):  # type: ignore[index]
                    raise ValueError("remove_sorted: values are not a sub-multiset of the sorted buffer")
                cnt[pos] -= oc  # type: ignore[index]
                npos[pos] -= op  # type: ignore[index]
                if np.any(npos[pos] < 0) or np.any(cnt[pos] < npos[pos]) or on > self.nan_n or onp > self.nan_p:  # type: ignore[index]
                    raise ValueError("remove_sorted: values are not a sub-multiset of the sorted buffer")
                self.nan_n -= on
                self.nan_p -= onp
                gone = pos[cnt[pos] == 0]  # type: ignore[index]
                if len(gone):
                    ux, cnt, npos = np.delete(ux, gone), np.delete(cnt, gone), np.delete(npos, gone)
                n_pos -= int(np.count_nonzero(old_y))
        bv, bc, bp, bn, bnp = _distinct(new_c, new_y)
        self.nan_n += bn
        self.nan_p += bnp
        u = len(ux)
        pos = np.searchsorted(ux, bv)  # type: ignore[arg-type]
        if u:
            hit = ux[np.minimum(pos, u - 1)] == bv  # type: ignore[index]
            hp = pos[hit]
            cnt[hp] += bc[hit]  # type: ignore[index]
            npos[hp] += bp[hit]  # type: ignore[index]
            miss = ~hit
            pos, bv, bc, bp = pos[miss], bv[miss], bc[miss], bp[miss]
        m = len(bv)
        if m:  # insert the new distinct confidences: one scatter per array
            at = pos + np.arange(m)
            old = np.ones(u + m, dtype=bool)
            old[at] = False
            out = []
            for base, vals in ((ux, bv), (cnt, bc), (npos, bp)):
                a = np.empty(u + m, dtype=base.dtype)  # type: ignore[union-attr]
                a[at] = vals
                a[old] = base
                out.append(a)
            ux, cnt, npos = out
        self.ux, self.cnt, self.npos = ux, cnt, npos
        self.n_pos_fit = n_pos + int(np.count_nonzero(new_y))
        self.n_merged = held

    # ------------------------------------------------------------- queries
    def p_hat(self, c: float) -> float:
        """Isotonic calibrated probability at c: bisection + linear interpolation, O(log n)."""
        if self.stale:
            self.fit()
        kx, ky = self._kx, self._ky
        i = bisect_right(kx, c)
        if i == 0:
            return ky[0]
        if i >= len(kx):
            return ky[-1]
        x0, x1 = kx[i - 1], kx[i]
        y0, y1 = ky[i - 1], ky[i]
        if x1 == x0:
            return y1
        return y0 + (y1 - y0) * (c - x0) / (x1 - x0)

    def log_lr(self, c: float, reference: bool = True) -> float:
        """log Lambda_hat(c) of Eq. 2: log[p_hat / (1 - p_hat)] - log[pi / (1 - pi)], p_hat and pi
        clipped to [eps, 1 - eps]; ``reference=False`` keeps the calibrated posterior odds (base
        rate not divided out: odds against the uniform Beta(1, 1) prior); :func:`~sgbelief.fusion.rules.calibrated_log_lr`."""
        if self.stale:
            self.fit()
        kx, ky = self._kx, self._ky
        i = bisect_right(kx, c)  # p_hat(c), inlined (hot path)
        if i == 0:
            p = ky[0]
        elif i >= len(kx):
            p = ky[-1]
        else:
            x0, x1 = kx[i - 1], kx[i]
            p = ky[i] if x1 == x0 else ky[i - 1] + (ky[i] - ky[i - 1]) * (c - x0) / (x1 - x0)
        return calibrated_log_lr(p, self.eps, self._log_prior_odds if reference else 0.0)


#: stands for a level that does not exist yet (never fitted) in the query cache
_NO_SLICE = CalibrationSlice(0.0)


class MondrianCalibrator:
    """Streaming calibration buffer C, sliced per (kappa, phi), with per-phi and global pooling."""

    def __init__(self, config: CalibrationConfig | None = None, alpha: float = 0.1) -> None:
        self.config = config or CalibrationConfig()
        self._gamma = self.config.adaptive_gamma
        self.alpha = alpha
        self.slices: dict[tuple[str, str], CalibrationSlice] = {}
        self._log_lr_max = math.log(self.config.lr_max)
        self._ref = self.config.lr_reference == "slice"
        self._target = self.config.target_size
        #: (slice, predicate pool, global pool, adaptive conformal state) per (context, predicate) that added outcomes
        self._levels: dict[tuple[str, str], tuple[Any, ...]] = {}
        #: the same per queried (context, predicate), ``_NO_SLICE`` for missing ones (reset when a slice is created)
        self._query: dict[tuple[str, str], tuple[CalibrationSlice, CalibrationSlice, CalibrationSlice]] = {}
        self.frozen = False

    @property
    def alpha(self) -> float:
        return self._alpha

    @alpha.setter
    def alpha(self, value: float) -> None:
        self._alpha = value
        # adaptive step alpha_{t+1} = alpha_t + gamma (alpha - err_t), for err_t = 0 and err_t = 1
        self._step_ok = self._gamma * (value - 0)
        self._step_err = self._gamma * (value - 1)

    # ------------------------------------------------------------------ data
    def _slice(self, key: tuple[str, str]) -> CalibrationSlice:
        s = self.slices.get(key)
        if s is None:
            cfg = self.config
            s = self.slices[key] = CalibrationSlice(
                self._alpha, cfg.buffer_size, min_refit=cfg.min_refit, refit_growth=cfg.refit_growth
            )
            self._query.clear()
        return s

    def _make_levels(self, context: str, predicate: str) -> tuple[Any, ...]:
        keys = ((context, predicate), ("*", predicate), _GLOBAL)
        s0, s1, s2 = (self._slice(k) for k in keys)
        # the slice's conformal state takes the adaptive step (not for a "*" context: that is a pool)
        lv = self._levels[(context, predicate)] = (s0, s1, s2, s0.conformal if context != "*" else None)
        return lv

    def add(self, context: str, predicate: str, c: float, y: int) -> None:
        """Append one verification outcome to its slice, its predicate pool and the global pool.

        The adaptive conformal level of the slice is updated first with this outcome (was y
        in the set the slice would have produced for c?), as in Alg. 1's outcome loop:
        q = the ceil((n+1)(1-alpha_t))-th smallest score (``conformal_quantile``), err = s > q,
        alpha_{t+1} = alpha_t + gamma (alpha - err).
        """
        if self.frozen:
            return
        lv = self._levels.get((context, predicate))
        if lv is None:
            lv = self._make_levels(context, predicate)
        s0, s1, s2, conf = lv
        # Eq. 1 (nonconformity), the same for the three levels
        if c < _EPS:
            cc = _EPS
        elif c > _ONE_MINUS_EPS:
            cc = _ONE_MINUS_EPS
        else:
            cc = c
        score = -_log(cc) if y == 1 else -_log(1.0 - cc)
        if conf is not None and s0.n_fit > 0:
            a = conf.alpha_t
            if a > 0:
                if a >= 1.0:
                    q = -_INF
                else:
                    m = conf.n_sorted
                    rank = _ceil((m + 1) * (1.0 - a))
                    if rank > m or m == 0:
                        q = _INF
                    elif rank < 1:
                        q = -_INF
                    else:
                        if conf.chunks:
                            conf.merge()
                        srt = conf.srt
                        q = srt[rank - 1] if type(srt) is list else srt.item(rank - 1)
            else:
                q = _INF
            conf.n_seen += 1
            if score <= q:
                conf.alpha_t = a + self._step_ok
            else:
                conf.n_err += 1
                conf.alpha_t = a + self._step_err
        # the three levels (s0 is s1 for a "*" context: appended twice, as its own slice and as the pool)
        for s in (s0, s1, s2):
            cs = s.c
            cs.append(c)
            s.y.append(y)
            s.sc.append(score)
            if len(cs) >= s.refit_gap:
                s.refit()

    def refit_all(self) -> None:
        for s in self.slices.values():
            if s.c:
                s.refit()

    def n_outcomes(self, context: str = "*", predicate: str = "*", *, seen: bool = False) -> int:
        """Outcomes held in a slice (``seen=True``: ever added, including those slid out)."""
        s = self.slices.get((context, predicate))
        if s is None:
            return 0
        return s.n_seen if seen else s.n

    # --------------------------------------------------------------- queries
    def _query_levels(self, context: str, predicate: str) -> tuple[CalibrationSlice, CalibrationSlice, CalibrationSlice]:
        get = self.slices.get
        lv = self._query[(context, predicate)] = (
            get((context, predicate), _NO_SLICE), get(("*", predicate), _NO_SLICE), get(_GLOBAL, _NO_SLICE)
        )
        return lv

    def likelihood_ratio(self, c: float, context: str, predicate: str) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) for a claim with raw confidence c (Eq. 2 with shrinkage)."""
        lv = self._query.get((context, predicate))
        if lv is None:
            lv = self._query_levels(context, predicate)
        s, p, g = lv
        target = self._target
        n_s = s.n_fit
        if n_s >= target and g.n_fit:  # full weight: the slice alone, kappa = 1
            log_lr = s.log_lr(c, self._ref)
            m = self._log_lr_max
            if log_lr > m:
                log_lr = m
            elif log_lr < -m:
                log_lr = -m
            return _exp(log_lr), 1.0
        cfg = self.config
        if g.n_fit == 0:
            return _exp(self._cold_log_lr(c)), cfg.kappa_min
        ref = self._ref
        # a level with full weight (n >= target_size) makes the coarser ones irrelevant:
        # 1 * x + 0 * y == x, so they are not evaluated
        n_p = p.n_fit
        if n_p >= target:
            log_lr = p.log_lr(c, ref)
        else:
            log_lr = g.log_lr(c, ref)
            n_g = g.n_fit
            if n_g < target:  # the hierarchy ends at the cold-start rule: a sparse global level shrinks toward it
                lg = n_g / target
                log_lr = lg * log_lr + (1.0 - lg) * self._cold_log_lr(c)
            if n_p:
                lp = n_p / target
                log_lr = lp * p.log_lr(c, ref) + (1.0 - lp) * log_lr
        if n_s:
            ls = n_s / target
            log_lr = ls * s.log_lr(c, ref) + (1.0 - ls) * log_lr
        m = self._log_lr_max
        if log_lr > m:
            log_lr = m
        elif log_lr < -m:
            log_lr = -m
        if cfg.kappa_pooling == "pooled":
            ls = min(1.0, n_s / target)
            lp = min(1.0, n_p / target)
            kappa = ls + (1.0 - ls) * (lp + (1.0 - lp) * min(1.0, g.n_fit / target))
        else:
            kappa = n_s / target
        if kappa > 1.0:
            kappa = 1.0
        elif kappa < cfg.kappa_min:
            kappa = cfg.kappa_min
        return _exp(log_lr), kappa

    def _cold_log_lr(self, c: float) -> float:
        """log Lambda of the cold-start rule: log(c / (1 - c)) clipped to +-log(lr_max) ("raw", the
        model at its word) or 0 ("neutral")."""
        if self.config.cold_start == "neutral":
            return 0.0
        cc = min(max(c, 1e-6), 1.0 - 1e-6)
        m = self._log_lr_max
        lo = _log(cc / (1.0 - cc))
        return m if lo > m else -m if lo < -m else lo

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

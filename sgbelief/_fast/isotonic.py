"""Private: the incremental isotonic merge, a fast :class:`~sgbelief.calibration.isotonic.IsotonicStore`.

A slice's outcomes are held as distinct confidences ``ux`` (ascending) with their counts ``cnt``
and positives ``npos``; a batch of k new outcomes is merged into the u held values in
O(u + k log k), and the fit is the weighted pool-adjacent-violators regression of npos / cnt with
weights cnt over them (:func:`pava`), clipped to [0, 1], interior points of constant runs dropped.
That is what scikit-learn's ``IsotonicRegression`` computes when neighbouring confidences are at
least its resolution (1e-15) apart: its points are then the distinct confidences with exactly
these means and weights. Closer neighbours (scikit-learn pools them by its own rule) are fitted by
the reference estimator itself. Up to ``SMALL`` outcomes the columns are Python lists, beyond
numpy arrays (numpy's fixed per-call cost dominates small slices). ``tests/test_fast_isotonic.py``
proves the knots equal to the reference's (:func:`sgbelief.testing.check_isotonic_matches_reference`);
measurements in ``docs/performance.md``.

The engine that wants it passes the class as the calibrator's store factory:
``MondrianCalibrator(config, alpha, isotonic=IncrementalIsotonic)``.
"""

from __future__ import annotations

from array import array
from bisect import bisect_left

import numpy as np
from scipy.optimize import isotonic_regression

from sgbelief.calibration.conformal import slide_window
from sgbelief.calibration.isotonic import ScikitLearnIsotonic

__all__ = ["IncrementalIsotonic", "pava"]

#: slices up to this many outcomes keep their columns as Python lists
SMALL = 128
#: scikit-learn pools sorted confidences into one point while they are less than this apart
_RES = float(np.finfo(np.float64).resolution)
#: the estimator that fits confidences closer than _RES (scikit-learn's own pooling rule)
_REFERENCE = ScikitLearnIsotonic()


def pava(values: list[float], weights: list[float]) -> list[float]:
    """Weighted isotonic (non-decreasing) least-squares regression by pool adjacent violators, O(n).

    The single-pass form of Busing (2022, J. Stat. Softw. 102, Algorithm 1): a stack of blocks
    (value, weight, end); a point not above the top block's value is pooled with it, then with
    the following points while they are not above the pooled value, then with the blocks below
    while those are not below it. A pool's weighted sum starts as the top block's value times its
    weight and then adds one weight times value per point or block, each block value a division
    of that sum by the pooled weight: the floating-point operations of
    ``scipy.optimize.isotonic_regression``, in its order, so the fitted values are equal bit for bit.

    Parameters
    ----------
    values : list of float
        The responses, in the order of the regressor.
    weights : list of float
        Their positive weights.

    Returns
    -------
    list of float
        The fitted non-decreasing values, one per point.
    """
    n = len(values)
    if n == 0:
        return []
    bx = [values[0]]  # block values
    bw = [weights[0]]  # block weights
    be = [1]  # block ends (exclusive)
    i = 1
    while i < n:
        x, w = values[i], weights[i]
        if bx[-1] >= x:  # a violation: pool with the top block
            s = bw[-1] * bx[-1] + w * x
            w += bw.pop()
            bx.pop()
            be.pop()
            x = s / w
            while i < n - 1 and x >= values[i + 1]:  # ... and with the next points
                i += 1
                s += weights[i] * values[i]
                w += weights[i]
                x = s / w
            while bx and bx[-1] >= x:  # ... and with the blocks below
                s += bw[-1] * bx[-1]
                w += bw.pop()
                bx.pop()
                be.pop()
                x = s / w
        bx.append(x)
        bw.append(w)
        be.append(i + 1)
        i += 1
    out: list[float] = []
    start = 0
    for x, end in zip(bx, be):
        out += [x] * (end - start)
        start = end
    return out


def _trim(ux: list[float], fit: list[float]) -> tuple[list[float], list[float]]:
    """Clip the fit to [0, 1] and drop the interior points of constant runs (scikit-learn's knots)."""
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


def _expand(ux: np.ndarray, cnt: np.ndarray, npos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outcomes the counts stand for, sorted by confidence (negatives first at a tie)."""
    neg = cnt - npos
    reps = np.empty(2 * len(ux), dtype=np.int64)
    reps[0::2] = neg
    reps[1::2] = npos
    x = np.repeat(np.repeat(ux, 2), reps)
    y = np.repeat(np.tile(np.array([0.0, 1.0]), len(ux)), reps)
    return x, y


def _near_ties(ux: np.ndarray) -> bool:
    """Some neighbouring distinct confidences are closer than scikit-learn's resolution."""
    return len(ux) > 1 and not bool(np.all(ux[1:] - ux[:-1] >= _RES))


def _knots_numpy(ux: np.ndarray, cnt: np.ndarray, npos: np.ndarray) -> tuple[list[float], list[float]]:
    """The knots of the isotonic fit of the outcomes given as distinct confidences with counts and positives."""
    if _near_ties(ux):
        return _REFERENCE.fit_knots(*_expand(ux, cnt, npos))
    uw = cnt.astype(np.float64)
    # the compiled PAVA (the same operations as ``pava``) beyond the list path's sizes
    fit = np.asarray(isotonic_regression(npos / uw, weights=uw, increasing=True).x, dtype=np.float64)
    np.clip(fit, 0.0, 1.0, fit)
    u = len(fit)
    if u > 2:
        keep = np.ones(u, dtype=bool)
        keep[1:-1] = np.logical_or(np.not_equal(fit[1:-1], fit[:-2]), np.not_equal(fit[1:-1], fit[2:]))
        return ux[keep].tolist(), fit[keep].tolist()
    return ux.tolist(), fit.tolist()


def _knots_lists(ux: list[float], cnt: list[int], npos: list[int]) -> tuple[list[float], list[float]]:
    """``_knots_numpy`` for short Python lists: :func:`pava`, clip and trim in Python."""
    for a, b in zip(ux, ux[1:]):
        if not b - a >= _RES:  # near-ties: scikit-learn's own pooling
            return _knots_numpy(np.array(ux), np.array(cnt, dtype=np.int64), np.array(npos, dtype=np.int64))
    return _trim(ux, pava([p / w for p, w in zip(npos, cnt)], [float(w) for w in cnt]))


def _distinct(c: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A batch of outcomes as (distinct confidences ascending, counts, positives). (Equal
    confidences are one value; of +0.0 and -0.0, the one the sort puts first stands for both.)"""
    o = np.argsort(c)
    v = c[o]
    lab = y[o]
    k = len(v)
    brk = np.empty(k, dtype=bool)
    brk[:1] = True
    np.not_equal(v[1:], v[:-1], out=brk[1:])
    starts = np.flatnonzero(brk)
    if len(starts) == k:
        return v, np.ones(k, dtype=np.int64), lab.astype(np.int64)
    ends = np.empty(len(starts), dtype=np.intp)
    ends[:-1] = starts[1:]
    ends[-1:] = k
    cum = np.zeros(k + 1, dtype=np.int64)
    np.cumsum(lab, dtype=np.int64, out=cum[1:])
    return v[starts], ends - starts, cum[ends] - cum[starts]


class IncrementalIsotonic:
    """The fast :class:`~sgbelief.calibration.isotonic.IsotonicStore` (see the module docstring).

    Parameters
    ----------
    capacity : int or None
        Outcomes kept, the most recent; None keeps all.
    """

    __slots__ = ("capacity", "ux", "cnt", "npos", "wc", "wy", "n", "n_pos")

    def __init__(self, capacity: int | None = None) -> None:
        self.capacity = capacity
        #: the held outcomes as distinct confidences (ascending), their counts and positives
        self.ux: list[float] | np.ndarray = []
        self.cnt: list[int] | np.ndarray = []
        self.npos: list[int] | np.ndarray = []
        #: the held outcomes in arrival order
        self.wc: list[float] | np.ndarray = []
        self.wy: list[int] | np.ndarray = []
        #: outcomes held, positives among them
        self.n = 0
        self.n_pos = 0

    def clear(self) -> None:
        self.ux, self.cnt, self.npos, self.wc, self.wy = [], [], [], [], []
        self.n = self.n_pos = 0

    def merge(self, c: array, y: array) -> None:
        if type(self.ux) is list and self.n + len(c) <= SMALL:
            self._merge_lists(c, [1 if v else 0 for v in y])
        else:
            self._merge_arrays(np.frombuffer(c, dtype=np.float64), (np.frombuffer(y, dtype=np.int8) != 0).view(np.int8))

    def knots(self) -> tuple[list[float], list[float]]:
        if not self.n:
            return [], []
        if type(self.ux) is list:
            return _knots_lists(self.ux, self.cnt, self.npos)  # type: ignore[arg-type]
        return _knots_numpy(self.ux, self.cnt, self.npos)  # type: ignore[arg-type]

    def window(self) -> tuple[list[float] | np.ndarray, list[int] | np.ndarray]:
        return self.wc, self.wy

    def sorted_by_label(self, label: int) -> np.ndarray:
        cnt = np.asarray(self.cnt, dtype=np.int64)
        npos = np.asarray(self.npos, dtype=np.int64)
        return np.repeat(np.asarray(self.ux, dtype=np.float64), npos if label else cnt - npos)

    # ------------------------------------------------------------ merges
    def _merge_lists(self, cs: array, labs: list[int]) -> None:
        ux, cnt, npos = self.ux, self.cnt, self.npos
        n_pos = self.n_pos
        held = self.n + len(cs)
        fc, fy = self.wc, self.wy
        cap = self.capacity
        if cap is not None:
            drop = len(fc) + len(cs) - cap
            if drop > 0:
                drop_old = min(drop, len(fc))
                for v, lab in zip(fc[:drop_old], fy[:drop_old]):  # evict the oldest outcomes
                    i = bisect_left(ux, v)  # type: ignore[arg-type]
                    if i >= len(ux) or ux[i] != v or not (npos[i] if lab else cnt[i] - npos[i]):  # type: ignore[operator]
                        raise ValueError("evicted outcomes are not among the held ones")
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
        self.n_pos = n_pos
        self.n = held

    def _merge_arrays(self, new_c: np.ndarray, new_y: np.ndarray) -> None:
        ux, cnt, npos = self.ux, self.cnt, self.npos
        if type(ux) is list:
            ux = np.array(ux, dtype=np.float64)
            cnt = np.array(cnt, dtype=np.int64)
            npos = np.array(npos, dtype=np.int64)
        n_pos = self.n_pos
        fc, fy = self.wc, self.wy
        if type(fc) is list:
            fc, fy = np.array(fc, dtype=np.float64), np.array(fy, dtype=np.int8)
        if self.capacity is not None:
            fc, old_c, new_c, fy, old_y, new_y = slide_window(fc, new_c, self.capacity, (fy, new_y))  # type: ignore[arg-type]
            if len(old_c):  # evict the oldest outcomes
                ov, oc, op = _distinct(old_c, old_y)
                pos = np.searchsorted(ux, ov)  # type: ignore[arg-type]
                if len(ov) and (pos[-1] >= len(ux) or not np.array_equal(ux[pos], ov)):  # type: ignore[index]
                    raise ValueError("evicted outcomes are not among the held ones")
                cnt[pos] -= oc  # type: ignore[index]
                npos[pos] -= op  # type: ignore[index]
                if np.any(npos[pos] < 0) or np.any(cnt[pos] < npos[pos]):  # type: ignore[index]
                    raise ValueError("evicted outcomes are not among the held ones")
                gone = pos[cnt[pos] == 0]  # type: ignore[index]
                if len(gone):
                    ux, cnt, npos = np.delete(ux, gone), np.delete(cnt, gone), np.delete(npos, gone)
                n_pos -= int(np.count_nonzero(old_y))
        else:
            fc, fy = np.concatenate((fc, new_c)), np.concatenate((fy, new_y))  # type: ignore[arg-type]
        bv, bc, bp = _distinct(new_c, new_y)
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
        if m:  # insert the new distinct confidences: one scatter per column
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
        self.wc, self.wy = fc, fy
        self.n_pos = n_pos + int(np.count_nonzero(new_y))
        self.n = len(fc)

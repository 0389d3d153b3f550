"""Conformal prediction sets over the binary outcome {0, 1} (§4.1 Eq. 1, Prop. 1, Gibbs & Candès 2021).

The equations are small pure functions: :func:`nonconformity` (Eq. 1), :func:`conformal_quantile`
(the split-conformal threshold), :func:`adaptive_alpha` (the adaptive level's step) and
:func:`prediction_set`. :class:`ConformalSlice` holds one Mondrian slice's scores as a sorted view
kept up to date lazily (a Python list while small, a numpy array beyond, ``docs/performance.md``).
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_left, insort_right
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ConformalSlice",
    "PredictionSet",
    "adaptive_alpha",
    "conformal_quantile",
    "merge_sorted",
    "no_coverage",
    "nonconformity",
    "prediction_set",
    "remove_sorted",
    "slide_window",
]

#: confidences are clipped to [EPS, 1 - EPS] in Eq. 1, so every score is finite
EPS = 1e-12
_ONE_MINUS_EPS = 1.0 - EPS
#: score buffers up to this size are kept as Python lists (numpy's fixed per-call cost dominates there)
SMALL = 128
_log = math.log
_ceil = math.ceil
_INF = math.inf


def _no_nan(values: Iterable[float]) -> bool:
    """True when the (short) sequence has no NaN (nor +inf together with -inf): Python's sort order
    then equals numpy's."""
    total = sum(values)
    return total == total


def nonconformity(c: float, y: int) -> float:
    """Eq. 1: the nonconformity score of outcome ``y`` for a claim of confidence ``c``.

    The model's negative log-likelihood of y::

        s(e, y) = -y log c - (1 - y) log(1 - c)

    with c clipped to [1e-12, 1 - 1e-12] so that the score is always finite.

    Parameters
    ----------
    c : float
        The claim's raw confidence.
    y : int
        The outcome, 1 or 0.

    Returns
    -------
    float
        s(e, y) >= 0.
    """
    if c < EPS:
        c = EPS
    elif c > _ONE_MINUS_EPS:
        c = _ONE_MINUS_EPS
    return -_log(c) if y == 1 else -_log(1.0 - c)


def conformal_quantile(sorted_scores: np.ndarray | list[float], alpha: float) -> float:
    """Eq. 1's threshold: the (1 - alpha) quantile q_hat_{1-alpha} of the slice's nonconformity scores.

    The finite-sample split-conformal rank::

        q_hat_{1-alpha} = the ceil((n + 1)(1 - alpha))-th smallest of s(e_1, y_1), ..., s(e_n, y_n)

    so a fresh exchangeable score is <= q_hat with probability >= 1 - alpha (Prop. 1).

    Parameters
    ----------
    sorted_scores : numpy.ndarray or list of float
        The calibration scores, ascending.
    alpha : float
        The miscoverage level.

    Returns
    -------
    float
        q_hat; +inf when the rank exceeds n (too few scores for a finite threshold: the full set),
        -inf when alpha >= 1 (the empty set).
    """
    n = len(sorted_scores)
    if alpha >= 1.0:
        return -_INF
    rank = _ceil((n + 1) * (1.0 - alpha))
    if rank > n or n == 0:
        return _INF
    if rank < 1:
        return -_INF
    if isinstance(sorted_scores, np.ndarray):
        return sorted_scores.item(rank - 1)
    return float(sorted_scores[rank - 1])


def adaptive_alpha(alpha_t: float, alpha: float, gamma: float, err: int) -> float:
    """The adaptive conformal level's step (Gibbs & Candès 2021)::

        alpha_{t+1} = alpha_t + gamma (alpha - err_t)

    ``err_t`` is 1 when the outcome fell outside the set of level alpha_t, else 0: the level
    tightens after misses and relaxes after hits, so the long-run miscoverage tends to alpha.
    """
    return alpha_t + gamma * (alpha - err)


@dataclass(frozen=True, slots=True)
class PredictionSet:
    """A (1 - alpha) prediction set over {0, 1}, or an explicit "no coverage claim".

    ``labels`` is the set; ``coverage`` the nominal level when a claim applies, None outside the
    calibratable regime R (Property 1), with ``reason`` saying why.
    """

    labels: frozenset[int]
    coverage: float | None
    n_calibration: int = 0
    reason: str = ""

    @property
    def claims_coverage(self) -> bool:
        return self.coverage is not None

    def __contains__(self, y: object) -> bool:
        return y in self.labels


def no_coverage(reason: str) -> PredictionSet:
    """The full set {0, 1} with no coverage claim, saying why (outside the calibratable regime R)."""
    return PredictionSet(frozenset({0, 1}), None, 0, f"no coverage claim: {reason}")


class ConformalSlice:
    """Scores of one calibration slice (Eq. 1), the static threshold and the adaptive level alpha_t.

    New scores wait in ``pending`` (O(1) append). ``refresh`` commits them (``n_sorted`` at once);
    the merge into the ascending view is done when it is next read (``sorted``, ``threshold``, ...),
    all committed batches at once (sort the k new, one linear merge: O(n + k log k)), the same view
    as merging batch by batch; an unread slice costs O(1) per score. ``sorted`` is a Python list up
    to ``SMALL`` scores, a float64 numpy array beyond; ties keep older scores first. With a
    ``capacity``: a sliding window over the most recent scores. Adaptive level (Gibbs & Candès):
    alpha_{t+1} = alpha_t + gamma (alpha - err_t), err_t = 1 when y_t was not in the set.
    """

    __slots__ = ("pending", "_merged_ascending", "_merged_arrival", "chunks", "n_chunks", "n_sorted", "alpha_t", "n_err",
                 "n_seen", "capacity")

    def __init__(self, alpha: float, capacity: int | None = None) -> None:
        self.pending: array = array("d")
        #: the merged scores, ascending (read ``sorted``: it merges the committed batches first)
        self._merged_ascending: list[float] | np.ndarray = []
        #: the merged scores in arrival order (kept only with a capacity)
        self._merged_arrival: list[float] | np.ndarray = []
        #: batches committed by ``refresh`` and not merged yet (arrival order), and their total size
        self.chunks: list[array] = []
        self.n_chunks = 0
        self.n_sorted = 0
        self.alpha_t = alpha
        self.n_err = 0
        self.n_seen = 0
        self.capacity = capacity

    @property
    def n(self) -> int:
        """Scores held (sorted + pending)."""
        return self.n_sorted + len(self.pending)

    @property
    def sorted(self) -> list[float] | np.ndarray:
        """The committed scores, ascending."""
        if self.chunks:
            self.merge()
        return self._merged_ascending

    @property
    def fifo(self) -> list[float] | np.ndarray:
        """The scores of ``sorted`` in arrival order (kept only with a capacity)."""
        if self.chunks:
            self.merge()
        return self._merged_arrival

    def add(self, score: float) -> None:
        """Append one score to the pending ones (committed by the next :meth:`refresh`)."""
        self.pending.append(score)

    def add_score(self, score: float, min_refit: int, refit_growth: float) -> None:
        """Append one score; refresh once the pending ones reach max(min_refit, refit_growth * n_sorted)
        (or at the first score). Same as ``pending.append(score)`` plus that rule, O(1)."""
        p = self.pending
        p.append(score)
        m = self.n_sorted
        k = len(p)
        if m == 0 or (k >= min_refit and k >= refit_growth * m):
            self.refresh()

    def add_outcome(self, c: float, y: int, min_refit: int, refit_growth: float) -> None:
        """``add_score(nonconformity(c, y), min_refit, refit_growth)``: the score of Eq. 1."""
        self.add_score(nonconformity(c, y), min_refit, refit_growth)

    def observe(self, score: float, alpha: float, gamma: float) -> None:
        """One step of the adaptive level alpha_t with a new outcome's score (Alg. 1's outcome loop).

        err = 1 when the score exceeds the threshold of level alpha_t (the outcome was not in the
        set this slice would have produced), then alpha_t moves by :func:`adaptive_alpha`.
        """
        a = self.alpha_t
        if a > 0:
            if self.chunks:
                self.merge()
            q = conformal_quantile(self._merged_ascending, a)  # self.threshold(a), one call less per outcome
        else:
            q = _INF
        err = 1 if score > q else 0
        self.n_seen += 1
        self.n_err += err
        self.alpha_t = adaptive_alpha(a, alpha, gamma, err)

    def refresh(self) -> None:
        """Commit the pending scores to the sorted view (merged when it is next read), evicting the
        oldest beyond capacity."""
        pending = self.pending
        if not pending:
            return
        p = pending[:] if type(pending) is array else array("d", pending)
        del pending[:]  # the same object stays the pending buffer
        chunks = self.chunks
        chunks.append(p)
        self.n_chunks += len(p)
        n = self.n_sorted + len(p)
        cap = self.capacity
        if cap is not None:
            if n > cap:
                n = cap
            if self.n_chunks >= cap:  # the committed batches alone fill the window: the merged scores all slide out
                self._merged_ascending = []
                self._merged_arrival = []
                while self.n_chunks - len(chunks[0]) >= cap:
                    self.n_chunks -= len(chunks.pop(0))
        self.n_sorted = n

    def merge(self) -> None:
        """Merge the committed batches into the sorted view (as ``refresh`` did one batch at a time)."""
        chunks = self.chunks
        if not chunks:
            return
        new = chunks[0]
        for ch in chunks[1:]:
            new += ch
        self.chunks = []
        self.n_chunks = 0
        ascending = self._merged_ascending
        # no NaN: list order == numpy order
        if type(ascending) is list and len(ascending) + len(new) <= SMALL and _no_nan(new):
            self._merge_small(ascending, new)
        else:
            self._merge_numpy(np.frombuffer(new, dtype=np.float64))

    def _merge_small(self, ascending: list[float], new: array) -> None:
        cap = self.capacity
        if cap is not None:
            fifo = self._merged_arrival
            drop = len(fifo) + len(new) - cap
            if drop > 0:
                drop_old = min(drop, len(fifo))
                for v in fifo[:drop_old]:  # remove_sorted: the leftmost equal score
                    i = bisect_left(ascending, v)
                    if i >= len(ascending) or ascending[i] != v:
                        raise ValueError("remove_sorted: values are not a sub-multiset of the sorted buffer")
                    del ascending[i]
                new = new[max(drop - len(fifo), 0):]
                fifo = fifo[drop_old:]  # type: ignore[assignment]
            fifo.extend(new)  # type: ignore[union-attr]
            self._merged_arrival = fifo
        for v in new:  # merge_sorted: a new score goes after the equal ones already there
            insort_right(ascending, v)

    def _merge_numpy(self, new: np.ndarray) -> None:
        ascending = self._merged_ascending
        if type(ascending) is list:
            ascending = np.array(ascending, dtype=np.float64)
        if self.capacity is not None:
            arrival = np.asarray(self._merged_arrival, dtype=np.float64)
            self._merged_arrival, evicted, new = slide_window(arrival, new, self.capacity)
            if len(evicted):
                ascending = remove_sorted(ascending, evicted)  # type: ignore[arg-type]
        self._merged_ascending = merge_sorted(ascending, new)  # type: ignore[arg-type,assignment]

    def threshold(self, alpha: float) -> float:
        """:func:`conformal_quantile` of the committed scores at level ``alpha``."""
        if self.chunks:
            self.merge()
        return conformal_quantile(self._merged_ascending, alpha)

    def coverage_of_rank(self, q: float) -> int:
        """How many committed scores are <= q."""
        return int(np.searchsorted(self.sorted, q, side="right"))


def slide_window(
    fifo: np.ndarray, new: np.ndarray, capacity: int, *payload: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, ...]:
    """Append ``new`` to the arrival-ordered window ``fifo`` and keep its last ``capacity`` items.

    Returns (window, evicted, admitted): ``evicted`` are the old items pushed out (to be removed
    from the sorted views), ``admitted`` the tail of ``new`` that is kept (to be merged into them;
    items of ``new`` older than the window are never merged). Each ``payload`` pair
    (fifo_values, new_values) adds (window, evicted, admitted) of a parallel column.
    """
    drop = len(fifo) + len(new) - capacity
    drop_old = min(max(drop, 0), len(fifo))
    drop_new = max(drop - len(fifo), 0)
    out: list[np.ndarray] = []
    for old_col, new_col in ((fifo, new), *payload):
        admitted = new_col[drop_new:]
        out += [np.concatenate((old_col[drop_old:], admitted)), old_col[:drop_old], admitted]
    return tuple(out)


def remove_sorted(base: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Remove one occurrence of each of ``values`` (a sub-multiset of ``base``) from sorted ``base``, O(n + k log k)."""
    if len(values) == 0:
        return base
    v = np.sort(values)
    first = np.searchsorted(v, v, side="left")
    pos = np.searchsorted(base, v, side="left") + (np.arange(len(v)) - first)
    if pos[-1] >= len(base) or not np.array_equal(base[pos], v):
        raise ValueError("remove_sorted: values are not a sub-multiset of the sorted buffer")
    return np.delete(base, pos)


def merge_sorted(base: np.ndarray, new: np.ndarray, *payload: tuple[np.ndarray, np.ndarray]) -> np.ndarray | tuple[np.ndarray, ...]:
    """Merge unsorted ``new`` into sorted ``base`` (O(n + k log k)); ``payload`` pairs
    (base_values, new_values) are carried along in the same order. Ties keep base first, then
    ``new`` in its order."""
    if payload:
        order = np.argsort(new, kind="stable")
        new = new[order]
    else:
        ordered = np.sort(new)  # (SIMD) sort; equal values are bit-identical unless zeros (+-0) or NaN,
        if len(ordered) and (not ordered.all() or ordered[-1] != ordered[-1]):  # whose arrival order is kept then
            ordered = np.sort(new, kind="stable")
        new = ordered
    at = np.searchsorted(base, new, side="right")
    n, k = len(base), len(new)
    at += np.arange(k)  # positions of the new values in the merged array
    keep = np.ones(n + k, dtype=bool)
    keep[at] = False
    merged = np.empty(n + k, dtype=np.result_type(base, new))
    merged[at] = new
    merged[keep] = base
    if not payload:
        return merged
    out = [merged]
    for b, v in payload:
        m = np.empty(n + k, dtype=np.result_type(b, v))
        m[at] = v[order]
        m[keep] = b
        out.append(m)
    return tuple(out)


def prediction_set(c: float, q: float) -> frozenset[int]:
    """The conformal set {y in {0, 1} : s(c, y) <= q} for confidence ``c`` and threshold ``q``
    (Eq. 1 scores, ``q`` from :func:`conformal_quantile`)."""
    return frozenset(y for y in (0, 1) if nonconformity(c, y) <= q)

"""Conformal prediction sets over the binary outcome {0, 1} (§4.1 Eq. 1, Prop. 1, Gibbs & Candès 2021)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_EPS = 1e-12
_ONE_MINUS_EPS = 1.0 - _EPS


def nonconformity(c: float, y: int) -> float:
    """Eq. 1: s(e, y) = -y log c - (1 - y) log(1 - c), the model's negative log-likelihood of y."""
    if c < _EPS:
        c = _EPS
    elif c > _ONE_MINUS_EPS:
        c = _ONE_MINUS_EPS
    return -math.log(c) if y == 1 else -math.log(1.0 - c)


def conformal_quantile(sorted_scores: np.ndarray | list[float], alpha: float) -> float:
    """Finite-sample split-conformal threshold: the ceil((n+1)(1-alpha))-th smallest score.

    Returns +inf when that rank exceeds n (too few scores for a finite threshold: full set),
    and -inf when alpha >= 1 (empty set).
    """
    n = len(sorted_scores)
    if alpha >= 1.0:
        return -math.inf
    rank = math.ceil((n + 1) * (1.0 - alpha))
    if rank > n or n == 0:
        return math.inf
    if rank < 1:
        return -math.inf
    if isinstance(sorted_scores, np.ndarray):
        return sorted_scores.item(rank - 1)
    return float(sorted_scores[rank - 1])


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
    return PredictionSet(frozenset({0, 1}), None, 0, f"no coverage claim: {reason}")


class ConformalSlice:
    """Scores of one calibration slice, the static threshold and the adaptive level alpha_t.

    New scores wait in ``pending`` (O(1) append); ``refresh`` merges them into the sorted
    numpy array ``sorted`` in O(n + k log k) (sort the k new ones, one linear merge), so the
    amortised cost per score stays O(log n) and memory is 8 bytes per score. Queries are
    O(1) after a refresh. With a ``capacity`` the slice is a sliding window over the most
    recent ``capacity`` scores (the oldest are removed from the sorted view at the refresh that
    pushes them out), so memory is bounded. The adaptive variant updates alpha_t online:
    alpha_{t+1} = alpha_t + gamma (alpha - err_t), err_t = 1 when y_t was not in the set.
    """

    __slots__ = ("pending", "sorted", "n_sorted", "alpha_t", "n_err", "n_seen", "capacity", "fifo")

    def __init__(self, alpha: float, capacity: int | None = None) -> None:
        self.pending: list[float] = []
        self.sorted: np.ndarray = np.empty(0, dtype=np.float64)
        self.n_sorted = 0
        self.alpha_t = alpha
        self.n_err = 0
        self.n_seen = 0
        self.capacity = capacity
        #: the scores of ``sorted`` in arrival order (kept only with a capacity)
        self.fifo: np.ndarray = np.empty(0, dtype=np.float64)

    @property
    def n(self) -> int:
        """Scores held (sorted + pending)."""
        return self.n_sorted + len(self.pending)

    def add(self, score: float) -> None:
        self.pending.append(score)

    def refresh(self) -> None:
        """Merge the pending scores into the sorted view (evicting the oldest beyond capacity)."""
        if self.pending:
            new = np.array(self.pending, dtype=np.float64)
            self.pending = []
            if self.capacity is not None:
                self.fifo, evicted, new = slide_window(self.fifo, new, self.capacity)
                if len(evicted):
                    self.sorted = remove_sorted(self.sorted, evicted)
            self.sorted = merge_sorted(self.sorted, new)
        self.n_sorted = len(self.sorted)

    def threshold(self, alpha: float) -> float:
        return conformal_quantile(self.sorted, alpha)

    def coverage_of_rank(self, q: float) -> int:
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
    (base_values, new_values) are carried along in the same order. Ties keep base first."""
    order = np.argsort(new, kind="stable")
    new = new[order]
    at = np.searchsorted(base, new, side="right")
    merged = np.insert(base, at, new)
    if not payload:
        return merged
    return (merged, *(np.insert(b, at, v[order]) for b, v in payload))


def prediction_set(c: float, q: float) -> frozenset[int]:
    """{y in {0, 1} : s(c, y) <= q}."""
    return frozenset(y for y in (0, 1) if nonconformity(c, y) <= q)

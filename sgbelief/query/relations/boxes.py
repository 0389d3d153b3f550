"""Axis-aligned boxes: the :class:`Box` value, the box-to-box distance the relations use, and the
filling of box arrays from node attributes (a ``bbox`` pair, or a ``centroid`` as a degenerate box)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import chain
from typing import Any

import numpy as np

__all__ = ["Box", "box_distance", "fill_boxes"]


@dataclass(frozen=True, slots=True)
class Box:
    """Axis-aligned box ``lo`` .. ``hi`` (numpy arrays of 3 floats)."""

    lo: np.ndarray
    hi: np.ndarray

    @property
    def center(self) -> np.ndarray:
        return (self.lo + self.hi) / 2.0

    @property
    def size(self) -> np.ndarray:
        return self.hi - self.lo

    @property
    def volume(self) -> float:
        return float(np.prod(self.size))

    @property
    def footprint(self) -> float:
        s = self.size
        return float(s[0] * s[1])


def box_distance(a: Box, b: Box) -> float:
    """Euclidean distance between two axis-aligned boxes (0 when they touch or overlap)."""
    gap = np.maximum(0.0, np.maximum(a.lo - b.hi, b.lo - a.hi))
    return float(math.sqrt(float(gap @ gap)))


def fill_boxes(lo: np.ndarray, hi: np.ndarray, rows: list[int] | None, values: list[Any], pair: bool) -> None:
    """``lo[i], hi[i] = v[0], v[1]`` (``pair``: a bbox) or ``lo[i] = hi[i] = v`` (a centroid) for
    each row i and its value v (``rows`` None: every row): one array conversion when every value
    has the usual shape, else row by row (numpy's own broadcasting and errors)."""
    if not values:
        return
    rows_ix: Any = slice(None) if rows is None else rows
    arr = None
    try:  # every value 2 x 3 (a bbox) or 3 (a centroid): one pass over the numbers
        if pair and set(map(len, values)) == {2}:
            if set(map(len, chain.from_iterable(values))) == {3}:
                arr = np.fromiter(chain.from_iterable(chain.from_iterable(values)), dtype=float,
                                  count=6 * len(values)).reshape(-1, 2, 3)
        elif not pair and set(map(len, values)) == {3}:
            arr = np.fromiter(chain.from_iterable(values), dtype=float, count=3 * len(values)).reshape(-1, 3)
    except (ValueError, TypeError):
        arr = None
    if arr is not None:
        lo[rows_ix] = arr[:, 0] if pair else arr
        hi[rows_ix] = arr[:, 1] if pair else arr
        return
    for i, v in zip(range(len(values)) if rows is None else rows, values):
        if pair:
            lo[i] = v[0]
            hi[i] = v[1]
        else:
            lo[i] = hi[i] = v

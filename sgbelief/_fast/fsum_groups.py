"""Private: the compaction fold (``math.fsum`` of a pair's folded increments) on numpy groups.

:meth:`ProvenanceStore.compact <sgbelief.graph.provenance.ProvenanceStore.compact>` folds each
pair's settled entries with one ``math.fsum`` per pair and pass (the reference). An engine that
holds the increments of many pairs in one array folds them here, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np


def group_fsums(values: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """``math.fsum`` of each group ``values[starts[g]:starts[g] + sizes[g]]``, bit for bit.

    fsum is the correctly rounded exact sum (a zero sum is +0.0). A float addition is correctly
    rounded too, so groups of one or two values are done in numpy (``+ 0.0`` turns -0.0 into
    fsum's +0.0); only groups of three or more go through ``math.fsum``.
    """
    out = values[starts] + 0.0
    two = sizes == 2
    out[two] += values[starts[two] + 1]
    big = np.flatnonzero(sizes >= 3)
    if len(big):
        vals = values[np.repeat(sizes >= 3, sizes)].tolist()
        ends = np.cumsum(sizes[big]).tolist()
        fsum = math.fsum
        out[big] = [fsum(vals[a:b]) for a, b in zip([0, *ends[:-1]], ends)]
    return out


__all__ = ["group_fsums"]

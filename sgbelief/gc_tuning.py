"""Cyclic garbage-collector settings for long replays.

A map holds one provenance entry object per update inside the horizon T_prov, plus the events a
replay keeps in memory. CPython's cyclic collector runs a young-generation pass every 700 net
container allocations and regularly re-traverses every surviving object, so on a long stream a
large share of the time goes to the collector rather than to fusion (measured in
``benchmarks/bench_throughput.py``). The maps themselves create no reference cycles on the hot
path, so a higher threshold only delays, never prevents, the collection of real garbage.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

#: generation-0 threshold used while replaying (CPython's default is 700)
REPLAY_GC_THRESHOLD = 100_000


@contextmanager
def relaxed_gc(threshold0: int = REPLAY_GC_THRESHOLD) -> Iterator[None]:
    """Raise the collector's generation-0 threshold for the duration of a replay, then restore it.

    Nested uses are safe (the outermost restores the caller's setting); collection stays enabled.
    """
    old = gc.get_threshold()
    gc.set_threshold(max(int(threshold0), old[0]), *old[1:])
    try:
        yield
    finally:
        gc.set_threshold(*old)

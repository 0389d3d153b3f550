"""Private: every cyclic-garbage-collector setting of sgbelief, in one place.

A map holds one provenance entry object per update inside the horizon T_prov, plus the events a
replay keeps in memory, and a load or a save builds or walks millions of objects. CPython's cyclic
collector runs a young-generation pass every 700 net container allocations and regularly
re-traverses every surviving object, so on a long stream, a large load or a long mapping session
a large share of the time goes to the collector rather than to the work (measured in
``benchmarks/bench_throughput.py`` and ``benchmarks/bench_conceptgraphs.py``; docs/performance.md,
"GC options"). The maps create no reference cycles on the hot paths, so each setting here only
delays, never prevents, the collection of real garbage; each restores the caller's setting.

- :func:`relaxed_gc`: a replay (generation-0 threshold raised);
- :func:`young_collections_only`: a load (full collections postponed until the graph is built);
- :func:`gc_paused`: a save (the collector off while it walks the graph);
- :func:`checkpoint` / :func:`release_checkpoints`: a long-lived map in a mapping loop (what
  survives is frozen out of the collector's view; the ConceptGraphs backend's ``gc_checkpoints``).
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

#: generation-0 threshold used while replaying (CPython's default is 700)
REPLAY_GC_THRESHOLD = 100_000
#: a generation-2 threshold no load reaches (full collections wait for the end of the load)
_NO_FULL_COLLECTIONS = 2**30


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


@contextmanager
def young_collections_only() -> Iterator[None]:
    """Loading makes millions of long-lived objects. Young collections stay on (they are cheap
    while the new objects are still in cache, and they untrack the float tuples early, so the
    attribute dicts holding them are created untracked); full collections, which would re-traverse
    the whole growing heap again and again, are postponed until the graph is built."""
    t0, t1, t2 = gc.get_threshold()
    gc.set_threshold(t0, t1, _NO_FULL_COLLECTIONS)
    try:
        yield
    finally:
        gc.set_threshold(t0, t1, t2)


@contextmanager
def gc_paused() -> Iterator[None]:
    """Saving allocates millions of temporaries: pause the cyclic GC meanwhile."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def checkpoint() -> None:
    """Collect the cyclic garbage made since the last checkpoint, then freeze what survives.

    CPython's generation-2 collection re-traverses every tracked object; a map holds several per
    provenance entry (live for T_prov steps), so its pauses grow with objects x history (about
    3 s at 5,000 objects x 500 detections). Frozen objects (``gc.freeze()``) are skipped, and
    reference counting still frees them; each checkpoint only scans what is new since the
    previous one. Cycles that become garbage after being frozen wait for
    :func:`release_checkpoints`.
    """
    gc.collect()
    gc.freeze()


def release_checkpoints() -> None:
    """Give the objects frozen by :func:`checkpoint` back to the collector."""
    gc.unfreeze()


__all__ = ["REPLAY_GC_THRESHOLD", "checkpoint", "gc_paused", "relaxed_gc", "release_checkpoints", "young_collections_only"]

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
- :func:`gc_paused`: a save (the collector off while it walks the graph); these two are defined
  beside the binary layout that uses them (:mod:`sgbelief.graph.npz_archive`, a layer below this
  package) and re-exported here;
- :func:`checkpoint` / :func:`release_checkpoints`: a long-lived map in a mapping loop (what
  survives is frozen out of the collector's view; the ConceptGraphs backend's ``gc_checkpoints``).
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

from sgbelief.graph.npz_archive import gc_paused, young_collections_only

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

"""Node life cycle in the provenance store, as free functions over an
:class:`~sgbelief.graph.entry_log.EntryLog`: belief migration when two nodes merge, and dropping
a node's logs when it is removed.

Migration keeps every entry (its increments and status): the absorbed node's logs merge into the
same predicates' logs of the kept node in time order and the beliefs are recomputed (Eq. 4), so
the evidence count is unchanged (nothing lost, nothing doubled). A log holds at most one
compacted bucket, so a second one merges into the first with
:func:`~sgbelief.graph.compaction.merge_into_bucket`, as compaction itself does.
"""

from __future__ import annotations

from typing import Any

from sgbelief.graph.compaction import merge_into_bucket
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance_log import EntryStatus, ProvenanceEntry

_COMPACTED = EntryStatus.COMPACTED


def merged_entries(dst: list[ProvenanceEntry], src: list[ProvenanceEntry], node: Any, predicate: str
                   ) -> tuple[list[ProvenanceEntry], list[ProvenanceEntry]]:
    """Two logs of one pair as one: (the entries in time order, ``dst``'s first among equal times,
    with one bucket first when there is one; the further buckets merged into it)."""
    merged = sorted(dst + src, key=lambda e: e.t)
    buckets = [e for e in merged if e.status is _COMPACTED]
    if len(buckets) <= 1:
        return merged, []
    head, extras = buckets[0], buckets[1:]
    for extra in extras:
        merge_into_bucket(head, node, predicate, extra.t, extra.d_alpha, extra.d_beta, extra.n_folded, extra.summary)
    folded = {id(e) for e in extras}
    merged = [e for e in merged if id(e) not in folded]
    merged.remove(head)
    merged.insert(0, head)
    return merged, extras


def move_node(log: EntryLog, absorb: Any, keep: Any) -> None:
    """Belief migration: every log of ``absorb`` merges into the same predicate's log of ``keep``."""
    if absorb == keep:
        return
    logs = log.logs()
    for key in [k for k in logs if k[0] == absorb]:
        dst_key = (keep, key[1])
        dst = logs.get(dst_key)
        entries, folded = merged_entries([] if dst is None else dst.entries, logs[key].entries, keep, key[1])
        log.merge_pair(key, dst_key, entries, folded)


def remove_node(log: EntryLog, node: Any) -> int:
    """Drop every log of a node (its beliefs go back to the prior); returns the original entries
    dropped (a compacted entry counts what it folded)."""
    return sum(e.n_folded for key in [k for k in log.logs() if k[0] == node] for e in log.drop_pair(key))


__all__ = ["merged_entries", "move_node", "remove_node"]

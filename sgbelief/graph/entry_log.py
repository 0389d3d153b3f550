"""The entry log: what a provenance store is, as a protocol (paper §4.3, Eq. 4).

A provenance store holds one ordered log of entries per (node, predicate) pair
(:mod:`sgbelief.graph.provenance_log`: entries, statuses, Eq. 4) with a running belief per pair,
an event index, the arrival-order timeline compaction scans, the two queues of pending entries
and the memory of compacted event ids. :class:`EntryLog` is the narrow set of operations every
store implements on its own:

- writes: :meth:`~EntryLog.append` (and its hot-path form :meth:`~EntryLog.commit`),
  :meth:`~EntryLog.transition`, :meth:`~EntryLog.remove` (entries leave the store),
  :meth:`~EntryLog.drop_pair`, :meth:`~EntryLog.merge_pair` (one pair's log into another's) and
  :meth:`~EntryLog.fold` (old entries into their pairs' compacted buckets);
- read views: beliefs (:meth:`~EntryLog.alpha_beta`, :meth:`~EntryLog.pair_index`), the logs
  (:meth:`~EntryLog.logs`), the event index, the pending entries and queues, the timeline and
  the compacted-id memory.

The policies are free functions over an :class:`EntryLog`: the queues
(:mod:`sgbelief.fusion.queues`), retraction (:mod:`sgbelief.graph.retraction`), compaction
(:func:`sgbelief.graph.compaction.compact`), node migration (:mod:`sgbelief.graph.migration`) and
the JSON form (:mod:`sgbelief.graph.provenance_json`). Two implementations exist: the
object-backed reference store (:class:`sgbelief.graph.provenance.ProvenanceStore`) and the
journalled store of the private ``sgbelief._fast.journal``, which holds committed increments as
tuples until something reads them and is observably the same store
(``sgbelief.testing.check_store_matches_reference``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable, Iterable, Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

from sgbelief.graph.provenance_log import EntryRecord, EntryStatus, EntryVerdict, PairLog, ProvenanceEntry

Node = Hashable
PairKey = tuple[Any, str]


@runtime_checkable
class EntryLog(Protocol):
    """The operations of a provenance store (see the module docstring)."""

    prior_alpha: float
    prior_beta: float
    #: entries folded into compacted buckets so far
    n_compacted: int
    #: revisions pending in Q, and refused claims pending in Q⊥, in arrival order (lazy deletion:
    #: entries that left the queue stay until they reach its head)
    quarantine: deque[ProvenanceEntry]
    disagreement: deque[ProvenanceEntry]
    #: how many compacted event ids are remembered
    remember_compacted: int

    # ------------------------------------------------------------------ writes
    def append(self, record: EntryRecord) -> ProvenanceEntry:
        """Append an entry; counted statuses change the belief, pending ones join their queue."""

    def commit(self, node: Any, predicate: str, event_id: str | None, t: int, d_alpha: float, d_beta: float,
               stance: int = 0, verdict: EntryVerdict | None = None, confidence: float | None = None) -> None:
        """:meth:`append` of a committed entry, returning nothing (a store may build it later)."""

    def transition(self, entry: ProvenanceEntry, status: EntryStatus, *, scale: float = 1.0,
                   corroborated_by: str | None = None) -> None:
        """Move an entry to a new status (the only way an entry's status changes)."""

    def reweigh(self, changes: Iterable[tuple[ProvenanceEntry, float, float, int]]) -> None:
        """New increments and stance for committed entries, ``(entry, d_alpha, d_beta, stance)``
        each; the pairs touched get their belief recomputed from their logs (Eq. 4)."""

    def remove(self, entries: Iterable[ProvenanceEntry]) -> None:
        """Entries leave the store (logs, event index, pending lists); a pair left without
        entries is dropped, the others' beliefs are recomputed from their logs (Eq. 4)."""

    def drop_pair(self, key: PairKey) -> list[ProvenanceEntry]:
        """A pair leaves the store with every entry of its log; returns those entries."""

    def merge_pair(self, src: PairKey, dst: PairKey, entries: Sequence[ProvenanceEntry],
                   folded: Iterable[ProvenanceEntry] = ()) -> None:
        """The log of ``src`` joins ``dst`` (made when missing): ``dst``'s log becomes ``entries``
        (its own and ``src``'s, in the caller's order; ``folded``: buckets merged away), pending
        entries keep their order after ``dst``'s own, the belief is recomputed."""

    def fold(self, before_t: int) -> int:
        """Fold every settled entry with ``t < before_t`` into its pair's compacted bucket
        (:func:`sgbelief.graph.compaction.compact` is the policy); returns the number folded."""

    # ------------------------------------------------------------------ read views
    def alpha_beta(self, node: Any, predicate: str) -> tuple[float, float]:
        """A pair's running (alpha, beta) (the prior without evidence). O(1)."""

    def pair_index(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log with its running belief, live and read-only; the entry lists may lag
        behind a store that builds entries later (read entries through :meth:`logs`)."""

    def logs(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log with all its entries, in pair order (live, read-only)."""

    def entries(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        """A pair's log in order (a copy)."""

    def event_entries(self, event_id: str) -> list[ProvenanceEntry]:
        """An event's live entries, in recording order."""

    def event_index(self) -> dict[str, list[ProvenanceEntry]]:
        """Every event id with live entries -> those entries (a copy)."""

    def has_event(self, event_id: str) -> bool:
        """Whether an event has live entries."""

    def pending(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        """A pair's pending entries (a copy)."""

    def pending_index(self) -> Mapping[PairKey, list[ProvenanceEntry]]:
        """Each pair with pending entries -> those entries (live, read-only)."""

    def compaction_timeline(self) -> list[ProvenanceEntry]:
        """The entries a compaction pass scans, in arrival order (a copy)."""

    def timeline_view(self) -> Sequence[ProvenanceEntry]:
        """The built entries a compaction pass scans, in arrival order (live, read-only)."""

    def compacted_ids(self) -> list[str]:
        """The remembered compacted event ids, oldest first."""

    def is_compacted(self, event_id: str) -> bool:
        """Whether the id is among the remembered compacted ids."""

    def materialize(self) -> None:
        """Build every entry a store holds in another form (nothing for the reference store)."""

    @property
    def deferred(self) -> bool:
        """Whether loaded entries are still to be built."""

    def object_log(self) -> Any:
        """The object-backed store (a :class:`sgbelief.graph.provenance.ProvenanceStore`, typed
        Any here: that module imports this one) holding this store's entries, every one built:
        the store itself, or the one a journalled store builds into. For loaders (its
        bulk-building methods) and the compaction kernels."""


__all__ = ["EntryLog", "Node", "PairKey"]

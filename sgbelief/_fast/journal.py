"""The journalled provenance store: the reference store's behaviour, built lazily.

:class:`JournalledProvenanceStore` is a :class:`~sgbelief.graph.provenance.ProvenanceStore` whose
``commit`` (the operators' hot path) updates the belief at once and appends a plain tuple to a
journal; the entry object, the event index and the timeline are built only when something reads
or changes entries (every such method materialises the journal first, in arrival order, so every
observable order is the one ``record`` would have produced). A compaction pass folds journal
records older than the horizon straight into the compacted buckets (:mod:`sgbelief._fast.folds`),
so a streaming replay never builds objects for entries nobody looks at.

A store loaded from the binary layout defers its settled entries the same way
(:meth:`JournalledProvenanceStore.defer_entries`): the beliefs, the pending queues and their
entries exist at once, the other entry objects, the event index and the timeline are built by the
first materialisation, before any journal record.

The functions at the end are this package's private API for code that fills or reads a store's
structures in bulk (the batched engine, the binary loader): nothing outside ``sgbelief._fast``
should call them (``sgbelief.eval.batched`` does until it moves into this package).
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Iterable, Iterator, Mapping
from itertools import islice
from operator import eq, le
from typing import Any, Protocol

from sgbelief._fast.folds import JournalRecord, fold_journal_records, fold_with_journal, record_event_id, record_t
from sgbelief.graph.compaction import old_prefix_length
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA
from sgbelief.graph.provenance import (
    COUNTED,
    EntryRecord,
    EntryStatus,
    EntryVerdict,
    PairKey,
    PairLog,
    ProvenanceEntry,
    ProvenanceStore,
    index_event,
)

#: the journal's first record while a loader's entries are deferred (see defer_entries): every
#: reader that materialises a non-empty journal then builds them first
DEFERRED: JournalRecord = ((None, ""), None, -1, 0.0, 0.0, 0, None, None, None)
_COMMITTED = EntryStatus.COMMITTED


class DeferredEntries(Protocol):
    """Entries a loader builds on demand (see :meth:`JournalledProvenanceStore.defer_entries`)."""

    def build(self, store: ProvenanceStore) -> None:
        """Fill the loaded pairs' entry lists, the event index and the timeline of ``store``."""

    def has_event(self, event_id: str) -> bool:
        """Whether a loaded (not yet built) entry carries this event id."""


class JournalledProvenanceStore(ProvenanceStore):
    """:class:`~sgbelief.graph.provenance.ProvenanceStore` with committed increments journaled
    as tuples and loaded entries deferred; observably the same store (same beliefs, entries,
    orders, errors and saved form under any sequence of calls)."""

    #: journal records from which a compaction pass groups them by pair in numpy
    #: (:func:`sgbelief._fast.folds.fold_journal_records`); smaller passes take the loop
    vector_fold_min = 128

    def __init__(
        self,
        prior: tuple[float, float] = (PRIOR_ALPHA, PRIOR_BETA),
        *,
        remember_compacted: int = 100_000,
    ) -> None:
        super().__init__(prior, remember_compacted=remember_compacted)
        # committed increments not yet materialised, in arrival order (they come after every
        # entry of the timeline); see commit() and materialize()
        self._journal: list[JournalRecord] = []
        # how many leading journal records check_journal() has verified, the last one's t, and
        # each verified id's t
        self._j_checked = 0
        self._j_last_t: float = -math.inf
        self._j_id_t: dict[str, int] = {}
        # the event ids of the journal's records (has_event without materialising)
        self._j_ids: set[str | None] = set()
        self._j_ids_add = self._j_ids.add
        # entries a loader has not built yet (then _journal[0] is DEFERRED); see defer_entries()
        self._deferred: DeferredEntries | None = None

    # ------------------------------------------------------------ the journal
    def commit(
        self, node: Any, predicate: str, event_id: str | None, t: int, d_alpha: float, d_beta: float, stance: int = 0,
        verdict: EntryVerdict | None = None, confidence: float | None = None,
    ) -> None:
        """Record a committed increment: the belief changes at once (Eq. 3); the entry is
        journaled and materialised only when something reads the log, or folded straight into
        its pair's compacted bucket."""
        key = (node, predicate)
        log = self._pairs.get(key)
        if log is None:
            log = self._pairs[key] = PairLog(self.prior_alpha, self.prior_beta)
        log.alpha += d_alpha
        log.beta += d_beta
        self._journal.append((key, event_id, t, d_alpha, d_beta, stance, log, verdict, confidence))
        self._j_ids_add(event_id)

    def materialize(self) -> None:
        """Turn the journal into entries (logs, event index, timeline), exactly as ``record`` would
        have built them. Every method that reads or changes entries calls it first; code that
        touches the store's private structures must call it too."""
        journal = self._journal
        if not journal:
            return
        self._journal = []
        self._j_checked, self._j_last_t = 0, -math.inf
        self._j_id_t.clear()
        self._j_ids.clear()
        if journal[0] is DEFERRED:  # a loader's entries come before every journal record
            deferred, self._deferred = self._deferred, None
            assert deferred is not None
            deferred.build(self)
            del journal[0]
        by_event = self._by_event
        tl_append = self._timeline.append
        committed = _COMMITTED
        for key, eid, t, da, db, stance, log, verdict, confidence in journal:
            entry = ProvenanceEntry(eid, t, da, db, committed, key[0], key[1], stance, verdict, confidence)
            log.entries.append(entry)  # type: ignore[union-attr]
            if eid is not None:
                index_event(by_event, eid, entry)
            tl_append(entry)

    def defer_entries(self, deferred: DeferredEntries) -> None:
        """Let ``deferred.build(store)`` make the loaded entries on the first materialisation.

        For loaders: the store must already hold every loaded pair (its running belief, an
        empty entry list), the pending queues with their entries, and nothing else; the
        journal must be empty. ``build`` then fills, in one pass, what an eager load would have:
        each loaded pair's entry list, the event index and the timeline, reusing the pending
        entry objects. Status transitions of pending entries meanwhile act on those objects, and
        commits are journaled after the marker, so the result is the eager load followed by the
        same operations."""
        if self._journal or self._deferred is not None or self._by_event or self._timeline:
            raise ValueError("defer_entries needs a freshly loaded store (no journal, index or timeline)")
        self._deferred = deferred
        self._journal.append(DEFERRED)

    @property
    def deferred(self) -> bool:
        """Whether loaded entries are still to be built (by the first read of the logs)."""
        return self._deferred is not None

    # ------------------------------------------- reads and writes that see entries
    def entries(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        if self._journal:
            self.materialize()
        return ProvenanceStore.entries(self, node, predicate)

    def event_entries(self, event_id: str) -> list[ProvenanceEntry]:
        if self._journal:
            self.materialize()
        return ProvenanceStore.event_entries(self, event_id)

    def event_index(self) -> dict[str, list[ProvenanceEntry]]:
        if self._journal:
            self.materialize()
        return ProvenanceStore.event_index(self)

    def has_event(self, event_id: str) -> bool:
        if event_id in self._by_event or event_id in self._j_ids:
            return True
        deferred = self._deferred
        return deferred is not None and deferred.has_event(event_id)

    def logs(self) -> Mapping[PairKey, PairLog]:
        if self._journal:
            self.materialize()
        return self._pairs

    def compaction_timeline(self) -> list[ProvenanceEntry]:
        if self._journal:
            self.materialize()
        return list(self._timeline)

    def count_entries(self, node: Any = None) -> int:
        if self._journal:
            self.materialize()
        return ProvenanceStore.count_entries(self, node)

    def iter_entries(self) -> Iterator[ProvenanceEntry]:
        if self._journal:
            self.materialize()
        return ProvenanceStore.iter_entries(self)

    def append(self, record: EntryRecord) -> ProvenanceEntry:
        if self._journal:  # keep arrival order: journal records come first
            self.materialize()
        return ProvenanceStore.append(self, record)

    def transition(
        self, entry: ProvenanceEntry, status: EntryStatus, *, scale: float = 1.0, corroborated_by: str | None = None
    ) -> None:
        if self._journal and entry.status in COUNTED and status not in COUNTED:
            self.materialize()  # the belief is recomputed from the whole log
        ProvenanceStore.transition(self, entry, status, scale=scale, corroborated_by=corroborated_by)

    def retract(self, event_id: str, *, cascade_window: int | None = None) -> list[str]:
        if self._journal:
            self.materialize()
        return ProvenanceStore.retract(self, event_id, cascade_window=cascade_window)

    def remove_node(self, node: Any) -> int:
        if self._journal:
            self.materialize()
        return ProvenanceStore.remove_node(self, node)

    def move_node(self, absorb: Any, keep: Any) -> None:
        if absorb != keep and self._journal:
            self.materialize()
        ProvenanceStore.move_node(self, absorb, keep)

    def compact(self, before_t: int) -> int:
        """:meth:`ProvenanceStore.compact`, folding old journal records without materialising
        them when that gives exactly what materialising them first would (:meth:`old_journal`)."""
        if not self._journal:
            return ProvenanceStore.compact(self, before_t)
        n_old = old_prefix_length(self._timeline, before_t)
        raws = self.old_journal(before_t, n_old == len(self._timeline))
        if raws is None:  # the journal cannot be folded as it stands
            self.materialize()
            return ProvenanceStore.compact(self, before_t)
        if not raws:  # the journal is entirely young: the timeline's pass alone
            return ProvenanceStore.compact(self, before_t)
        if not n_old and len(raws) >= self.vector_fold_min:  # journal records only
            folded = fold_journal_records(self, raws)
            if folded is not None:
                return folded
        return fold_with_journal(self, before_t, n_old, raws)

    # ------------------------------------------------ journal checks for compaction
    def old_journal(self, before_t: int, timeline_all_old: bool) -> list[JournalRecord] | None:
        """The journal records a compaction at ``before_t`` folds, when folding them unmaterialised
        gives exactly what materialising them first would, else None (the caller materialises).

        Exact when (:meth:`check_journal`) the journal is in time order, no journaled id is in
        the event index, and no id occurs at two times: then the old records are a prefix (found
        by bisection), every id they hold has all its live entries among them (so "an id's last
        entry is folded" is a count), and the index's order is untouched. They may fold only
        after an entirely old timeline (arrival order); otherwise the journal must be entirely young.
        """
        journal = self._journal
        if not journal:
            return []
        if journal[0] is DEFERRED or not self.check_journal():
            return None
        if not timeline_all_old:
            return [] if journal[0][2] >= before_t else None
        n = bisect_left(journal, before_t, key=record_t)
        return journal[:n] if n else []

    def check_journal(self) -> bool:
        """Extend the verified prefix of the journal to all of it (each record is checked once:
        the event index only gains ids when the journal is materialised, which resets this)."""
        journal = self._journal
        k = self._j_checked
        if k == len(journal):
            return True
        new = journal[k:]
        ts = list(map(record_t, new))
        if ts[0] < self._j_last_t or not all(map(le, ts, islice(ts, 1, None))):
            return False  # not in time order
        ids = list(map(record_event_id, new))
        chunk = dict(zip(ids, ts))  # each id's last t
        if not all(map(eq, map(chunk.__getitem__, ids), ts)):
            return False  # an id at two times
        chunk.pop(None, None)  # type: ignore[call-overload]
        if self._by_event and not self._by_event.keys().isdisjoint(chunk):
            return False
        seen = self._j_id_t
        for eid in seen.keys() & chunk.keys():
            if seen[eid] != chunk[eid]:
                return False
        seen.update(chunk)  # type: ignore[arg-type]
        self._j_checked = len(journal)
        self._j_last_t = ts[-1]
        return True

    def drop_folded_records(self, k: int) -> None:
        """Remove the first ``k`` journal records (folded by a compaction pass)."""
        journal = self._journal
        # every record of a folded id is folded (an id has one t and the fold takes a time prefix)
        self._j_ids.difference_update(map(record_event_id, islice(journal, k)))
        del journal[:k]
        self._j_checked -= k
        if len(self._j_id_t) > 2 * len(journal) + 1024:  # drop the folded ids, in one C pass
            # (until then a folded id reused later only costs a materialisation)
            id_t = self._j_id_t = dict(zip(map(record_event_id, journal), map(record_t, journal)))
            id_t.pop(None, None)  # type: ignore[call-overload]

    @property
    def journal_length(self) -> int:
        """Committed increments not yet materialised (the deferral marker included)."""
        return len(self._journal)


# ------------------------------------------------------------------------------------
# The private API of sgbelief._fast for code that fills a store's structures in bulk. The store
# must be materialised (``store.materialize()``) before any of these is called.
def add_logs(store: ProvenanceStore, keys: Iterable[PairKey], alphas: Iterable[float],
             betas: Iterable[float]) -> list[PairLog]:
    """New logs (running beliefs as given, no entries) for pairs the store does not hold yet,
    appended in order; returns them, for the caller to fill their ``entries``."""
    logs = list(map(PairLog, alphas, betas))
    store._pairs.update(zip(keys, logs))
    return logs


def extend_timeline(store: ProvenanceStore, entries: Iterable[ProvenanceEntry]) -> None:
    """Append entries (already in their logs) to the compaction timeline, in order."""
    store._timeline.extend(entries)


def set_event_index(store: ProvenanceStore,
                    items: Iterable[tuple[str, ProvenanceEntry | list[ProvenanceEntry]]]) -> None:
    """Add event ids to the event index, in order: each with its entry, or the list of its
    entries when it has several (as :func:`~sgbelief.graph.provenance.index_event` builds them)."""
    store._by_event.update(items)


def remember_compacted_ids(store: ProvenanceStore, ids: Iterable[str]) -> None:
    """Append ids to the bounded memory of compacted event ids (the oldest drop out)."""
    store._compacted_order.extend(ids)


def index_pending(store: ProvenanceStore, entries: Iterable[ProvenanceEntry]) -> None:
    """Append pending entries (already in their logs and queues) to their pairs' pending lists, in order."""
    by_pair = store._pending_by_pair
    for e in entries:
        by_pair.setdefault((e.node, e.predicate), []).append(e)


def pending_index(store: ProvenanceStore) -> Mapping[PairKey, list[ProvenanceEntry]]:
    """Each pair with pending entries -> those entries in time order (a live read-only view)."""
    return store._pending_by_pair

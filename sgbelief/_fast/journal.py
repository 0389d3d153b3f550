"""The journalled provenance store: the reference store's behaviour, built lazily.

:class:`JournalledProvenanceStore` implements :class:`~sgbelief.graph.entry_log.EntryLog` on its
own, by composition: it holds an object-backed :class:`~sgbelief.graph.provenance.ProvenanceStore`
(its *object log*) for every entry that exists as an object, and a journal of plain tuples for
committed increments not built yet. ``commit`` (the operators' hot path) updates the pair's
running belief at once and appends a tuple to the journal; the entry objects, the event index
and the timeline are built only when something reads or changes entries (every such operation
materialises the journal first, in arrival order, so every observable order is the one
``append`` would have produced). A compaction pass folds journal records older than the horizon
straight into the compacted buckets (:mod:`sgbelief._fast.folds`), so a streaming replay never
builds objects for entries nobody looks at.

A store loaded from the binary layout defers its settled entries the same way
(:meth:`JournalledProvenanceStore.defer_entries`): the beliefs, the pending queues and their
entries exist at once, the other entry objects, the event index and the timeline are built by the
first materialisation, before any journal record.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Iterable, Mapping, Sequence
from itertools import islice
from operator import eq, le
from typing import Any, Protocol

from sgbelief._fast.folds import JournalRecord, fold_journal_records, fold_with_journal, record_event_id, record_t
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA
from sgbelief.graph.compaction import fold_pass, old_prefix_length
from sgbelief.graph.entry_log import PairKey
from sgbelief.graph.provenance import (
    COUNTED,
    EntryRecord,
    EntryStatus,
    EntryVerdict,
    PairLog,
    ProvenanceEntry,
    ProvenanceStore,
)
from sgbelief.graph.store_methods import StoreMethods

#: the journal's first record while a loader's entries are deferred (see defer_entries): every
#: reader that materialises a non-empty journal then builds them first
DEFERRED: JournalRecord = ((None, ""), None, -1, 0.0, 0.0, 0, None, None, None)
_COMMITTED = EntryStatus.COMMITTED


class DeferredEntries(Protocol):
    """Entries a loader builds on demand (see :meth:`JournalledProvenanceStore.defer_entries`)."""

    def build(self, store: ProvenanceStore) -> None:
        """Fill the loaded pairs' entry lists, the event index and the timeline of ``store`` (the
        object log, through its builder methods)."""

    def has_event(self, event_id: str) -> bool:
        """Whether a loaded (not yet built) entry carries this event id."""


class JournalledProvenanceStore(StoreMethods):
    """An :class:`~sgbelief.graph.entry_log.EntryLog` with committed increments journaled as
    tuples and loaded entries deferred, built into an object log on demand; observably the
    reference store (same beliefs, entries, orders, errors and saved form under any sequence of
    calls)."""

    #: journal records from which a compaction pass groups them by pair in numpy
    #: (:func:`sgbelief._fast.folds.fold_journal_records`); smaller passes take the loop
    vector_fold_min = 128

    def __init__(
        self,
        prior: tuple[float, float] = (PRIOR_ALPHA, PRIOR_BETA),
        *,
        remember_compacted: int = 100_000,
    ) -> None:
        objects = self._objects = ProvenanceStore(prior, remember_compacted=remember_compacted)
        self.prior_alpha, self.prior_beta = objects.prior_alpha, objects.prior_beta
        # the object log's queues and live views (their objects never change)
        self.quarantine = objects.quarantine
        self.disagreement = objects.disagreement
        self._index = objects.pair_index()
        self._built_ids = objects.indexed_events()
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

    @property
    def n_compacted(self) -> int:
        """Entries folded into compacted buckets so far."""
        return self._objects.n_compacted

    @n_compacted.setter
    def n_compacted(self, n: int) -> None:
        self._objects.n_compacted = n

    @property
    def remember_compacted(self) -> int:
        """How many of the most recently compacted event ids are remembered (oldest dropped first)."""
        return self._objects.remember_compacted

    @remember_compacted.setter
    def remember_compacted(self, n: int) -> None:
        self._objects.remember_compacted = n

    # ------------------------------------------------------------ the journal
    def commit(
        self, node: Any, predicate: str, event_id: str | None, t: int, d_alpha: float, d_beta: float, stance: int = 0,
        verdict: EntryVerdict | None = None, confidence: float | None = None,
    ) -> None:
        """Record a committed increment: the belief changes at once (Eq. 3); the entry is
        journaled and materialised only when something reads the log, or folded straight into
        its pair's compacted bucket."""
        key = (node, predicate)
        log = self._index.get(key)
        if log is None:
            log = self._objects.open_pair(key)
        log.alpha += d_alpha
        log.beta += d_beta
        self._journal.append((key, event_id, t, d_alpha, d_beta, stance, log, verdict, confidence))
        self._j_ids_add(event_id)

    def materialize(self) -> None:
        """Turn the journal into entries of the object log (logs, event index, timeline), exactly
        as ``append`` would have built them. Every operation that reads or changes entries calls
        it first."""
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
            deferred.build(self._objects)
            del journal[0]
        committed = _COMMITTED
        built: list[ProvenanceEntry] = []
        add = built.append
        for key, eid, t, da, db, stance, log, verdict, confidence in journal:
            entry = ProvenanceEntry(eid, t, da, db, committed, key[0], key[1], stance, verdict, confidence)
            log.entries.append(entry)  # type: ignore[union-attr]  # already counted in log's belief
            add(entry)
        self._objects.attach(built)

    def defer_entries(self, deferred: DeferredEntries) -> None:
        """Let ``deferred.build(object_log)`` make the loaded entries on the first materialisation.

        For loaders: the store must already hold every loaded pair (its running belief, an
        empty entry list), the pending queues with their entries, and nothing else; the
        journal must be empty. ``build`` then fills, in one pass, what an eager load would have:
        each loaded pair's entry list, the event index and the timeline, reusing the pending
        entry objects. Status transitions of pending entries meanwhile act on those objects, and
        commits are journaled after the marker, so the result is the eager load followed by the
        same operations."""
        if self._journal or self._deferred is not None or self._built_ids or self._objects.timeline_view():
            raise ValueError("defer_entries needs a freshly loaded store (no journal, index or timeline)")
        self._deferred = deferred
        self._journal.append(DEFERRED)

    @property
    def deferred(self) -> bool:
        """Whether loaded entries are still to be built (by the first read of the logs)."""
        return self._deferred is not None

    def object_log(self) -> ProvenanceStore:
        """The object log, every entry built (materialises the journal)."""
        if self._journal:
            self.materialize()
        return self._objects

    # ------------------------------------------------------------ read views
    def alpha_beta(self, node: Any, predicate: str) -> tuple[float, float]:
        """Current (alpha, beta) of a pair (the prior when it has no entry). O(1), nothing built."""
        log = self._index.get((node, predicate))
        if log is None:
            return self.prior_alpha, self.prior_beta
        return log.alpha, log.beta

    def pair_index(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log with its running belief (live, read-only; the entry lists lag behind
        the journal)."""
        return self._index

    def logs(self) -> Mapping[PairKey, PairLog]:
        return self.object_log().logs()

    def entries(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        return self.object_log().entries(node, predicate)

    def event_entries(self, event_id: str) -> list[ProvenanceEntry]:
        return self.object_log().event_entries(event_id)

    def event_index(self) -> dict[str, list[ProvenanceEntry]]:
        return self.object_log().event_index()

    def has_event(self, event_id: str) -> bool:
        if event_id in self._built_ids or event_id in self._j_ids:
            return True
        deferred = self._deferred
        return deferred is not None and deferred.has_event(event_id)

    def pending(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        return self._objects.pending(node, predicate)  # pending entries are never journaled

    def pending_index(self) -> Mapping[PairKey, list[ProvenanceEntry]]:
        return self._objects.pending_index()

    def compaction_timeline(self) -> list[ProvenanceEntry]:
        return self.object_log().compaction_timeline()

    def timeline_view(self) -> Sequence[ProvenanceEntry]:
        """The built part of the timeline (live, read-only; journal records come after it)."""
        return self._objects.timeline_view()

    def compacted_ids(self) -> list[str]:
        return self._objects.compacted_ids()

    def is_compacted(self, event_id: str) -> bool:
        return self._objects.is_compacted(event_id)

    # ------------------------------------------------------------ writes
    def append(self, record: EntryRecord) -> ProvenanceEntry:
        return self.object_log().append(record)  # journal records come first (arrival order)

    def transition(
        self, entry: ProvenanceEntry, status: EntryStatus, *, scale: float = 1.0, corroborated_by: str | None = None
    ) -> None:
        if self._journal and entry.status in COUNTED and status not in COUNTED:
            self.materialize()  # the belief is recomputed from the whole log
        self._objects.transition(entry, status, scale=scale, corroborated_by=corroborated_by)

    def reweigh(self, changes: Iterable[tuple[ProvenanceEntry, float, float, int]]) -> None:
        self.object_log().reweigh(changes)  # entries given are built; the belief is recomputed from the log

    def remove(self, entries: Iterable[ProvenanceEntry]) -> None:
        self.object_log().remove(entries)

    def drop_pair(self, key: PairKey) -> list[ProvenanceEntry]:
        return self.object_log().drop_pair(key)

    def merge_pair(self, src: PairKey, dst: PairKey, entries: Sequence[ProvenanceEntry],
                   folded: Iterable[ProvenanceEntry] = ()) -> None:
        self.object_log().merge_pair(src, dst, entries, folded)

    def fold(self, before_t: int) -> int:
        """Compaction's pass (:func:`sgbelief.graph.compaction.fold_pass` on the object log),
        folding old journal records without materialising them when that gives exactly what
        materialising them first would (:meth:`old_journal`)."""
        objects = self._objects
        if not self._journal:
            return fold_pass(objects, before_t)
        timeline = objects.timeline_view()
        n_old = old_prefix_length(timeline, before_t)
        raws = self.old_journal(before_t, n_old == len(timeline))
        if raws is None:  # the journal cannot be folded as it stands
            self.materialize()
            return fold_pass(objects, before_t)
        if not raws:  # the journal is entirely young: the timeline's pass alone
            return fold_pass(objects, before_t)
        if not n_old and len(raws) >= self.vector_fold_min:  # journal records only
            folded = fold_journal_records(objects, raws)
            if folded is not None:
                self.drop_folded_records(len(raws))
                return folded
        folded = fold_with_journal(objects, before_t, n_old, raws)
        self.drop_folded_records(len(raws))
        return folded

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
        if self._built_ids and not self._built_ids.isdisjoint(chunk):
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


__all__ = ["DEFERRED", "DeferredEntries", "JournalledProvenanceStore"]

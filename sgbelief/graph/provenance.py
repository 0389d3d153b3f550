"""The reference provenance store P (paper §4.3, Eq. 4): every entry an object from the start.

Every update an operator makes to a belief is an entry ``(event id, t, d_alpha, d_beta, status)``
in the log of its (node, predicate) pair. The belief is *defined* by the log::

    (alpha, beta) = (alpha_0, beta_0) + sum of (d_alpha, d_beta) over counted entries   (Eq. 4)

(:func:`belief_from_entries`; the paper's ``\\label{eq:provrecon}``). The counted statuses are
committed, released (revision timeout at weight w/k), confirmed and compacted. Refused (⊥) and
quarantined entries carry the increments the event *would* contribute but are not counted while
they sit in the disagreement queue Q⊥ or the revision quarantine Q; those queues are simply the
pending entries of the store, so they are saved, loaded and migrated with the graph.

:class:`ProvenanceStore` implements the operations of :class:`~sgbelief.graph.entry_log.EntryLog`
over entry objects: it keeps a running (alpha, beta) per pair so that reads are O(1), and
whatever stops counting an increment recomputes the pair's belief from its log with
``math.fsum``. The policies are free functions over an EntryLog, with thin methods here for the
public API (:mod:`sgbelief.graph.store_methods`): retraction (:mod:`~sgbelief.graph.retraction`),
compaction (:mod:`~sgbelief.graph.compaction`, whose :func:`fold_pass` this store's ``fold``
runs), node migration (:mod:`~sgbelief.graph.migration`), the JSON form
(:mod:`~sgbelief.graph.provenance_json`) and the queues (:mod:`sgbelief.fusion.queues`).

The bulk-building methods at the end (``add_pairs``, ``add_logs``, ``index_events``,
``extend_timeline``, ``index_pending``, ``retire``) are the one builder every loader fills a store
with: ``from_logs`` (:func:`sgbelief.graph.store_methods.fill_from_logs`), the JSON and binary
loaders, the deferred binary load, the journal's materialisation (``attach``) and the batched
engine of ``sgbelief._fast``.

The streaming engines use a store with the same observable behaviour that journals committed
increments as plain tuples and builds objects only when something reads them (private,
``sgbelief._fast.journal``; ``sgbelief.testing.check_store_matches_reference`` proves the two equal).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable, Iterable, KeysView, Mapping, Sequence
from typing import Any

from sgbelief.errors import RetractionError
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA
from sgbelief.graph.compaction import (
    FoldSummary,
    fold_into_bucket,
    fold_pass,
    merge_into_bucket,
    settled_before,
)
from sgbelief.graph.entry_log import EntryLog, PairKey
from sgbelief.graph.provenance_log import (
    COUNTED,
    PENDING,
    EntryRecord,
    EntryStatus,
    EntryVerdict,
    PairLog,
    ProvenanceEntry,
    belief_from_entries,
    event_list,
    index_event,
)
from sgbelief.graph.store_methods import StoreMethods

Node = Hashable


__all__ = [
    "COUNTED", "PENDING", "EntryLog", "EntryRecord", "EntryStatus", "EntryVerdict", "FoldSummary", "Node", "PairKey",
    "PairLog", "ProvenanceEntry", "ProvenanceStore", "belief_from_entries", "event_list", "fold_into_bucket",
    "index_event", "merge_into_bucket", "settled_before"
]

# members read once (an attribute lookup on an Enum class runs Python code)
_COMMITTED, _COMPACTED = EntryStatus.COMMITTED, EntryStatus.COMPACTED
_QUARANTINED, _REFUSED = EntryStatus.QUARANTINED, EntryStatus.REFUSED


class ProvenanceStore(StoreMethods):
    """Per-(node, predicate) ordered logs of belief increments, every entry an object
    (:class:`~sgbelief.graph.entry_log.EntryLog`, the reference implementation).

    Parameters
    ----------
    prior:
        (alpha_0, beta_0) of every pair; Beta(1, 1) by default.
    remember_compacted:
        How many compacted event ids are remembered so that retracting one of them gives a
        precise error (bounded so memory does not grow with the stream length).
    """

    def __init__(
        self,
        prior: tuple[float, float] = (PRIOR_ALPHA, PRIOR_BETA),
        *,
        remember_compacted: int = 100_000,
    ) -> None:
        self.prior_alpha, self.prior_beta = float(prior[0]), float(prior[1])
        self._compacted_order: deque[str] = deque(maxlen=0)
        self.remember_compacted = int(remember_compacted)
        self._pairs: dict[PairKey, PairLog] = {}
        # event id -> its entry, or the list of its entries when it has several (index_event)
        self._by_event: dict[str, ProvenanceEntry | list[ProvenanceEntry]] = {}
        # every live, not-yet-compacted entry in arrival order (drives amortised compaction)
        self._timeline: deque[ProvenanceEntry] = deque()
        self.n_compacted = 0
        # queues: pending entries in arrival order (lazy deletion) and indexed by pair
        self.quarantine: deque[ProvenanceEntry] = deque()
        self.disagreement: deque[ProvenanceEntry] = deque()
        self._pending_by_pair: dict[PairKey, list[ProvenanceEntry]] = {}

    @property
    def remember_compacted(self) -> int:
        """How many of the most recently compacted event ids are remembered (oldest dropped first)."""
        return self._remember

    @remember_compacted.setter
    def remember_compacted(self, n: int) -> None:
        self._remember = int(n)
        # the most recent compacted event ids, oldest first (the bounded deque drops the oldest)
        self._compacted_order = deque(self._compacted_order, maxlen=max(self._remember, 0))

    # ------------------------------------------------------------------ read views
    def alpha_beta(self, node: Any, predicate: str) -> tuple[float, float]:
        """Current (alpha, beta) of a pair (the prior when it has no entry). O(1)."""
        log = self._pairs.get((node, predicate))
        if log is None:
            return self.prior_alpha, self.prior_beta
        return log.alpha, log.beta

    def pair_index(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log with its running belief (a live read-only view)."""
        return self._pairs

    def logs(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log, in the store's pair order (a live read-only view: change the store
        only through its methods)."""
        return self._pairs

    def entries(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        """The pair's log in order (a copy of the list; entries are live objects)."""
        log = self._pairs.get((node, predicate))
        return list(log.entries) if log is not None else []

    def event_entries(self, event_id: str) -> list[ProvenanceEntry]:
        """The live entries an event recorded, in recording order."""
        return event_list(self._by_event.get(event_id))

    def event_index(self) -> dict[str, list[ProvenanceEntry]]:
        """Every event id with live entries -> those entries (a copy, in the index's order)."""
        return {eid: event_list(v) for eid, v in self._by_event.items()}

    def indexed_events(self) -> KeysView[str]:
        """The event ids with live entries (a live read-only set view, for fast membership tests)."""
        return self._by_event.keys()

    def has_event(self, event_id: str) -> bool:
        return event_id in self._by_event

    def pending(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        return list(self._pending_by_pair.get((node, predicate), ()))

    def pending_index(self) -> Mapping[PairKey, list[ProvenanceEntry]]:
        """Each pair with pending entries -> those entries in time order (a live read-only view)."""
        return self._pending_by_pair

    def compaction_timeline(self) -> list[ProvenanceEntry]:
        """The entries a compaction pass scans, in arrival order (a copy; dead entries included)."""
        return list(self._timeline)

    def timeline_view(self) -> Sequence[ProvenanceEntry]:
        """The entries a compaction pass scans, in arrival order (a live read-only view)."""
        return self._timeline

    def compacted_ids(self) -> list[str]:
        """The remembered compacted event ids, oldest first."""
        return list(self._compacted_order)

    def is_compacted(self, event_id: str) -> bool:
        """Whether the id is among the ``remember_compacted`` most recently compacted (O(n) scan)."""
        return event_id in self._compacted_order

    def materialize(self) -> None:
        """Make every entry an object. The reference store holds objects from the start, so this
        does nothing here; a store that journals or defers entries builds them."""

    @property
    def deferred(self) -> bool:
        """Whether loaded entries are still to be built (never, for the reference store)."""
        return False

    def object_log(self) -> ProvenanceStore:
        """This store (its entries are objects already)."""
        return self

    # ------------------------------------------------------------------ writes
    def append(self, record: EntryRecord) -> ProvenanceEntry:
        """Append an entry (:class:`EntryRecord`); counted statuses update the belief, pending
        ones join their queue. Returns the entry (a live object: change it through the store)."""
        node, predicate, event_id, t, d_alpha, d_beta, status, stance, verdict, confidence = record
        key = (node, predicate)
        log = self._pairs.get(key)
        if log is None:
            log = self._pairs[key] = PairLog(self.prior_alpha, self.prior_beta)
        entry = ProvenanceEntry(event_id, t, d_alpha, d_beta, status, node, predicate, stance, verdict, confidence)
        log.entries.append(entry)
        if status in COUNTED:
            log.alpha += d_alpha
            log.beta += d_beta
        elif status in PENDING:
            self._add_pending(key, entry)
        if event_id is not None:
            index_event(self._by_event, event_id, entry)
        self._timeline.append(entry)
        return entry

    def commit(
        self, node: Any, predicate: str, event_id: str | None, t: int, d_alpha: float, d_beta: float, stance: int = 0,
        verdict: EntryVerdict | None = None, confidence: float | None = None,
    ) -> None:
        """Append a committed increment (Eq. 3) without returning the entry (so a store is free
        to build the entry later): the operators' hot path, positional for speed."""
        self.append(EntryRecord(node, predicate, event_id, t, d_alpha, d_beta, _COMMITTED, stance, verdict,
                                confidence))

    def transition(
        self, entry: ProvenanceEntry, status: EntryStatus, *, scale: float = 1.0, corroborated_by: str | None = None
    ) -> None:
        """Move an entry to a new status; ``scale`` multiplies its increments (w/k on timeout);
        ``corroborated_by``: the event whose corroboration moves it (added to the entry's
        ``corroborated_by``, so that retracting the entry's event cascades to it).

        The belief changes exactly when the entry starts (or stops) being counted.
        """
        if not entry.alive:
            raise RetractionError(f"entry of event {entry.event_id!r} is no longer in the store")
        was_counted, was_pending = entry.status in COUNTED, entry.status in PENDING
        log = self._pairs[(entry.node, entry.predicate)]
        if was_counted:
            log.alpha -= entry.d_alpha
            log.beta -= entry.d_beta
        if scale != 1.0:
            entry.d_alpha *= scale
            entry.d_beta *= scale
        entry.status = status
        counted, pending = status in COUNTED, status in PENDING
        if counted:
            log.alpha += entry.d_alpha
            log.beta += entry.d_beta
        if was_pending and not pending:
            self._drop_pending(entry)
        elif pending and not was_pending:
            self._add_pending((entry.node, entry.predicate), entry)
        if was_counted and not counted:
            self._refresh(log)
        if corroborated_by is not None:
            entry.corroborated_by = [*(entry.corroborated_by or ()), corroborated_by]

    def reweigh(self, changes: Iterable[tuple[ProvenanceEntry, float, float, int]]) -> None:
        """Give committed entries new increments and stance, ``(entry, d_alpha, d_beta, stance)``
        each: a claim weighed again under a refitted calibration (docs/method.md §8, "Silent claims
        under the current calibration"). The pairs touched get their belief recomputed from their
        logs (Eq. 4), in the order first touched. Only committed entries change: a pending entry
        carries what it would add once counted, a compacted one what it folded."""
        touched: dict[PairKey, None] = {}
        for entry, d_alpha, d_beta, stance in changes:
            if not entry.alive:
                raise RetractionError(f"entry of event {entry.event_id!r} is no longer in the store")
            if entry.status is not _COMMITTED:
                raise ValueError(f"only committed entries are weighed again, not {entry.status.value} "
                                 f"(event {entry.event_id!r})")
            entry.d_alpha, entry.d_beta, entry.stance = d_alpha, d_beta, stance
            touched[(entry.node, entry.predicate)] = None
        pairs = self._pairs
        for key in touched:
            self._refresh(pairs[key])

    def remove(self, entries: Iterable[ProvenanceEntry]) -> None:
        """Entries leave the store (retraction): out of their logs, the event index and the
        pending lists (the queues and the timeline drop them lazily); a pair left without
        entries is dropped, the others' beliefs are recomputed (Eq. 4), in the order first touched."""
        touched: dict[PairKey, None] = {}
        pairs = self._pairs
        for entry in entries:
            key = (entry.node, entry.predicate)
            if entry.status in PENDING:
                self._drop_pending(entry)
            self._unindex(entry)
            entry.alive = False
            pairs[key].entries.remove(entry)
            touched[key] = None
        for key in touched:
            log = pairs[key]
            if not log.entries:
                del pairs[key]
            else:
                self._refresh(log)

    def drop_pair(self, key: PairKey) -> list[ProvenanceEntry]:
        """A pair leaves the store with its whole log (node removal); returns its entries."""
        entries = self._pairs.pop(key).entries
        for entry in entries:
            entry.alive = False
            if entry.status in PENDING:
                self._drop_pending(entry)
            self._unindex(entry)
        return entries

    def merge_pair(self, src: PairKey, dst: PairKey, entries: Sequence[ProvenanceEntry],
                   folded: Iterable[ProvenanceEntry] = ()) -> None:
        """``src``'s log joins ``dst``'s (made at the end of the pair order when missing): its
        entries take ``dst``'s node, ``dst``'s log becomes ``entries`` (the caller's merge of the
        two; ``folded``: buckets merged into another, which die), ``src``'s pending entries follow
        ``dst``'s, and the belief is recomputed (Eq. 4)."""
        moved = self._pairs.pop(src)
        log = self._pairs.get(dst)
        if log is None:
            log = self._pairs[dst] = PairLog(self.prior_alpha, self.prior_beta)
        for entry in moved.entries:
            entry.node = dst[0]
        pend = self._pending_by_pair.pop(src, None)
        if pend:
            self._pending_by_pair.setdefault(dst, []).extend(pend)
        for bucket in folded:
            bucket.alive = False
        log.entries = list(entries)
        self._refresh(log)

    def fold(self, before_t: int) -> int:
        """Compaction's reference pass over this store (:func:`sgbelief.graph.compaction.fold_pass`)."""
        return fold_pass(self, before_t)

    # ------------------------------------------------ the fold's operations (compaction.FoldTarget)
    def pop_timeline(self, n: int) -> list[ProvenanceEntry]:
        """Take the timeline's first ``n`` entries, in arrival order."""
        timeline = self._timeline
        if n == len(timeline):
            old = list(timeline)
            timeline.clear()
            return old
        popleft = timeline.popleft
        return [popleft() for _ in range(n)]

    def fold_pair(self, log: PairLog, bucket: ProvenanceEntry, folded: Iterable[ProvenanceEntry],
                  keep: list[ProvenanceEntry] | None) -> list[str]:
        """A pair's log becomes ``[bucket, *keep]`` (``keep`` None: unchanged); the folded entries
        die and leave the event index. Returns the ids whose last live entry they were, in order."""
        if keep is not None:
            keep.insert(0, bucket)
            log.entries = keep
        gone: list[str] = []
        unindex = self._unindex
        for entry in folded:
            entry.alive = False
            if unindex(entry):
                gone.append(entry.event_id)  # type: ignore[arg-type]
        return gone

    def retire(self, event_ids: Iterable[str], n_folded: int) -> None:
        """Count folded entries and remember the retired ids (bounded: the oldest drop out)."""
        self.n_compacted += n_folded
        self._compacted_order.extend(event_ids)

    # ------------------------------------------------------------------ internals
    def _refresh(self, log: PairLog) -> None:
        """Recompute a pair's running belief from its log (Eq. 4)."""
        log.alpha, log.beta = belief_from_entries((self.prior_alpha, self.prior_beta), log.entries)

    def _add_pending(self, key: PairKey, entry: ProvenanceEntry) -> None:
        (self.quarantine if entry.status is _QUARANTINED else self.disagreement).append(entry)
        self._pending_by_pair.setdefault(key, []).append(entry)

    def _drop_pending(self, entry: ProvenanceEntry) -> None:
        key = (entry.node, entry.predicate)
        bucket = self._pending_by_pair.get(key)
        if bucket is not None:
            try:
                bucket.remove(entry)
            except ValueError:
                pass
            if not bucket:
                del self._pending_by_pair[key]

    def _unindex(self, entry: ProvenanceEntry) -> bool:
        """Take an entry out of the event index; True when its id has no live entry left."""
        eid = entry.event_id
        if eid is None:
            return False
        found = self._by_event.get(eid)
        if found is entry:
            del self._by_event[eid]
            return True
        if type(found) is list:
            found[:] = [e for e in found if e is not entry]
            if not found:
                del self._by_event[eid]
                return True
        return False

    # ------------------------------------------------------------------ the builder
    # Every loader fills a store through these (from_logs, the JSON and binary loaders, the
    # deferred binary load, the journal's materialisation, the batched engine); each keeps the
    # store's invariants given what its docstring asks of the caller (``retire`` above too).
    def open_pair(self, key: PairKey) -> PairLog:
        """The pair's log, made (prior belief, no entries) at the end of the pair order when missing."""
        log = self._pairs.get(key)
        if log is None:
            log = self._pairs[key] = PairLog(self.prior_alpha, self.prior_beta)
        return log

    def add_pairs(self, keys: Iterable[PairKey], alphas: Iterable[float], betas: Iterable[float]) -> list[PairLog]:
        """New logs (running beliefs as given, no entries) for pairs the store does not hold yet,
        appended in order; returns them, for the caller to fill their ``entries``."""
        logs = list(map(PairLog, alphas, betas))
        self._pairs.update(zip(keys, logs))
        return logs

    def add_logs(self, logs: Mapping[PairKey, PairLog]) -> None:
        """Loaded logs (entries and running beliefs agreeing with Eq. 4) of pairs the store does
        not hold yet, appended in order; index their entries with the methods below."""
        self._pairs.update(logs)

    def attach(self, entries: Iterable[ProvenanceEntry]) -> None:
        """Index entries already in their pairs' logs and counted in their beliefs (committed
        ones), in arrival order: the event index and the timeline (a journal's materialisation)."""
        entries = list(entries)
        by_event = self._by_event
        for entry in entries:
            eid = entry.event_id
            if eid is not None:
                index_event(by_event, eid, entry)
        self._timeline.extend(entries)

    def index_events(self, items: Iterable[tuple[str, ProvenanceEntry | list[ProvenanceEntry]]]) -> None:
        """Add event ids to the event index, in order: each with its entry, or the list of its
        entries when it has several (as :func:`index_event` builds them)."""
        self._by_event.update(items)

    def extend_timeline(self, entries: Iterable[ProvenanceEntry]) -> None:
        """Append entries (already in their logs) to the compaction timeline, in order."""
        self._timeline.extend(entries)

    def index_pending(self, entries: Iterable[ProvenanceEntry]) -> None:
        """Append pending entries (already in their logs and queues) to their pairs' pending lists, in order."""
        by_pair = self._pending_by_pair
        for e in entries:
            by_pair.setdefault((e.node, e.predicate), []).append(e)

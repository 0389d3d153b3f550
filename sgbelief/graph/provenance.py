"""Provenance store P (paper §4.3, Eq. 5): an ordered log of increments per (node, predicate).

Every update an operator makes to a belief is an entry ``(event id, t, d_alpha, d_beta, status)``
in the log of its (node, predicate) pair. The belief is *defined* by the log::

    (alpha, beta) = (alpha_0, beta_0) + sum of (d_alpha, d_beta) over counted entries   (Eq. 5)

where the counted statuses are committed, released (revision timeout at weight w/k),
confirmed and compacted. Refused (⊥) and quarantined entries carry the increments the event
*would* contribute but are not counted while they sit in the disagreement queue Q⊥ or the
revision quarantine Q; those queues are simply the pending entries of the store, so they are
saved, loaded and migrated with the graph.

The store keeps a running (alpha, beta) cache per pair so that reads are O(1); retraction and
merges recompute the cache from the log with ``math.fsum``.

Committed increments written by the operators' hot path (:meth:`ProvenanceStore.commit`) go to a
journal of plain tuples first: the belief is updated at once, the entry object, the event index
and the timeline are built only when something reads them (any method that returns or changes
entries materialises the journal first, in arrival order, so every observable order is the one
:meth:`ProvenanceStore.record` would have produced). A compaction pass folds journal records older
than the horizon straight into the compacted buckets, so a streaming replay never builds objects
for entries nobody looks at.

A store loaded from the binary layout defers its settled entries the same way
(:meth:`ProvenanceStore.defer_entries`): the beliefs, the pending queues and their entries exist at
once, the other entry objects, the event index and the timeline are built by the first
materialisation, before any journal record.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections import Counter, deque
from collections.abc import Hashable, Iterable, Iterator
from itertools import chain, islice
from operator import eq, itemgetter, le
from enum import Enum
from typing import Any, Protocol

import numpy as np

from sgbelief.errors import FormatError, RetractionError
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA, BetaBelief

Node = Hashable
PairKey = tuple[Any, str]


class EntryStatus(str, Enum):
    """Life-cycle status of a provenance entry."""

    COMMITTED = "committed"  #: applied to the belief (Eq. 4)
    REFUSED = "refused"  #: ⊥ verdict: refused, pending in the disagreement queue Q⊥
    RESOLVED = "resolved"  #: ⊥ later corroborated by ⊤ within T_disagree; never committed
    EXPIRED = "expired"  #: ⊥ released on timeout, unresolved; never committed
    DISMISSED = "dismissed"  #: ⊥ closed by an explicit operator decision without committing
    QUARANTINED = "quarantined"  #: revision (KL > tau_rev) pending in the quarantine Q
    RELEASED = "released"  #: revision released on timeout, committed at reduced weight w/k
    DISCARDED = "discarded"  #: revision disconfirmed within T_cor; never committed
    CONFIRMED = "confirmed"  #: committed by an explicit operator confirmation
    COMPACTED = "compacted"  #: several old entries folded into one equivalent increment


#: statuses whose increments count in the belief (Eq. 5)
COUNTED: frozenset[EntryStatus] = frozenset(
    {EntryStatus.COMMITTED, EntryStatus.RELEASED, EntryStatus.CONFIRMED, EntryStatus.COMPACTED}
)
#: statuses of entries still waiting in a queue
PENDING: frozenset[EntryStatus] = frozenset({EntryStatus.REFUSED, EntryStatus.QUARANTINED})

_STATUS_BY_VALUE = {s.value: s for s in EntryStatus}
_COMMITTED = EntryStatus.COMMITTED
_COMPACTED = EntryStatus.COMPACTED
_REFUSED = EntryStatus.REFUSED
_QUARANTINED = EntryStatus.QUARANTINED
#: the counted set keyed by identity (hashing a str-Enum member runs Python code)
_COUNTED_IDS = frozenset(id(s) for s in COUNTED)
_PENDING_IDS = frozenset(id(s) for s in PENDING)

#: fields of a journal record (a committed entry not yet materialised as a ProvenanceEntry):
#: (pair key, event id, t, d_alpha, d_beta, stance, the pair's log). The log is the one the store
#: holds for the key: whatever removes or replaces a pair's log materialises the journal first.
JournalRecord = tuple[PairKey, "str | None", int, float, float, int, "_PairLog | None"]
#: the journal's first record while a loader's entries are deferred (see defer_entries): every
#: reader that materialises a non-empty journal then builds them first
_DEFERRED: JournalRecord = ((None, ""), None, -1, 0.0, 0.0, 0, None)
_rec_eid = itemgetter(1)
_rec_t = itemgetter(2)
_rec_da = itemgetter(3)
_rec_db = itemgetter(4)
_rec_log = itemgetter(6)
#: journal records a compaction pass folds from which it groups them by pair in numpy
#: (:meth:`ProvenanceStore._fold_journal`); smaller passes take the per-record loop
VECTOR_FOLD_MIN = 128


def _last_seen_order(ids: Iterable[str | None]) -> list[str]:
    """The distinct ids, None left out, each placed where it occurs last."""
    last_first = dict.fromkeys(reversed(list(ids)))
    last_first.pop(None, None)  # type: ignore[call-overload]  # entries without an id are never remembered
    order = list(last_first)
    order.reverse()
    return order  # type: ignore[return-value]


class ProvenanceEntry:
    """One log entry. Mutable only through :class:`ProvenanceStore` (status transitions)."""

    __slots__ = (
        "event_id",
        "t",
        "d_alpha",
        "d_beta",
        "status",
        "node",
        "predicate",
        "stance",
        "corroborated_by",
        "n_folded",
        "alive",
    )

    def __init__(
        self,
        event_id: str | None,
        t: int,
        d_alpha: float,
        d_beta: float,
        status: EntryStatus,
        node: Any,
        predicate: str,
        stance: int = 0,
    ) -> None:
        self.event_id = event_id
        self.t = t
        self.d_alpha = d_alpha
        self.d_beta = d_beta
        self.status = status
        self.node = node
        self.predicate = predicate
        #: +1 when the evidence supports the predicate, -1 when it denies it, 0 neutral
        self.stance = stance
        #: ids of events whose corroboration committed this (revision) entry
        self.corroborated_by: list[str] | None = None
        #: number of original entries a compacted entry stands for
        self.n_folded = 1
        #: False once retracted or folded away
        self.alive = True

    @property
    def counted(self) -> bool:
        return id(self.status) in _COUNTED_IDS

    @property
    def pending(self) -> bool:
        return id(self.status) in _PENDING_IDS

    def as_tuple(self) -> tuple[str | None, int, float, float, str]:
        """(event id, t, d_alpha, d_beta, status) as in the paper's log."""
        return (self.event_id, self.t, self.d_alpha, self.d_beta, self.status.value)

    def __repr__(self) -> str:
        return (
            f"ProvenanceEntry(event_id={self.event_id!r}, t={self.t}, d_alpha={self.d_alpha:.6g}, "
            f"d_beta={self.d_beta:.6g}, status={self.status.value}, node={self.node!r}, "
            f"predicate={self.predicate!r})"
        )


def _event_list(found: ProvenanceEntry | list[ProvenanceEntry] | None) -> list[ProvenanceEntry]:
    """A value of the event index as a (new) list of entries."""
    if found is None:
        return []
    if type(found) is list:
        return list(found)
    return [found]  # type: ignore[list-item]


def index_event(by_event: dict[str, Any], event_id: str, entry: ProvenanceEntry) -> None:
    """Add an entry to the event index: the entry itself for an id's first entry, a list from its
    second on (the id keeps its place in the dict). ``record`` does the same inline."""
    prev = by_event.get(event_id)
    if prev is None:
        by_event[event_id] = entry
    elif type(prev) is list:
        prev.append(entry)
    else:
        by_event[event_id] = [prev, entry]


class _PairLog:
    __slots__ = ("alpha", "beta", "entries")

    def __init__(self, alpha: float, beta: float) -> None:
        self.alpha = alpha
        self.beta = beta
        self.entries: list[ProvenanceEntry] = []


class DeferredEntries(Protocol):
    """Entries a loader builds on demand (see :meth:`ProvenanceStore.defer_entries`)."""

    def build(self, store: ProvenanceStore) -> None:
        """Fill the loaded pairs' entry lists, the event index and the timeline of ``store``."""


class ProvenanceStore:
    """Per-(node, predicate) ordered logs of belief increments, with retraction and compaction.

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
        self._pairs: dict[PairKey, _PairLog] = {}
        # event id -> its entry, or the list of its entries when it has several (most events have
        # one: no list is allocated for them); use _event_list() to read it
        self._by_event: dict[str, ProvenanceEntry | list[ProvenanceEntry]] = {}
        # every live, not-yet-compacted entry in arrival order (drives amortised compaction)
        self._timeline: deque[ProvenanceEntry] = deque()
        # committed increments not yet materialised, in arrival order (they come after every
        # entry of the timeline); see commit() and materialize()
        self._journal: list[JournalRecord] = []
        # how many leading journal records _check_journal() has verified, the last one's t, and
        # each verified id's t (see _check_journal)
        self._j_checked = 0
        self._j_last_t: float = -math.inf
        self._j_id_t: dict[str, int] = {}
        # entries a loader has not built yet (then _journal[0] is _DEFERRED); see defer_entries()
        self._deferred: DeferredEntries | None = None
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

    # ------------------------------------------------------------------ reads
    def __len__(self) -> int:
        return len(self._pairs)

    def __contains__(self, key: object) -> bool:
        return key in self._pairs

    def alpha_beta(self, node: Any, predicate: str) -> tuple[float, float]:
        """Current (alpha, beta) of a pair (the prior when it has no entry). O(1)."""
        log = self._pairs.get((node, predicate))
        if log is None:
            return self.prior_alpha, self.prior_beta
        return log.alpha, log.beta

    def belief(self, node: Any, predicate: str) -> BetaBelief:
        a, b = self.alpha_beta(node, predicate)
        return BetaBelief(a, b)

    def mean(self, node: Any, predicate: str) -> float:
        a, b = self.alpha_beta(node, predicate)
        return a / (a + b)

    def entries(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        """The pair's log in order (a copy of the list; entries are live objects)."""
        if self._journal:
            self.materialize()
        log = self._pairs.get((node, predicate))
        return list(log.entries) if log is not None else []

    def event_entries(self, event_id: str) -> list[ProvenanceEntry]:
        """The live entries an event recorded, in recording order."""
        if self._journal:
            self.materialize()
        return _event_list(self._by_event.get(event_id))

    def event_index(self) -> dict[str, list[ProvenanceEntry]]:
        """Every event id with live entries -> those entries (a copy, in the index's order)."""
        if self._journal:
            self.materialize()
        return {eid: _event_list(v) for eid, v in self._by_event.items()}

    def has_event(self, event_id: str) -> bool:
        if self._journal:
            self.materialize()
        return event_id in self._by_event

    def pairs(self) -> Iterator[PairKey]:
        return iter(self._pairs)

    def predicates(self) -> set[str]:
        return {p for _, p in self._pairs}

    def predicates_of(self, node: Any) -> list[str]:
        return [p for (n, p) in self._pairs if n == node]

    def nodes_with(self, predicate: str) -> Iterator[Any]:
        return (n for (n, p) in self._pairs if p == predicate)

    def _plain_means(self) -> bool:
        """True when ``mean`` is alpha / (alpha + beta) of the stored pair (no subclass overrides
        ``mean`` or ``alpha_beta``), so bulk reads may take it from the pair logs directly."""
        cls = type(self)
        return cls.mean is ProvenanceStore.mean and cls.alpha_beta is ProvenanceStore.alpha_beta

    def means(self, nodes: Iterable[Any], predicate: str) -> list[float]:
        """:meth:`mean` of (node, predicate) for each node, in order (the prior mean without evidence)."""
        if not self._plain_means():
            return [self.mean(n, predicate) for n in nodes]
        get = self._pairs.get
        prior = self.prior_alpha / (self.prior_alpha + self.prior_beta)
        out: list[float] = []
        for node in nodes:
            log = get((node, predicate))
            if log is None:
                out.append(prior)
            else:
                a = log.alpha
                out.append(a / (a + log.beta))
        return out

    def means_with(self, predicate: str) -> Iterator[tuple[Any, float]]:
        """(node, :meth:`mean`) for every node with evidence on ``predicate``."""
        if not self._plain_means():
            return ((n, self.mean(n, predicate)) for n in self.nodes_with(predicate))
        return ((n, log.alpha / (log.alpha + log.beta)) for (n, p), log in self._pairs.items() if p == predicate)

    def pending(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        return list(self._pending_by_pair.get((node, predicate), ()))

    def count_entries(self, node: Any = None) -> int:
        """Number of original evidence entries (compacted entries count what they folded)."""
        if self._journal:
            self.materialize()
        total = 0
        for (n, _p), log in self._pairs.items():
            if node is not None and n != node:
                continue
            total += sum(e.n_folded for e in log.entries)
        return total

    def reconstruct(self, node: Any, predicate: str) -> tuple[float, float]:
        """Recompute (alpha, beta) from the log alone (Eq. 5), with exactly rounded sums."""
        if self._journal:
            self.materialize()
        log = self._pairs.get((node, predicate))
        if log is None:
            return self.prior_alpha, self.prior_beta
        counted = [e for e in log.entries if id(e.status) in _COUNTED_IDS]
        return (
            self.prior_alpha + math.fsum(e.d_alpha for e in counted),
            self.prior_beta + math.fsum(e.d_beta for e in counted),
        )

    # ------------------------------------------------------------------ writes
    def record(
        self,
        node: Any,
        predicate: str,
        event_id: str | None,
        t: int,
        d_alpha: float,
        d_beta: float,
        status: EntryStatus = EntryStatus.COMMITTED,
        stance: int = 0,
    ) -> ProvenanceEntry:
        """Append an entry; counted statuses update the belief, pending ones join their queue."""
        if self._journal:  # keep arrival order: journal records come first
            self.materialize()
        key = (node, predicate)
        log = self._pairs.get(key)
        if log is None:
            log = self._pairs[key] = _PairLog(self.prior_alpha, self.prior_beta)
        entry = ProvenanceEntry(event_id, t, d_alpha, d_beta, status, node, predicate, stance)
        log.entries.append(entry)
        # identity tests: hashing a str-Enum member for a frozenset lookup runs Python code
        if status is _COMMITTED or id(status) in _COUNTED_IDS:
            log.alpha += d_alpha
            log.beta += d_beta
        elif status is _REFUSED or status is _QUARANTINED:
            self._add_pending(key, entry)
        if event_id is not None:
            by_event = self._by_event
            prev = by_event.get(event_id)
            if prev is None:
                by_event[event_id] = entry
            elif type(prev) is list:
                prev.append(entry)
            else:  # a second entry: the id's value becomes a list (its place in the dict is kept)
                by_event[event_id] = [prev, entry]
        self._timeline.append(entry)
        return entry

    def commit(
        self, node: Any, predicate: str, event_id: str | None, t: int, d_alpha: float, d_beta: float, stance: int = 0
    ) -> None:
        """Record a committed increment (``record(..., COMMITTED, stance)`` without returning the entry).

        The belief changes at once (Eq. 4); the entry is journaled and materialised only when
        something reads the log, or folded straight into its pair's compacted bucket.
        """
        key = (node, predicate)
        log = self._pairs.get(key)
        if log is None:
            log = self._pairs[key] = _PairLog(self.prior_alpha, self.prior_beta)
        log.alpha += d_alpha
        log.beta += d_beta
        self._journal.append((key, event_id, t, d_alpha, d_beta, stance, log))

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
        if journal[0] is _DEFERRED:  # a loader's entries come before every journal record
            deferred, self._deferred = self._deferred, None
            assert deferred is not None
            deferred.build(self)
            del journal[0]
        by_event = self._by_event
        tl_append = self._timeline.append
        committed = _COMMITTED
        for key, eid, t, da, db, stance, log in journal:
            entry = ProvenanceEntry(eid, t, da, db, committed, key[0], key[1], stance)
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
        self._journal.append(_DEFERRED)

    @property
    def deferred(self) -> bool:
        """Whether loaded entries are still to be built (by the first read of the logs)."""
        return self._deferred is not None

    def _add_pending(self, key: PairKey, entry: ProvenanceEntry) -> None:
        (self.quarantine if entry.status is EntryStatus.QUARANTINED else self.disagreement).append(entry)
        bucket = self._pending_by_pair.get(key)
        if bucket is None:
            self._pending_by_pair[key] = [entry]
        else:
            bucket.append(entry)

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

    def transition(self, entry: ProvenanceEntry, status: EntryStatus, *, scale: float = 1.0) -> None:
        """Move an entry to a new status; ``scale`` multiplies its increments (w/k on timeout).

        The belief changes exactly when the entry starts (or stops) being counted.
        """
        if not entry.alive:
            raise RetractionError(f"entry of event {entry.event_id!r} is no longer in the store")
        was_counted = id(entry.status) in _COUNTED_IDS
        was_pending = id(entry.status) in _PENDING_IDS
        log = self._pairs[(entry.node, entry.predicate)]
        if was_counted:
            log.alpha -= entry.d_alpha
            log.beta -= entry.d_beta
        if scale != 1.0:
            entry.d_alpha *= scale
            entry.d_beta *= scale
        entry.status = status
        counted = id(status) in _COUNTED_IDS
        pending = id(status) in _PENDING_IDS
        if counted:
            log.alpha += entry.d_alpha
            log.beta += entry.d_beta
        if was_pending and not pending:
            self._drop_pending(entry)
        elif pending and not was_pending:
            self._add_pending((entry.node, entry.predicate), entry)
        if was_counted and not counted:
            if self._journal:
                self.materialize()
            self._refresh(log)

    def _refresh(self, log: _PairLog) -> None:
        counted = [e for e in log.entries if id(e.status) in _COUNTED_IDS]
        log.alpha = self.prior_alpha + math.fsum(e.d_alpha for e in counted)
        log.beta = self.prior_beta + math.fsum(e.d_beta for e in counted)

    # ------------------------------------------------------------- retraction
    def _closure(self, event_id: str, cascade_window: int | None) -> list[str]:
        """The event and, transitively, the corroborating events its revision commits depend on."""
        order: list[str] = []
        stack = [event_id]
        seen: set[str] = set()
        while stack:
            eid = stack.pop()
            if eid in seen:
                continue
            seen.add(eid)
            found = self._by_event.get(eid)
            if found is None:
                if eid in self._compacted_order:  # a linear scan, on this error path only
                    raise RetractionError(
                        f"event {eid!r} was folded into a compacted increment (older than the provenance "
                        "horizon T_prov) and can no longer be retracted"
                    )
                if eid == event_id:
                    raise RetractionError(
                        f"unknown event id {eid!r} (never recorded, already retracted, or compacted "
                        "beyond the remembered horizon)"
                    )
                continue  # a dependent that was already retracted on its own
            order.append(eid)
            for entry in _event_list(found):
                if entry.corroborated_by:
                    for dep in entry.corroborated_by:
                        dep_entries = _event_list(self._by_event.get(dep))
                        if cascade_window is not None and dep_entries:
                            if all(d.t - entry.t > cascade_window for d in dep_entries):
                                continue
                        stack.append(dep)
        return order

    def retract(self, event_id: str, *, cascade_window: int | None = None) -> list[str]:
        """Remove an event's increments exactly (R of §4.3) and return the retracted event ids.

        For a revision committed via corroboration, the corroborating events it depends on are
        retracted too (cascade bounded by ``cascade_window`` = T_cor when given). The whole
        cascade is checked before anything changes, so a failed retraction leaves the store
        untouched.
        """
        if self._journal:
            self.materialize()
        ids = self._closure(event_id, cascade_window)
        touched: set[PairKey] = set()
        for eid in ids:
            for entry in _event_list(self._by_event.pop(eid)):
                key = (entry.node, entry.predicate)
                if id(entry.status) in _PENDING_IDS:
                    self._drop_pending(entry)
                entry.alive = False
                log = self._pairs[key]
                log.entries.remove(entry)
                touched.add(key)
        for key in touched:
            log = self._pairs[key]
            if not log.entries:
                del self._pairs[key]
            else:
                self._refresh(log)
        return ids

    # ------------------------------------------------------------- compaction
    def compact(self, before_t: int) -> int:
        """Fold every settled entry with ``t < before_t`` into one equivalent increment per pair.

        Pending entries are never folded. Cost is amortised O(1) per entry: only pairs that
        received entries older than the horizon are visited, in the order their oldest such
        entry arrived (deterministic: the compacted-id memory fills in that order). Journal
        records older than the horizon are folded without being materialised when that is
        exactly what materialising them first would give (see :meth:`_old_journal`); otherwise
        the journal is materialised first. Returns the number of entries folded.

        The timeline is scanned in arrival order up to the first live entry not older than the
        horizon: when times go back (replayed or merged logs), entries behind it wait for a later
        pass. Dead entries (retracted) hold nothing back, so a loaded copy, which no longer holds
        them, folds the same entries.
        """
        timeline = self._timeline
        n_old = 0  # the timeline's prefix older than the horizon (dead entries, e.g. retracted, hold nothing back)
        for entry in timeline:
            if entry.t >= before_t and entry.alive:
                break
            n_old += 1
        raws = self._old_journal(before_t, n_old == len(timeline))
        if raws is None:  # the journal cannot be folded as it stands
            self.materialize()
            for entry in islice(timeline, n_old, None):
                if entry.t >= before_t and entry.alive:
                    break
                n_old += 1
            raws = []
        if not n_old and not raws:
            return 0
        if not n_old and len(raws) >= VECTOR_FOLD_MIN:  # journal records only (the timeline is empty)
            folded = self._fold_journal(raws)
            if folded is not None:
                return folded
        if n_old == len(timeline):
            old = list(timeline)
            timeline.clear()
        else:
            popleft = timeline.popleft
            old = [popleft() for _ in range(n_old)]
        # the old journal records by pair, in the order each pair's first record arrived
        groups: dict[PairKey, list[JournalRecord]] = {}
        if raws:
            group_of = groups.get
            for rec in raws:
                grp = group_of(rec[0])
                if grp is None:
                    groups[rec[0]] = [rec]
                else:
                    grp.append(rec)
        # pairs in the order their oldest entry past the horizon arrived (journal records arrived
        # after every timeline entry)
        dirty = dict.fromkeys(chain([(e.node, e.predicate) for e in old if e.alive], groups))
        pairs_get = self._pairs.get
        by_event = self._by_event
        # the ids the folded entries took out of the event index, in order, and per pair with
        # journal records: how many of those ids came before its records, and the records (their
        # ids are gone with the last of their records)
        gone: list[str] = []
        marks: list[tuple[int, list[JournalRecord]]] = []
        all_recs_seen = True
        folded_total = 0
        refused, quarantined, compacted = _REFUSED, _QUARANTINED, _COMPACTED
        counted_ids = _COUNTED_IDS
        fsum = math.fsum
        for key in dirty:
            log = pairs_get(key)
            recs = groups.get(key) if raws else None  # journal records come after every entry
            if log is None:
                if recs:
                    all_recs_seen = False
                continue
            # fold this pair's settled entries older than before_t into its compacted bucket
            entries = log.entries
            fold: list[ProvenanceEntry] = []
            if not entries:
                keep: list[ProvenanceEntry] | None = []
                bucket: ProvenanceEntry | None = None
            elif len(entries) == 1 and entries[0].status is compacted:  # only the bucket: kept as is
                keep, bucket = None, entries[0]
            else:
                keep, bucket = [], None
                for entry in entries:
                    st = entry.status
                    if st is compacted:
                        bucket = entry
                    elif entry.t < before_t and st is not refused and st is not quarantined:
                        fold.append(entry)
                    else:
                        keep.append(entry)
            n_fold = len(fold) + len(recs) if recs else len(fold)
            if not n_fold:
                continue
            if n_fold == 1:  # the common case: fsum of one value is that value
                if fold:
                    first = fold[0]
                    if id(first.status) in counted_ids:
                        d_alpha, d_beta = first.d_alpha + 0.0, first.d_beta + 0.0
                    else:
                        d_alpha = d_beta = 0.0
                    n, t_max = first.n_folded, first.t
                else:
                    rec = recs[0]  # type: ignore[index]
                    t_max, d_alpha, d_beta, n = rec[2], rec[3] + 0.0, rec[4] + 0.0, 1
            elif not fold:  # journal records only (committed: all counted), in time order
                d_alpha = fsum(map(_rec_da, recs))  # type: ignore[arg-type]
                d_beta = fsum(map(_rec_db, recs))  # type: ignore[arg-type]
                n, t_max = len(recs), recs[-1][2]  # type: ignore[arg-type, index]
            else:  # one loop, not four comprehensions (each costs a function call in CPython 3.11)
                das: list[float] = []
                dbs: list[float] = []
                n = 0
                t_max = fold[0].t
                for e in fold:
                    if id(e.status) in counted_ids:
                        das.append(e.d_alpha)
                        dbs.append(e.d_beta)
                    n += e.n_folded
                    if e.t > t_max:
                        t_max = e.t
                if recs:
                    das += map(_rec_da, recs)
                    dbs += map(_rec_db, recs)
                    if recs[-1][2] > t_max:
                        t_max = recs[-1][2]
                    n += len(recs)
                d_alpha = fsum(das)
                d_beta = fsum(dbs)
            if bucket is None:  # (the numpy fold, _fold_journal, merges the same way)
                bucket = ProvenanceEntry(None, t_max, d_alpha, d_beta, compacted, key[0], key[1])
                bucket.n_folded = n
            else:
                # = fsum((bucket, d)): one IEEE addition is correctly rounded (neither is -0.0)
                bucket.d_alpha += d_alpha
                bucket.d_beta += d_beta
                bucket.n_folded += n
                if t_max > bucket.t:
                    bucket.t = t_max
            for entry in fold:
                entry.alive = False
                eid = entry.event_id
                if eid is not None:
                    same_event = by_event.get(eid)
                    if same_event is entry:
                        del by_event[eid]
                        gone.append(eid)
                    elif type(same_event) is list:
                        try:
                            same_event.remove(entry)
                        except ValueError:
                            pass
                        if not same_event:
                            del by_event[eid]
                            gone.append(eid)
            if recs:
                marks.append((len(gone), recs))
            if keep is not None:
                keep.insert(0, bucket)
                log.entries = keep
            folded_total += n_fold
        if raws:
            gone = self._retired_ids(gone, marks, raws, all_recs_seen)
            self._drop_folded_records(len(raws))
        self.n_compacted += folded_total
        if gone:
            self._compacted_order.extend(gone)
        return folded_total

    def _drop_folded_records(self, k: int) -> None:
        """Remove the first ``k`` journal records (folded by a compaction pass)."""
        journal = self._journal
        del journal[:k]
        self._j_checked -= k
        if len(self._j_id_t) > 2 * len(journal) + 1024:  # drop the folded ids, in one C pass
            # (until then a folded id reused later only costs a materialisation)
            id_t = self._j_id_t = dict(zip(map(_rec_eid, journal), map(_rec_t, journal)))
            id_t.pop(None, None)  # type: ignore[call-overload]

    def _fold_journal(self, raws: list[JournalRecord]) -> int | None:
        """:meth:`compact` of journal records alone (the timeline is empty), grouped by pair in
        numpy instead of record by record; returns the number folded.

        The result is the loop's, bit for bit: pairs in the order of their first record; per pair
        one ``math.fsum`` of its increments (for one value that is the value + 0.0, for two their
        IEEE sum + 0.0: both correctly rounded, -0.0 turned into 0.0 as fsum does), added to the
        pair's bucket with one addition; the bucket's t is the last record's (the journal is in
        time order) and its count grows by the records folded; retired ids as
        :meth:`_retired_ids` orders them. Returns None, having changed nothing, when a pair's log
        holds more than its bucket, a time does not fit in 64 bits or a sum is not finite: the
        loop then takes the pass (and raises where ``math.fsum`` does).
        """
        m = len(raws)
        logs = list(map(_rec_log, raws))
        try:
            t = np.fromiter(map(_rec_t, raws), np.int64, m)
        except OverflowError:
            return None
        glogs = list(dict.fromkeys(logs))  # the pairs in the order of their first record
        k = len(glogs)
        compacted = _COMPACTED
        for log in glogs:
            entries = log.entries  # type: ignore[union-attr]
            if entries and (len(entries) > 1 or entries[0].status is not compacted):
                return None
        da = np.fromiter(map(_rec_da, raws), np.float64, m)
        db = np.fromiter(map(_rec_db, raws), np.float64, m)
        if k == m:  # one record per pair: each is its own group, in journal order
            order: Any = None
            n = np.ones(m, dtype=np.int64)
            head = list(range(m))
            sa, sb, t_last = da + 0.0, db + 0.0, t
        else:
            slot = dict(zip(glogs, range(k)))
            group = np.fromiter(map(slot.__getitem__, logs), np.intp, m)
            order = np.argsort(group, kind="stable")  # records by pair, journal order within
            n = np.bincount(group, minlength=k)
            ends = np.cumsum(n)
            starts = ends - n
            head = order[starts].tolist()
            t_last = t[order[ends - 1]]
            da, db = da[order], db[order]
            sa, sb = da[starts], db[starts]
            two = np.flatnonzero(n == 2)
            if len(two):
                sa[two] += da[starts[two] + 1]
                sb[two] += db[starts[two] + 1]
            sa += 0.0
            sb += 0.0
            big = np.flatnonzero(n > 2)
            if len(big):
                da_l, db_l = da.tolist(), db.tolist()
                fsum = math.fsum
                try:
                    for g, a, b in zip(big.tolist(), starts[big].tolist(), ends[big].tolist()):
                        sa[g] = fsum(da_l[a:b])
                        sb[g] = fsum(db_l[a:b])
                except (OverflowError, ValueError):
                    return None
        if not (np.isfinite(sa).all() and np.isfinite(sb).all()):
            return None
        # ---- nothing has changed so far; the bucket merge below is the loop's (kept in step with it)
        for log, d_alpha, d_beta, c, t_max, i in zip(glogs, sa.tolist(), sb.tolist(), n.tolist(),
                                                     t_last.tolist(), head):
            entries = log.entries  # type: ignore[union-attr]
            if entries:
                bucket = entries[0]
                bucket.d_alpha += d_alpha
                bucket.d_beta += d_beta
                bucket.n_folded += c
                if t_max > bucket.t:
                    bucket.t = t_max
            else:
                key = raws[i][0]
                bucket = ProvenanceEntry(None, t_max, d_alpha, d_beta, compacted, key[0], key[1])
                bucket.n_folded = c
                log.entries = [bucket]  # type: ignore[union-attr]
        eids = list(map(_rec_eid, raws))
        gone = _last_seen_order(eids if order is None else map(eids.__getitem__, order.tolist()))
        self._drop_folded_records(m)
        self.n_compacted += m
        if gone:
            self._compacted_order.extend(gone)
        return m

    @staticmethod
    def _retired_ids(
        entry_ids: list[str], marks: list[tuple[int, list[JournalRecord]]], raws: list[JournalRecord], all_recs_seen: bool
    ) -> list[str]:
        """The event ids a compaction pass that folds journal records retires, in the order it
        folds them. Per folded pair, in order: the ids its entries took out of the event index
        (``entry_ids[i:j]`` for consecutive marks), then each journal id whose last record is among
        the pair's records (``marks``: (j, records)); the journal holds no id of the index. An id
        with records in a pair the pass skipped (``all_recs_seen`` false) is not retired."""
        if all_recs_seen and not entry_ids:
            # journal records only: each id is retired at its last record, in that order
            return _last_seen_order(map(_rec_eid, chain.from_iterable([recs for _, recs in marks])))
        remaining: Counter[str | None] = Counter(map(_rec_eid, raws))
        remaining.pop(None, None)
        gone: list[str] = []
        done = 0
        for upto, recs in marks:
            gone += entry_ids[done:upto]
            done = upto
            for rec in recs:
                eid = rec[1]
                left = remaining[eid]  # 0 for None
                if left == 1:
                    gone.append(eid)  # type: ignore[arg-type]
                else:
                    remaining[eid] = left - 1
        gone += entry_ids[done:]
        return gone

    def _old_journal(self, before_t: int, timeline_all_old: bool) -> list[JournalRecord] | None:
        """The journal records a compaction at ``before_t`` folds, when folding them unmaterialised
        gives exactly what materialising them first would, else None (the caller materialises).

        Exact when (_check_journal) the journal is in time order, no journaled id is in the event
        index, and no id occurs at two times: then the old records are a prefix (found by
        bisection), every id they hold has all its live entries among them (so "an id's last entry
        is folded" is a count), and the index's order is untouched. They may fold only after an
        entirely old timeline (arrival order); otherwise the journal must be entirely young.
        """
        journal = self._journal
        if not journal:
            return []
        if journal[0] is _DEFERRED or not self._check_journal():
            return None
        if not timeline_all_old:
            return [] if journal[0][2] >= before_t else None
        n = bisect_left(journal, before_t, key=_rec_t)
        return journal[:n] if n else []

    def _check_journal(self) -> bool:
        """Extend the verified prefix of the journal to all of it (each record is checked once:
        the event index only gains ids when the journal is materialised, which resets this)."""
        journal = self._journal
        k = self._j_checked
        if k == len(journal):
            return True
        new = journal[k:]
        ts = list(map(_rec_t, new))
        if ts[0] < self._j_last_t or not all(map(le, ts, islice(ts, 1, None))):
            return False  # not in time order
        ids = list(map(_rec_eid, new))
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

    def _remember_compacted(self, event_id: str) -> None:
        self._compacted_order.append(event_id)

    def is_compacted(self, event_id: str) -> bool:
        """Whether the id is among the ``remember_compacted`` most recently compacted (O(n) scan)."""
        return event_id in self._compacted_order

    # -------------------------------------------------------- node life cycle
    def remove_node(self, node: Any) -> int:
        """Drop every log of a node (its beliefs go back to the prior). Returns entries dropped."""
        if self._journal:
            self.materialize()
        keys = [k for k in self._pairs if k[0] == node]
        dropped = 0
        for key in keys:
            log = self._pairs.pop(key)
            for entry in log.entries:
                entry.alive = False
                dropped += entry.n_folded
                if id(entry.status) in _PENDING_IDS:
                    self._drop_pending(entry)
                if entry.event_id is not None:
                    bucket = self._by_event.get(entry.event_id)
                    if bucket is entry:
                        del self._by_event[entry.event_id]
                    elif type(bucket) is list:
                        bucket[:] = [e for e in bucket if e is not entry]
                        if not bucket:
                            del self._by_event[entry.event_id]
        return dropped

    def move_node(self, absorb: Any, keep: Any) -> None:
        """Belief migration: every log of ``absorb`` merges into the same predicate's log of ``keep``.

        Entries keep their increments and statuses; logs are merged in time order and the
        beliefs recomputed, so the evidence count is unchanged (nothing lost, nothing doubled).
        """
        if absorb == keep:
            return
        if self._journal:
            self.materialize()
        keys = [k for k in self._pairs if k[0] == absorb]
        for key in keys:
            src = self._pairs.pop(key)
            dst_key = (keep, key[1])
            dst = self._pairs.get(dst_key)
            if dst is None:
                dst = self._pairs[dst_key] = _PairLog(self.prior_alpha, self.prior_beta)
            for entry in src.entries:
                entry.node = keep
            pend = self._pending_by_pair.pop(key, None)
            if pend:
                self._pending_by_pair.setdefault(dst_key, []).extend(pend)
            merged = sorted(dst.entries + src.entries, key=lambda e: e.t)
            # at most one compacted bucket per pair: fold a second one into the first
            buckets = [e for e in merged if e.status is EntryStatus.COMPACTED]
            if len(buckets) > 1:
                head = buckets[0]
                for extra in buckets[1:]:
                    head.d_alpha = math.fsum((head.d_alpha, extra.d_alpha))
                    head.d_beta = math.fsum((head.d_beta, extra.d_beta))
                    head.n_folded += extra.n_folded
                    head.t = max(head.t, extra.t)
                    extra.alive = False
                merged = [e for e in merged if e.alive]
                merged.remove(head)
                merged.insert(0, head)
            dst.entries = merged
            self._refresh(dst)

    # ---------------------------------------------------------- serialisation
    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (node ids must be str or int)."""
        if self._journal:
            self.materialize()
        pairs = []
        for (node, predicate), log in self._pairs.items():
            pairs.append(
                {
                    "node": node,
                    "predicate": predicate,
                    "alpha": log.alpha,
                    "beta": log.beta,
                    "entries": [
                        [
                            e.event_id,
                            e.t,
                            e.d_alpha,
                            e.d_beta,
                            e.status.value,
                            e.stance,
                            e.corroborated_by,
                            e.n_folded,
                        ]
                        for e in log.entries
                    ],
                }
            )
        return {
            "prior": [self.prior_alpha, self.prior_beta],
            "pairs": pairs,
            "compacted_ids": list(self._compacted_order),
            "n_compacted": self.n_compacted,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, where: str = "provenance") -> ProvenanceStore:
        """Rebuild a store; checks that every stored belief equals its log's reconstruction (Eq. 5)."""
        try:
            prior = data["prior"]
            store = cls((float(prior[0]), float(prior[1])))
            all_entries: list[ProvenanceEntry] = []
            for i, pair in enumerate(data["pairs"]):
                node, predicate = pair["node"], pair["predicate"]
                if not isinstance(predicate, str) or not predicate:
                    raise FormatError(f"{where}.pairs[{i}].predicate must be a non-empty string")
                log = store._pairs.setdefault((node, predicate), _PairLog(store.prior_alpha, store.prior_beta))
                for j, raw in enumerate(pair["entries"]):
                    eid, t, da, db, status, stance, corr, n_folded = raw
                    st = _STATUS_BY_VALUE.get(status)
                    if st is None:
                        raise FormatError(f"{where}.pairs[{i}].entries[{j}]: unknown status {status!r}")
                    if not (math.isfinite(da) and math.isfinite(db)):
                        raise FormatError(f"{where}.pairs[{i}].entries[{j}]: increments must be finite")
                    e = ProvenanceEntry(eid, int(t), float(da), float(db), st, node, predicate, int(stance))
                    e.corroborated_by = list(corr) if corr else None
                    e.n_folded = int(n_folded)
                    log.entries.append(e)
                    all_entries.append(e)
                    if eid is not None:
                        store._by_event.setdefault(eid, []).append(e)
                store._refresh(log)
                for name, stored, rebuilt in (("alpha", pair["alpha"], log.alpha), ("beta", pair["beta"], log.beta)):
                    if not math.isclose(float(stored), rebuilt, rel_tol=1e-9, abs_tol=1e-9):
                        raise FormatError(
                            f"{where}.pairs[{i}] ({node!r}, {predicate!r}): stored {name}={stored!r} does not "
                            f"equal prior + sum of logged increments ({rebuilt!r}); the file was edited or corrupted"
                        )
                if log.alpha <= 0 or log.beta <= 0:
                    raise FormatError(f"{where}.pairs[{i}]: belief parameters must stay > 0")
                # keep the stored running values bit-for-bit (they agree with the log to 1e-9)
                log.alpha, log.beta = float(pair["alpha"]), float(pair["beta"])
            all_entries.sort(key=lambda e: e.t)
            for e in all_entries:
                if e.status is not EntryStatus.COMPACTED:
                    store._timeline.append(e)
                if id(e.status) in _PENDING_IDS:
                    store._add_pending((e.node, e.predicate), e)
            for eid in data.get("compacted_ids", []):
                store._remember_compacted(eid)
            store.n_compacted = int(data.get("n_compacted", 0))
        except FormatError:
            raise
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise FormatError(f"{where}: malformed provenance data ({type(exc).__name__}: {exc})") from exc
        return store

    def iter_entries(self) -> Iterable[ProvenanceEntry]:
        if self._journal:
            self.materialize()
        for log in self._pairs.values():
            yield from log.entries

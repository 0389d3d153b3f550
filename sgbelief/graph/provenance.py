"""Provenance store P (paper §4.3, Eq. 4): an ordered log of increments per (node, predicate).

Every update an operator makes to a belief is an entry ``(event id, t, d_alpha, d_beta, status)``
in the log of its (node, predicate) pair. The belief is *defined* by the log::

    (alpha, beta) = (alpha_0, beta_0) + sum of (d_alpha, d_beta) over counted entries   (Eq. 4)

(:func:`belief_from_entries`; the paper's ``\\label{eq:provrecon}``). The counted statuses are
committed, released (revision timeout at weight w/k), confirmed and compacted. Refused (⊥) and
quarantined entries carry the increments the event *would* contribute but are not counted while
they sit in the disagreement queue Q⊥ or the revision quarantine Q; those queues are simply the
pending entries of the store, so they are saved, loaded and migrated with the graph.

Two operations change the log without changing any belief:

- retraction (R of §4.3) removes an event's entries, and those of the corroborating events a
  committed revision depends on, and recomputes the pair's belief from what is left;
- compaction folds the settled entries older than the horizon T_prov into one ``compacted``
  entry per pair whose increment is their sum (:func:`fold_into_bucket`), so Eq. 4 still holds.

The store keeps a running (alpha, beta) per pair so that reads are O(1); whatever removes a
counted increment recomputes it from the log with ``math.fsum``.

This module is the reference store: every entry is an object from the moment it is recorded.
The streaming engines use a store with the same observable behaviour that journals committed
increments as plain tuples and builds objects only when something reads them (private, in
``sgbelief._fast``; ``sgbelief.testing.check_store_matches_reference`` proves the two equal).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Hashable, Iterable, Iterator, Mapping
from operator import attrgetter
from typing import Any

from sgbelief.errors import FormatError, RetractionError
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA, BetaBelief
from sgbelief.graph.compaction import (
    FoldSummary,
    attach_summary,
    bucket_summary,
    fold_into_bucket,
    merge_into_bucket,
    settled_before,
    take_old,
)
from sgbelief.graph.provenance_log import (
    COUNTED,
    PENDING,
    EntryRecord,
    EntryStatus,
    EntryVerdict,
    PairLog,
    ProvenanceEntry,
    belief_from_entries,
    entry_extras,
    entry_row,
    event_list,
    index_event,
)

Node = Hashable
PairKey = tuple[Any, str]


__all__ = [
    "COUNTED", "PENDING", "EntryRecord", "EntryStatus", "EntryVerdict", "FoldSummary", "Node", "PairKey", "PairLog",
    "ProvenanceEntry", "ProvenanceStore", "belief_from_entries", "event_list", "fold_into_bucket",
    "index_event", "merge_into_bucket", "settled_before"
]

_STATUS_BY_VALUE = {s.value: s for s in EntryStatus}
# members read once (an attribute lookup on an Enum class runs Python code)
_COMMITTED, _COMPACTED = EntryStatus.COMMITTED, EntryStatus.COMPACTED
_QUARANTINED, _REFUSED = EntryStatus.QUARANTINED, EntryStatus.REFUSED


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

    def means(self, nodes: Iterable[Any], predicate: str) -> list[float]:
        """:meth:`mean` of (node, predicate) for each node, in order (the prior mean without evidence)."""
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
        return ((n, log.alpha / (log.alpha + log.beta)) for (n, p), log in self._pairs.items() if p == predicate)

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

    def has_event(self, event_id: str) -> bool:
        return event_id in self._by_event

    def pairs(self) -> Iterator[PairKey]:
        return iter(self._pairs)

    def logs(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log, in the store's pair order (a live read-only view: change the store
        only through its methods)."""
        return self._pairs

    def compaction_timeline(self) -> list[ProvenanceEntry]:
        """The entries a compaction pass scans, in arrival order (a copy; dead entries included)."""
        return list(self._timeline)

    def compacted_ids(self) -> list[str]:
        """The remembered compacted event ids, oldest first."""
        return list(self._compacted_order)

    def predicates(self) -> set[str]:
        return {p for _, p in self._pairs}

    def predicates_of(self, node: Any) -> list[str]:
        return [p for (n, p) in self._pairs if n == node]

    def nodes_with(self, predicate: str) -> Iterator[Any]:
        return (n for (n, p) in self._pairs if p == predicate)

    def pending(self, node: Any, predicate: str) -> list[ProvenanceEntry]:
        return list(self._pending_by_pair.get((node, predicate), ()))

    def count_entries(self, node: Any = None) -> int:
        """Number of original evidence entries (compacted entries count what they folded)."""
        return sum(
            e.n_folded for (n, _p), log in self._pairs.items() if node is None or n == node for e in log.entries
        )

    def reconstruct(self, node: Any, predicate: str) -> tuple[float, float]:
        """Recompute (alpha, beta) from the log alone (Eq. 4, :func:`belief_from_entries`)."""
        return belief_from_entries((self.prior_alpha, self.prior_beta), self.entries(node, predicate))

    def iter_entries(self) -> Iterator[ProvenanceEntry]:
        for log in self._pairs.values():
            yield from log.entries

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
        verdict: EntryVerdict | None = None,
        confidence: float | None = None,
    ) -> ProvenanceEntry:
        """:meth:`append` of the :class:`EntryRecord` with these fields (a shorthand for tests
        and scripts; library code builds the record by keyword)."""
        return self.append(EntryRecord(node, predicate, event_id, t, d_alpha, d_beta, status, stance, verdict,
                                       confidence))

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
            for entry in event_list(found):
                for dep in entry.corroborated_by or ():
                    dep_entries = event_list(self._by_event.get(dep))
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
        ids = self._closure(event_id, cascade_window)
        touched: dict[PairKey, None] = {}
        for eid in ids:
            for entry in event_list(self._by_event.pop(eid)):
                key = (entry.node, entry.predicate)
                if entry.status in PENDING:
                    self._drop_pending(entry)
                entry.alive = False
                self._pairs[key].entries.remove(entry)
                touched[key] = None
        for key in touched:
            log = self._pairs[key]
            if not log.entries:
                del self._pairs[key]
            else:
                self._refresh(log)
        return ids

    # ------------------------------------------------------------- compaction
    def compact(self, before_t: int) -> int:
        """Fold every settled entry with ``t < before_t`` into one equivalent increment per pair
        (:func:`fold_into_bucket`); returns the number of entries folded.

        Pending entries are never folded. Cost is amortised O(1) per entry: only pairs that
        received entries older than the horizon are visited, in the order their oldest such
        entry arrived (deterministic: the compacted-id memory fills in that order, each pair's
        folded entries in log order, an id when its last live entry is folded).

        The timeline is scanned in arrival order up to the first live entry not older than the
        horizon: when times go back (replayed or merged logs), entries behind it wait for a later
        pass. Dead entries (retracted) hold nothing back, so a loaded copy, which no longer holds
        them, folds the same entries.
        """
        old = take_old(self._timeline, before_t)
        folded = 0
        retired: list[str] = []
        for key in dict.fromkeys([(e.node, e.predicate) for e in old if e.alive]):
            log = self._pairs.get(key)
            if log is None:
                continue
            bucket, fold, keep = settled_before(log.entries, before_t)
            if not fold:
                continue
            log.entries = [fold_into_bucket(bucket, fold, key[0], key[1]), *keep]
            for entry in fold:
                entry.alive = False
                if self._unindex(entry):
                    retired.append(entry.event_id)  # type: ignore[arg-type]
            folded += len(fold)
        self.n_compacted += folded
        self._compacted_order.extend(retired)
        return folded

    # -------------------------------------------------------- node life cycle
    def remove_node(self, node: Any) -> int:
        """Drop every log of a node (its beliefs go back to the prior). Returns entries dropped."""
        dropped = 0
        for key in [k for k in self._pairs if k[0] == node]:
            for entry in self._pairs.pop(key).entries:
                entry.alive = False
                dropped += entry.n_folded
                if entry.status in PENDING:
                    self._drop_pending(entry)
                self._unindex(entry)
        return dropped

    def move_node(self, absorb: Any, keep: Any) -> None:
        """Belief migration: every log of ``absorb`` merges into the same predicate's log of ``keep``.

        Entries keep their increments and statuses; logs are merged in time order and the
        beliefs recomputed, so the evidence count is unchanged (nothing lost, nothing doubled).
        """
        if absorb == keep:
            return
        for key in [k for k in self._pairs if k[0] == absorb]:
            src = self._pairs.pop(key)
            dst_key = (keep, key[1])
            dst = self._pairs.get(dst_key)
            if dst is None:
                dst = self._pairs[dst_key] = PairLog(self.prior_alpha, self.prior_beta)
            for entry in src.entries:
                entry.node = keep
            pend = self._pending_by_pair.pop(key, None)
            if pend:
                self._pending_by_pair.setdefault(dst_key, []).extend(pend)
            merged = sorted(dst.entries + src.entries, key=lambda e: e.t)
            # at most one compacted bucket per pair: fold a second one into the first
            buckets = [e for e in merged if e.status is _COMPACTED]
            if len(buckets) > 1:
                head = buckets[0]
                for extra in buckets[1:]:
                    merge_into_bucket(head, keep, key[1], extra.t, extra.d_alpha, extra.d_beta, extra.n_folded,
                                      extra.summary)
                    extra.alive = False
                merged = [e for e in merged if e.alive]
                merged.remove(head)
                merged.insert(0, head)
            dst.entries = merged
            self._refresh(dst)

    # ---------------------------------------------------------- serialisation
    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (node ids must be str or int)."""
        pairs = []
        for (node, predicate), log in self.logs().items():
            pair: dict[str, Any] = {
                "node": node,
                "predicate": predicate,
                "alpha": log.alpha,
                "beta": log.beta,
                "entries": list(map(entry_row, log.entries)),
            }
            summary = bucket_summary(log.entries)
            if summary is not None:
                # optional: older readers ignore it, and files without it load with unknown counts
                pair["fold_summary"] = summary.to_dict()
            pairs.append(pair)
        return {
            "prior": [self.prior_alpha, self.prior_beta],
            "pairs": pairs,
            "compacted_ids": self.compacted_ids(),
            "n_compacted": self.n_compacted,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, where: str = "provenance") -> ProvenanceStore:
        """Rebuild a store; checks that every stored belief equals its log's reconstruction (Eq. 4)."""
        try:
            prior = (float(data["prior"][0]), float(data["prior"][1]))
            logs: dict[PairKey, PairLog] = {}
            for i, pair in enumerate(data["pairs"]):
                node, predicate = pair["node"], pair["predicate"]
                if not isinstance(predicate, str) or not predicate:
                    raise FormatError(f"{where}.pairs[{i}].predicate must be a non-empty string")
                log = logs.setdefault((node, predicate), PairLog(*prior))
                for j, raw in enumerate(pair["entries"]):
                    eid, t, da, db, status, stance, corr, n_folded = raw[:8]
                    st = _STATUS_BY_VALUE.get(status)
                    if st is None:
                        raise FormatError(f"{where}.pairs[{i}].entries[{j}]: unknown status {status!r}")
                    if not (math.isfinite(da) and math.isfinite(db)):
                        raise FormatError(f"{where}.pairs[{i}].entries[{j}]: increments must be finite")
                    verdict, confidence = entry_extras(raw, f"{where}.pairs[{i}].entries[{j}]")
                    e = ProvenanceEntry(eid, int(t), float(da), float(db), st, node, predicate, int(stance),
                                        verdict, confidence)
                    e.corroborated_by = list(corr) if corr else None
                    e.n_folded = int(n_folded)
                    log.entries.append(e)
                if pair.get("fold_summary") is not None:
                    attach_summary(log.entries, FoldSummary.from_dict(pair["fold_summary"]), f"{where}.pairs[{i}]")
                rebuilt = belief_from_entries(prior, log.entries)
                for name, stored, value in zip(("alpha", "beta"), (pair["alpha"], pair["beta"]), rebuilt):
                    if not math.isclose(float(stored), value, rel_tol=1e-9, abs_tol=1e-9):
                        raise FormatError(
                            f"{where}.pairs[{i}] ({node!r}, {predicate!r}): stored {name}={stored!r} does not "
                            f"equal prior + sum of logged increments ({value!r}); the file was edited or corrupted"
                        )
                if rebuilt[0] <= 0 or rebuilt[1] <= 0:
                    raise FormatError(f"{where}.pairs[{i}]: belief parameters must stay > 0")
                # keep the stored running values bit-for-bit (they agree with the log to 1e-9)
                log.alpha, log.beta = float(pair["alpha"]), float(pair["beta"])
            return cls.from_logs(
                logs,
                prior=prior,
                compacted_ids=data.get("compacted_ids", []),
                n_compacted=int(data.get("n_compacted", 0)),
            )
        except FormatError:
            raise
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise FormatError(f"{where}: malformed provenance data ({type(exc).__name__}: {exc})") from exc

    @classmethod
    def from_logs(
        cls,
        logs: dict[PairKey, PairLog],
        *,
        prior: tuple[float, float],
        remember_compacted: int = 100_000,
        timeline: Iterable[ProvenanceEntry] | None = None,
        quarantine: Iterable[ProvenanceEntry] | None = None,
        disagreement: Iterable[ProvenanceEntry] | None = None,
        compacted_ids: Iterable[str] = (),
        n_compacted: int = 0,
    ) -> ProvenanceStore:
        """A store holding these (loaded, already checked) logs, for loaders.

        The event index and each pair's pending list are rebuilt from the logs: the index in
        log order, the pending lists in time order. The timeline and the queues default to the
        non-compacted entries and the pending entries in time order (what a JSON file implies);
        a loader that saved their exact order passes it. Entries must be distinct objects."""
        store = cls(prior, remember_compacted=remember_compacted)
        store._pairs = logs
        by_event = store._by_event
        for log in logs.values():
            for e in log.entries:
                if e.event_id is not None:
                    index_event(by_event, e.event_id, e)
        by_time = attrgetter("t")
        pending = sorted((e for log in logs.values() for e in log.entries if e.status in PENDING), key=by_time)
        for e in pending:
            store._pending_by_pair.setdefault((e.node, e.predicate), []).append(e)
        if timeline is None:
            timeline = sorted((e for log in logs.values() for e in log.entries if e.status is not _COMPACTED),
                              key=by_time)
        store._timeline.extend(timeline)
        if quarantine is None:
            quarantine = (e for e in pending if e.status is _QUARANTINED)
        if disagreement is None:
            disagreement = (e for e in pending if e.status is _REFUSED)
        store.quarantine.extend(quarantine)
        store.disagreement.extend(disagreement)
        store._compacted_order.extend(compacted_ids)  # bounded by remember_compacted: keeps the newest
        store.n_compacted = n_compacted
        return store

"""The public methods every provenance store shares, each a thin call of a read view or a free
function over the :class:`~sgbelief.graph.entry_log.EntryLog` operations.

:class:`StoreMethods` is a mixin of conveniences (``prov.belief``, ``prov.retract``,
``prov.compact``, ``prov.to_dict``, ``ProvenanceStore.from_dict``, ...): it holds no state and
implements none of the protocol's operations, so a store that inherits it is complete on its own
(the reference :class:`~sgbelief.graph.provenance.ProvenanceStore` and the journalled store of
``sgbelief._fast.journal``); nothing here depends on which store it runs on.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from operator import attrgetter
from typing import Any, TypeVar

from sgbelief.graph.belief import BetaBelief
from sgbelief.graph.compaction import compact
from sgbelief.graph.entry_log import EntryLog, PairKey
from sgbelief.graph.migration import move_node, remove_node
from sgbelief.graph.provenance_json import store_from_dict, store_to_dict
from sgbelief.graph.provenance_log import (
    PENDING,
    EntryRecord,
    EntryStatus,
    EntryVerdict,
    PairLog,
    ProvenanceEntry,
    belief_from_entries,
    index_event,
)
from sgbelief.graph.retraction import retract

S = TypeVar("S", bound="StoreMethods")
_COMPACTED, _QUARANTINED, _REFUSED = EntryStatus.COMPACTED, EntryStatus.QUARANTINED, EntryStatus.REFUSED


class StoreMethods:
    """Reads and policies shared by the stores (each one line over :class:`EntryLog`)."""

    # the rest of what these use is the EntryLog operations each store implements
    prior_alpha: float
    prior_beta: float

    # ------------------------------------------------------------------ reads
    def __len__(self) -> int:
        return len(self.pair_index())

    def __contains__(self, key: object) -> bool:
        return key in self.pair_index()

    def belief(self, node: Any, predicate: str) -> BetaBelief:
        a, b = self.alpha_beta(node, predicate)
        return BetaBelief(a, b)

    def mean(self, node: Any, predicate: str) -> float:
        a, b = self.alpha_beta(node, predicate)
        return a / (a + b)

    def means(self, nodes: Iterable[Any], predicate: str) -> list[float]:
        """:meth:`mean` of (node, predicate) for each node, in order (the prior mean without evidence)."""
        get = self.pair_index().get
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
        return ((n, log.alpha / (log.alpha + log.beta)) for (n, p), log in self.pair_index().items() if p == predicate)

    def pairs(self) -> Iterator[PairKey]:
        return iter(self.pair_index())

    def predicates(self) -> set[str]:
        return {p for _, p in self.pair_index()}

    def predicates_of(self, node: Any) -> list[str]:
        return [p for (n, p) in self.pair_index() if n == node]

    def nodes_with(self, predicate: str) -> Iterator[Any]:
        return (n for (n, p) in self.pair_index() if p == predicate)

    def count_entries(self, node: Any = None) -> int:
        """Number of original evidence entries (compacted entries count what they folded)."""
        return sum(e.n_folded for (n, _p), log in self.logs().items() if node is None or n == node
                   for e in log.entries)

    def reconstruct(self, node: Any, predicate: str) -> tuple[float, float]:
        """Recompute (alpha, beta) from the log alone (Eq. 4, :func:`belief_from_entries`)."""
        return belief_from_entries((self.prior_alpha, self.prior_beta), self.entries(node, predicate))

    def iter_entries(self) -> Iterator[ProvenanceEntry]:
        for log in self.logs().values():
            yield from log.entries

    # ------------------------------------------------------------------ writes and policies
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
        """``append`` of the :class:`EntryRecord` with these fields (a shorthand for tests and
        scripts; library code builds the record by keyword)."""
        return self.append(EntryRecord(node, predicate, event_id, t, d_alpha, d_beta, status, stance, verdict,
                                       confidence))

    def retract(self, event_id: str, *, cascade_window: int | None = None) -> list[str]:
        """:func:`sgbelief.graph.retraction.retract` of this store."""
        return retract(self, event_id, cascade_window=cascade_window)  # type: ignore[arg-type]

    def compact(self, before_t: int) -> int:
        """:func:`sgbelief.graph.compaction.compact` of this store."""
        return compact(self, before_t)  # type: ignore[arg-type]

    def move_node(self, absorb: Any, keep: Any) -> None:
        """:func:`sgbelief.graph.migration.move_node` of this store."""
        move_node(self, absorb, keep)  # type: ignore[arg-type]

    def remove_node(self, node: Any) -> int:
        """:func:`sgbelief.graph.migration.remove_node` of this store."""
        return remove_node(self, node)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, Any]:
        """:func:`sgbelief.graph.provenance_json.store_to_dict` of this store."""
        return store_to_dict(self)  # type: ignore[arg-type]

    @classmethod
    def from_dict(cls: type[S], data: dict[str, Any], *, where: str = "provenance") -> S:
        """A store of this class from :meth:`to_dict`'s form (checked: Eq. 4 per pair;
        :func:`sgbelief.graph.provenance_json.store_from_dict`)."""
        return store_from_dict(data, cls.from_logs, where=where)  # type: ignore[no-any-return]

    @classmethod
    def from_logs(
        cls: type[S],
        logs: dict[PairKey, PairLog],
        *,
        prior: tuple[float, float],
        remember_compacted: int = 100_000,
        timeline: Iterable[ProvenanceEntry] | None = None,
        quarantine: Iterable[ProvenanceEntry] | None = None,
        disagreement: Iterable[ProvenanceEntry] | None = None,
        compacted_ids: Iterable[str] = (),
        n_compacted: int = 0,
    ) -> S:
        """A store of this class holding these (loaded, already checked) logs, for loaders
        (:func:`fill_from_logs`)."""
        store = cls(prior, remember_compacted=remember_compacted)  # type: ignore[call-arg]
        fill_from_logs(store.object_log(), logs, timeline=timeline, quarantine=quarantine,  # type: ignore[attr-defined]
                       disagreement=disagreement, compacted_ids=compacted_ids, n_compacted=n_compacted)
        return store


def fill_from_logs(
    objects: Any,
    logs: Mapping[PairKey, PairLog],
    *,
    timeline: Iterable[ProvenanceEntry] | None = None,
    quarantine: Iterable[ProvenanceEntry] | None = None,
    disagreement: Iterable[ProvenanceEntry] | None = None,
    compacted_ids: Iterable[str] = (),
    n_compacted: int = 0,
) -> None:
    """Fill an empty object-backed store (a :class:`~sgbelief.graph.provenance.ProvenanceStore`)
    with these (loaded, already checked) logs, through its builder methods.

    The event index and each pair's pending list are rebuilt from the logs: the index in log
    order, the pending lists in time order. The timeline and the queues default to the
    non-compacted entries and the pending entries in time order (what a JSON file implies); a
    loader that saved their exact order passes it. Entries must be distinct objects."""
    if len(objects.pair_index()) or objects.timeline_view():
        raise ValueError("from_logs fills an empty store")
    objects.add_logs(logs)
    by_event: dict[str, Any] = {}
    for log in logs.values():
        for e in log.entries:
            if e.event_id is not None:
                index_event(by_event, e.event_id, e)
    objects.index_events(by_event.items())
    by_time = attrgetter("t")
    pending = sorted((e for log in logs.values() for e in log.entries if e.status in PENDING), key=by_time)
    objects.index_pending(pending)
    if timeline is None:
        timeline = sorted((e for log in logs.values() for e in log.entries if e.status is not _COMPACTED),
                          key=by_time)
    objects.extend_timeline(timeline)
    if quarantine is None:
        quarantine = (e for e in pending if e.status is _QUARANTINED)
    if disagreement is None:
        disagreement = (e for e in pending if e.status is _REFUSED)
    objects.quarantine.extend(quarantine)
    objects.disagreement.extend(disagreement)
    objects.retire(compacted_ids, n_compacted)  # the memory is bounded by remember_compacted: keeps the newest


__all__ = ["StoreMethods", "fill_from_logs"]

"""Loading a saved graph into a journalled store, with the binary layout's entries deferred.

:data:`FAST_LOADING` is a :class:`~sgbelief.graph.loading.GraphLoading`: a JSON file's store
becomes a :class:`~sgbelief._fast.journal.JournalledProvenanceStore`; a binary file's store gets
its beliefs, queues and pending entries at once, and every other entry object, the event index
and the timeline on the first read of a log (:class:`DeferredLoad`). Pass it to the loaders:
``sgbelief.graph.persistence.load_graph(path, loading=FAST_LOADING)``.
"""

from __future__ import annotations

from collections import deque
from itertools import islice
from typing import Any

import networkx as nx
import numpy as np

from sgbelief._fast.journal import JournalledProvenanceStore
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.loading import GraphLoading
from sgbelief.graph.npz_archive import young_collections_only
from sgbelief.graph.npz_columns import pylist
from sgbelief.graph.npz_provenance import ProvenanceColumns
from sgbelief.graph.provenance import PairLog, ProvenanceEntry, ProvenanceStore, index_event


class DeferredLoad:
    """The checked entry columns of a binary load; :meth:`build` makes, on the first read, what
    an eager load makes (entry objects in each pair's log, the event index, the timeline),
    reusing the pending entries made at load time."""

    def __init__(self, columns: ProvenanceColumns, pending: dict[int, ProvenanceEntry]) -> None:
        self.columns = columns
        #: entry index -> the entry already made (the pending ones)
        self.pending = pending
        self._event_ids: set[str] | None = None  # built on the first has_event

    def has_event(self, event_id: str) -> bool:
        """Whether a loaded entry carries this id (a set of the id column, built once)."""
        ids = self._event_ids
        if ids is None:
            cols = self.columns
            ids = self._event_ids = set(cols.eid_array()[~cols.null].tolist())
        return event_id in ids

    def build(self, store: ProvenanceStore) -> None:
        """Fill the journalled store's object log (``store``) through its builder methods."""
        with young_collections_only():  # ~10⁶ long-lived objects, as in the load itself
            self._build(store)

    def _build(self, store: ProvenanceStore) -> None:
        cols = self.columns
        entries = cols.entries()
        for i, e in self.pending.items():  # the objects the queues hold
            entries[i] = e
        pick = entries.__getitem__
        # the loaded pairs come first in the store (pairs are only removed after materialising)
        logs = list(islice(store.pair_index().values(), len(cols.lengths)))
        set_entries = PairLog.entries.__set__  # type: ignore[attr-defined]
        deque(map(set_entries, logs, cols.split(entries)), maxlen=0)
        # event index: each event's entries in log order
        named = np.flatnonzero(~cols.null)
        ev = cols.eid_array()[named].tolist()
        ents = list(map(pick, named.tolist()))
        # (an id with one entry maps to the entry itself, as index_event builds it)
        by_event: dict[str, Any] = dict(zip(ev, ents))
        if len(by_event) != len(ev):  # some event has several entries
            by_event = {}
            for eid, e in zip(ev, ents):
                index_event(by_event, eid, e)
        store.index_events(by_event.items())
        store.extend_timeline(map(pick, cols.timeline.tolist()))


def build_deferred_store(cols: ProvenanceColumns) -> JournalledProvenanceStore:
    """The journalled store of checked columns: beliefs, queues and pending entries now, the
    other entries, the event index and the timeline on first read (:class:`DeferredLoad`)."""
    store = JournalledProvenanceStore(cols.prior, remember_compacted=cols.remember_compacted)
    objects = store.object_log()  # the builder (empty: nothing to materialise)
    objects.add_pairs(cols.pair_keys, pylist(cols.alpha), pylist(cols.beta))
    if len(store) != len(cols.pair_keys):
        raise cols.duplicate_pair_error()
    # the pending entries exist at once: the queues hold them (transitions act on these objects)
    pending = cols.pending_rows()
    built = dict(zip(pending.tolist(), cols.entries(pending))) if len(pending) else {}
    pick = built.__getitem__
    store.quarantine.extend(map(pick, cols.quarantine.tolist()))
    store.disagreement.extend(map(pick, cols.disagreement.tolist()))
    # per-pair pending lists in time order (stable), as the reference loader builds them
    objects.index_pending(map(pick, pending[np.argsort(cols.t[pending], kind="stable")].tolist()))
    objects.retire(cols.compacted_ids, cols.n_compacted)  # bounded by remember_compacted: keeps the newest
    if cols.n_entries:
        store.defer_entries(DeferredLoad(cols, built))
    return store


class FastLoading:
    """Journalled stores, binary entries deferred; nodes inserted with networkx's public
    ``add_nodes_from``."""

    def store_from_dict(self, data: dict[str, Any], *, where: str = "provenance") -> EntryLog:
        return JournalledProvenanceStore.from_dict(data, where=where)

    def store_from_columns(self, columns: ProvenanceColumns) -> EntryLog:
        return build_deferred_store(columns)

    def add_nodes(self, g: nx.MultiDiGraph, ids: list[Any], attrs: list[dict[str, Any]]) -> None:
        g.add_nodes_from(zip(ids, attrs))


FAST_LOADING: GraphLoading = FastLoading()


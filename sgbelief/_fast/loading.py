"""Loading a saved graph into a journalled store, with the binary layout's entries deferred.

:data:`FAST_LOADING` is a :class:`~sgbelief.graph.loading.GraphLoading`: a JSON file's store
becomes a :class:`~sgbelief._fast.journal.JournalledProvenanceStore`; a binary file's store gets
its beliefs, queues and pending entries at once, and every other entry object, the event index
and the timeline on the first read of a log (:class:`DeferredLoad`); nodes go straight into
networkx's node and adjacency dicts. Pass it to the loaders:
``sgbelief.graph.persistence.load_graph(path, loading=FAST_LOADING)``.
"""

from __future__ import annotations

from collections import deque
from itertools import islice
from typing import Any

import networkx as nx
import numpy as np

from sgbelief._fast.journal import (
    JournalledProvenanceStore,
    add_logs,
    extend_timeline,
    index_pending,
    remember_compacted_ids,
    set_event_index,
)
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

    def build(self, store: ProvenanceStore) -> None:
        with young_collections_only():  # ~10⁶ long-lived objects, as in the load itself
            self._build(store)

    def _build(self, store: ProvenanceStore) -> None:
        cols = self.columns
        entries = cols.entries()
        for i, e in self.pending.items():  # the objects the queues hold
            entries[i] = e
        pick = entries.__getitem__
        # the loaded pairs come first in the store (pairs are only removed after materialising)
        logs = list(islice(store._pairs.values(), len(cols.lengths)))
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
        set_event_index(store, by_event.items())
        extend_timeline(store, map(pick, cols.timeline.tolist()))


def build_deferred_store(cols: ProvenanceColumns) -> JournalledProvenanceStore:
    """The journalled store of checked columns: beliefs, queues and pending entries now, the
    other entries, the event index and the timeline on first read (:class:`DeferredLoad`)."""
    store = JournalledProvenanceStore(cols.prior, remember_compacted=cols.remember_compacted)
    add_logs(store, cols.pair_keys, pylist(cols.alpha), pylist(cols.beta))
    if len(store) != len(cols.pair_keys):
        raise cols.duplicate_pair_error()
    # the pending entries exist at once: the queues hold them (transitions act on these objects)
    pending = cols.pending_rows()
    built = dict(zip(pending.tolist(), cols.entries(pending))) if len(pending) else {}
    pick = built.__getitem__
    store.quarantine.extend(map(pick, cols.quarantine.tolist()))
    store.disagreement.extend(map(pick, cols.disagreement.tolist()))
    # per-pair pending lists in time order (stable), as the reference loader builds them
    index_pending(store, map(pick, pending[np.argsort(cols.t[pending], kind="stable")].tolist()))
    remember_compacted_ids(store, cols.compacted_ids)  # bounded by remember_compacted: keeps the newest
    store.n_compacted = cols.n_compacted
    if cols.n_entries:
        store.defer_entries(DeferredLoad(cols, built))
    return store


def add_nodes_to_dicts(g: nx.MultiDiGraph, ids: list[Any], attrs: list[dict[str, Any]]) -> None:
    """Insert nodes with their attribute dicts (taken as they are, not copied).

    An empty plain MultiDiGraph is filled through its documented adjacency dicts (``_node``,
    ``_succ``/``_adj``, ``_pred``) - add_nodes_from copies every dict and is ~4x slower."""
    plain = (type(g) is nx.MultiDiGraph and len(g) == 0 and g.node_attr_dict_factory is dict
             and g.adjlist_inner_dict_factory is dict and g._succ is g._adj)
    if not plain:  # pragma: no cover - SceneGraph always makes a plain MultiDiGraph
        g.add_nodes_from(zip(ids, attrs))
        return
    if any(n is None for n in ids):
        raise ValueError("None cannot be a node")
    g._node.update(zip(ids, attrs))
    g._succ.update(zip(ids, [{} for _ in range(len(ids))]))
    g._pred.update(zip(ids, [{} for _ in range(len(ids))]))
    cache = getattr(g, "__networkx_cache__", None)  # what networkx's own mutators clear
    if cache:
        cache.clear()


class FastLoading:
    """Journalled stores, binary entries deferred, nodes inserted into networkx's dicts."""

    def store_from_dict(self, data: dict[str, Any], *, where: str = "provenance") -> ProvenanceStore:
        return JournalledProvenanceStore.from_dict(data, where=where)

    def store_from_columns(self, columns: ProvenanceColumns) -> ProvenanceStore:
        return build_deferred_store(columns)

    def add_nodes(self, g: nx.MultiDiGraph, ids: list[Any], attrs: list[dict[str, Any]]) -> None:
        add_nodes_to_dicts(g, ids, attrs)


FAST_LOADING: GraphLoading = FastLoading()


"""How the loaders build what they read: the provenance store and networkx's node table.

A loader (:func:`sgbelief.graph.persistence.load_graph` for both formats) checks a file and then
hands the checked parts to a :class:`GraphLoading`. :data:`REFERENCE_LOADING` builds the
reference :class:`~sgbelief.graph.provenance.ProvenanceStore` with every entry an object, and
inserts nodes through networkx's public API; a faster strategy (``sgbelief._fast``) may defer the
entries and fill networkx's dicts directly, giving an observably equal graph.
"""

from __future__ import annotations

from typing import Any, Protocol

import networkx as nx

from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.npz_provenance import ProvenanceColumns, build_reference_store
from sgbelief.graph.provenance import ProvenanceStore


class GraphLoading(Protocol):
    """What a loader builds its graph with."""

    def store_from_dict(self, data: dict[str, Any], *, where: str = "provenance") -> EntryLog:
        """The store of a JSON file's ``provenance`` object (checked: Eq. 4 per pair)."""

    def store_from_columns(self, columns: ProvenanceColumns) -> EntryLog:
        """The store of a binary file's checked provenance columns."""

    def add_nodes(self, g: nx.MultiDiGraph, ids: list[Any], attrs: list[dict[str, Any]]) -> None:
        """Insert nodes (ids in order, with their attribute dicts) into an empty graph."""


class ReferenceLoading:
    """The reference store, built now; nodes inserted with ``add_nodes_from``."""

    def store_from_dict(self, data: dict[str, Any], *, where: str = "provenance") -> ProvenanceStore:
        return ProvenanceStore.from_dict(data, where=where)

    def store_from_columns(self, columns: ProvenanceColumns) -> ProvenanceStore:
        return build_reference_store(columns)

    def add_nodes(self, g: nx.MultiDiGraph, ids: list[Any], attrs: list[dict[str, Any]]) -> None:
        g.add_nodes_from(zip(ids, attrs))


REFERENCE_LOADING: GraphLoading = ReferenceLoading()

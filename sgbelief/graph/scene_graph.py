"""The belief scene graph M = (G, Phi, B) of Def. 1: a typed wrapper over a networkx graph.

This is the model: it imports neither the file formats nor the query layer. Saving, loading and
querying are free functions over a graph (:func:`sgbelief.graph.persistence.save_graph` /
:func:`~sgbelief.graph.persistence.load_graph`, :func:`sgbelief.query.run_query`); the public
:class:`sgbelief.SceneGraph` (:mod:`sgbelief.api.scene_graph`) adds them as methods.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import networkx as nx

from sgbelief.errors import UnknownNodeError, UnknownPredicateError
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA, BetaBelief
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.migration import move_node, remove_node
from sgbelief.graph.provenance import ProvenanceStore

NodeId = str | int


def _as_point(value: Any, name: str) -> tuple[float, float, float]:
    """``value`` as a point: a tuple of 3 Python floats (ValueError otherwise)."""
    if type(value) is tuple and len(value) == 3 and type(value[0]) is float and type(value[1]) is float \
            and type(value[2]) is float:
        return value  # already one (a ConceptGraphs geometry summary): float() would give the same floats
    return _as_point_plain(value, name)


def _as_point_plain(value: Any, name: str) -> tuple[float, float, float]:
    """:func:`_as_point` of any value (each coordinate through ``float``)."""
    try:
        pt = tuple(map(float, value))
    except TypeError as exc:
        raise ValueError(f"{name} must be a sequence of 3 numbers, got {value!r}") from exc
    if len(pt) != 3:
        raise ValueError(f"{name} must have 3 coordinates, got {len(pt)}")
    return pt  # type: ignore[return-value]


class SceneGraphModel:
    """Object nodes and relation edges (a networkx ``MultiDiGraph``) with one Beta belief per
    (node, predicate) backed by a :class:`ProvenanceStore` (Def. 1): the model every layer above
    takes. It knows neither files nor queries, and builds the reference store unless given one.
    Users build :class:`sgbelief.SceneGraph` (``sgbelief.api.scene_graph``), its subclass with
    save / load / query / explain and the fast store by default.

    Node attributes are plain dicts on ``graph.nx.nodes[n]`` (``centroid``, ``bbox``, ``label``
    and anything the user adds); relation edges are keyed by their relation name. Beliefs live
    in ``graph.provenance`` so that every one of them is reconstructable from its log (Eq. 4).

    ``vocabulary``: when given (an iterable of predicate names, or an object with a
    ``predicates`` attribute such as a SubsumptionTable), belief reads and updates of any other
    predicate raise :class:`~sgbelief.errors.UnknownPredicateError` (typo protection).

    ``create_nodes``: whether evidence that targets a node id the graph does not hold adds that
    node. Off by default, so a mistyped id raises :class:`~sgbelief.errors.UnknownNodeError`
    instead of making a ghost node; on for graphs built from evidence logs (replays, benches).
    """

    def __init__(
        self,
        vocabulary: Iterable[str] | Any | None = None,
        *,
        prior: tuple[float, float] = (PRIOR_ALPHA, PRIOR_BETA),
        name: str | None = None,
        provenance: EntryLog | None = None,
        create_nodes: bool = False,
    ) -> None:
        self.nx: nx.MultiDiGraph = nx.MultiDiGraph(name=name or "sgbelief")
        #: the beliefs and their logs; ``provenance``: an empty store to use instead of a
        #: new reference store with ``prior`` (then ``prior`` is ignored)
        self.provenance: EntryLog = ProvenanceStore(prior) if provenance is None else provenance
        self.vocabulary: frozenset[str] | None = None
        if vocabulary is not None:
            preds = getattr(vocabulary, "predicates", vocabulary)
            self.vocabulary = frozenset(preds)
        #: whether evidence naming an unknown node creates it (else the update is rejected)
        self.create_nodes: bool = bool(create_nodes)
        #: latest time step an operator processed on this graph
        self.clock: int = -1
        #: operator bookkeeping that must survive save/load (compaction epoch, ...)
        self.meta: dict[str, Any] = {}

    # ---------------------------------------------------------------- nodes
    def add_node(
        self,
        node: NodeId,
        *,
        centroid: Sequence[float] | None = None,
        bbox: Sequence[Sequence[float]] | None = None,
        label: str | None = None,
        **attrs: Any,
    ) -> None:
        """Add (or update the attributes of) an object node.

        ``bbox`` is an axis-aligned box ``((xmin, ymin, zmin), (xmax, ymax, zmax))``.
        """
        if isinstance(node, bool) or not isinstance(node, (str, int)):
            raise TypeError(f"node ids must be str or int (JSON-serialisable), got {type(node).__name__}")
        data: dict[str, Any] = attrs  # the keyword arguments' own dict: no copy needed
        if centroid is not None:
            data["centroid"] = _as_point(centroid, "centroid")
        if bbox is not None:
            if len(bbox) != 2:
                raise ValueError("bbox must be ((xmin, ymin, zmin), (xmax, ymax, zmax))")
            lo, hi = _as_point(bbox[0], "bbox min"), _as_point(bbox[1], "bbox max")
            if lo[0] > hi[0] or lo[1] > hi[1] or lo[2] > hi[2]:  # both have 3 coordinates (_as_point)
                raise ValueError(f"bbox min {lo} exceeds max {hi}")
            data["bbox"] = (lo, hi)
        if label is not None:
            data["label"] = str(label)
        self.nx.add_node(node, **data)

    def ensure_node(self, node: NodeId) -> None:
        """Add a bare node if it is not there yet (used when evidence names a new element)."""
        if node not in self.nx:
            self.add_node(node)

    def remove_node(self, node: NodeId) -> None:
        """Remove a node, its edges and its beliefs/provenance."""
        self._require(node)
        remove_node(self.provenance, node)
        self.nx.remove_node(node)

    def has_node(self, node: object) -> bool:
        return node in self.nx

    def __contains__(self, node: object) -> bool:
        return node in self.nx

    def __len__(self) -> int:
        return self.nx.number_of_nodes()

    def __iter__(self) -> Iterator[NodeId]:
        return iter(self.nx)

    def nodes(self) -> list[NodeId]:
        return list(self.nx.nodes)

    def node_attrs(self, node: NodeId) -> dict[str, Any]:
        """The node's attribute dict (live); raises UnknownNodeError."""
        try:
            return self.nx.nodes[node]
        except (KeyError, TypeError, nx.NetworkXError):  # absent, unhashable, or a slice
            raise UnknownNodeError(node) from None

    def node_attr_table(self) -> dict[NodeId, dict[str, Any]]:
        """Every node's attribute dict (live), by node in the order of :meth:`nodes`: the bulk form
        of :meth:`node_attrs` that reads over the whole map make (a subclass that changes what
        one returns changes the other with it)."""
        return dict(self.nx.nodes(data=True))

    def find_node(self, node: object) -> dict[str, Any] | None:
        """The node's attribute dict, or None when absent."""
        return self.nx.nodes[node] if node in self.nx else None

    def _require(self, node: object) -> None:
        if node not in self.nx:
            raise UnknownNodeError(node)

    # ------------------------------------------------------------ relations
    def add_relation(self, u: NodeId, v: NodeId, relation: str, **attrs: Any) -> None:
        """Add a directed relation edge ``u -relation-> v`` (e.g. ``on``, ``near``)."""
        self._require(u)
        self._require(v)
        if not isinstance(relation, str) or not relation:
            raise ValueError("relation must be a non-empty string")
        self.nx.add_edge(u, v, key=relation, relation=relation, **attrs)

    def relations(
        self, node: NodeId | None = None, relation: str | None = None
    ) -> list[tuple[NodeId, NodeId, str, dict[str, Any]]]:
        """Edges as (u, v, relation, attrs), optionally those touching ``node`` / of one kind."""
        if node is not None:
            self._require(node)
            edges: Iterable[tuple[Any, Any, Any, dict[str, Any]]] = list(
                self.nx.out_edges(node, keys=True, data=True)
            ) + list(self.nx.in_edges(node, keys=True, data=True))
        else:
            edges = self.nx.edges(keys=True, data=True)
        return [(u, v, k, d) for u, v, k, d in edges if relation is None or k == relation]

    def remove_relation(self, u: NodeId, v: NodeId, relation: str) -> None:
        self.nx.remove_edge(u, v, key=relation)

    # -------------------------------------------------------------- beliefs
    def check_predicate(self, predicate: str) -> None:
        """Raise UnknownPredicateError when a vocabulary is set and does not hold ``predicate``."""
        if self.vocabulary is not None and predicate not in self.vocabulary:
            raise UnknownPredicateError(predicate, self.vocabulary)

    def belief(self, node: NodeId, predicate: str) -> BetaBelief:
        """B(v, phi): the pair's Beta belief (the prior when it has no evidence)."""
        self._require(node)
        self.check_predicate(predicate)
        return self.provenance.belief(node, predicate)

    def probability(self, node: NodeId, predicate: str) -> float:
        """Posterior mean alpha / (alpha + beta) of B(v, phi)."""
        self._require(node)
        self.check_predicate(predicate)
        return self.provenance.mean(node, predicate)

    def probabilities(self, nodes: Iterable[NodeId] | None, predicate: str) -> list[float]:
        """:meth:`probability` of each node, in order, with the same checks and errors (the
        predicate checked once): the bulk read a query over many nodes makes. ``nodes=None``:
        every node of the graph, in the order of :meth:`nodes`.

        Both read the posterior means of the provenance store; a subclass that changes what
        :meth:`probability` returns changes this bulk form with it."""
        if nodes is None:
            every = self.nodes()
            if every:
                self.check_predicate(predicate)
            return self.provenance.means(every, predicate)
        nodes = list(nodes)
        if not nodes:
            return []
        self._require(nodes[0])
        self.check_predicate(predicate)
        graph = self.nx
        for n in nodes:
            if n not in graph:  # (networkx answers False for an unhashable id)
                raise UnknownNodeError(n)
        return self.provenance.means(nodes, predicate)

    def beliefs(self, node: NodeId) -> dict[str, BetaBelief]:
        """All beliefs of a node that have evidence, by predicate."""
        self._require(node)
        return {p: self.provenance.belief(node, p) for p in sorted(self.provenance.predicates_of(node))}

    def committed(self, predicate: str, tau: float = 0.5) -> set[NodeId]:
        """Nodes whose probability for ``predicate`` is strictly above ``tau``.

        A pair still at its prior Beta(1, 1) (mean 0.5) is never committed at tau = 0.5.
        """
        self.check_predicate(predicate)
        prov = self.provenance
        return {n for n in prov.nodes_with(predicate) if prov.mean(n, predicate) > tau}

    def predicates(self) -> list[str]:
        """Predicates with evidence in the graph, plus the vocabulary's when one is set."""
        preds = set(self.provenance.predicates())
        if self.vocabulary is not None:
            preds |= self.vocabulary
        return sorted(preds)

    def evidence_count(self, node: NodeId | None = None) -> int:
        """Number of evidence entries in the provenance logs (of one node, or of all)."""
        return self.provenance.count_entries(node)

    # ---------------------------------------------------------------- merge
    def merge_nodes(self, keep: NodeId, absorb: NodeId) -> None:
        """Merge ``absorb`` into ``keep`` (belief migration).

        The absorbed node's provenance moves to ``keep`` and the beliefs are recomputed from the
        merged logs, so every evidence entry is counted exactly once; its relation edges are
        rewired to ``keep`` (self-loops dropped) and its id is recorded in ``keep``'s
        ``merged_from`` attribute.
        """
        self._require(keep)
        self._require(absorb)
        if keep == absorb:
            return
        move_node(self.provenance, absorb, keep)
        g = self.nx
        for _, v, k, d in list(g.out_edges(absorb, keys=True, data=True)):
            if v != keep and v != absorb and not g.has_edge(keep, v, key=k):
                g.add_edge(keep, v, key=k, **d)
        for u, _, k, d in list(g.in_edges(absorb, keys=True, data=True)):
            if u != keep and u != absorb and not g.has_edge(u, keep, key=k):
                g.add_edge(u, keep, key=k, **d)
        merged = list(g.nodes[keep].get("merged_from", ()))
        merged.append(absorb)
        merged.extend(g.nodes[absorb].get("merged_from", ()))
        g.nodes[keep]["merged_from"] = merged
        g.remove_node(absorb)

    def __repr__(self) -> str:
        return (
            f"SceneGraphModel(nodes={len(self)}, edges={self.nx.number_of_edges()}, "
            f"beliefs={len(self.provenance)})"
        )


def __getattr__(name: str) -> Any:
    # the model's old name; it shared sgbelief.SceneGraph's name but not its default store
    if name == "SceneGraph":
        import warnings

        from sgbelief.errors import SgbeliefDeprecationWarning

        warnings.warn("sgbelief.graph.scene_graph.SceneGraph is deprecated (removed in sgbelief 0.2.0): it is "
                      "SceneGraphModel, the model without files, queries or the fast store; users build "
                      "sgbelief.SceneGraph", SgbeliefDeprecationWarning, stacklevel=2)
        return SceneGraphModel
    raise AttributeError(f"module 'sgbelief.graph.scene_graph' has no attribute {name!r}")

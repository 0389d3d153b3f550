"""The public scene graph: the model's :class:`~sgbelief.graph.scene_graph.SceneGraphModel` with the
conveniences a user reaches for first.

The model class (Def. 1: nodes, relations, one Beta belief per (node, predicate) and its provenance)
knows neither files nor queries. This subclass adds them as thin methods over the free functions of
the layers that own them::

    g.save(path)                 # sgbelief.graph.persistence.save_graph(g, path)
    SceneGraph.load(path)        # sgbelief.graph.persistence.load_graph(path, graph_type=SceneGraph, loading=...)
    g.query("is_chair & !is_near_window")   # sgbelief.query.run_query(g, expr)
    g.explain(node, "is_chair")  # sgbelief.graph.story.explain(g, node, predicate)

and chooses the provenance store: ``engine="fast"`` (the default) or ``engine="reference"`` (the
plain log of Eq. 4). ``sgbelief.SceneGraph`` is this class.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Literal

from sgbelief._fast.journal import JournalledProvenanceStore
from sgbelief._fast.loading import FAST_LOADING
from sgbelief.graph import scene_graph as model
from sgbelief.graph.belief import PRIOR_ALPHA, PRIOR_BETA
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.loading import REFERENCE_LOADING, GraphLoading
from sgbelief.graph.persistence import load_graph, save_graph
from sgbelief.graph.provenance import ProvenanceStore
from sgbelief.graph.story import BeliefStory, explain
from sgbelief.query.engine import QueryResult, run_query

__all__ = ["SceneGraph", "Engine", "ENGINES"]

Engine = Literal["fast", "reference"]

#: provenance store per engine (built from the prior): the journalled store of sgbelief._fast, or
#: the reference log; both observably equal (sgbelief.testing.check_store_matches_reference)
_PROVENANCE_STORES: dict[str, Callable[[tuple[float, float]], EntryLog]] = {
    "fast": JournalledProvenanceStore,
    "reference": ProvenanceStore,
}
#: how a loaded graph's store is built, per engine
_LOADINGS: dict[str, GraphLoading] = {"fast": FAST_LOADING, "reference": REFERENCE_LOADING}
ENGINES: tuple[str, ...] = tuple(_PROVENANCE_STORES)


def provenance_store(engine: str, prior: tuple[float, float] = (PRIOR_ALPHA, PRIOR_BETA)) -> EntryLog:
    """An empty provenance store of ``engine`` ("fast" or "reference") with Beta ``prior``."""
    try:
        make = _PROVENANCE_STORES[engine]
    except KeyError:
        raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}") from None
    return make(prior)


class SceneGraph(model.SceneGraphModel):
    """The belief scene graph of :mod:`sgbelief.graph.scene_graph` plus ``save`` / ``load`` /
    ``query``, with the provenance store chosen by ``engine`` ("fast", the default, or "reference").

    Everything else (nodes, relations, beliefs, merges) is the model class's; code below the
    public API works on the model class and reaches files and queries through the free functions.
    """

    def __init__(
        self,
        vocabulary: Iterable[str] | Any | None = None,
        *,
        prior: tuple[float, float] = (PRIOR_ALPHA, PRIOR_BETA),
        name: str | None = None,
        engine: Engine = "fast",
        create_nodes: bool = False,
    ) -> None:
        super().__init__(
            vocabulary, prior=prior, name=name, provenance=provenance_store(engine, prior), create_nodes=create_nodes
        )

    def save(self, path: str | Path, *, format: str | None = None) -> Path:
        """Save losslessly and atomically; returns the file written.

        ``format="json"`` (the default; a directory path gets ``graph.json``) or ``"npz"``, the
        columnar binary layout for large maps (a directory path gets ``graph.npz``). A ``.json`` /
        ``.npz`` suffix selects the format when ``format`` is not given.
        """
        return save_graph(self, path, format=format)

    @classmethod
    def load(cls, path: str | Path, *, format: str | None = None, engine: Engine = "fast") -> SceneGraph:
        """Load a graph written by :meth:`save` (format from the suffix, or the file found in a
        directory) as an instance of this class, its store built by ``engine``; malformed,
        truncated or edited files raise FormatError."""
        if engine not in _LOADINGS:
            raise ValueError(f"engine must be one of {list(ENGINES)}, got {engine!r}")
        return load_graph(path, format=format, graph_type=cls, loading=_LOADINGS[engine])

    def query(self, expr: Any, **kwargs: Any) -> QueryResult:
        """Answer a compound query: :func:`sgbelief.query.run_query` on this graph."""
        return run_query(self, expr, **kwargs)

    def explain(self, node: Any, predicate: str, *, tau: float = 0.5) -> BeliefStory:
        """The story of one belief: every provenance entry of (node, predicate) in time order,
        what compaction folded (counts per status, time range, first and last event ids), and
        why the pair is or is not committed at ``tau`` (:func:`sgbelief.graph.story.explain`)."""
        return explain(self, node, predicate, tau=tau)

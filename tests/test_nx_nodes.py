"""The one private fast path into networkx (sgbelief._fast.nx_nodes.node_table) against the public API."""

from __future__ import annotations

import networkx as nx
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief._fast.nx_nodes import node_table
from sgbelief.graph.scene_graph import SceneGraphModel

_ops = st.lists(st.tuples(st.sampled_from(["add", "remove", "edge"]), st.integers(0, 6), st.integers(0, 6)),
                max_size=30)


@settings(max_examples=100, deadline=None)
@given(ops=_ops, cls=st.sampled_from([nx.MultiDiGraph, nx.DiGraph, nx.Graph]))
def test_node_table_is_the_public_node_view(ops: list[tuple[str, int, int]], cls: type[nx.Graph]) -> None:
    """Same nodes in the same order, the same attribute dicts, membership as has_node; live:
    taken once, it follows every change made through the public API."""
    g = cls()
    table = node_table(g)
    for kind, a, b in ops:
        if kind == "add":
            g.add_node(a, w=b)
        elif kind == "remove" and g.has_node(a):
            g.remove_node(a)
        elif kind == "edge":
            g.add_edge(a, b)
        assert list(table) == list(g.nodes)
        assert dict(table) == dict(g.nodes(data=True))
        assert all(table[n] is g.nodes[n] for n in g)  # the attribute dicts themselves
        assert all((n in table) == g.has_node(n) for n in range(-1, 8))


def test_node_table_of_a_scene_graph() -> None:
    g = SceneGraphModel()
    g.add_node("a", label="chair")
    assert "a" in node_table(g.nx) and "b" not in node_table(g.nx)
    assert node_table(g.nx)["a"] == g.node_attrs("a")

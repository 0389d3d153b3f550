"""Private: the one fast path into networkx's internals, read-only.

networkx keeps a graph's nodes in a plain dict, node -> attribute dict (``G._node``, the mapping
behind ``G.nodes``; networkx documents it as the graph's node data structure, the one
``node_dict_factory`` makes). The fused loops of this package test "is this node in the graph?"
once per evidence target: on that dict the test runs in C, through ``G.nodes`` or
``G.__contains__`` it runs Python code. :func:`node_table` is the only place sgbelief reads it;
``tests/test_nx_nodes.py`` holds it to the public API (same keys in the same order, same
attribute dicts, live as the graph changes). Nothing in sgbelief writes networkx's internals.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import networkx as nx


def node_table(g: nx.Graph) -> Mapping[Any, dict[str, Any]]:
    """``g``'s node -> attribute dict table, live and read-only (``dict(g.nodes(data=True))``
    without the copy): for fast membership tests (``node in node_table(g)``). Change the graph
    only through its public API."""
    return g._node  # type: ignore[no-any-return]


__all__ = ["node_table"]

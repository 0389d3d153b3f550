"""Writing relations into a graph: ``near`` and ``on`` edges from the geometry, via ``add_relation``."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from sgbelief.errors import ConfigError
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.query.relations.config import RelationConfig
from sgbelief.query.relations.context import GeometryContext

__all__ = ["materialise_relations"]


def materialise_relations(graph: SceneGraphModel, config: RelationConfig | None = None, *,
                          relations: Iterable[str] = ("near", "on")) -> int:
    """Add ``near`` (both directions, attr ``distance``) and ``on`` (upper -> lower) edges via
    ``graph.add_relation``; structural nodes (walls, floor, ceiling) are skipped. Returns the number
    of edges written (re-running overwrites: the edge key is the relation name)."""
    ctx = GeometryContext(graph, config)
    ctx.build()
    wanted = set(relations)
    unknown = wanted - {"near", "on"}
    if unknown:
        raise ConfigError(f"materialise_relations: unknown relation(s) {sorted(unknown)}; known: ['near', 'on']")
    count = 0
    if "on" in wanted:
        for u, v in ctx.on_pairs():
            graph.add_relation(u, v, "on")
            count += 1
    if "near" in wanted:
        from scipy.spatial import cKDTree

        d = ctx.config.near_distance
        for ix in ctx.groups.values():
            ok = ix[ctx.has_box[ix] & ~ctx.structural[ix]]
            if ok.size < 2:
                continue
            lo, hi = ctx.lo[ok], ctx.hi[ok]
            centers = (lo + hi) / 2.0
            radius = float(np.max(np.linalg.norm(hi - lo, axis=1)) / 2.0)
            tree = cKDTree(centers)
            for a, b in sorted(tree.query_pairs(d + 2 * radius + 1e-9)):
                gap = np.maximum(0.0, np.maximum(lo[a] - hi[b], lo[b] - hi[a]))
                dist = float(np.sqrt(gap @ gap))
                if dist <= d:
                    u, v = ctx.nodes[int(ok[a])], ctx.nodes[int(ok[b])]
                    graph.add_relation(u, v, "near", distance=dist)
                    graph.add_relation(v, u, "near", distance=dist)
                    count += 2
    return count

"""Deterministic geometric relation predicates (the paper's geometric-channel context predicates).

A geometric predicate is a pure function ``fn(ctx, node) -> bool | None`` of a node's plain
attributes and of its neighbours' geometry. ``None`` means "cannot be decided" (the node lacks an
attribute the predicate needs); the query engine treats it as *not satisfied* in either polarity.

Predicates live in a :class:`RelationRegistry`. The module-level :data:`DEFAULT_REGISTRY` holds the
built-ins and is what queries use unless told otherwise; users extend it with the
:func:`relation` decorator or :meth:`RelationRegistry.register`::

    from sgbelief.query.relations import relation

    @relation("is_large", needs=("bbox",))
    def is_large(ctx, node):
        \"\"\"Box volume above ``ctx.config.extra['large_volume']`` (default 1 m^3).\"\"\"
        box = ctx.box(node)
        return None if box is None else box.volume >= ctx.config.extra.get("large_volume", 1.0)

Node attributes read by the built-ins (all optional; a predicate returns None when its own input is
missing): ``bbox`` ((min xyz), (max xyz)) or ``centroid`` (3 floats), ``label`` (ground-truth /
committed class name), ``scene`` (neighbourhood queries never cross scenes), ``floor_z``,
``front`` (horizontal facing vector), ``track`` (list of centroids, or of dicts with ``centroid``),
``stationary``, ``speed``, ``road_distance_px``, ``near_road``, ``on_sidewalk``,
``at_intersection``, ``intersection_distance``, ``visible_in_drive_direction``.

Every threshold is a field of :class:`RelationConfig` (metres unless stated).

The package, one concept a module: :mod:`~sgbelief.query.relations.config` (the thresholds),
:mod:`~sgbelief.query.relations.boxes` (box values and arrays), :mod:`~sgbelief.query.relations.context`
(the cached geometric view of a graph), :mod:`~sgbelief.query.relations.registry` (named predicates and
families), :mod:`~sgbelief.query.relations.indoor` / :mod:`~sgbelief.query.relations.outdoor` (the
built-ins), :mod:`~sgbelief.query.relations.defaults` (:data:`DEFAULT_REGISTRY`) and
:mod:`~sgbelief.query.relations.materialise` (relations written as graph edges).
"""

from __future__ import annotations

from sgbelief.query.relations.boxes import Box, box_distance
from sgbelief.query.relations.config import RelationConfig
from sgbelief.query.relations.context import GeometryContext
from sgbelief.query.relations.defaults import DEFAULT_REGISTRY, register_relation, relation
from sgbelief.query.relations.indoor import (
    INDOOR_RELATIONS,
    is_accessible,
    is_facing_seating,
    is_on_top_of,
    is_unobstructed,
    is_workspace_height,
)
from sgbelief.query.relations.materialise import materialise_relations
from sgbelief.query.relations.outdoor import (
    OUTDOOR_RELATIONS,
    is_at_intersection,
    is_near_road_px,
    is_on_sidewalk,
    is_stationary,
    is_visible_in_drive_direction,
)
from sgbelief.query.relations.registry import FamilyFactory, GeoPredicate, PredicateFn, RelationRegistry

__all__ = [
    "RelationConfig",
    "GeoPredicate",
    "PredicateFn",
    "FamilyFactory",
    "RelationRegistry",
    "GeometryContext",
    "Box",
    "DEFAULT_REGISTRY",
    "INDOOR_RELATIONS",
    "OUTDOOR_RELATIONS",
    "relation",
    "register_relation",
    "materialise_relations",
    "box_distance",
    "is_on_top_of",
    "is_workspace_height",
    "is_unobstructed",
    "is_accessible",
    "is_facing_seating",
    "is_stationary",
    "is_near_road_px",
    "is_on_sidewalk",
    "is_at_intersection",
    "is_visible_in_drive_direction",
]

"""The built-in indoor relations (ScanNet-like maps): nearness to a class, support (``on``), workspace
height, a free top, accessibility and facing a seat. Thresholds come from :class:`RelationConfig`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sgbelief.query.relations.boxes import Box
from sgbelief.query.relations.context import GeometryContext
from sgbelief.query.relations.registry import PredicateFn, RelationRegistry

__all__ = ["INDOOR_RELATIONS", "is_on_top_of", "is_workspace_height", "is_unobstructed", "is_accessible",
           "is_facing_seating"]

INDOOR_RELATIONS = RelationRegistry()


def _near_factory(cls_name: str) -> PredicateFn:
    def is_near(ctx: GeometryContext, node: Any) -> bool | None:
        i = ctx.idx(node)  # (builds the arrays)
        if not ctx.has_box[i]:
            return None
        return ctx.has_neighbour_of_class(node, cls_name, ctx.config.near_distance)

    is_near.__doc__ = f"Box distance <= near_distance to another node of class {cls_name!r}."
    return is_near


INDOOR_RELATIONS.register_family(
    "is_near_", _near_factory, needs=("bbox|centroid", "label", "scene"),
    doc="Box-to-box distance <= near_distance (default 1.0 m) to another node in the same scene whose "
    "label is <class> or one of class_aliases[<class>] (or whose is_<class> belief is committed).",
)


def _on_top_of_factory(cls_name: str) -> PredicateFn:
    def is_on_top_of_cls(ctx: GeometryContext, node: Any) -> bool | None:
        if ctx.box(node) is None:
            return None
        mask = ctx.class_mask(cls_name)
        return any(mask[ctx.idx(v)] for v in ctx.supported_by(node))

    return is_on_top_of_cls


INDOOR_RELATIONS.register_family(
    "is_on_top_of_", _on_top_of_factory, needs=("bbox", "label", "scene"),
    doc="Rests on a node of class <class> (see is_on_top_of).",
)


@INDOOR_RELATIONS.predicate("is_on_top_of", needs=("bbox", "scene"))
def is_on_top_of(ctx: GeometryContext, node: Any) -> bool | None:
    """Rests on another non-structural node: bottom within +-on_tolerance (0.05 m) of its top and
    >= on_min_overlap (30 %) of the own footprint over it."""
    if ctx.box(node) is None:
        return None
    return bool(ctx.supported_by(node))


@INDOOR_RELATIONS.predicate("is_workspace_height", needs=("bbox", "floor_z|scene"))
def is_workspace_height(ctx: GeometryContext, node: Any) -> bool | None:
    """Top surface (bbox zmax) within workspace_band (0.6-1.1 m) above the floor."""
    box, floor = ctx.box(node), ctx.floor(node)
    if box is None or floor is None:
        return None
    lo, hi = ctx.config.workspace_band
    return lo <= float(box.hi[2]) - floor <= hi


@INDOOR_RELATIONS.predicate("is_unobstructed", needs=("bbox", "scene"))
def is_unobstructed(ctx: GeometryContext, node: Any) -> bool | None:
    """Nothing rests on the top surface (no node is ``on`` this one)."""
    if ctx.box(node) is None:
        return None
    return not ctx.resting_on(node)


def _slab(box: Box, direction: np.ndarray, depth: float, floor: float, zband: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned slab of free space in front of ``box`` along the dominant axis of ``direction``."""
    axis = int(np.argmax(np.abs(direction)))
    sign = 1.0 if direction[axis] >= 0 else -1.0
    lo, hi = box.lo.copy(), box.hi.copy()
    if sign > 0:
        lo[axis], hi[axis] = box.hi[axis], box.hi[axis] + depth
    else:
        lo[axis], hi[axis] = box.lo[axis] - depth, box.lo[axis]
    lo[2], hi[2] = floor + zband[0], floor + zband[1]
    return lo, hi


@INDOOR_RELATIONS.predicate("is_accessible", needs=("bbox", "front?", "scene"))
def is_accessible(ctx: GeometryContext, node: Any) -> bool | None:
    """Some front side has a free slab: access_depth (0.6 m) deep, as wide as the box, from
    access_z[0] to access_z[1] (0.1-1.5 m) above the floor, that no non-structural box penetrates
    by more than min_overlap (0.02 m). Fronts: attr ``front`` or both long-side normals."""
    box, floor = ctx.box(node), ctx.floor(node)
    if box is None or floor is None:
        return None
    cfg = ctx.config
    for d in ctx.front_directions(node):
        lo, hi = _slab(box, d, cfg.access_depth, floor, cfg.access_z)
        if not ctx.obstacles_in(node, lo, hi):
            return True
    return False


@INDOOR_RELATIONS.predicate("is_facing_seating", needs=("bbox", "front?", "label", "scene"))
def is_facing_seating(ctx: GeometryContext, node: Any) -> bool | None:
    """A seat (class seating_class) within facing_distance (3 m, box distance) whose centre lies
    within facing_half_angle_deg (60 deg) of a front direction (attr ``front`` or long-side normals)."""
    box = ctx.box(node)
    if box is None:
        return None
    cfg = ctx.config
    fronts = ctx.front_directions(node)
    cos_max = math.cos(math.radians(cfg.facing_half_angle_deg))
    c = box.center[:2]
    for seat, _d in ctx.neighbours_of_class(node, cfg.seating_class, cfg.facing_distance):
        sb = ctx.box(seat)
        assert sb is not None
        v = sb.center[:2] - c
        nv = float(np.linalg.norm(v))
        if nv == 0:
            continue
        if any(float(v @ f) / nv >= cos_max for f in fronts):
            return True
    return False

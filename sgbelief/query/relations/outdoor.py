"""The built-in outdoor relations (attributes of the simulated / KITTI-360 maps): stationary, near a
road (image space), on a sidewalk, at an intersection, visible in the drive direction."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from sgbelief.query.relations.context import GeometryContext
from sgbelief.query.relations.registry import RelationRegistry

__all__ = ["OUTDOOR_RELATIONS", "is_stationary", "is_near_road_px", "is_on_sidewalk", "is_at_intersection",
           "is_visible_in_drive_direction"]

OUTDOOR_RELATIONS = RelationRegistry()


def _track_points(track: Any) -> np.ndarray | None:
    pts = []
    for item in track:
        if isinstance(item, Mapping):
            item = item.get("centroid")
            if item is None:
                continue
        pts.append([float(x) for x in list(item)[-3:]] if len(item) >= 3 else [float(x) for x in item])
    if not pts:
        return None
    return np.asarray(pts, dtype=float)


@OUTDOOR_RELATIONS.predicate("is_stationary", needs=("track|speed|stationary",))
def is_stationary(ctx: GeometryContext, node: Any) -> bool | None:
    """Every centroid of ``track`` (>= stationary_min_track entries) within
    stationary_max_displacement (1.0 m) of the track's median; else ``speed`` <=
    stationary_max_speed (0.3 m/s); else the boolean ``stationary``."""
    cfg = ctx.config
    track = ctx.attr(node, "track")
    if track is not None:
        pts = _track_points(track)
        if pts is not None and len(pts) >= cfg.stationary_min_track:
            med = np.median(pts, axis=0)
            return float(np.max(np.linalg.norm(pts - med, axis=1))) <= cfg.stationary_max_displacement
    if ctx.attr(node, "speed") is not None:
        return float(ctx.attr(node, "speed")) <= cfg.stationary_max_speed
    if ctx.attr(node, "stationary") is not None:
        return bool(ctx.attr(node, "stationary"))
    return None


@OUTDOOR_RELATIONS.predicate("is_near_road_px", needs=("road_distance_px|near_road",))
def is_near_road_px(ctx: GeometryContext, node: Any) -> bool | None:
    """Image-space distance to the nearest road pixel ``road_distance_px`` <= near_road_px (50 px);
    else the boolean ``near_road``."""
    if ctx.attr(node, "road_distance_px") is not None:
        return float(ctx.attr(node, "road_distance_px")) <= ctx.config.near_road_px
    if ctx.attr(node, "near_road") is not None:
        return bool(ctx.attr(node, "near_road"))
    return None


@OUTDOOR_RELATIONS.predicate("is_on_sidewalk", needs=("on_sidewalk",))
def is_on_sidewalk(ctx: GeometryContext, node: Any) -> bool | None:
    """The boolean attribute ``on_sidewalk`` (footprint on sidewalk pixels / cells)."""
    v = ctx.attr(node, "on_sidewalk")
    return None if v is None else bool(v)


@OUTDOOR_RELATIONS.predicate("is_at_intersection", needs=("at_intersection|intersection_distance",))
def is_at_intersection(ctx: GeometryContext, node: Any) -> bool | None:
    """The boolean ``at_intersection``; else ``intersection_distance`` <= intersection_radius (15 m)."""
    if ctx.attr(node, "at_intersection") is not None:
        return bool(ctx.attr(node, "at_intersection"))
    if ctx.attr(node, "intersection_distance") is not None:
        return float(ctx.attr(node, "intersection_distance")) <= ctx.config.intersection_radius
    return None


@OUTDOOR_RELATIONS.predicate("is_visible_in_drive_direction", needs=("visible_in_drive_direction",))
def is_visible_in_drive_direction(ctx: GeometryContext, node: Any) -> bool | None:
    """The boolean ``visible_in_drive_direction`` (inside the forward field of view)."""
    v = ctx.attr(node, "visible_in_drive_direction")
    return None if v is None else bool(v)

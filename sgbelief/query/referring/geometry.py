"""Footprint geometry for referring relations: axis-aligned boxes seen from above (convex polygons),
their clipping, the box-to-box distance, and the Sr3D-style measures of each relation family.

Boxes are ``lo``/``hi`` arrays of 3 floats (metres, z up). A footprint is the box's top view, a
rectangle; regions (the convex hull of two anchors, an anchor's front/left/... section) are convex
polygons, counter-clockwise ``(k, 2)`` arrays. Every measure here is a plain number; the soft
versions the scorer uses are :func:`soft_above` (a logistic step) of these numbers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "between_measures", "clip_convex", "convex_hull", "effective_distance", "footprint_overlap",
    "occupancy", "polygon_area", "rect", "soft_above", "vertical_measures", "z_overlap",
]


def soft_above(x: float | np.ndarray, threshold: float, width: float) -> np.ndarray:
    """Logistic step: ~0 well below ``threshold``, 0.5 at it, ~1 well above (``width`` > 0 is
    the distance over which it goes from 0.27 to 0.73)."""
    z = (np.asarray(x, dtype=float) - threshold) / width
    return 0.5 * (1.0 + np.tanh(0.5 * z))


# -- polygons ------------------------------------------------------------------------------------
def rect(lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    """The footprint of a box: its top-view rectangle, counter-clockwise."""
    x0, y0, x1, y1 = float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def polygon_area(poly: np.ndarray) -> float:
    """Area of a simple polygon (shoelace; 0 for fewer than 3 vertices)."""
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2.0)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of 2-D points, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.asarray(points, dtype=float).tolist())))
    if len(pts) <= 2:
        return np.array(pts, dtype=float).reshape(-1, 2)

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1], dtype=float)


def clip_convex(subject: np.ndarray, clipper: np.ndarray) -> np.ndarray:
    """The part of polygon ``subject`` inside the convex, counter-clockwise polygon ``clipper``
    (Sutherland-Hodgman)."""
    out = [tuple(p) for p in subject]
    k = len(clipper)
    for i in range(k):
        if not out:
            break
        ax, ay = clipper[i]
        bx, by = clipper[(i + 1) % k]
        ex, ey = bx - ax, by - ay

        def inside(p: tuple[float, float]) -> bool:
            return ex * (p[1] - ay) - ey * (p[0] - ax) >= -1e-12

        def cut(p: tuple[float, float], q: tuple[float, float]) -> tuple[float, float]:
            dx, dy = q[0] - p[0], q[1] - p[1]
            den = ex * dy - ey * dx
            if den == 0.0:
                return q
            t = (ex * (ay - p[1]) - ey * (ax - p[0])) / den
            return (p[0] + t * dx, p[1] + t * dy)

        src, out = out, []
        for j, cur in enumerate(src):
            prev = src[j - 1]
            if inside(cur):
                if not inside(prev):
                    out.append(cut(prev, cur))
                out.append(cur)
            elif inside(prev):
                out.append(cut(prev, cur))
    return np.array(out, dtype=float).reshape(-1, 2)


def occupancy(lo: Sequence[float], hi: Sequence[float], region: np.ndarray) -> float:
    """Fraction of the box's footprint inside the convex ``region`` (0 for a degenerate footprint)."""
    r = rect(lo, hi)
    area = polygon_area(r)
    if area <= 0.0:
        cx, cy = (float(lo[0]) + float(hi[0])) / 2.0, (float(lo[1]) + float(hi[1])) / 2.0
        return 1.0 if len(clip_convex(np.array([[cx, cy], [cx + 1e-6, cy], [cx, cy + 1e-6]]), region)) else 0.0
    return polygon_area(clip_convex(r, region)) / area


# -- boxes ---------------------------------------------------------------------------------------
def footprint_overlap(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray, hi_b: np.ndarray) -> np.ndarray:
    """Top-view intersection area of boxes a and b (broadcasts over leading axes)."""
    dx = np.minimum(hi_a[..., 0], hi_b[..., 0]) - np.maximum(lo_a[..., 0], lo_b[..., 0])
    dy = np.minimum(hi_a[..., 1], hi_b[..., 1]) - np.maximum(lo_a[..., 1], lo_b[..., 1])
    return np.maximum(dx, 0.0) * np.maximum(dy, 0.0)


def z_overlap(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray, hi_b: np.ndarray) -> np.ndarray:
    """Signed length of the z-intervals' intersection (negative: the gap between them)."""
    return np.minimum(hi_a[..., 2], hi_b[..., 2]) - np.maximum(lo_a[..., 2], lo_b[..., 2])


def effective_distance(lo: np.ndarray, hi: np.ndarray, lo_a: np.ndarray, hi_a: np.ndarray) -> np.ndarray:
    """Distance between each box (rows of ``lo``/``hi``) and box a: the Euclidean gap between them
    when they are apart, else minus the penetration depth (the smallest of the three overlaps), so
    that of two boxes touching the anchor the more deeply interleaved one counts as closer."""
    gap = np.maximum(0.0, np.maximum(lo - hi_a, lo_a - hi))
    dist = np.sqrt(np.sum(gap * gap, axis=-1))
    over = np.minimum(hi, hi_a) - np.maximum(lo, lo_a)
    depth = np.min(over, axis=-1)
    return np.where(dist > 0.0, dist, -np.maximum(depth, 0.0))


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.maximum(hi[..., 0] - lo[..., 0], 0.0) * np.maximum(hi[..., 1] - lo[..., 1], 0.0)


def vertical_measures(lo: np.ndarray, hi: np.ndarray, lo_a: np.ndarray, hi_a: np.ndarray) -> dict[str, np.ndarray]:
    """The numbers the support and vertical relations read, target rows vs anchor a:

    ``i_target`` / ``i_anchor``: footprint intersection over the target's / anchor's footprint;
    ``area_ratio``: target footprint over anchor footprint; ``gap_up``: target bottom minus anchor
    top (> 0: the target is higher); ``gap_down``: anchor bottom minus target top."""
    inter = footprint_overlap(lo, hi, lo_a, hi_a)
    at = np.maximum(_area(lo, hi), 1e-12)
    aa = max(float(_area(lo_a, hi_a)), 1e-12)
    return {
        "i_target": inter / at,
        "i_anchor": inter / aa,
        "area_ratio": at / aa,
        "gap_up": lo[..., 2] - hi_a[2],
        "gap_down": lo_a[2] - hi[..., 2],
    }


def between_measures(lo: np.ndarray, hi: np.ndarray, lo_a: np.ndarray, hi_a: np.ndarray,
                     lo_b: np.ndarray, hi_b: np.ndarray) -> dict[str, np.ndarray]:
    """The numbers the between relation reads, target rows vs anchors a and b:

    ``hull``: fraction of the target footprint inside the convex hull of the two anchors'
    footprints; ``over_a`` / ``over_b``: fraction of the target footprint over each anchor;
    ``z_a`` / ``z_b``: the target's z-overlap with each anchor over the target's height."""
    hull = convex_hull(np.vstack([rect(lo_a, hi_a), rect(lo_b, hi_b)]))
    n = len(lo)
    occ = np.array([occupancy(lo[i], hi[i], hull) if len(hull) >= 3 else 0.0 for i in range(n)])
    at = np.maximum(_area(lo, hi), 1e-12)
    height = np.maximum(hi[:, 2] - lo[:, 2], 1e-6)
    return {
        "hull": occ,
        "over_a": footprint_overlap(lo, hi, lo_a, hi_a) / at,
        "over_b": footprint_overlap(lo, hi, lo_b, hi_b) / at,
        "z_a": z_overlap(lo, hi, lo_a, hi_a) / height,
        "z_b": z_overlap(lo, hi, lo_b, hi_b) / height,
    }


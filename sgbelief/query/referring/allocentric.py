"""View-dependent relations (left / right / front / back of an anchor): the anchor's sections and
its front direction.

**Sections** follow the allocentric definition of Sr3D (Achlioptas et al., ReferIt3D, ECCV 2020):
in the anchor's own frame, the *front* section is a strip that starts at the anchor's front face,
as wide as the face, flares out by ``angle`` degrees over a first depth ``df = min(2 * depth,
max_front_depth)`` and then runs straight for ``far_depth`` more metres; *back* is the same strip
behind the anchor; *left* and *right* are the strips off the two side faces (first depth ``dl =
min(2 * width, max_side_depth)``). Left and right are those of a viewer **facing the anchor's
front** (standing in the front section, looking at the anchor) -- what "facing the front of the
bed, the nightstand on its left" means. A target is in a section by the fraction of its footprint
inside it; Sr3D keeps a reference only when one target has more than 90 % of itself in the section
and every other same-class object less than 8 %.

**The front.** A map of axis-aligned boxes has no orientation. A node's ``front`` attribute (a
horizontal vector) is used when present; otherwise the four axis directions are hypotheses,
weighted by a prior built from the room (see :func:`front_hypotheses`): the back of furniture
stands against a wall or the room's edge and its front faces free space; elongated furniture
faces across its long side (beds, toilets and bathtubs along it); seats face their table or desk,
desks and screens face their seat. The scorer then weighs each hypothesis by how well it explains
the utterance (exactly one target in the named section).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sgbelief.query.referring.classes import NodeTable, singular_key
from sgbelief.query.referring.geometry import convex_hull, occupancy
from sgbelief.query.referring.model import Relation

__all__ = ["FrontHypothesis", "SectionConfig", "front_hypotheses", "section_polygon", "section_occupancy"]

AXES: tuple[tuple[float, float], ...] = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))

#: classes whose front lies along the long side of the footprint (the foot of a bed)
FRONT_ALONG_LONG_AXIS = frozenset(singular_key(c) for c in (
    "bed", "beds", "bunk bed", "loft bed", "crib", "mattress", "toilet", "bathtub", "treadmill", "urinal"))
#: seats: their front faces the nearest table-like object
SEATS = frozenset(singular_key(c) for c in (
    "chair", "office chair", "desk chair", "armchair", "sofa chair", "stool", "seat", "wheelchair",
    "rocking chair", "dining chair", "recliner", "folded chair", "couch", "sofa", "loveseat", "bench",
    "ottoman", "piano bench"))
TABLES = frozenset(singular_key(c) for c in (
    "table", "desk", "dining table", "coffee table", "end table", "kitchen counter", "counter", "round table",
    "side table", "computer desk", "kitchen island", "bar", "tv", "monitor", "piano"))
#: things used from a seat: their front faces the nearest seat
SEAT_FACING = frozenset(singular_key(c) for c in (
    "desk", "table", "dining table", "computer desk", "monitor", "tv", "computer", "piano", "keyboard piano",
    "laptop", "screen", "projector screen"))
WALLS = frozenset(singular_key(c) for c in ("wall", "walls"))


@dataclass(frozen=True)
class SectionConfig:
    """The section geometry (Sr3D's values: 10 degrees, 1 m, 1 m, 4 m) and the front prior's weights."""

    angle_deg: float = 10.0
    max_front_depth: float = 1.0
    max_side_depth: float = 1.0
    far_depth: float = 4.0
    back_to_wall: float = 2.5     # weight of "the back is at a wall / the room's edge"
    wall_scale: float = 0.4       # metres over which that evidence decays
    open_front: float = 1.0       # weight of "free space in front" (saturates at 1.5 m)
    shape: float = 1.5            # weight of the long-axis rule
    facing: float = 2.0           # weight of "faces its table / seat"
    facing_range: float = 1.5     # metres: partners farther than this (box distance) are ignored


@dataclass(frozen=True)
class FrontHypothesis:
    """A front direction (horizontal unit vector) with its prior weight (normalised) and why."""

    front: tuple[float, float]
    prior: float
    note: str


def _frame(lo: np.ndarray, hi: np.ndarray, front: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    u = np.array(front, dtype=float)
    u /= np.linalg.norm(u)
    w = np.array([u[1], -u[0]])  # the left of a viewer who faces the anchor's front
    c = (lo[:2] + hi[:2]) / 2.0
    ext = hi[:2] - lo[:2]
    hd = 0.5 * float(abs(u[0]) * ext[0] + abs(u[1]) * ext[1])
    hw = 0.5 * float(abs(w[0]) * ext[0] + abs(w[1]) * ext[1])
    return c, u, w, hd, hw


def section_polygon(lo: np.ndarray, hi: np.ndarray, front: tuple[float, float], side: Relation,
                    config: SectionConfig | None = None) -> np.ndarray:
    """The anchor's ``side`` section (FRONT, BACK, LEFT or RIGHT) as a convex polygon (world xy)."""
    cfg = config or SectionConfig()
    c, u, w, hd, hw = _frame(np.asarray(lo, float), np.asarray(hi, float), front)
    tan = math.tan(math.radians(cfg.angle_deg))
    if side in (Relation.FRONT, Relation.BACK):
        d1 = min(2.0 * (2.0 * hd), cfg.max_front_depth)
        spread = hw + tan * d1
        local = [(hd, -hw), (hd, hw), (hd + d1, spread), (hd + d1, -spread),
                 (hd + d1 + cfg.far_depth, -spread), (hd + d1 + cfg.far_depth, spread)]
        sign_s, sign_t, swap = (1.0 if side is Relation.FRONT else -1.0), 1.0, False
    elif side in (Relation.LEFT, Relation.RIGHT):
        d1 = min(2.0 * (2.0 * hw), cfg.max_side_depth)
        spread = hd + tan * d1
        local = [(hw, -hd), (hw, hd), (hw + d1, spread), (hw + d1, -spread),
                 (hw + d1 + cfg.far_depth, -spread), (hw + d1 + cfg.far_depth, spread)]
        sign_s, sign_t, swap = (1.0 if side is Relation.LEFT else -1.0), 1.0, True
    else:
        raise ValueError(f"not a view-dependent relation: {side}")
    pts = []
    for a, b in local:
        if swap:  # a runs along w (outwards), b along u
            pts.append(c + sign_s * a * w + sign_t * b * u)
        else:
            pts.append(c + sign_s * a * u + sign_t * b * w)
    return convex_hull(np.array(pts))


def section_occupancy(lo: np.ndarray, hi: np.ndarray, anchor_lo: np.ndarray, anchor_hi: np.ndarray,
                      front: tuple[float, float], side: Relation, config: SectionConfig | None = None) -> np.ndarray:
    """Fraction of each target footprint (rows of ``lo``/``hi``) inside the anchor's section."""
    poly = section_polygon(anchor_lo, anchor_hi, front, side, config)
    return np.array([occupancy(lo[i], hi[i], poly) for i in range(len(lo))])


def _clearance(table: NodeTable, scene_ix: np.ndarray, a: int, d: tuple[float, float],
               bounds: tuple[np.ndarray, np.ndarray], walls: np.ndarray) -> float:
    """Free distance from anchor a's face in direction d to the room's edge or the nearest wall box
    that faces it (overlapping it sideways)."""
    lo, hi = table.lo[a], table.hi[a]
    axis = 0 if d[0] != 0.0 else 1
    other = 1 - axis
    if d[axis] > 0:
        best = float(bounds[1][axis] - hi[axis])
    else:
        best = float(lo[axis] - bounds[0][axis])
    for j in walls.tolist():
        if j == a:
            continue
        wlo, whi = table.lo[j], table.hi[j]
        if min(whi[other], hi[other]) - max(wlo[other], lo[other]) <= 0.0:
            continue
        gap = float(wlo[axis] - hi[axis]) if d[axis] > 0 else float(lo[axis] - whi[axis])
        if gap >= -0.05 * float(hi[axis] - lo[axis]):
            best = min(best, max(gap, 0.0))
    return max(best, 0.0)


def _nearest_partner(table: NodeTable, scene_ix: np.ndarray, a: int, classes: frozenset[str],
                     max_distance: float) -> int | None:
    lo, hi = table.lo[a], table.hi[a]
    best, best_d = None, max_distance
    for j in scene_ix.tolist():
        if j == a or table.skeys[j] not in classes or not table.has_box[j]:
            continue
        gap = np.maximum(0.0, np.maximum(table.lo[j][:2] - hi[:2], lo[:2] - table.hi[j][:2]))
        dist = float(np.hypot(gap[0], gap[1]))
        if dist <= best_d:
            best, best_d = j, dist
    return best


def front_hypotheses(table: NodeTable, scene: Any, anchor: int,
                     config: SectionConfig | None = None) -> list[FrontHypothesis]:
    """The anchor's candidate front directions with their prior weights (summing to 1).

    A node ``front`` attribute is taken as known (one hypothesis, weight 1). Otherwise each axis
    direction f gets the log-weight ``back_to_wall * exp(-clearance(-f) / wall_scale) + open_front
    * min(clearance(f), 1.5) / 1.5 + shape * [f obeys the long-axis rule] + facing * cos(f, partner)``
    (see the module docstring)."""
    cfg = config or SectionConfig()
    if anchor in table.fronts:
        fx, fy = table.fronts[anchor]
        n = math.hypot(fx, fy)
        return [FrontHypothesis((fx / n, fy / n), 1.0, "front attribute")]
    scene_ix = table.load_scene(scene)
    ok = scene_ix[table.has_box[scene_ix]]
    bounds = (np.min(table.lo[ok], axis=0), np.max(table.hi[ok], axis=0)) if len(ok) else (table.lo[anchor], table.hi[anchor])
    walls = np.asarray([j for j in ok.tolist() if table.skeys[j] in WALLS], dtype=np.intp)
    lo, hi = table.lo[anchor], table.hi[anchor]
    ext = hi[:2] - lo[:2]
    kind = table.skeys[anchor]
    aspect = float(max(ext) / max(min(ext), 1e-6))
    long_axis = 0 if ext[0] >= ext[1] else 1
    partner = None
    if kind in SEATS:
        partner = _nearest_partner(table, ok, anchor, TABLES, cfg.facing_range)
    elif kind in SEAT_FACING:
        partner = _nearest_partner(table, ok, anchor, SEATS, cfg.facing_range)
    centre = (lo[:2] + hi[:2]) / 2.0
    to_partner = None
    if partner is not None:
        v = (table.lo[partner][:2] + table.hi[partner][:2]) / 2.0 - centre
        if float(np.hypot(*v)) > 1e-6:
            to_partner = v / float(np.hypot(*v))
    logits, notes = [], []
    for f in AXES:
        axis = 0 if f[0] != 0.0 else 1
        back = _clearance(table, scene_ix, anchor, (-f[0], -f[1]), bounds, walls)
        ahead = _clearance(table, scene_ix, anchor, f, bounds, walls)
        score = cfg.back_to_wall * math.exp(-back / cfg.wall_scale) + cfg.open_front * min(ahead, 1.5) / 1.5
        shape = 0.5
        if aspect >= 1.3:
            along = axis == long_axis
            shape = 1.0 if along == (kind in FRONT_ALONG_LONG_AXIS) else 0.0
        score += cfg.shape * shape
        face = 0.0
        if to_partner is not None:
            face = float(f[0] * to_partner[0] + f[1] * to_partner[1])
            score += cfg.facing * face
        logits.append(score)
        notes.append(f"back clearance {back:.2f} m, front clearance {ahead:.2f} m, shape {shape:.1f}, facing {face:+.2f}")
    z = np.exp(np.asarray(logits) - max(logits))
    z /= z.sum()
    return [FrontHypothesis(f, float(p), note) for f, p, note in zip(AXES, z, notes)]

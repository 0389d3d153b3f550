"""Sr3D-style referring utterances, with the true referent of each, from any scene of labelled boxes.

The generation rules follow the published definition of Sr3D (Achlioptas et al., ReferIt3D, ECCV
2020), written anew here over boxes:

* **horizontal** (closest / farthest): the anchor's class occurs once in the scene; the target's
  class 2 to 6 times; the nearest (farthest) target must beat the runner-up by ``gap`` (0.2 m)
  in box-to-box distance;
* **between**: two anchors of different, unique classes whose footprints do not overlap; the target
  has at least 51 % of its footprint in the convex hull of the anchors' footprints, at most 10 %
  over either anchor and a z-overlap of at least 20 % of its height with each; a same-class object
  with 10-51 % in the hull, or closer than 0.3 m to the target, makes the combination ambiguous;
* **support / vertical** (on, supporting, above, below): over every target-class x anchor-class
  pair with overlapping footprints, the first relation that holds of supported-by (footprint overlap
  > 30 % of the target, |target bottom - anchor top| <= 0.15 m, target footprint < 1.5 x anchor's),
  supporting (the same, reversed), above, below (vertical gap > 0.06 m, overlap > 20 % of either);
  a class pair is kept only when exactly one pair of objects is so related;
* **allocentric** (left, right, front, back): unique anchors with a front (tables, stools and the
  like excluded); the target must have > 90 % of its footprint in the anchor's section (computed
  with the anchor's *true* front), every other target-class object < 8 %, and no target-class
  object may overlap the anchor by more than 20 % of its footprint.

Utterances vary the lead verb, the copula (is/are by the class's number), the relation's wording,
the viewpoint frame and the supporting "with the Y on top" forms, as Sr3D's templates do.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from sgbelief.eval.refer_scenes import Room, SceneObject
from sgbelief.query.referring.allocentric import section_polygon
from sgbelief.query.referring.geometry import (
    convex_hull,
    effective_distance,
    footprint_overlap,
    occupancy,
    rect,
    z_overlap,
)
from sgbelief.query.referring.model import Relation

__all__ = ["Reference", "generate_references", "utterance_for"]

STRUCTURAL = frozenset({"wall", "floor", "ceiling"})
SMALL = frozenset({"cup", "book", "books", "bottle", "towel", "clothes", "clothing"})
NO_ALLOCENTRIC_ANCHOR = frozenset({"table", "coffee table", "dining table", "end table", "side table",
                                   "round table", "stool", "bathtub", "blanket"})
HAS_FRONT = frozenset({"bed", "desk", "office chair", "chair", "couch", "armchair", "sofa chair", "dresser",
                       "nightstand", "bookshelf", "file cabinet", "refrigerator", "tv", "monitor", "tv stand",
                       "kitchen cabinets", "wardrobe closet", "printer", "cabinet", "toilet", "sink"})
PLURAL_LABELS = frozenset({"kitchen cabinets", "cabinets", "doors", "books", "shoes", "curtains", "blinds",
                           "stairs", "clothes", "pipes", "shower walls", "closet doors", "mailboxes"})
SEATS = frozenset({"couch", "office chair", "chair", "armchair", "sofa chair"})


@dataclass(frozen=True)
class Reference:
    """One generated reference: the true target, the relation, the anchors and an utterance."""

    scene: str
    target: str
    relation: Relation
    anchors: tuple[str, ...]
    target_label: str
    anchor_labels: tuple[str, ...]
    utterance: str
    n_distractors: int

    @property
    def view_dependent(self) -> bool:
        return self.relation.view_dependent


def _box_distance(a: SceneObject, b: SceneObject) -> float:
    return float(max(effective_distance(a.lo_a[None], a.hi_a[None], b.lo_a, b.hi_a)[0], 0.0))


def _horizontal(room: Room, gap: float) -> list[tuple[str, Relation, tuple[str, ...]]]:
    counts = Counter(o.label for o in room.objects)
    out = []
    anchors = [o for o in room.objects if counts[o.label] == 1 and o.label not in STRUCTURAL | SMALL]
    groups = defaultdict(list)
    for o in room.objects:
        if 2 <= counts[o.label] <= 6 and o.label not in STRUCTURAL:
            groups[o.label].append(o)
    for a in anchors:
        for objs in groups.values():
            d = np.array([_box_distance(t, a) for t in objs])
            order = np.argsort(d, kind="stable")
            if d[order[0]] + gap < d[order[1]]:
                out.append((objs[order[0]].id, Relation.CLOSEST, (a.id,)))
            if d[order[-1]] - gap > d[order[-2]]:
                out.append((objs[order[-1]].id, Relation.FARTHEST, (a.id,)))
    return out


def _between(room: Room) -> list[tuple[str, Relation, tuple[str, ...]]]:
    counts = Counter(o.label for o in room.objects)
    anchors = [o for o in room.objects if counts[o.label] == 1 and o.label not in STRUCTURAL | SMALL]
    groups = defaultdict(list)
    for o in room.objects:
        if counts[o.label] <= 6 and o.label not in STRUCTURAL:
            groups[o.label].append(o)
    out = []
    for a, b in combinations(anchors, 2):
        if a.label == b.label or footprint_overlap(a.lo_a, a.hi_a, b.lo_a, b.hi_a) > 0.0:
            continue
        hull = convex_hull(np.vstack([rect(a.lo, a.hi), rect(b.lo, b.hi)]))
        for label, objs in groups.items():
            if label in (a.label, b.label):
                continue
            hits, bad = [], False
            for t in objs:
                occ = occupancy(t.lo, t.hi, hull)
                if occ < 0.51:
                    bad |= 0.1 < occ
                    continue
                area = max((t.hi[0] - t.lo[0]) * (t.hi[1] - t.lo[1]), 1e-12)
                over = max(footprint_overlap(t.lo_a, t.hi_a, a.lo_a, a.hi_a), footprint_overlap(t.lo_a, t.hi_a, b.lo_a, b.hi_a))
                height = max(t.hi[2] - t.lo[2], 1e-6)
                za = z_overlap(t.lo_a, t.hi_a, a.lo_a, a.hi_a) / height
                zb = z_overlap(t.lo_a, t.hi_a, b.lo_a, b.hi_a) / height
                if over / area > 0.1 or za < 0.2 or zb < 0.2:
                    bad = True
                    continue
                if any(u is not t and _box_distance(u, t) < 0.3 for u in objs):
                    bad = True
                    continue
                hits.append(t)
            if not bad and len(hits) == 1:
                out.append((hits[0].id, Relation.BETWEEN, (a.id, b.id)))
    return out


def _vertical(room: Room) -> list[tuple[str, Relation, tuple[str, ...]]]:
    counts = Counter(o.label for o in room.objects)
    objs = [o for o in room.objects if o.label not in STRUCTURAL]
    found: dict[tuple[str, str], list[tuple[str, Relation, tuple[str, ...]]]] = defaultdict(list)
    for a in objs:
        if a.label in ("cup", "keyboard"):
            continue
        for t in objs:
            if t.label == a.label or counts[t.label] > 6:
                continue
            inter = float(footprint_overlap(t.lo_a, t.hi_a, a.lo_a, a.hi_a))
            if inter <= 0.0:
                continue
            at = (t.hi[0] - t.lo[0]) * (t.hi[1] - t.lo[1])
            aa = (a.hi[0] - a.lo[0]) * (a.hi[1] - a.lo[1])
            it, ia = inter / at, inter / aa
            up, down = t.lo[2] - a.hi[2], a.lo[2] - t.hi[2]
            if it > 0.3 and abs(up) <= 0.15 and at / aa < 1.5:
                rel = Relation.ON
            elif ia > 0.3 and abs(down) <= 0.15 and aa / at < 1.5:
                rel = Relation.SUPPORTING
            elif up > 0.06 and max(it, ia) > 0.2:
                rel = Relation.ABOVE
            elif down > 0.06 and max(it, ia) > 0.2:
                rel = Relation.BELOW
            else:
                continue
            found[(t.label, a.label)].append((t.id, rel, (a.id,)))
    return [refs[0] for refs in found.values() if len(refs) == 1]


def _allocentric(room: Room) -> list[tuple[str, Relation, tuple[str, ...]]]:
    counts = Counter(o.label for o in room.objects)
    anchors = [o for o in room.objects if counts[o.label] == 1 and o.front is not None and o.label in HAS_FRONT
               and o.label not in NO_ALLOCENTRIC_ANCHOR]
    groups = defaultdict(list)
    for o in room.objects:
        if counts[o.label] <= 6 and o.label not in STRUCTURAL:
            groups[o.label].append(o)
    out = []
    for a in anchors:
        assert a.front is not None
        for label, objs in groups.items():
            if label == a.label:
                continue
            if any(float(footprint_overlap(t.lo_a, t.hi_a, a.lo_a, a.hi_a))
                   / max((t.hi[0] - t.lo[0]) * (t.hi[1] - t.lo[1]), 1e-12) > 0.2 for t in objs):
                continue
            for side in (Relation.FRONT, Relation.RIGHT, Relation.BACK, Relation.LEFT):
                poly = section_polygon(a.lo_a, a.hi_a, a.front, side)
                occ = [occupancy(t.lo, t.hi, poly) for t in objs]
                inside = [t for t, o in zip(objs, occ) if o > 0.9]
                if len(inside) == 1 and sum(o < 0.08 for o in occ) == len(objs) - 1:
                    out.append((inside[0].id, side, (a.id,)))
    return out


_VERBS = ("", "find ", "choose ", "select ")
_WORDS = {
    Relation.ON: ("on top of", "on", "lying on"), Relation.SUPPORTING: ("supporting",),
    Relation.ABOVE: ("above", "over"), Relation.BELOW: ("below", "under", "beneath", "underneath"),
    Relation.FARTHEST: ("farthest from", "far from", "far away from"),
    Relation.CLOSEST: ("closer to", "close to", "near"), Relation.FRONT: ("in front of",),
    Relation.RIGHT: ("on the right of", "to the right of", "on the right side of"),
    Relation.BACK: ("on the back of", "behind"),
    Relation.LEFT: ("on the left of", "to the left of", "on the left side of"),
}


def utterance_for(rel: Relation, target: str, anchors: tuple[str, ...], rng: np.random.Generator,
                  next_to: bool = False) -> str:
    """One Sr3D-style utterance for a reference (template and wording drawn with ``rng``)."""
    def pick(xs: tuple[str, ...]) -> str:
        return xs[int(rng.integers(len(xs)))]

    verb = "are" if target in PLURAL_LABELS else "is"
    a0 = anchors[0]
    pron = "them" if a0 in PLURAL_LABELS else "it"
    if rel is Relation.BETWEEN:
        phrase = pick(("between", "in the middle of", "in the center of"))
        return f"{pick(_VERBS)}the {target} that {verb} {phrase} the {a0} and the {anchors[1]}"
    if rel is Relation.SUPPORTING and rng.random() < 0.5:
        tpron = "them" if target in PLURAL_LABELS else "it"
        tposs = "their" if target in PLURAL_LABELS else "its"
        art = pick(("%anchor_article% ", "the ", "a "))
        tail = pick((f"on top of {tpron}", f"on {tposs} top", "on top"))
        return f"{pick(_VERBS)}the {target} with {art}{a0} {tail}"
    if rel is Relation.CLOSEST and next_to:
        return f"{pick(_VERBS)}the {target} that {verb} {pick(('next to', 'beside'))} the {a0}"
    words = pick(_WORDS[rel])
    if rel.view_dependent and rel is not Relation.FRONT and rng.random() < 0.8:
        if a0 in SEATS and rng.random() < 0.3:
            demo = "these" if a0 in PLURAL_LABELS else "this"
            look = pick(("facing", "looking"))
            return f"{look} the {a0} from the side you sit on {pron}, choose the {target} that {verb} {words} {demo} {a0}"
        frame = pick(("looking at the front of", "facing the front of"))
        lead = pick(("choose ", "select ", "pick "))
        end = f"the {a0}" if lead == "pick " else pron
        return f"{frame} the {a0}, {lead}the {target} that {verb} {words} {end}"
    if rel.view_dependent:
        return f"{pick(('choose ', 'select ', 'find '))}the {target} that {verb} {words} the {a0}"
    return f"{pick(_VERBS)}the {target} that {verb} {words} the {a0}"


def generate_references(rooms: Iterable[Room], seed: int = 0, gap: float = 0.2) -> list[Reference]:
    """Every Sr3D-style reference the rooms admit, one utterance each (drawn with ``seed``)."""
    rng = np.random.default_rng(seed)
    out: list[Reference] = []
    for room in rooms:
        objs = room.by_id()
        counts = Counter(o.label for o in room.objects)
        rels = _horizontal(room, gap) + _between(room) + _vertical(room) + _allocentric(room)
        for target, rel, anchors in rels:
            t = objs[target]
            alabels = tuple(objs[a].label for a in anchors)
            near = rel is Relation.CLOSEST and _box_distance(t, objs[anchors[0]]) < 0.3 and rng.random() < 0.5
            utt = utterance_for(rel, t.label, alabels, rng, next_to=near)
            out.append(Reference(room.scene, target, rel, anchors, t.label, alabels, utt, counts[t.label] - 1))
    return out

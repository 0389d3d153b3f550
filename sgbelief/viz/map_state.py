"""What a picture of a belief map shows, independent of the drawing library.

For every object: its footprint (an axis-aligned box, else a point), its *committed label*, the
predicate with the highest posterior mean among those strictly above tau (the commit rule
P > tau used everywhere in sgbelief), and that probability. An object with evidence but no
predicate above tau is *uncommitted*; one that no claim has touched has *no evidence*.

For every refused claim (a ⊥ verdict: an entry of the refusal family in the provenance, still
pending in Q⊥ or closed since as resolved / expired / dismissed): its pair, its time and the
object's position at that time (the object's track when it moves, else its centroid). What
compaction folded away is no longer in the provenance and is not shown; :func:`folded_history`
says how much that is.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.viz.style import REFUSED_STATUSES

Point = tuple[float, float, float]
Box = tuple[Point, Point]
TrackPoint = tuple[int, float, float, float]


@dataclass(frozen=True)
class ObjectView:
    """One object as a picture shows it."""

    node: Any
    box: Box | None  #: ((xmin, ymin, zmin), (xmax, ymax, zmax)) in metres, when known
    centroid: Point | None
    track: tuple[TrackPoint, ...]  #: (t, x, y, z) over time, for objects that move
    label: str | None  #: the committed predicate (highest P among P > tau), None when nothing commits
    probability: float  #: P(label); for an uncommitted object the highest P of any predicate (0 without evidence)
    committed: tuple[str, ...]  #: every predicate with P > tau, most probable first
    has_evidence: bool

    @property
    def position(self) -> Point | None:
        """The centroid, else the box centre, else None."""
        if self.centroid is not None:
            return self.centroid
        if self.box is not None:
            lo, hi = self.box
            return (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2]))
        return None

    @property
    def located(self) -> bool:
        return self.box is not None or self.centroid is not None

    def position_at(self, t: int) -> Point | None:
        """Where the object was at time ``t``: its track, linearly interpolated (held at the ends),
        else its position."""
        if not self.track:
            return self.position
        times = [p[0] for p in self.track]
        i = bisect_right(times, t)
        if i == 0:
            return self.track[0][1:]
        if i == len(self.track):
            return self.track[-1][1:]
        (t0, *a), (t1, *b) = self.track[i - 1], self.track[i]
        w = (t - t0) / (t1 - t0) if t1 != t0 else 0.0
        return (a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2]))


@dataclass(frozen=True)
class RefusedClaim:
    """One refused (⊥) claim that the provenance still holds."""

    node: Any
    predicate: str
    event_id: str | None
    t: int
    status: str  #: refused (pending in Q⊥), resolved, expired or dismissed
    position: Point | None  #: the object's position at ``t``


@dataclass(frozen=True)
class RefusedSite:
    """The refused claims made about one object, for a map marker."""

    node: Any
    position: Point  #: mean position of its refused claims
    claims: int
    predicates: tuple[str, ...]  #: the refused predicates, most refused first
    first_t: int
    last_t: int


@dataclass(frozen=True)
class MapState:
    """Everything a top-down picture or a rerun frame shows of one map."""

    objects: tuple[ObjectView, ...]
    refused: tuple[RefusedClaim, ...]
    tau: float
    predicates: tuple[str, ...]  #: the predicates whose colours the legend assigns (sorted)
    folded: int = 0  #: entries of these objects that compaction folded into buckets (their refusals are gone)
    folded_until: int | None = None  #: the latest time such a bucket covers

    @property
    def located(self) -> list[ObjectView]:
        return [o for o in self.objects if o.located]

    @property
    def unlocated(self) -> list[ObjectView]:
        return [o for o in self.objects if not o.located]

    def sites(self) -> list[RefusedSite]:
        return refused_sites(self.refused)


# ------------------------------------------------------------------------------ reading
def committed_predicates(graph: SceneGraphModel, node: Any, tau: float = 0.5) -> list[tuple[str, float]]:
    """(predicate, P) for every predicate with P > tau at ``node``, most probable first
    (ties: predicate name)."""
    probs = [(pred, bel.mean) for pred, bel in graph.beliefs(node).items() if bel.mean > tau]
    probs.sort(key=lambda pp: (-pp[1], pp[0]))
    return probs


def _point(value: Any) -> Point | None:
    try:
        pt = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        return None
    return pt if len(pt) == 3 and all(math.isfinite(x) for x in pt) else None  # type: ignore[return-value]


def _box(value: Any) -> Box | None:
    try:
        lo, hi = value
    except (TypeError, ValueError):
        return None
    a, b = _point(lo), _point(hi)
    if a is None or b is None or any(x > y for x, y in zip(a, b)):
        return None
    return a, b


def _track(value: Any) -> tuple[TrackPoint, ...]:
    if not isinstance(value, Sequence) or isinstance(value, str):
        return ()
    out: list[TrackPoint] = []
    for row in value:
        try:
            t, x, y, z = row
            out.append((int(t), float(x), float(y), float(z)))
        except (TypeError, ValueError):
            return ()
    out.sort(key=lambda p: p[0])
    # a track whose position never changes is a parked object: nothing to interpolate
    return tuple(out) if len({p[1:] for p in out}) > 1 else ()


def object_view(graph: SceneGraphModel, node: Any, tau: float = 0.5, *, box: Box | None = None) -> ObjectView:
    """One object: geometry from its attributes (``bbox``, ``centroid``, ``track``) or ``box``
    (which wins), labels from its beliefs. Malformed geometry attributes count as absent."""
    attrs = graph.find_node(node) or {}
    beliefs = graph.beliefs(node)
    committed = committed_predicates(graph, node, tau)
    if committed:
        label, p = committed[0]
    else:
        label, p = None, max((b.mean for b in beliefs.values()), default=0.0)
    the_box = box if box is not None else _box(attrs.get("bbox"))
    centroid = _point(attrs.get("centroid"))
    if box is not None:
        lo, hi = box
        centroid = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2]))
    return ObjectView(node, the_box, centroid, _track(attrs.get("track")), label, float(p),
                      tuple(pred for pred, _ in committed), bool(beliefs))


def refused_claims(graph: SceneGraphModel, objects: Mapping[Any, ObjectView] | None = None) -> list[RefusedClaim]:
    """Every refused (⊥) claim the provenance holds, in time order (ties: log order)."""
    views = objects or {}
    out = []
    for e in graph.provenance.iter_entries():
        if not e.alive or e.status.value not in REFUSED_STATUSES:
            continue
        view = views.get(e.node)
        pos = view.position_at(e.t) if view is not None else None
        out.append(RefusedClaim(e.node, e.predicate, e.event_id, int(e.t), e.status.value, pos))
    out.sort(key=lambda c: c.t)
    return out


def refused_sites(claims: Iterable[RefusedClaim]) -> list[RefusedSite]:
    """The located refused claims grouped by object, most refused first (ties: earliest)."""
    groups: dict[Any, list[RefusedClaim]] = {}
    for c in claims:
        if c.position is not None:
            groups.setdefault(c.node, []).append(c)
    sites = []
    for node, cs in groups.items():
        n = len(cs)
        pos = tuple(sum(c.position[k] for c in cs) / n for k in range(3))  # type: ignore[index]
        counts: dict[str, int] = {}
        for c in cs:
            counts[c.predicate] = counts.get(c.predicate, 0) + 1
        preds = tuple(sorted(counts, key=lambda p: (-counts[p], p)))
        sites.append(RefusedSite(node, pos, n, preds, min(c.t for c in cs), max(c.t for c in cs)))  # type: ignore[arg-type]
    sites.sort(key=lambda s: (-s.claims, s.first_t))
    return sites


def scene_of(graph: SceneGraphModel, node: Any) -> str | None:
    """A node's scene: its ``scene`` attribute, else the part of a string id before its first ``/``
    (``d04/0056``, ``scene0000_00/3``), else None. Scenes have their own frames: a picture shows one."""
    scene = (graph.find_node(node) or {}).get("scene")
    if scene is not None:
        return str(scene)
    return node.split("/", 1)[0] if isinstance(node, str) and "/" in node else None


def nodes_by_scene(graph: SceneGraphModel) -> dict[str | None, list[Any]]:
    """scene -> its nodes (in graph order); nodes without a scene under None."""
    out: dict[str | None, list[Any]] = {}
    for n in graph.nodes():
        out.setdefault(scene_of(graph, n), []).append(n)
    return out


def folded_history(graph: SceneGraphModel, nodes: Iterable[Any] | None = None) -> tuple[int, int | None]:
    """(entries folded into compacted buckets, the latest time a bucket covers) at ``nodes``
    (default: every node): how much history a picture of the map can no longer show."""
    wanted = None if nodes is None else set(nodes)
    folded, until = 0, None
    for e in graph.provenance.iter_entries():
        if e.alive and e.status.value == "compacted" and (wanted is None or e.node in wanted):
            folded += max(1, int(e.n_folded or 1))
            until = e.t if until is None else max(until, e.t)
    return folded, until


def map_state(graph: SceneGraphModel, tau: float = 0.5, *, boxes: Mapping[Any, Box] | None = None,
              nodes: Iterable[Any] | None = None) -> MapState:
    """The picture's content for ``graph`` (every node, or ``nodes``); ``boxes`` (node -> box, e.g.
    from the ScanNet loader) replace the attributes' geometry where given."""
    boxes = boxes or {}
    chosen = list(graph.nodes() if nodes is None else nodes)
    objects = tuple(object_view(graph, n, tau, box=boxes.get(n)) for n in chosen)
    by_node = {o.node: o for o in objects}
    refused = [c for c in refused_claims(graph, by_node) if c.node in by_node]
    preds = sorted(graph.vocabulary) if graph.vocabulary else graph.predicates()
    folded, until = folded_history(graph, by_node)
    return MapState(objects, tuple(refused), tau, tuple(sorted(preds)), folded, until)

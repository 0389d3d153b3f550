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
"""

from __future__ import annotations

import math
from itertools import chain, repeat
from operator import is_
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from sgbelief.errors import ConfigError, UnknownPredicateError

__all__ = [
    "RelationConfig",
    "GeoPredicate",
    "RelationRegistry",
    "GeometryContext",
    "Box",
    "DEFAULT_REGISTRY",
    "relation",
    "register_relation",
    "materialise_relations",
    "box_distance",
]

PredicateFn = Callable[["GeometryContext", Any], "bool | None"]


# --------------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RelationConfig:
    """Thresholds of the built-in geometric predicates (lengths in metres).

    near_distance: ``is_near_<class>`` / ``near`` edges hold when the box-to-box distance
        (0 when the boxes touch or overlap) is <= this.
    workspace_band: ``is_workspace_height`` holds when the top surface (bbox zmax) lies this many
        metres above the floor, inclusive (desks ~0.72-0.76 m, counters ~0.9 m).
    on_tolerance: ``on``: the upper box's bottom lies within +-this of the lower box's top.
    on_min_overlap: ``on``: the fraction of the upper box's footprint (xy area) that overlaps
        the lower box's footprint must be >= this.
    access_depth: ``is_accessible``: depth of the free-floor slab checked in front of the node.
    access_z: ``is_accessible``: the slab spans these heights above the floor (ignores carpets
        and things hanging from the ceiling).
    min_overlap: an obstacle blocks the slab only if it penetrates it by more than this along
        every axis (boxes that merely touch do not block).
    facing_distance: ``is_facing_seating``: a seat counts when its box is within this distance.
    facing_half_angle_deg: ... and the horizontal direction to its centre is within this angle of
        a front direction.
    seating_class: the class name whose members are seats (see ``class_aliases``).
    structural_labels: labels that are never obstacles nor supporting / resting objects.
    stationary_max_displacement: ``is_stationary``: every track centroid lies within this
        distance of the track's median centroid (tracks need >= ``stationary_min_track``
        entries); without a track, ``speed <= stationary_max_speed`` (m/s) or ``stationary``.
    near_road_px: ``is_near_road_px``: ``road_distance_px`` (pixels) <= this.
    intersection_radius: ``is_at_intersection`` from ``intersection_distance`` (m) when the
        boolean ``at_intersection`` is absent.
    class_aliases: class name -> labels that count as that class (e.g. pedestrian -> person).
    use_committed_labels: a node also counts as class ``c`` when its belief on ``is_<c>`` is
        committed (probability > ``commit_tau``) -- the paper's "committed or ground-truth label".
    extra: free-form thresholds for user predicates.
    """

    near_distance: float = 1.0
    workspace_band: tuple[float, float] = (0.6, 1.1)
    on_tolerance: float = 0.05
    on_min_overlap: float = 0.3
    access_depth: float = 0.6
    access_z: tuple[float, float] = (0.1, 1.5)
    min_overlap: float = 0.02
    facing_distance: float = 3.0
    facing_half_angle_deg: float = 60.0
    seating_class: str = "seating"
    structural_labels: tuple[str, ...] = ("wall", "floor", "ceiling")
    stationary_max_displacement: float = 1.0
    stationary_min_track: int = 2
    stationary_max_speed: float = 0.3
    near_road_px: float = 50.0
    intersection_radius: float = 15.0
    class_aliases: Mapping[str, tuple[str, ...]] = field(
        default_factory=lambda: {
            "pedestrian": ("person", "pedestrian"),
            "car": ("car",),
            "seating": ("chair", "sofa", "couch", "bench", "stool", "armchair", "seat"),
            "table_or_desk": ("table", "desk"),
        }
    )
    use_committed_labels: bool = True
    commit_tau: float = 0.5
    extra: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any] | None, *, base: RelationConfig | None = None) -> RelationConfig:
        """Build from a plain mapping (e.g. a YAML ``relations:`` section); unknown keys raise."""
        base = base or cls()
        if not data:
            return base
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ConfigError(f"relations: unknown key(s) {unknown}; known: {sorted(names)}")
        kw: dict[str, Any] = {}
        for key, value in data.items():
            if key in ("workspace_band", "access_z"):
                if not (isinstance(value, (list, tuple)) and len(value) == 2):
                    raise ConfigError(f"relations.{key}: expected [low, high], got {value!r}")
                value = (float(value[0]), float(value[1]))
            elif key == "structural_labels":
                value = tuple(str(v) for v in value)
            elif key == "class_aliases":
                merged = dict(base.class_aliases)
                merged.update({str(k): tuple(str(x) for x in v) for k, v in dict(value).items()})
                value = merged
            elif key == "extra":
                value = {**base.extra, **dict(value)}
            elif key in ("use_committed_labels",):
                value = bool(value)
            elif key in ("seating_class",):
                value = str(value)
            elif key == "stationary_min_track":
                value = int(value)
            else:
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise ConfigError(f"relations.{key}: expected a number, got {value!r}") from None
            kw[key] = value
        return replace(base, **kw)

    def labels_of(self, cls_name: str) -> frozenset[str]:
        """Labels counting as class ``cls_name`` (itself plus its aliases)."""
        return frozenset((cls_name, *self.class_aliases.get(cls_name, ())))


# --------------------------------------------------------------------------------------------
# boxes
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Box:
    """Axis-aligned box ``lo`` .. ``hi`` (numpy arrays of 3 floats)."""

    lo: np.ndarray
    hi: np.ndarray

    @property
    def center(self) -> np.ndarray:
        return (self.lo + self.hi) / 2.0

    @property
    def size(self) -> np.ndarray:
        return self.hi - self.lo

    @property
    def volume(self) -> float:
        return float(np.prod(self.size))

    @property
    def footprint(self) -> float:
        s = self.size
        return float(s[0] * s[1])


def box_distance(a: Box, b: Box) -> float:
    """Euclidean distance between two axis-aligned boxes (0 when they touch or overlap)."""
    gap = np.maximum(0.0, np.maximum(a.lo - b.hi, b.lo - a.hi))
    return float(math.sqrt(float(gap @ gap)))


def _attr_getter(graph: Any) -> Callable[[Any], dict[str, Any]]:
    """``graph.node_attrs``; for a SceneGraph that does not override it, a direct read of
    networkx's node dict (the same dict; an unknown node still gets the graph's own error)."""
    from sgbelief.graph.scene_graph import SceneGraph

    if not (isinstance(graph, SceneGraph) and type(graph).node_attrs is SceneGraph.node_attrs):
        return graph.node_attrs  # type: ignore[no-any-return]
    node_dict = graph.nx._node

    def attrs_of(node: Any) -> dict[str, Any]:
        try:
            return node_dict[node]  # type: ignore[no-any-return]
        except (KeyError, TypeError):
            return graph.node_attrs(node)  # type: ignore[no-any-return]

    return attrs_of


def _fill_boxes(lo: np.ndarray, hi: np.ndarray, rows: list[int] | None, values: list[Any], pair: bool) -> None:
    """``lo[i], hi[i] = v[0], v[1]`` (``pair``: a bbox) or ``lo[i] = hi[i] = v`` (a centroid) for
    each row i and its value v (``rows`` None: every row): one array conversion when every value
    has the usual shape, else row by row (numpy's own broadcasting and errors)."""
    if not values:
        return
    rows_ix: Any = slice(None) if rows is None else rows
    arr = None
    try:  # every value 2 x 3 (a bbox) or 3 (a centroid): one pass over the numbers
        if pair and set(map(len, values)) == {2}:
            if set(map(len, chain.from_iterable(values))) == {3}:
                arr = np.fromiter(chain.from_iterable(chain.from_iterable(values)), dtype=float,
                                  count=6 * len(values)).reshape(-1, 2, 3)
        elif not pair and set(map(len, values)) == {3}:
            arr = np.fromiter(chain.from_iterable(values), dtype=float, count=3 * len(values)).reshape(-1, 3)
    except (ValueError, TypeError):
        arr = None
    if arr is not None:
        lo[rows_ix] = arr[:, 0] if pair else arr
        hi[rows_ix] = arr[:, 1] if pair else arr
        return
    for i, v in zip(range(len(values)) if rows is None else rows, values):
        if pair:
            lo[i] = v[0]
            hi[i] = v[1]
        else:
            lo[i] = hi[i] = v


# --------------------------------------------------------------------------------------------
# evaluation context: cached arrays + per-scene spatial indexes over one graph
# --------------------------------------------------------------------------------------------
class GeometryContext:
    """Read-only geometric view of a graph, built lazily and cached for one evaluation batch.

    Holds node boxes as arrays, scene groups, per-class KD-trees (scipy) and derived relations
    (``on`` pairs). Create one per batch; it does not notice later graph edits.
    """

    def __init__(self, graph: Any, config: RelationConfig | None = None) -> None:
        self.graph = graph
        self.config = config or RelationConfig()
        self._built = False
        self._class_cache: dict[str, np.ndarray] = {}
        self._tree_cache: dict[str, dict[Any, tuple[Any, np.ndarray, float]]] = {}
        self._on_pairs: list[tuple[int, int]] | None = None
        self._supports: dict[int, list[int]] | None = None  # upper -> lowers
        self._loads: dict[int, list[int]] | None = None  # lower -> uppers
        #: (class, distance) -> (per node: has a neighbour of the class, scenes computed so far)
        self._near_cache: dict[tuple[str, float], tuple[np.ndarray, set[Any]]] = {}
        self._attrs_of: Callable[[Any], dict[str, Any]] = _attr_getter(graph)

    # -- arrays --------------------------------------------------------------------------------
    def _build(self) -> None:
        if self._built:
            return
        g = self.graph
        nodes = list(g.nodes())
        n = len(nodes)
        get_attrs = self._attrs_of
        attrs = list(map(get_attrs, nodes))
        lo = np.full((n, 3), np.nan)
        hi = np.full((n, 3), np.nan)
        bboxes = [a.get("bbox") for a in attrs]
        if not any(map(is_, bboxes, repeat(None))):  # (not ``None in``: that compares with ==)
            _fill_boxes(lo, hi, None, bboxes, True)
        else:
            _fill_boxes(lo, hi, [i for i, b in enumerate(bboxes) if b is not None],
                        [b for b in bboxes if b is not None], True)
            cents = [(i, c) for i, (a, b) in enumerate(zip(attrs, bboxes))
                     if b is None and (c := a.get("centroid")) is not None]
            _fill_boxes(lo, hi, [i for i, _ in cents], [c for _, c in cents], False)
        labels: list[str | None] = [None if (lab := a.get("label")) is None else str(lab) for a in attrs]
        scenes: list[Any] = [a.get("scene") for a in attrs]
        floor_attr = np.array([np.nan if (z := a.get("floor_z")) is None else float(z) for a in attrs], dtype=float)
        self.nodes = nodes
        self.index = dict(zip(nodes, range(n)))
        self.lo, self.hi = lo, hi
        self.has_box = ~np.isnan(lo).any(axis=1)
        self.labels = labels
        self.scenes = scenes
        structural = set(self.config.structural_labels)
        kinds = {lab: (lab in structural, lab == "floor") for lab in dict.fromkeys(labels)}
        self.structural = np.fromiter((kinds[lab][0] for lab in labels), dtype=bool, count=n)
        is_floor = np.fromiter((kinds[lab][1] for lab in labels), dtype=bool, count=n)
        # scene -> its node indices (ascending), scenes in order of first appearance
        code_of = {s: c for c, s in enumerate(dict.fromkeys(scenes))}
        scene_code = np.fromiter(map(code_of.__getitem__, scenes), dtype=np.intp, count=n)
        order = np.argsort(scene_code, kind="stable")
        bounds = np.cumsum(np.bincount(scene_code, minlength=len(code_of)))[:-1]
        self.groups = dict(zip(code_of, np.split(order, bounds))) if n else {}
        # floor height per scene: 'floor' objects' top, else the lowest box bottom
        floor_z = np.array(floor_attr)
        for ix in self.groups.values():
            ok = ix[self.has_box[ix]]
            if ok.size == 0:
                continue
            floors = ok[is_floor[ok]]
            fz = float(np.median(hi[floors, 2])) if floors.size else float(np.min(lo[ok, 2]))
            missing = ix[np.isnan(floor_z[ix])]
            floor_z[missing] = fz
        self.floor_z = floor_z
        self._built = True

    def idx(self, node: Any) -> int:
        self._build()
        return self.index[node]

    def attrs(self, node: Any) -> dict[str, Any]:
        return self._attrs_of(node)

    def attr(self, node: Any, key: str) -> Any:
        """A node attribute: top level first, then inside its ``attributes`` dict (nodes.json)."""
        a = self._attrs_of(node)
        v = a.get(key)
        if v is None:
            inner = a.get("attributes")
            if isinstance(inner, Mapping):
                v = inner.get(key)
        return v

    def box(self, node: Any) -> Box | None:
        """The node's box (degenerate at the centroid when only a centroid is known), or None."""
        i = self.idx(node)
        if not self.has_box[i]:
            return None
        return Box(self.lo[i], self.hi[i])

    def floor(self, node: Any) -> float | None:
        """Floor height under the node: attr ``floor_z``, else its scene's floor estimate."""
        v = self.floor_z[self.idx(node)]
        return None if np.isnan(v) else float(v)

    # -- classes -------------------------------------------------------------------------------
    def class_mask(self, cls_name: str) -> np.ndarray:
        """Boolean mask of nodes of class ``cls_name``: label in its aliases, or (if enabled)
        committed belief on ``is_<cls_name>`` (or ``is_<alias>``)."""
        self._build()
        mask = self._class_cache.get(cls_name)
        if mask is not None:
            return mask
        wanted = self.config.labels_of(cls_name)
        mask = np.array([lab in wanted for lab in self.labels], dtype=bool)
        if self.config.use_committed_labels:
            try:
                known = set(self.graph.predicates())
            except Exception:  # pragma: no cover - graphs without predicates()
                known = set()
            preds = [f"is_{c}" for c in sorted(wanted) if f"is_{c}" in known]
            for p in preds:
                committed = self._committed(p)
                if committed is not None:
                    mask |= committed
                    continue
                for i, node in enumerate(self.nodes):
                    if not mask[i] and self.graph.probability(node, p) > self.config.commit_tau:
                        mask[i] = True
        self._class_cache[cls_name] = mask
        return mask

    def _committed(self, predicate: str) -> np.ndarray | None:
        """``graph.probability(v, predicate) > commit_tau`` for every node, from the belief table
        of a SceneGraph whose ``probability`` is the belief mean (nodes without evidence sit at the
        prior mean). None for other graphs: the caller asks node by node."""
        from sgbelief.graph.scene_graph import SceneGraph

        g = self.graph
        if not (isinstance(g, SceneGraph) and type(g).probability is SceneGraph.probability):
            return None
        self._build()
        if self.nodes:
            g.check_predicate(predicate)  # what probability() raises for a predicate outside the vocabulary
        tau = self.config.commit_tau
        prov = g.provenance
        out = np.full(len(self.nodes), prov.prior_alpha / (prov.prior_alpha + prov.prior_beta) > tau, dtype=bool)
        index_of = self.index.get
        rows: list[int] = []
        values: list[bool] = []
        for node, p in prov.means_with(predicate):
            i = index_of(node)
            if i is not None:
                rows.append(i)
                values.append(p > tau)
        if rows:
            out[rows] = values
        return out

    def _class_trees(self, cls_name: str) -> dict[Any, tuple[Any, np.ndarray, float]]:
        trees = self._tree_cache.get(cls_name)
        if trees is not None:
            return trees
        from scipy.spatial import cKDTree

        mask = self.class_mask(cls_name) & self.has_box
        trees = {}
        for s, ix in self.groups.items():
            members = ix[mask[ix]]
            if members.size == 0:
                continue
            centers = (self.lo[members] + self.hi[members]) / 2.0
            radius = float(np.max(np.linalg.norm(self.hi[members] - self.lo[members], axis=1)) / 2.0)
            trees[s] = (cKDTree(centers), members, radius)
        self._tree_cache[cls_name] = trees
        return trees

    def neighbours_of_class(self, node: Any, cls_name: str, distance: float) -> list[tuple[Any, float]]:
        """Other nodes of ``cls_name`` in the node's scene with box distance <= ``distance``."""
        i = self.idx(node)
        if not self.has_box[i]:
            return []
        entry = self._class_trees(cls_name).get(self.scenes[i])
        if entry is None:
            return []
        tree, members, radius = entry
        lo, hi = self.lo[i], self.hi[i]
        own = float(np.linalg.norm(hi - lo)) / 2.0
        cand = tree.query_ball_point((lo + hi) / 2.0, distance + own + radius + 1e-9)
        out: list[tuple[Any, float]] = []
        if not cand:
            return out
        js = members[np.asarray(cand, dtype=int)]
        js = js[js != i]
        gap = np.maximum(0.0, np.maximum(self.lo[js] - hi, lo - self.hi[js]))
        d = np.sqrt((gap * gap).sum(axis=1))
        for j, dj in zip(js, d):
            if dj <= distance:
                out.append((self.nodes[int(j)], float(dj)))
        return out

    def has_neighbour_of_class(self, node: Any, cls_name: str, distance: float) -> bool:
        """``bool(neighbours_of_class(node, cls_name, distance))``, computed for the node's whole
        scene at its first query (one KD-tree ball query over the scene's boxes, the same box
        distance test) and cached."""
        i = self.idx(node)
        if not self.has_box[i]:
            return False
        key = (cls_name, distance)
        cached = self._near_cache.get(key)
        if cached is None:
            cached = self._near_cache[key] = (np.zeros(len(self.nodes), dtype=bool), set())
        near, done = cached
        scene = self.scenes[i]
        if scene not in done:
            self._near_scene(scene, cls_name, distance, near)
            done.add(scene)
        return bool(near[i])

    def _near_scene(self, scene: Any, cls_name: str, distance: float, near: np.ndarray) -> None:
        """near[i] for every boxed node i of the scene, as :meth:`neighbours_of_class` decides it:
        candidates from a ball around the box centre of radius distance + own half-diagonal +
        the class's largest half-diagonal (+1e-9), then the exact box-to-box distance <= distance."""
        entry = self._class_trees(cls_name).get(scene)
        if entry is None:
            return
        tree, members, radius = entry
        ix = self.groups[scene]
        q = ix[self.has_box[ix]]
        if q.size == 0:
            return
        lo_q, hi_q = self.lo[q], self.hi[q]
        # (rounding in the radius cannot change the answer: a box within ``distance`` lies within
        # distance + both half-diagonals of the centre, far inside the 1e-9 margin, and every
        # candidate then gets the exact test)
        own = np.linalg.norm(hi_q - lo_q, axis=1) / 2.0
        cand = tree.query_ball_point((lo_q + hi_q) / 2.0, distance + own + radius + 1e-9)
        counts = np.fromiter(map(len, cand), dtype=np.intp, count=len(cand))
        if not counts.any():
            return
        flat = np.fromiter(chain.from_iterable(cand), dtype=np.intp, count=int(counts.sum()))
        qi = np.repeat(np.arange(q.size), counts)
        js = members[flat]
        keep = js != q[qi]
        js, qi = js[keep], qi[keep]
        gap = np.maximum(0.0, np.maximum(self.lo[js] - hi_q[qi], lo_q[qi] - self.hi[js]))
        d = np.sqrt((gap * gap).sum(axis=1))
        near[q[np.unique(qi[d <= distance])]] = True

    # -- support ("on") ------------------------------------------------------------------------
    def _build_on(self) -> None:
        if self._supports is not None:
            return
        self._build()
        cfg = self.config
        supports: dict[int, list[int]] = {}
        loads: dict[int, list[int]] = {}
        pairs: list[tuple[int, int]] = []
        for ix in self.groups.values():
            ok = ix[self.has_box[ix] & ~self.structural[ix]]
            if ok.size < 2:
                continue
            lo, hi = self.lo[ok], self.hi[ok]
            # lower candidates sorted by top height: |bottom(u) - top(l)| <= tol by binary search
            order = np.argsort(hi[:, 2], kind="stable")
            tops = hi[order, 2]
            for a in range(ok.size):
                z = lo[a, 2]
                s0 = int(np.searchsorted(tops, z - cfg.on_tolerance, side="left"))
                s1 = int(np.searchsorted(tops, z + cfg.on_tolerance, side="right"))
                if s1 <= s0:
                    continue
                cand = order[s0:s1]
                cand = cand[cand != a]
                if cand.size == 0:
                    continue
                # the upper's centre must lie above the lower's top (minus tol)
                cand = cand[(lo[a, 2] + hi[a, 2]) / 2.0 > hi[cand, 2] - cfg.on_tolerance]
                ox = np.clip(np.minimum(hi[a, 0], hi[cand, 0]) - np.maximum(lo[a, 0], lo[cand, 0]), 0, None)
                oy = np.clip(np.minimum(hi[a, 1], hi[cand, 1]) - np.maximum(lo[a, 1], lo[cand, 1]), 0, None)
                area = max(float((hi[a, 0] - lo[a, 0]) * (hi[a, 1] - lo[a, 1])), 1e-12)
                for b in cand[ox * oy / area >= cfg.on_min_overlap]:
                    u, l_ = int(ok[a]), int(ok[int(b)])
                    pairs.append((u, l_))
                    supports.setdefault(u, []).append(l_)
                    loads.setdefault(l_, []).append(u)
        self._on_pairs, self._supports, self._loads = pairs, supports, loads

    def supported_by(self, node: Any) -> list[Any]:
        """Nodes the given node rests on (see ``on_tolerance`` / ``on_min_overlap``)."""
        self._build_on()
        assert self._supports is not None
        return [self.nodes[j] for j in self._supports.get(self.idx(node), [])]

    def resting_on(self, node: Any) -> list[Any]:
        """Nodes resting on the given node."""
        self._build_on()
        assert self._loads is not None
        return [self.nodes[j] for j in self._loads.get(self.idx(node), [])]

    def on_pairs(self) -> list[tuple[Any, Any]]:
        self._build_on()
        assert self._on_pairs is not None
        return [(self.nodes[u], self.nodes[v]) for u, v in self._on_pairs]

    # -- facing / access ---------------------------------------------------------------------
    def front_directions(self, node: Any) -> list[np.ndarray]:
        """Horizontal unit vectors the node faces: attr ``front`` if set, else both normals of
        its box's long horizontal axis (all four sides for a square footprint)."""
        front = self.attrs(node).get("front")
        if front is not None:
            v = np.asarray(front, dtype=float)[:2]
            nrm = float(np.linalg.norm(v))
            if nrm > 0:
                return [v / nrm]
        box = self.box(node)
        if box is None:
            return []
        sx, sy = float(box.size[0]), float(box.size[1])
        ex, ey = np.array([1.0, 0.0]), np.array([0.0, 1.0])
        if abs(sx - sy) <= 1e-6 * max(sx, sy, 1e-9):
            return [ex, -ex, ey, -ey]
        return [ey, -ey] if sx > sy else [ex, -ex]

    def obstacles_in(self, node: Any, lo: np.ndarray, hi: np.ndarray) -> list[Any]:
        """Non-structural nodes (other than ``node`` and what rests on it) whose boxes penetrate
        the box lo..hi by more than ``min_overlap`` along every axis."""
        i = self.idx(node)
        ix = self.groups[self.scenes[i]]
        ix = ix[self.has_box[ix] & ~self.structural[ix]]
        ix = ix[ix != i]
        if ix.size == 0:
            return []
        ov = np.minimum(self.hi[ix], hi) - np.maximum(self.lo[ix], lo)
        hit = ix[(ov > self.config.min_overlap).all(axis=1)]
        if hit.size == 0:
            return []
        on_me = {self.index[u] for u in self.resting_on(node)}
        return [self.nodes[int(j)] for j in hit if int(j) not in on_me]


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GeoPredicate:
    """A named geometric predicate: ``fn(ctx, node) -> bool | None``; ``needs`` lists the node
    attributes it reads (documentation and error messages only)."""

    name: str
    fn: PredicateFn
    needs: tuple[str, ...] = ()
    doc: str = ""

    def __call__(self, ctx: GeometryContext, node: Any) -> bool | None:
        value = self.fn(ctx, node)
        return None if value is None else bool(value)


FamilyFactory = Callable[[str], PredicateFn]


@dataclass(frozen=True)
class _Family:
    prefix: str
    factory: FamilyFactory
    needs: tuple[str, ...]
    doc: str


class RelationRegistry:
    """Named geometric predicates plus *families* (``is_near_<class>``): a family is a prefix and a
    factory called with the suffix. Exact names take precedence over families."""

    def __init__(self) -> None:
        self._preds: dict[str, GeoPredicate] = {}
        self._families: dict[str, _Family] = {}
        self._family_cache: dict[str, GeoPredicate] = {}

    def copy(self) -> RelationRegistry:
        new = RelationRegistry()
        new._preds = dict(self._preds)
        new._families = dict(self._families)
        return new

    def register(self, name: str, fn: PredicateFn, *, needs: Iterable[str] = (), doc: str | None = None,
                 replace: bool = False) -> GeoPredicate:
        """Register ``fn`` under ``name`` (an identifier); re-registering needs ``replace=True``."""
        if not name.isidentifier():
            raise ConfigError(f"relation name {name!r} is not an identifier")
        if name in self._preds and not replace:
            raise ConfigError(f"relation {name!r} is already registered (pass replace=True)")
        pred = GeoPredicate(name, fn, tuple(needs), (doc if doc is not None else (fn.__doc__ or "")).strip())
        self._preds[name] = pred
        self._family_cache.clear()
        return pred

    def predicate(self, name: str | None = None, *, needs: Iterable[str] = (), doc: str | None = None,
                  replace: bool = False) -> Callable[[PredicateFn], PredicateFn]:
        """Decorator form of :meth:`register` (name defaults to the function's name)."""

        def deco(fn: PredicateFn) -> PredicateFn:
            self.register(name or fn.__name__, fn, needs=needs, doc=doc, replace=replace)
            return fn

        return deco

    def register_family(self, prefix: str, factory: FamilyFactory, *, needs: Iterable[str] = (),
                        doc: str = "", replace: bool = False) -> None:
        """Register a family: any name ``<prefix><suffix>`` resolves to ``factory(suffix)``."""
        if prefix in self._families and not replace:
            raise ConfigError(f"relation family {prefix!r} is already registered (pass replace=True)")
        self._families[prefix] = _Family(prefix, factory, tuple(needs), doc.strip())
        self._family_cache.clear()

    def find(self, name: str) -> GeoPredicate | None:
        """The predicate called ``name`` (exact or via a family), or None."""
        pred = self._preds.get(name)
        if pred is not None:
            return pred
        pred = self._family_cache.get(name)
        if pred is not None:
            return pred
        for prefix in sorted(self._families, key=len, reverse=True):
            if name.startswith(prefix) and len(name) > len(prefix):
                fam = self._families[prefix]
                pred = GeoPredicate(name, fam.factory(name[len(prefix):]), fam.needs, fam.doc)
                self._family_cache[name] = pred
                return pred
        return None

    def get(self, name: str) -> GeoPredicate:
        """Like :meth:`find` but raises :class:`UnknownPredicateError` listing the known names."""
        pred = self.find(name)
        if pred is None:
            raise UnknownPredicateError(name, self.names())
        return pred

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self.find(name) is not None

    def names(self) -> list[str]:
        """Exact names plus family patterns (``is_near_<class>``)."""
        return sorted(self._preds) + sorted(f"{p}<class>" for p in self._families)

    def describe(self) -> list[tuple[str, tuple[str, ...], str]]:
        """(name, attributes needed, doc) for every predicate and family."""
        out = [(p.name, p.needs, p.doc) for p in self._preds.values()]
        out += [(f"{f.prefix}<class>", f.needs, f.doc) for f in self._families.values()]
        return sorted(out)


DEFAULT_REGISTRY = RelationRegistry()
relation = DEFAULT_REGISTRY.predicate
register_relation = DEFAULT_REGISTRY.register


# --------------------------------------------------------------------------------------------
# built-in indoor predicates
# --------------------------------------------------------------------------------------------
def _near_factory(cls_name: str) -> PredicateFn:
    def is_near(ctx: GeometryContext, node: Any) -> bool | None:
        i = ctx.idx(node)  # (builds the arrays)
        if not ctx.has_box[i]:
            return None
        return ctx.has_neighbour_of_class(node, cls_name, ctx.config.near_distance)

    is_near.__doc__ = f"Box distance <= near_distance to another node of class {cls_name!r}."
    return is_near


DEFAULT_REGISTRY.register_family(
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


DEFAULT_REGISTRY.register_family(
    "is_on_top_of_", _on_top_of_factory, needs=("bbox", "label", "scene"),
    doc="Rests on a node of class <class> (see is_on_top_of).",
)


@relation("is_on_top_of", needs=("bbox", "scene"))
def is_on_top_of(ctx: GeometryContext, node: Any) -> bool | None:
    """Rests on another non-structural node: bottom within +-on_tolerance (0.05 m) of its top and
    >= on_min_overlap (30 %) of the own footprint over it."""
    if ctx.box(node) is None:
        return None
    return bool(ctx.supported_by(node))


@relation("is_workspace_height", needs=("bbox", "floor_z|scene"))
def is_workspace_height(ctx: GeometryContext, node: Any) -> bool | None:
    """Top surface (bbox zmax) within workspace_band (0.6-1.1 m) above the floor."""
    box, floor = ctx.box(node), ctx.floor(node)
    if box is None or floor is None:
        return None
    lo, hi = ctx.config.workspace_band
    return lo <= float(box.hi[2]) - floor <= hi


@relation("is_unobstructed", needs=("bbox", "scene"))
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


@relation("is_accessible", needs=("bbox", "front?", "scene"))
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


@relation("is_facing_seating", needs=("bbox", "front?", "label", "scene"))
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


# --------------------------------------------------------------------------------------------
# built-in outdoor predicates (attributes of the simulated / KITTI-360 maps)
# --------------------------------------------------------------------------------------------
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


@relation("is_stationary", needs=("track|speed|stationary",))
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


@relation("is_near_road_px", needs=("road_distance_px|near_road",))
def is_near_road_px(ctx: GeometryContext, node: Any) -> bool | None:
    """Image-space distance to the nearest road pixel ``road_distance_px`` <= near_road_px (50 px);
    else the boolean ``near_road``."""
    if ctx.attr(node, "road_distance_px") is not None:
        return float(ctx.attr(node, "road_distance_px")) <= ctx.config.near_road_px
    if ctx.attr(node, "near_road") is not None:
        return bool(ctx.attr(node, "near_road"))
    return None


@relation("is_on_sidewalk", needs=("on_sidewalk",))
def is_on_sidewalk(ctx: GeometryContext, node: Any) -> bool | None:
    """The boolean attribute ``on_sidewalk`` (footprint on sidewalk pixels / cells)."""
    v = ctx.attr(node, "on_sidewalk")
    return None if v is None else bool(v)


@relation("is_at_intersection", needs=("at_intersection|intersection_distance",))
def is_at_intersection(ctx: GeometryContext, node: Any) -> bool | None:
    """The boolean ``at_intersection``; else ``intersection_distance`` <= intersection_radius (15 m)."""
    if ctx.attr(node, "at_intersection") is not None:
        return bool(ctx.attr(node, "at_intersection"))
    if ctx.attr(node, "intersection_distance") is not None:
        return float(ctx.attr(node, "intersection_distance")) <= ctx.config.intersection_radius
    return None


@relation("is_visible_in_drive_direction", needs=("visible_in_drive_direction",))
def is_visible_in_drive_direction(ctx: GeometryContext, node: Any) -> bool | None:
    """The boolean ``visible_in_drive_direction`` (inside the forward field of view)."""
    v = ctx.attr(node, "visible_in_drive_direction")
    return None if v is None else bool(v)


# --------------------------------------------------------------------------------------------
# materialising relations as graph edges
# --------------------------------------------------------------------------------------------
def materialise_relations(graph: Any, config: RelationConfig | None = None, *,
                          relations: Iterable[str] = ("near", "on")) -> int:
    """Add ``near`` (both directions, attr ``distance``) and ``on`` (upper -> lower) edges via
    ``graph.add_relation``; structural nodes (walls, floor, ceiling) are skipped. Returns the number
    of edges written (re-running overwrites: the edge key is the relation name)."""
    ctx = GeometryContext(graph, config)
    ctx._build()
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

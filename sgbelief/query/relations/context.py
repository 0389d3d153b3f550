"""The geometric view of one graph that the relations read: node boxes as arrays, scene groups, the
floor height per scene, class masks, per-class KD-trees and the support (``on``) relation, built
lazily and cached for one evaluation batch."""

from __future__ import annotations

from collections.abc import Mapping
from itertools import chain, repeat
from operator import is_
from typing import Any

import numpy as np

from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.query.relations.boxes import Box, fill_boxes
from sgbelief.query.relations.config import RelationConfig

__all__ = ["GeometryContext"]


class GeometryContext:
    """Read-only geometric view of a graph, built lazily and cached for one evaluation batch.

    Holds node boxes as arrays, scene groups, per-class KD-trees (scipy) and derived relations
    (``on`` pairs). Create one per batch; it does not notice later graph edits.

    It reads the graph through ``nodes()``, ``predicates()`` and the bulk reads
    ``node_attr_table()`` (every node's attributes, taken once, at the first read) and, for
    committed labels, ``probabilities(None, predicate)`` (every node's): a subclass of SceneGraphModel
    that changes these is read as it answers.
    """

    def __init__(self, graph: SceneGraphModel, config: RelationConfig | None = None) -> None:
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
        self._attr_table: dict[Any, dict[str, Any]] | None = None

    # -- arrays --------------------------------------------------------------------------------
    def build(self) -> None:
        """Read the graph into arrays (once; every reader below calls it)."""
        if self._built:
            return
        g = self.graph
        nodes = list(g.nodes())
        n = len(nodes)
        attrs = list(map(self.attrs, nodes))
        lo = np.full((n, 3), np.nan)
        hi = np.full((n, 3), np.nan)
        bboxes = [a.get("bbox") for a in attrs]
        if not any(map(is_, bboxes, repeat(None))):  # (not ``None in``: that compares with ==)
            fill_boxes(lo, hi, None, bboxes, True)
        else:
            fill_boxes(lo, hi, [i for i, b in enumerate(bboxes) if b is not None],
                       [b for b in bboxes if b is not None], True)
            cents = [(i, c) for i, (a, b) in enumerate(zip(attrs, bboxes))
                     if b is None and (c := a.get("centroid")) is not None]
            fill_boxes(lo, hi, [i for i, _ in cents], [c for _, c in cents], False)
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
        self.build()
        return self.index[node]

    def attrs(self, node: Any) -> dict[str, Any]:
        """The node's attribute dict, from the graph's ``node_attr_table()`` read at the first call
        (an unknown node gets the graph's own error, from ``node_attrs``)."""
        table = self._attr_table
        if table is None:
            table = self._attr_table = self.graph.node_attr_table()
        try:
            return table[node]
        except (KeyError, TypeError):
            return self.graph.node_attrs(node)

    def attr(self, node: Any, key: str) -> Any:
        """A node attribute: top level first, then inside its ``attributes`` dict (nodes.json)."""
        a = self.attrs(node)
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
        self.build()
        mask = self._class_cache.get(cls_name)
        if mask is not None:
            return mask
        wanted = self.config.labels_of(cls_name)
        mask = np.array([lab in wanted for lab in self.labels], dtype=bool)
        if self.config.use_committed_labels:
            known = set(self.graph.predicates())
            n = len(self.nodes)
            for p in [f"is_{c}" for c in sorted(wanted) if f"is_{c}" in known]:
                probs = np.fromiter(self.graph.probabilities(None, p), dtype=float, count=n)
                mask |= probs > self.config.commit_tau
        self._class_cache[cls_name] = mask
        return mask

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
        self.build()
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

"""Open-vocabulary class matching for referring queries, and the node table the resolver reads.

A class name of an utterance matches a node when their keys agree: lower case with every
non-alphanumeric removed ("Trash can", "trash_can" and "trashcan" are all ``trashcan``). Matching
is tiered, per scene: nodes whose key equals the class's key (tier ``exact``); when the scene has
none, nodes whose *singular* keys agree (tier ``plural``: "trash cans" finds "trash can", "shelves"
finds "shelf"). So a scene holding both "cabinet" and "cabinets" (distinct ScanNet categories) keeps
them apart, and a plural in the utterance still finds a singular label when nothing closer exists.

On a belief map a node without a matching ``label`` is a member with the posterior mean of its
``is_<class>`` belief (the predicate matched by the same keys) when that belief is committed (mean
strictly above ``commit_tau``, 0.5: the map's own decision), at ``o / (1 + sum_c o_c)`` with ``o``
the odds of that belief and ``o_c`` those of every class belief of the node (classes exclude each
other; a node committed to one class only keeps its posterior mean); a node with neither a
matching label nor a committed belief is not a member (probability 0).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from sgbelief.query.relations.boxes import fill_boxes

__all__ = ["NodeTable", "Membership", "class_key", "singular_key", "singular_word"]

_NON_ALNUM = re.compile(r"[^0-9a-z]+")
_IRREGULAR = {
    "shelves": "shelf", "knives": "knife", "leaves": "leaf", "people": "person", "mice": "mouse",
    "men": "man", "women": "woman", "children": "child", "feet": "foot", "teeth": "tooth",
    "loaves": "loaf", "halves": "half", "wolves": "wolf", "scarves": "scarf", "series": "series",
    "species": "species", "glasses": "glasses", "pants": "pants", "scissors": "scissors",
}


def class_key(name: str) -> str:
    """'Trash can' / 'trash_can' / 'trashcan' -> 'trashcan'."""
    return _NON_ALNUM.sub("", str(name).lower())


def singular_word(word: str) -> str:
    """English singular of one lower-case word, by the common rules (irregulars from a short list)."""
    if word in _IRREGULAR:
        return _IRREGULAR[word]
    if len(word) > 4 and word.endswith("ies"):
        return word[:-3] + "y"
    if len(word) > 4 and word.endswith(("sses", "shes", "ches", "xes", "zes")):
        return word[:-2]
    if len(word) > 3 and word.endswith("s") and not word.endswith(("ss", "us", "is")):
        return word[:-1]
    return word


def singular_key(name: str) -> str:
    """The key of the name with its last word made singular ('kitchen cabinets' -> 'kitchencabinet')."""
    words = [w for w in _NON_ALNUM.split(str(name).lower()) if w]
    if not words:
        return ""
    words[-1] = singular_word(words[-1])
    return "".join(words)


@dataclass(frozen=True)
class Membership:
    """The members of one class in one scene: node indices into the table, P(member), and the
    tier that matched (``exact``, ``plural`` or ``belief``)."""

    index: np.ndarray
    p: np.ndarray
    tier: str

    def __len__(self) -> int:
        return len(self.index)


class NodeTable:
    """Every node's box, label keys and scene, read once from a graph (a sgbelief SceneGraph or a
    plain networkx graph whose nodes carry ``bbox`` / ``centroid``, ``label``, ``scene``).

    Build one with :meth:`from_graph` and pass it to :func:`~sgbelief.query.refer` as ``index=``
    to answer many utterances without re-reading the graph (it does not notice later edits)."""

    def __init__(self, graph: Any, nodes: list[Any], attrs: list[Mapping[str, Any]]) -> None:
        self.graph = graph
        self.nodes = nodes
        self._attrs = attrs
        n = len(nodes)
        self.scenes: list[Any] = [a.get("scene") for a in attrs]
        # labels, keys and boxes are read per scene, when a query first looks at it
        self.labels: list[str | None] = [None] * n
        self.keys: list[str] = [""] * n
        self.skeys: list[str] = [""] * n
        self.lo = np.full((n, 3), np.nan)
        self.hi = np.full((n, 3), np.nan)
        self.has_box = np.zeros(n, dtype=bool)
        self.fronts: dict[int, tuple[float, float]] = {}
        self._loaded: set[Any] = set()
        self._scene_ix: dict[Any, np.ndarray] = {}
        self._all_scenes: dict[Any, np.ndarray] | None = None
        self._position: dict[Any, int] | None = None
        self._key_of: dict[str, tuple[str, str]] = {}
        #: label key -> scenes holding it (and the same by singular key), built at the first search
        self._key_scenes: tuple[dict[str, set[Any]], dict[str, set[Any]]] | None = None
        self._beliefs: dict[str, dict[int, float]] = {}
        self._belief_preds: dict[str, list[str]] = {}
        self._all_preds: list[str] | None = None

    @property
    def scene_nodes(self) -> dict[Any, np.ndarray]:
        """Scene -> its node indices, every scene (in order of first appearance)."""
        if self._all_scenes is None:
            groups: dict[Any, list[int]] = {}
            for i, s in enumerate(self.scenes):
                groups.setdefault(s, []).append(i)
            self._all_scenes = {s: np.asarray(ix, dtype=np.intp) for s, ix in groups.items()}
            self._scene_ix.update(self._all_scenes)
        return self._all_scenes

    @property
    def position(self) -> dict[Any, int]:
        if self._position is None:
            self._position = {node: i for i, node in enumerate(self.nodes)}
        return self._position

    def has_scene(self, scene: Any) -> bool:
        return len(self.scene_index(scene)) > 0

    def scene_index(self, scene: Any) -> np.ndarray:
        """The scene's node indices (cached)."""
        ix = self._scene_ix.get(scene)
        if ix is None:
            ix = self._scene_ix[scene] = np.asarray([i for i, s in enumerate(self.scenes) if s == scene], dtype=np.intp)
        return ix

    def _read_labels(self, rows: list[int]) -> None:
        key_of = self._key_of
        for i in rows:
            lab = self._attrs[i].get("label")
            if lab is None:
                continue
            lab = str(lab)
            ks = key_of.get(lab)
            if ks is None:
                ks = key_of[lab] = (class_key(lab), singular_key(lab))
            self.labels[i] = lab
            self.keys[i], self.skeys[i] = ks

    def load_scene(self, scene: Any) -> np.ndarray:
        """Read the labels, boxes (and ``front`` attributes) of one scene's nodes, once; its node indices."""
        ix = self.scene_index(scene)
        if scene in self._loaded:
            return ix
        self._loaded.add(scene)
        rows, boxes, crow, cents = [], [], [], []
        for i in ix.tolist():
            a = self._attrs[i]
            b = a.get("bbox")
            if b is not None:
                if len(b) == 6:  # a flat (xmin, ymin, zmin, xmax, ymax, zmax)
                    b = (tuple(b[:3]), tuple(b[3:]))
                rows.append(i)
                boxes.append(b)
            elif (c := a.get("centroid")) is not None:
                crow.append(i)
                cents.append(c)
            f = a.get("front")
            if f is not None:
                try:
                    fx, fy = float(f[0]), float(f[1])
                except (TypeError, ValueError, IndexError):
                    fx = fy = 0.0
                if fx or fy:
                    self.fronts[i] = (fx, fy)
        self._read_labels(ix.tolist())
        fill_boxes(self.lo, self.hi, rows, boxes, True)
        fill_boxes(self.lo, self.hi, crow, cents, False)
        self.has_box[ix] = ~np.isnan(self.lo[ix]).any(axis=1)
        return ix

    def _scene_key_index(self, scene: Any, key: str, singular: bool) -> np.ndarray:
        ix = self.load_scene(scene)
        keys = self.skeys if singular else self.keys
        return np.asarray([i for i in ix.tolist() if keys[i] == key], dtype=np.intp)

    @classmethod
    def from_graph(cls, graph: Any) -> NodeTable:
        if hasattr(graph, "node_attr_table"):
            table = graph.node_attr_table()
        elif hasattr(graph, "nodes") and hasattr(graph.nodes, "__call__") and hasattr(graph, "adj"):
            table = dict(graph.nodes(data=True))  # a networkx graph
        else:
            raise TypeError(f"refer: expected a sgbelief SceneGraph or a networkx graph, got {type(graph).__name__}")
        return cls(graph, list(table), list(table.values()))

    # -- class members ---------------------------------------------------------------------------
    def belief_predicates(self, name: str) -> list[str]:
        """The graph's belief predicates ``is_<class>`` that match a class name (exact key first,
        else singular key); [] for a graph without beliefs."""
        hit = self._belief_preds.get(name)
        if hit is not None:
            return hit
        if self._all_preds is None:
            preds = getattr(self.graph, "predicates", None)
            names: list[str] = []
            if callable(preds) and getattr(self.graph, "provenance", None) is not None:
                names = [p for p in preds() if isinstance(p, str) and p.startswith("is_")]
            self._all_preds = names
        key, skey = class_key(name), singular_key(name)
        exact = [p for p in self._all_preds if class_key(p[3:]) == key]
        hit = exact or [p for p in self._all_preds if singular_key(p[3:].replace("_", " ")) == skey]
        self._belief_preds[name] = hit
        return hit

    def _belief_means(self, predicate: str) -> dict[int, float]:
        """Posterior means of the nodes with evidence on ``predicate``, by table index (cached)."""
        hit = self._beliefs.get(predicate)
        if hit is None:
            prov = getattr(self.graph, "provenance", None)
            hit = {}
            if prov is not None:
                with_ev = [n for n in prov.nodes_with(predicate) if n in self.position]
                if with_ev:
                    means = prov.means(with_ev, predicate)
                    hit = {self.position[n]: float(m) for n, m in zip(with_ev, means)}
            self._beliefs[predicate] = hit
        return hit

    def _exclusive(self, i: int, predicate: str, mean: float) -> float:
        """P(node i is of the predicate's class) when classes exclude each other: each class belief
        ``b_c`` of the node (every ``is_*`` with evidence) is read as odds ``b_c / (1 - b_c)`` for its
        class against "none of them", so ``P = o / (1 + sum_c o_c)`` (= ``b`` when it is the node's
        only class belief)."""
        beliefs = getattr(self.graph, "beliefs", None)
        if beliefs is None:
            return mean
        odds = 0.0
        for pred, b in beliefs(self.nodes[i]).items():
            if pred.startswith("is_"):
                m = min(float(b.mean), 1.0 - 1e-9)
                odds += m / (1.0 - m)
        m = min(mean, 1.0 - 1e-9)
        own = m / (1.0 - m)
        odds = max(odds, own)
        return own / (1.0 + odds)

    def members(self, name: str, scene: Any, *, use_beliefs: bool = True, commit_tau: float = 0.5) -> Membership:
        """The class's members in ``scene``: labelled nodes (exact tier, else plural tier) with
        P = 1, plus nodes whose matching ``is_<class>`` belief is committed (posterior mean
        strictly above ``commit_tau``), at that posterior mean."""
        key, skey = class_key(name), singular_key(name)
        self.load_scene(scene)
        ix = self._scene_key_index(scene, key, False)
        tier = "exact"
        if not len(ix) and skey:
            ix = self._scene_key_index(scene, skey, True)
            tier = "plural"
        p: dict[int, float] = dict.fromkeys(ix.tolist(), 1.0)
        if use_beliefs:
            in_scene: set[int] | None = None
            for pred in self.belief_predicates(name):
                for i, m in self._belief_means(pred).items():
                    if i in p:
                        continue
                    if in_scene is None:
                        in_scene = set(self.scene_index(scene).tolist())
                    if i in in_scene and m > commit_tau:
                        p[i] = max(self._exclusive(i, pred, m), p.get(i, 0.0))
            if len(p) > len(ix):
                tier = tier if len(ix) else "belief"
        order = np.asarray(sorted(p), dtype=np.intp)
        probs = np.asarray([p[i] for i in order.tolist()], dtype=float)
        keep = self.has_box[order] if len(order) else np.zeros(0, dtype=bool)
        return Membership(order[keep], probs[keep], tier)

    def scenes_with(self, names: list[str], *, use_beliefs: bool = True, commit_tau: float = 0.5) -> list[Any]:
        """Scenes in which every class name has at least one member, in order of first appearance."""
        if self._key_scenes is None:
            self._read_labels(list(range(len(self.nodes))))
            exact: dict[str, set[Any]] = {}
            plural: dict[str, set[Any]] = {}
            for s, k, sk in zip(self.scenes, self.keys, self.skeys):
                if k:
                    exact.setdefault(k, set()).add(s)
                    plural.setdefault(sk, set()).add(s)
            self._key_scenes = (exact, plural)
        found: set[Any] | None = None
        for name in names:
            key, skey = class_key(name), singular_key(name)
            mine = self._key_scenes[0].get(key, set()) | self._key_scenes[1].get(skey, set())
            if use_beliefs:
                for pred in self.belief_predicates(name):
                    mine.update(self.scenes[i] for i, m in self._belief_means(pred).items() if m > commit_tau)
            found = mine if found is None else found & mine
        if not found:
            return []
        return [s for s in self.scene_nodes if s in found
                and all(len(self.members(n, s, use_beliefs=use_beliefs, commit_tau=commit_tau)) for n in names)]

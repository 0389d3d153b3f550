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
        n = len(nodes)
        lo = np.full((n, 3), np.nan)
        hi = np.full((n, 3), np.nan)
        rows, boxes, crow, cents = [], [], [], []
        labels: list[str | None] = []
        scenes: list[Any] = []
        fronts: dict[int, tuple[float, float]] = {}
        for i, a in enumerate(attrs):
            b = a.get("bbox")
            if b is not None:
                rows.append(i)
                boxes.append(b)
            elif (c := a.get("centroid")) is not None:
                crow.append(i)
                cents.append(c)
            lab = a.get("label")
            labels.append(None if lab is None else str(lab))
            scenes.append(a.get("scene"))
            f = a.get("front")
            if f is not None:
                try:
                    fx, fy = float(f[0]), float(f[1])
                except (TypeError, ValueError, IndexError):
                    fx = fy = 0.0
                if fx or fy:
                    fronts[i] = (fx, fy)
        fill_boxes(lo, hi, rows, boxes, True)
        fill_boxes(lo, hi, crow, cents, False)
        self.lo, self.hi = lo, hi
        self.has_box = ~np.isnan(lo).any(axis=1)
        self.labels = labels
        self.scenes = scenes
        self.fronts = fronts
        key_of: dict[str | None, tuple[str, str]] = {}
        keys, skeys = [], []
        for lab in labels:
            ks = key_of.get(lab)
            if ks is None:
                ks = key_of[lab] = ("", "") if lab is None else (class_key(lab), singular_key(lab))
            keys.append(ks[0])
            skeys.append(ks[1])
        self.keys = keys
        self.skeys = skeys
        self.position = {node: i for i, node in enumerate(nodes)}
        groups: dict[Any, list[int]] = {}
        for i, s in enumerate(scenes):
            groups.setdefault(s, []).append(i)
        self.scene_nodes = {s: np.asarray(ix, dtype=np.intp) for s, ix in groups.items()}
        exact: dict[str, dict[Any, list[int]]] = {}
        plural: dict[str, dict[Any, list[int]]] = {}
        for i, (s, k, sk) in enumerate(zip(scenes, keys, skeys)):
            if k:
                exact.setdefault(k, {}).setdefault(s, []).append(i)
                plural.setdefault(sk, {}).setdefault(s, []).append(i)
        #: label key -> scene -> node indices (and the same by singular key)
        self._exact = {k: {s: np.asarray(v, dtype=np.intp) for s, v in d.items()} for k, d in exact.items()}
        self._plural = {k: {s: np.asarray(v, dtype=np.intp) for s, v in d.items()} for k, d in plural.items()}
        self._beliefs: dict[str, dict[int, float]] = {}
        self._belief_preds: dict[str, list[str]] = {}
        self._all_preds: list[str] | None = None

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
        empty = np.zeros(0, dtype=np.intp)
        ix = self._exact.get(key, {}).get(scene, empty)
        tier = "exact"
        if not len(ix):
            ix = self._plural.get(skey, {}).get(scene, empty)
            tier = "plural"
        p: dict[int, float] = dict.fromkeys(ix.tolist(), 1.0)
        if use_beliefs:
            in_scene: set[int] | None = None
            for pred in self.belief_predicates(name):
                for i, m in self._belief_means(pred).items():
                    if i in p:
                        continue
                    if in_scene is None:
                        in_scene = set(self.scene_nodes.get(scene, np.zeros(0, dtype=np.intp)).tolist())
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
        found: set[Any] | None = None
        for name in names:
            key, skey = class_key(name), singular_key(name)
            mine = set(self._exact.get(key, {})) | set(self._plural.get(skey, {}))
            if use_beliefs:
                for pred in self.belief_predicates(name):
                    mine.update(self.scenes[i] for i, m in self._belief_means(pred).items() if m > commit_tau)
            found = mine if found is None else found & mine
        if not found:
            return []
        return [s for s in self.scene_nodes if s in found
                and all(len(self.members(n, s, use_beliefs=use_beliefs, commit_tau=commit_tau)) for n in names)]

"""The batched query paths give exactly what the per-node definitions give.

``QueryEngine.score_many`` (one literal at a time over the candidates) against ``score`` node by
node; ``is_near_<class>`` (one ball query per scene) against ``neighbours_of_class``; the
committed-label class mask read in bulk against ``graph.probability`` node by node; the array
build against a row-by-row reading of the attributes. A SceneGraphModel subclass is read as it answers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.errors import UnknownNodeError, UnknownPredicateError
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.query import DEFAULT_REGISTRY, GeometryContext, QueryEngine, RelationConfig
from sgbelief.query.language import Compound, Literal

# the random graphs leave geometry out of some nodes on purpose (undecidable predicates are part of
# what is compared), so the engine's missing-geometry warning is expected here, not a fault
pytestmark = pytest.mark.filterwarnings("ignore::sgbelief.query.engine.MissingGeometryWarning")

LABELS = ["car", "person", "floor", "wall", "chair", "table", None]
BELIEFS = ["is_car", "is_pedestrian", "is_chair"]
GEOMETRIC = ["is_near_pedestrian", "is_near_car", "is_stationary", "is_near_road_px", "is_workspace_height"]


class Inverted(SceneGraphModel):
    """A SceneGraphModel subclass whose reads answer otherwise (1 - p, and a relabelled chair): the
    engine and the context read it as it answers, in bulk and node by node alike."""

    def probability(self, node, predicate):  # noqa: ANN001, ANN201
        return 1.0 - super().probability(node, predicate)

    def probabilities(self, nodes, predicate):  # noqa: ANN001, ANN201
        return [1.0 - p for p in super().probabilities(nodes, predicate)]

    def node_attrs(self, node):  # noqa: ANN001, ANN201
        return self._relabel(super().node_attrs(node))

    def node_attr_table(self):  # noqa: ANN201
        return {v: self._relabel(a) for v, a in super().node_attr_table().items()}

    @staticmethod
    def _relabel(attrs):  # noqa: ANN001, ANN205
        return {**attrs, "label": "car"} if attrs.get("label") == "chair" else attrs


def random_graph(seed: int, n: int, cls: type[SceneGraphModel] = SceneGraphModel) -> SceneGraphModel:
    rng = np.random.default_rng(seed)
    g = cls()
    for i in range(n):
        a: dict = {}
        x, y, z = (rng.random(3) * [12, 12, 1]).tolist()
        sx, sy, sz = (rng.random(3) * [2, 2, 1] + 0.01).tolist()
        r = rng.random()
        if r < 0.6:
            a["bbox"] = ((x, y, z), (x + sx, y + sy, z + sz))
        elif r < 0.7:
            a["bbox"] = [[x, y, z], [x + sx, y + sy, z + sz]]
        elif r < 0.85:
            a["centroid"] = (x, y, z)
        lab = LABELS[int(rng.integers(len(LABELS)))]
        if lab is not None:
            a["label"] = lab
        if rng.random() < 0.9:
            a["scene"] = f"s{int(rng.integers(0, 3))}"
        if rng.random() < 0.3:
            a["floor_z"] = float(rng.random() * 0.1)
        if rng.random() < 0.5:
            a["speed"] = float(rng.random())
        if rng.random() < 0.5:
            a["road_distance_px"] = float(rng.random() * 100)
        if rng.random() < 0.1:
            a["geometric_predicates"] = {"is_stationary": bool(rng.random() < 0.5)}
        g.add_node(i, **a)
    for k in range(2 * n):
        node = int(rng.integers(n))
        pred = BELIEFS[int(rng.integers(len(BELIEFS)))]
        da, db = (2.0, 0.5) if rng.random() < 0.5 else (0.3, 1.5)
        g.provenance.record(node, pred, f"e{k}", 0, da, db)
    return g


def describe(matches) -> list:  # noqa: ANN001
    return [(m.node, m.probability, m.retrieved, m.components) for m in matches]


def reference_score(engine: QueryEngine, node, compound: Compound, kinds, prune: bool, tau: float):  # noqa: ANN001, ANN201
    """P(v, q) node by node, straight from the definition (beliefs, then geometry, literal order)."""
    from sgbelief.query.engine import BELIEF, GEOMETRIC, Component, Match

    comps, prob = [], 1.0
    for kind in (BELIEF, GEOMETRIC):
        for lit in compound.literals:
            if kinds[lit.name] != kind:
                continue
            if kind == BELIEF:
                p = float(engine.graph.probability(node, lit.name))
                f = 1.0 - p if lit.negated else p
                comps.append(Component(lit.name, BELIEF, lit.negated, p, f, node in engine.evidence_nodes(lit.name)))
            else:
                pre = engine.graph.node_attrs(node).get("geometric_predicates")
                v = bool(pre[lit.name]) if pre and pre.get(lit.name) is not None else \
                    DEFAULT_REGISTRY.get(lit.name)(GeometryContext(engine.graph, engine.config), node)
                f = 0.0 if v is None else float(v != lit.negated)
                comps.append(Component(lit.name, GEOMETRIC, lit.negated, v, f))
            prob *= f
            if prune and prob <= tau:
                return None
    order = {lit.name: i for i, lit in enumerate(compound.literals)}
    comps.sort(key=lambda c: order[c.name])
    return Match(node, prob, tuple(comps), prob > tau)


literal = st.tuples(st.sampled_from(BELIEFS + GEOMETRIC), st.booleans())


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), lits=st.lists(literal, min_size=1, max_size=4),
       tau=st.sampled_from([0.0, 0.3, 0.5, 0.9]), prune=st.booleans())
def test_score_many_is_score_node_by_node(seed: int, lits: list, tau: float, prune: bool) -> None:
    g = random_graph(seed, 60)
    compound = Compound(tuple(Literal(name, neg) for name, neg in lits))
    cfg = RelationConfig(near_distance=1.5)
    batched = QueryEngine(g, config=cfg)
    single = QueryEngine(g, config=cfg)
    _, kinds = batched.compile(compound)
    nodes = list(g.nodes())
    got = batched.score_many(nodes, compound, kinds, prune=prune, tau=tau)
    want = [m for m in (reference_score(batched, v, compound, kinds, prune, tau) for v in nodes) if m is not None]
    assert describe(got) == describe(want)
    one_by_one = [m for m in (single.score(v, compound, kinds, prune=prune, tau=tau) for v in nodes) if m is not None]
    assert describe(one_by_one) == describe(want)
    assert batched._prob == single._prob and batched._geo == single._geo
    # and through the public entry points, against an engine that reads node by node
    ref = QueryEngine(g, config=cfg, probability=g.probability)
    for include_all in (False, True):
        a = batched.evaluate(compound, tau=tau, include_all=include_all)
        b = ref.evaluate(compound, tau=tau, include_all=include_all)
        assert describe(a) == describe(b) and a.n_candidates == b.n_candidates
    assert batched.probabilities(compound) == ref.probabilities(compound)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("distance", [0.0, 0.5, 2.0])
def test_is_near_is_any_neighbour(seed: int, distance: float) -> None:
    g = random_graph(seed, 150)
    cfg = RelationConfig(near_distance=distance)
    for cls_name in ("pedestrian", "car", "table"):
        ctx = GeometryContext(g, cfg)
        fresh = GeometryContext(g, cfg)
        pred = DEFAULT_REGISTRY.get(f"is_near_{cls_name}")
        for v in g.nodes():
            box = fresh.box(v)
            want = None if box is None else bool(fresh.neighbours_of_class(v, cls_name, distance))
            assert pred(ctx, v) == want


def reference_class_mask(g: SceneGraphModel, cfg: RelationConfig, cls_name: str) -> np.ndarray:
    """Node by node: the label is one of the class's, or a committed belief on is_<label>."""
    wanted = cfg.labels_of(cls_name)
    preds = [f"is_{c}" for c in sorted(wanted) if f"is_{c}" in set(g.predicates())]
    return np.array([g.node_attrs(v).get("label") in wanted
                     or (cfg.use_committed_labels and any(g.probability(v, p) > cfg.commit_tau for p in preds))
                     for v in g.nodes()], dtype=bool)


@pytest.mark.parametrize("commit_tau", [0.3, 0.5, 0.7])
@pytest.mark.parametrize("cls", [SceneGraphModel, Inverted])
def test_committed_class_mask_is_the_per_node_definition(commit_tau: float, cls: type[SceneGraphModel]) -> None:
    for use_committed in (True, False):
        cfg = RelationConfig(commit_tau=commit_tau, use_committed_labels=use_committed)
        g = random_graph(3, 200, cls)
        ctx = GeometryContext(g, cfg)
        for cls_name in ("car", "pedestrian", "chair", "table"):
            assert np.array_equal(ctx.class_mask(cls_name), reference_class_mask(g, cfg, cls_name)), cls_name
    if cls is Inverted:  # the subclass's answers are what the context reads
        plain, inverted = random_graph(3, 200), random_graph(3, 200, Inverted)
        assert not np.array_equal(GeometryContext(plain).class_mask("car"), GeometryContext(inverted).class_mask("car"))


def reference_arrays(g: SceneGraphModel, cfg: RelationConfig) -> dict[str, object]:
    """The context's arrays read row by row from ``node_attrs``: a bbox, else a centroid as a
    degenerate box; the floor from ``floor_z``, else the median top of the scene's boxed 'floor'
    objects, else its lowest box bottom."""
    nodes = list(g.nodes())
    lo = np.full((len(nodes), 3), np.nan)
    hi = np.full((len(nodes), 3), np.nan)
    attrs = [g.node_attrs(v) for v in nodes]
    for i, a in enumerate(attrs):
        if a.get("bbox") is not None:
            lo[i], hi[i] = a["bbox"][0], a["bbox"][1]
        elif a.get("centroid") is not None:
            lo[i] = hi[i] = a["centroid"]
    has_box = ~np.isnan(lo).any(axis=1)
    labels = [None if a.get("label") is None else str(a["label"]) for a in attrs]
    scenes = [a.get("scene") for a in attrs]
    floor_z = np.array([np.nan if a.get("floor_z") is None else float(a["floor_z"]) for a in attrs])
    for s in dict.fromkeys(scenes):
        boxed = [i for i in range(len(nodes)) if scenes[i] == s and has_box[i]]
        if not boxed:
            continue
        floors = [hi[i, 2] for i in boxed if labels[i] == "floor"]
        fz = float(np.median(floors)) if floors else float(min(lo[i, 2] for i in boxed))
        for i in range(len(nodes)):
            if scenes[i] == s and np.isnan(floor_z[i]):
                floor_z[i] = fz
    structural = np.array([lab in cfg.structural_labels for lab in labels], dtype=bool)
    return {"lo": lo, "hi": hi, "has_box": has_box, "structural": structural, "floor_z": floor_z,
            "labels": labels, "scenes": scenes, "index": {v: i for i, v in enumerate(nodes)}}


@pytest.mark.parametrize("cls", [SceneGraphModel, Inverted])
def test_arrays_match_a_row_by_row_reading(cls: type[SceneGraphModel]) -> None:
    for seed in range(4):
        g = random_graph(seed, 120, cls)
        ctx = GeometryContext(g, None)
        ctx.build()
        want = reference_arrays(g, ctx.config)
        for name in ("lo", "hi", "has_box", "structural", "floor_z"):
            assert np.array_equal(getattr(ctx, name), want[name], equal_nan=True), name
        assert ctx.labels == want["labels"] and ctx.scenes == want["scenes"] and ctx.index == want["index"]
        fast = ctx
        # groups: every node once, ascending within its scene, scenes in order of first appearance
        firsts = list(dict.fromkeys(g.node_attrs(v).get("scene") for v in g.nodes()))
        assert list(fast.groups) == firsts
        for s, ix in fast.groups.items():
            assert list(ix) == [i for i, v in enumerate(g.nodes()) if g.node_attrs(v).get("scene") == s]


def test_unusual_boxes_fall_back_to_numpy_rules() -> None:
    # attributes set on the live dicts (add_node would have checked them)
    g = SceneGraphModel()
    for v in ("arr", "scalar_rows", "extra_row", "cent", "none"):
        g.add_node(v)
    g.node_attrs("arr")["bbox"] = np.array([[0.0, 0, 0], [1, 1, 1]])
    g.node_attrs("scalar_rows")["bbox"] = (0.5, 2.0)  # broadcast: lo = (0.5,)*3, hi = (2.0,)*3
    g.node_attrs("extra_row")["bbox"] = ((0, 0, 0), (1, 2, 3), (9, 9, 9))  # only the first two rows count
    g.node_attrs("cent")["centroid"] = np.array([4.0, 5.0, 6.0])
    ctx = GeometryContext(g)
    ctx.build()
    assert ctx.lo.tolist()[:4] == [[0, 0, 0], [0.5] * 3, [0, 0, 0], [4, 5, 6]]
    assert ctx.hi.tolist()[:4] == [[1, 1, 1], [2.0] * 3, [1, 2, 3], [4, 5, 6]]
    assert all(math.isnan(x) for x in ctx.lo[4]) and not ctx.has_box[4]
    bad = SceneGraphModel()
    bad.add_node("a")
    bad.node_attrs("a")["bbox"] = (("x", 0, 0), (1, 1, 1))
    with pytest.raises(ValueError):
        GeometryContext(bad).build()


def test_errors_are_those_of_the_per_node_reads() -> None:
    g = random_graph(1, 30)
    g.vocabulary = frozenset({"is_car"})
    engine = QueryEngine(g)
    with pytest.raises(UnknownPredicateError):
        engine.belief_many("is_pedestrian", [0, 1])
    with pytest.raises(UnknownNodeError):
        engine.belief_many("is_car", [0, "missing"])
    assert engine.belief_many("is_car", []) == []
    with pytest.raises(UnknownNodeError):
        QueryEngine(g).geometric_many("is_stationary", ["missing"])


def test_a_subclass_is_read_as_it_answers() -> None:
    g = random_graph(5, 80, Inverted)
    compound = Compound((Literal("is_car", False), Literal("is_near_car", True)))
    bulk = QueryEngine(g).evaluate(compound, include_all=True)
    per_node = QueryEngine(g, probability=g.probability).evaluate(compound, include_all=True)
    assert len(bulk) > 0 and describe(bulk) == describe(per_node)
    for m in bulk:
        assert m.components[0].value == g.probability(m.node, "is_car")

"""The batched query paths give exactly what the per-node definitions give.

``QueryEngine.score_many`` (one literal at a time over the candidates) against ``score`` node by
node; ``is_near_<class>`` (one ball query per scene) against ``neighbours_of_class``; the
committed-label class mask read from the belief table against ``graph.probability`` node by node;
the array build against a row-by-row reading of the attributes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.errors import UnknownNodeError, UnknownPredicateError
from sgbelief.graph.scene_graph import SceneGraph
from sgbelief.query import DEFAULT_REGISTRY, GeometryContext, QueryEngine, RelationConfig
from sgbelief.query.language import Compound, Literal

LABELS = ["car", "person", "floor", "wall", "chair", "table", None]
BELIEFS = ["is_car", "is_pedestrian", "is_chair"]
GEOMETRIC = ["is_near_pedestrian", "is_near_car", "is_stationary", "is_near_road_px", "is_workspace_height"]


class PerNodeGraph(SceneGraph):
    """A SceneGraph whose probability/node_attrs are overridden (same values): the engine and the
    context must then ask node by node, which is the reference here."""

    def probability(self, node, predicate):  # noqa: ANN001, ANN201
        return super().probability(node, predicate)

    def node_attrs(self, node):  # noqa: ANN001, ANN201
        return super().node_attrs(node)


def random_graph(seed: int, n: int, cls: type[SceneGraph] = SceneGraph) -> SceneGraph:
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
    # and through the public entry points, against a graph that forces the per-node reads
    ref = QueryEngine(random_graph(seed, 60, PerNodeGraph), config=cfg)
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


@pytest.mark.parametrize("commit_tau", [0.3, 0.5, 0.7])
def test_committed_class_mask_reads_the_belief_table(commit_tau: float) -> None:
    cfg = RelationConfig(commit_tau=commit_tau)
    fast = GeometryContext(random_graph(3, 200), cfg)
    slow = GeometryContext(random_graph(3, 200, PerNodeGraph), cfg)
    assert fast._committed("is_car") is not None and slow._committed("is_car") is None
    for cls_name in ("car", "pedestrian", "chair", "table"):
        assert np.array_equal(fast.class_mask(cls_name), slow.class_mask(cls_name))


def test_arrays_match_a_row_by_row_reading() -> None:
    for seed in range(4):
        fast = GeometryContext(random_graph(seed, 120), None)
        slow = GeometryContext(random_graph(seed, 120, PerNodeGraph), None)
        fast._build()
        slow._build()
        for name in ("lo", "hi", "has_box", "structural", "floor_z"):
            assert np.array_equal(getattr(fast, name), getattr(slow, name), equal_nan=True), name
        assert fast.labels == slow.labels and fast.scenes == slow.scenes and fast.index == slow.index
        assert fast.groups.keys() == slow.groups.keys()
        assert all(np.array_equal(fast.groups[s], slow.groups[s]) for s in fast.groups)
        # groups: every node once, ascending within its scene, scenes in order of first appearance
        g = random_graph(seed, 120)
        firsts = list(dict.fromkeys(g.node_attrs(v).get("scene") for v in g.nodes()))
        assert list(fast.groups) == firsts
        for s, ix in fast.groups.items():
            assert list(ix) == [i for i, v in enumerate(g.nodes()) if g.node_attrs(v).get("scene") == s]


def test_unusual_boxes_fall_back_to_numpy_rules() -> None:
    # attributes set on the live dicts (add_node would have checked them)
    g = SceneGraph()
    for v in ("arr", "scalar_rows", "extra_row", "cent", "none"):
        g.add_node(v)
    g.node_attrs("arr")["bbox"] = np.array([[0.0, 0, 0], [1, 1, 1]])
    g.node_attrs("scalar_rows")["bbox"] = (0.5, 2.0)  # broadcast: lo = (0.5,)*3, hi = (2.0,)*3
    g.node_attrs("extra_row")["bbox"] = ((0, 0, 0), (1, 2, 3), (9, 9, 9))  # only the first two rows count
    g.node_attrs("cent")["centroid"] = np.array([4.0, 5.0, 6.0])
    ctx = GeometryContext(g)
    ctx._build()
    assert ctx.lo.tolist()[:4] == [[0, 0, 0], [0.5] * 3, [0, 0, 0], [4, 5, 6]]
    assert ctx.hi.tolist()[:4] == [[1, 1, 1], [2.0] * 3, [1, 2, 3], [4, 5, 6]]
    assert all(math.isnan(x) for x in ctx.lo[4]) and not ctx.has_box[4]
    bad = SceneGraph()
    bad.add_node("a")
    bad.node_attrs("a")["bbox"] = (("x", 0, 0), (1, 1, 1))
    with pytest.raises(ValueError):
        GeometryContext(bad)._build()


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

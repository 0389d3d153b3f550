"""refer(): each relation on small hand-made scenes, class matching, scenes, beliefs, invariants."""

from __future__ import annotations

import math
import warnings

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief import SceneGraph
from sgbelief.query import refer
from sgbelief.query.referring import NodeTable, ReferError, ReferringQuery


def box(x: float, y: float, w: float = 0.4, d: float = 0.4, h: float = 0.5, z: float = 0.0):
    return ((x, y, z), (x + w, y + d, z + h))


def room(graph: SceneGraph | None = None, scene: str = "s0") -> SceneGraph:
    g = graph if graph is not None else SceneGraph()
    add = lambda n, lab, b, **kw: g.add_node(f"{scene}/{n}", bbox=b, label=lab, scene=scene, **kw)  # noqa: E731
    add("wall_w", "wall", ((-0.1, 0, 0), (0, 6, 2.5)))
    add("wall_e", "wall", ((6, 0, 0), (6.1, 6, 2.5)))
    add("wall_s", "wall", ((0, -0.1, 0), (6, 0, 2.5)))
    add("wall_n", "wall", ((0, 6, 0), (6, 6.1, 2.5)))
    add("door", "doors", box(5.9, 2.0, 0.1, 0.9, 2.0))
    add("can1", "trash can", box(4.8, 2.2))
    add("can2", "trash can", box(1.0, 4.5))
    add("can3", "trash can", box(0.5, 0.5))
    add("bed", "bed", ((2.0, 4.0, 0.0), (3.6, 6.0, 0.6)), front=(0.0, -1.0))
    add("ns_w", "nightstand", ((1.4, 5.5, 0.0), (1.85, 5.95, 0.55)))
    add("ns_e", "nightstand", ((3.75, 5.5, 0.0), (4.2, 5.95, 0.55)))
    add("lamp", "lamp", ((1.5, 5.6, 0.55), (1.75, 5.85, 1.0)))
    add("pillow", "pillow", ((2.5, 5.4, 0.58), (3.0, 5.8, 0.75)))
    add("picture", "picture", ((2.4, 5.95, 1.3), (3.2, 6.0, 1.8)))
    add("desk", "desk", ((0.0, 1.5, 0.0), (0.7, 3.0, 0.75)))
    add("sofa", "sofa", ((4.0, 0.0, 0.0), (6.0, 0.9, 0.8)))
    add("box_mid", "box", ((2.0, 1.8, 0.0), (2.4, 2.2, 0.4)))
    add("box_far", "box", ((3.0, 3.2, 0.0), (3.3, 3.5, 0.3)))
    add("monitor", "monitor", ((0.1, 2.0, 0.76), (0.3, 2.6, 1.2)))
    return g


@pytest.mark.parametrize("utterance,best", [
    ("select the trash can that is closest to the doors", "s0/can1"),
    ("the trash can that is farthest from the doors", "s0/can3"),
    ("the trash cans near the door", "s0/can1"),  # plural and singular find "trash can" / "doors"
    ("the TrashCan that is far away from the doors", "s0/can3"),
    ("the box in the middle of the desk and the sofa", "s0/box_mid"),
    ("the pillow on top of the bed", "s0/pillow"),
    ("the desk with %anchor_article% monitor on top of it", "s0/desk"),
    ("the nightstand that is supporting the lamp", "s0/ns_w"),
    ("the picture above the bed", "s0/picture"),
    ("the lamp that is above the nightstand", "s0/lamp"),
    # the bed faces -y (its front attribute): a viewer facing it looks along +y, their left is -x
    ("facing the front of the bed, the nightstand on its left", "s0/ns_w"),
    ("facing the front of the bed, choose the nightstand that is on the right of it", "s0/ns_e"),
])
def test_relations_pick_the_referent(utterance: str, best: str) -> None:
    ans = refer(room(), utterance)
    assert ans.best == best, ans.explain()
    assert math.isclose(sum(p for _, p in ans.ranked), 1.0)
    assert [p for _, p in ans.ranked] == sorted((p for _, p in ans.ranked), reverse=True)


def test_front_without_orientation_comes_from_the_room() -> None:
    """Without a front attribute the bed's head is at the wall, so its front is -y as before."""
    g = room()
    del g.node_attrs("s0/bed")["front"]
    ans = refer(g, "facing the front of the bed, the nightstand on its left")
    assert ans.best == "s0/ns_w", ans.explain()
    top = ans.anchors[0]
    assert top.front == (0.0, -1.0) and top.weight > 0.5


def test_structured_query_and_explain() -> None:
    ans = refer(room(), ReferringQuery(target="trash can", relation="closest", anchors=["doors"]))
    assert ans.best == "s0/can1" and ans.probability == 1.0
    text = ans.explain()
    assert "answer: s0/can1" in text and "distance=" in text and "s0/door" in text
    d = ans.to_dict()
    assert d["best"] == "s0/can1" and d["query"]["relation"] == "closest" and len(d["candidates"]) == 3


def test_exact_label_tier_keeps_distinct_categories_apart() -> None:
    g = SceneGraph()
    g.add_node("a", bbox=box(0, 0), label="cabinet", scene="s")
    g.add_node("b", bbox=box(3, 0), label="cabinets", scene="s")
    g.add_node("c", bbox=box(5, 0), label="cabinets", scene="s")
    g.add_node("d", bbox=box(6, 0), label="door", scene="s")
    assert refer(g, "the cabinets closest to the door").best == "c"
    assert refer(g, "the cabinets farthest from the door").best == "b"   # "cabinet" is not a candidate
    assert refer(g, "the cabinet closest to the door").best == "a"


def test_networkx_graph_and_missing_classes() -> None:
    g = nx.Graph()
    g.add_node(1, bbox=box(0, 0), label="chair", scene="x")
    g.add_node(2, bbox=box(2, 0), label="chair", scene="x")
    g.add_node(3, bbox=box(3, 0), label="table", scene="x")
    assert refer(g, "the chair closest to the table").best == 2
    ans = refer(g, "the piano closest to the table")
    assert ans.best is None and ans.ranked == () and "piano" in ans.explain()


def test_scenes_are_never_mixed_and_can_be_pinned() -> None:
    g = room(scene="s0")
    room(g, scene="s1")
    g.add_node("s2/can", bbox=box(0, 0), label="trash can", scene="s2")  # no doors in s2
    with pytest.warns(UserWarning, match="2 scenes hold"):
        ans = refer(g, "the trash can closest to the doors")
    assert ans.scene in ("s0", "s1") and ans.best.startswith(ans.scene + "/")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert refer(g, "the trash can closest to the doors", scene="s1").best == "s1/can1"
    with pytest.raises(ReferError, match="scene 'nowhere'"):
        refer(g, "the trash can closest to the doors", scene="nowhere")
    index = NodeTable.from_graph(g)
    assert refer(g, "the trash can closest to the doors", scene="s0", index=index).best == "s0/can1"


def test_beliefs_count_as_membership_in_expectation() -> None:
    """Unlabelled nodes with committed beliefs: P(v) = p_v prod_{nearer u} (1 - p_u), normalised."""
    g = SceneGraph()
    g.add_node("door", bbox=box(10, 0), label="door", scene="s")
    for name, x in (("near", 8.0), ("mid", 5.0), ("far", 1.0)):
        g.add_node(name, bbox=box(x, 0), scene="s")
    # Beta(1 + a, 1): means 0.75, 0.889, 0.944 (the only class belief of each node)
    for name, a in (("near", 2.0), ("mid", 7.0), ("far", 16.0)):
        g.provenance.record(name, "is_chair", f"e_{name}", 0, a, 0.0)
    p = {n: g.probability(n, "is_chair") for n in ("near", "mid", "far")}
    ans = refer(g, "the chair closest to the door")
    expect = {"near": p["near"], "mid": p["mid"] * (1 - p["near"]),
              "far": p["far"] * (1 - p["near"]) * (1 - p["mid"])}
    z = sum(expect.values())
    got = dict(ans.ranked)
    for n in expect:
        assert got[n] == pytest.approx(expect[n] / z, rel=1e-9)
    assert ans.best == "near"
    assert refer(g, "the chair closest to the door", use_beliefs=False).best is None


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 9), st.floats(0, 9)), min_size=2, max_size=7, unique=True),
       st.tuples(st.floats(0, 9), st.floats(0, 9)), st.booleans())
def test_certain_labels_reduce_to_the_geometric_answer(xy, anchor_xy, farthest) -> None:
    g = SceneGraph()
    g.add_node("a", bbox=box(*anchor_xy, w=0.3, d=0.3), label="lamp", scene="s")
    for i, (x, y) in enumerate(xy):
        g.add_node(f"c{i}", bbox=box(x, y, w=0.3, d=0.3), label="chair", scene="s")
    word = "farthest from" if farthest else "closest to"
    ans = refer(g, f"the chair {word} the lamp")
    t = NodeTable.from_graph(g)
    t.load_scene("s")
    from sgbelief.query.referring.geometry import effective_distance
    ix = [t.position[f"c{i}"] for i in range(len(xy))]
    d = effective_distance(t.lo[ix], t.hi[ix], t.lo[t.position["a"]], t.hi[t.position["a"]])
    order = np.lexsort((np.arange(len(d)), -d if farthest else d))
    assert ans.best == f"c{order[0]}"
    assert dict(ans.ranked)[ans.best] == 1.0
    assert sum(p for _, p in ans.ranked) == pytest.approx(1.0)


def test_scene_choice_follows_the_utterance_presuppositions() -> None:
    """Two scenes hold trash cans and doors; only s0 has one door and a clear nearest can."""
    g = SceneGraph()
    g.add_node("s1/door1", bbox=box(0, 0), label="doors", scene="s1")
    g.add_node("s1/door2", bbox=box(5, 0), label="doors", scene="s1")
    g.add_node("s1/can1", bbox=box(1, 0), label="trash can", scene="s1")
    g.add_node("s1/can2", bbox=box(4, 0), label="trash can", scene="s1")
    g.add_node("s0/door", bbox=box(0, 0), label="doors", scene="s0")
    g.add_node("s0/can1", bbox=box(1, 0), label="trash can", scene="s0")
    g.add_node("s0/can2", bbox=box(4, 0), label="trash can", scene="s0")
    with pytest.warns(UserWarning):
        assert refer(g, "the trash can closest to the doors").best == "s0/can1"


def test_flat_and_array_boxes_are_read() -> None:
    g = nx.Graph()
    g.add_node("a", bbox=[0, 0, 0, 0.4, 0.4, 0.5], label="chair", scene="x")
    g.add_node("b", bbox=np.array([[3, 0, 0], [3.4, 0.4, 0.5]]), label="chair", scene="x")
    g.add_node("t", bbox=[[4, 0, 0], [5, 1, 0.7]], label="table", scene="x")
    assert refer(g, "the chair closest to the table").best == "b"
    assert refer(g, "the chair farthest from the table").best == "a"

from __future__ import annotations

import pytest

from sgbelief.errors import ConfigError, UnknownPredicateError
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.query import DEFAULT_REGISTRY, GeometryContext, RelationConfig, RelationRegistry, materialise_relations
from sgbelief.query.relations import box_distance, Box

import numpy as np


def room() -> SceneGraphModel:
    """A 6 x 6 m room: desk with a monitor, empty table, chairs, window, bookshelves."""
    g = SceneGraphModel()
    add = lambda n, lab, lo, hi, **kw: g.add_node(n, bbox=(lo, hi), label=lab, scene="r", **kw)  # noqa: E731
    add("floor", "floor", (-3, -3, -0.01), (3, 3, 0.0))
    add("desk", "desk", (0, 0, 0), (1.2, 0.6, 0.74))
    add("monitor", "otherprop", (0.3, 0.2, 0.74), (0.8, 0.3, 1.1))
    add("table", "table", (-2.5, -2.5, 0), (-1.5, -1.9, 0.75))
    add("low_table", "table", (2.0, -2.5, 0), (2.6, -2.0, 0.4))
    add("chair", "chair", (0.3, 0.8, 0), (0.8, 1.3, 0.95))
    add("far_chair", "chair", (-2.8, 2.0, 0), (-2.3, 2.5, 0.9))
    add("window", "window", (1.6, -0.5, 0.9), (1.7, 1.0, 2.0))
    # bookshelf along the wall at y = 2.7..3, facing -y, a sofa in front at 2 m
    add("shelf", "bookshelf", (0.0, 2.7, 0), (1.5, 3.0, 2.0))
    add("sofa", "sofa", (0.0, 0.0 + 1.6, 0), (1.5, 0.6 + 1.6, 0.8))
    # a blocked bookshelf: boxes piled in front on both long sides
    add("shelf2", "bookshelf", (-3.0, -1.0, 0), (-2.7, 0.5, 2.0))
    add("box_a", "box", (-2.65, -1.0, 0), (-2.2, 0.5, 1.0))
    add("box_b", "box", (-3.5, -1.0, 0), (-3.05, 0.5, 1.0))
    return g


def ev(g, name, node, config=None):
    ctx = GeometryContext(g, config)
    return DEFAULT_REGISTRY.get(name)(ctx, node)


def test_box_distance():
    a = Box(np.zeros(3), np.ones(3))
    assert box_distance(a, Box(np.array([2.0, 0, 0]), np.array([3.0, 1, 1]))) == pytest.approx(1.0)
    assert box_distance(a, Box(np.array([0.5, 0.5, 0.5]), np.array([3.0, 1, 1]))) == 0.0


def test_is_near_class_family():
    g = room()
    assert ev(g, "is_near_window", "chair") is True  # 0.8 m gap
    assert ev(g, "is_near_window", "far_chair") is False
    assert ev(g, "is_near_window", "chair", RelationConfig(near_distance=0.5)) is False
    assert ev(g, "is_near_window", "window") is False  # never near itself


def test_is_near_uses_aliases_and_scene_boundaries():
    g = SceneGraphModel()
    g.add_node("car", bbox=((0, 0, 0), (4, 2, 1.5)), label="car", scene="a")
    g.add_node("p", bbox=((6, 0, 0), (6.5, 0.5, 1.8)), label="person", scene="a")
    g.add_node("car_b", bbox=((0, 0, 0), (4, 2, 1.5)), label="car", scene="b")
    cfg = RelationConfig(near_distance=5.0)
    assert ev(g, "is_near_pedestrian", "car", cfg) is True
    assert ev(g, "is_near_pedestrian", "car_b", cfg) is False  # the person is in another scene


def test_is_near_committed_labels():
    g = SceneGraphModel()
    g.add_node("c", bbox=((0, 0, 0), (0.5, 0.5, 0.9)))
    g.add_node("w", bbox=((0.8, 0, 1), (0.9, 1, 2)))
    assert ev(g, "is_near_window", "c") is False
    # without a label, a committed belief on is_window makes w a window
    _commit(g, "w", "is_window")
    assert ev(g, "is_near_window", "c") is True
    assert ev(g, "is_near_window", "c", RelationConfig(use_committed_labels=False)) is False


def _commit(g, node, predicate):
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.api.operators import make_operator

    op = make_operator("naive_bayes")
    for t in range(5):
        op.update(g, EvidenceEvent({node: 1.0}, predicate, 0.95, t=t))
    assert g.probability(node, predicate) > 0.5


def test_workspace_height():
    g = room()
    assert ev(g, "is_workspace_height", "desk") is True  # 0.74 m
    assert ev(g, "is_workspace_height", "low_table") is False  # 0.4 m
    assert ev(g, "is_workspace_height", "shelf") is False  # 2.0 m
    assert ev(g, "is_workspace_height", "low_table", RelationConfig(workspace_band=(0.3, 0.5))) is True


def test_on_top_of_and_unobstructed():
    g = room()
    assert ev(g, "is_on_top_of", "monitor") is True
    assert ev(g, "is_on_top_of", "chair") is False  # on the floor: floor is structural
    assert ev(g, "is_on_top_of_desk", "monitor") is True
    assert ev(g, "is_on_top_of_table", "monitor") is False
    assert ev(g, "is_unobstructed", "desk") is False
    assert ev(g, "is_unobstructed", "table") is True
    # a hovering box is not "on"
    g.add_node("hover", bbox=((2.1, -2.4, 0.6), (2.3, -2.2, 0.8)), label="box", scene="r")
    assert ev(g, "is_unobstructed", "low_table") is True
    assert ev(g, "is_on_top_of", "hover") is False


def test_accessible():
    g = room()
    assert ev(g, "is_accessible", "shelf") is True
    assert ev(g, "is_accessible", "shelf2") is False  # both long sides blocked
    # with an explicit front pointing at the free short side (-y): accessible again
    g.add_node("shelf2", front=(0.0, -1.0, 0.0))
    assert ev(g, "is_accessible", "shelf2") is True


def test_facing_seating():
    g = room()
    assert ev(g, "is_facing_seating", "shelf") is True  # sofa 0.5 m in front (-y)
    g.add_node("shelf", front=(0.0, 1.0, 0.0))  # facing the wall instead
    assert ev(g, "is_facing_seating", "shelf") is False
    # shelf2 faces +-x: the sofa is 2.9 m away inside the +x cone, the far chair is off-axis
    assert ev(g, "is_facing_seating", "shelf2") is True
    assert ev(g, "is_facing_seating", "shelf2", RelationConfig(facing_distance=2.0)) is False
    assert ev(g, "is_facing_seating", "shelf", RelationConfig(facing_half_angle_deg=180.0)) is True


def outdoor() -> SceneGraphModel:
    g = SceneGraphModel()
    g.add_node("parked", centroid=(0, 0, 0), label="car", scene="d",
               track=[[0, 0.0, 0.0, 0.0], [1, 0.1, 0.0, 0.0], [2, 0.05, 0.1, 0.0]], road_distance_px=12.0)
    g.add_node("moving", centroid=(0, 0, 0), label="car", scene="d",
               track=[[0, 0.0, 0.0, 0.0], [1, 5.0, 0.0, 0.0], [2, 10.0, 0.0, 0.0]], road_distance_px=400.0)
    g.add_node("ped", centroid=(0, 0, 0), label="person", scene="d2",
               attributes={"on_sidewalk": True, "at_intersection": False, "visible_in_drive_direction": True})
    g.add_node("sign", centroid=(0, 0, 0), label="traffic sign", scene="d3", intersection_distance=40.0,
               speed=0.0)
    g.add_node("bare", scene="d4")
    return g


def test_outdoor_predicates():
    g = outdoor()
    assert ev(g, "is_stationary", "parked") is True
    assert ev(g, "is_stationary", "moving") is False
    assert ev(g, "is_stationary", "sign") is True  # from speed
    assert ev(g, "is_near_road_px", "parked") is True
    assert ev(g, "is_near_road_px", "moving") is False
    assert ev(g, "is_on_sidewalk", "ped") is True  # nested attributes dict
    assert ev(g, "is_at_intersection", "ped") is False
    assert ev(g, "is_at_intersection", "sign") is False
    assert ev(g, "is_at_intersection", "sign", RelationConfig(intersection_radius=50.0)) is True
    assert ev(g, "is_visible_in_drive_direction", "ped") is True
    for name in ("is_stationary", "is_near_road_px", "is_on_sidewalk", "is_at_intersection",
                 "is_visible_in_drive_direction", "is_workspace_height", "is_near_window"):
        assert ev(g, name, "bare") is None  # missing attribute: undecidable


def test_registry_extension_decorator_and_errors():
    reg = DEFAULT_REGISTRY.copy()

    @reg.predicate("is_tall", needs=("bbox",))
    def is_tall(ctx, node):
        """Box height >= extra['tall'] (default 1.5 m)."""
        box = ctx.box(node)
        return None if box is None else box.size[2] >= ctx.config.extra.get("tall", 1.5)

    g = room()
    assert reg.get("is_tall")(GeometryContext(g), "shelf") is True
    assert reg.get("is_tall")(GeometryContext(g), "desk") is False
    assert "is_tall" not in DEFAULT_REGISTRY
    with pytest.raises(ConfigError):
        reg.register("is_tall", is_tall)
    reg.register("is_tall", lambda ctx, n: True, replace=True)
    with pytest.raises(UnknownPredicateError) as ei:
        reg.get("is_nope")
    assert "is_near_<class>" in str(ei.value) and "is_tall" in str(ei.value)
    assert ("is_tall", (), "") in reg.describe() or any(d[0] == "is_tall" for d in reg.describe())
    empty = RelationRegistry()
    assert "is_accessible" not in empty


def test_config_from_mapping():
    cfg = RelationConfig.from_mapping({"near_distance": 2, "workspace_band": [0.5, 1.0],
                                       "class_aliases": {"pedestrian": ["walker"]}})
    assert cfg.near_distance == 2.0 and cfg.workspace_band == (0.5, 1.0)
    assert cfg.labels_of("pedestrian") == {"pedestrian", "walker"}
    assert "chair" in cfg.labels_of("seating")
    with pytest.raises(ConfigError, match="unknown key"):
        RelationConfig.from_mapping({"nearr": 1})


def test_materialise_relations_edges():
    g = room()
    n = materialise_relations(g)
    on = {(u, v) for u, v, r, _ in g.relations(relation="on")}
    assert on == {("monitor", "desk")}
    near = {(u, v) for u, v, r, _ in g.relations(relation="near")}
    assert ("chair", "window") in near and ("window", "chair") in near
    assert ("chair", "far_chair") not in near
    assert not any("floor" in (u, v) for u, v in near)
    assert n == len(on) + len(near)
    assert materialise_relations(g) == n  # idempotent (edge key = relation)
    assert len(g.relations(relation="near")) == len(near)

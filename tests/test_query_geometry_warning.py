"""The missing-geometry warning reads a node's attributes as the query evaluates them: nested
``attributes`` (a nodes.json entry's) and precomputed ``geometric_predicates`` (what replay
saves), so a map that can answer a geometric predicate is not said to lack it."""

from __future__ import annotations

import warnings

import pytest

from sgbelief import SceneGraph
from sgbelief.query.engine import MissingGeometryWarning, missing_attributes


def _graph(**attrs_of: dict) -> SceneGraph:
    g = SceneGraph()
    for node, attrs in attrs_of.items():
        g.add_node(node, **attrs)
        g.provenance.record(node, "is_pedestrian", f"e-{node}", 0, 4.0, 0.0)  # Beta(5, 1)
    return g


def test_nested_attributes_count_as_present() -> None:
    assert missing_attributes({"attributes": {"road_distance_px": 3.0}}, ["road_distance_px|near_road"]) == []
    assert missing_attributes({"attributes": {"road_distance_px": None}}, ["road_distance_px|near_road"]) == [
        "road_distance_px|near_road"]
    assert missing_attributes({}, ["on_sidewalk", "scene", "front?"]) == ["on_sidewalk"]


def test_no_warning_when_the_query_can_evaluate_every_candidate() -> None:
    g = _graph(
        nested={"attributes": {"road_distance_px": 2.0, "on_sidewalk": True}},
        pre={"geometric_predicates": {"is_near_road_px": True, "is_on_sidewalk": True}},
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error", MissingGeometryWarning)
        got = g.query("is_pedestrian & is_on_sidewalk & is_near_road_px")
    assert sorted(m.node for m in got) == ["nested", "pre"]


def test_a_node_that_truly_lacks_the_attribute_is_still_named() -> None:
    g = _graph(
        pre={"geometric_predicates": {"is_near_road_px": True}},
        bare={"label": "pedestrian"},
    )
    with pytest.warns(MissingGeometryWarning, match="is_near_road_px: 1 of 2 candidate nodes"):
        got = g.query("is_pedestrian & is_near_road_px")
    assert [m.node for m in got] == ["pre"]


def test_a_precomputed_none_is_not_a_value() -> None:
    g = _graph(unknown={"geometric_predicates": {"is_near_road_px": None}})
    with pytest.warns(MissingGeometryWarning, match="1 of 1"):
        assert len(g.query("is_pedestrian & is_near_road_px")) == 0

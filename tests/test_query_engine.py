from __future__ import annotations

import pytest

from sgbelief import SceneGraph
from sgbelief.query import P, QueryEngine, QueryPredicateError, run_query


def setb(g, node, pred, a, b):
    """Give (node, pred) the belief Beta(a, b) (prior Beta(1, 1) + one entry)."""
    g.provenance.record(node, pred, f"e-{node}-{pred}", 0, a - 1.0, b - 1.0)


@pytest.fixture
def city() -> SceneGraph:
    g = SceneGraph()
    # three cars: parked near the road, parked far from the road, moving on the road
    g.add_node("c1", centroid=(0, 0, 0), bbox=((0, 0, 0), (4, 2, 1.5)), label="car", scene="s",
               road_distance_px=10.0, stationary=True)
    g.add_node("c2", centroid=(50, 0, 0), bbox=((50, 0, 0), (54, 2, 1.5)), label="car", scene="s",
               road_distance_px=300.0, stationary=True)
    g.add_node("c3", centroid=(100, 0, 0), bbox=((100, 0, 0), (104, 2, 1.5)), label="car", scene="s",
               road_distance_px=0.0, stationary=False)
    g.add_node("p1", bbox=((101, 3, 0), (101.5, 3.5, 1.8)), label="person", scene="s", road_distance_px=40.0,
               stationary=False)
    g.add_node("x", centroid=(200, 0, 0), scene="s", road_distance_px=5.0, stationary=True)  # no evidence
    setb(g, "c1", "is_car", 9, 1)  # 0.9
    setb(g, "c2", "is_car", 4, 1)  # 0.8
    setb(g, "c3", "is_car", 3, 1)  # 0.75
    setb(g, "p1", "is_car", 1, 4)  # 0.2
    setb(g, "c1", "is_pedestrian", 1, 3)  # 0.25
    return g


def test_hand_computed_compound(city):
    res = run_query(city, "is_car & is_stationary & is_near_road_px & !is_near_pedestrian")
    assert res.nodes == ["c1"]
    m = res[0]
    assert m.probability == pytest.approx(0.9)
    kinds = {c.name: c.kind for c in m.components}
    assert kinds == {"is_car": "belief", "is_stationary": "geometric", "is_near_road_px": "geometric",
                     "is_near_pedestrian": "geometric"}
    assert [c.factor for c in m.components] == [pytest.approx(0.9), 1.0, 1.0, 1.0]
    assert "retrieved" in m.explain() and "[belief]" in m.explain() and "[geometric" in m.explain()


def test_negated_belief_and_product(city):
    # P = p(car) * (1 - p(pedestrian)); c1: 0.9 * 0.75 = 0.675; others: no pedestrian evidence -> x 0.5
    eng = QueryEngine(city)
    probs = eng.probabilities("is_car & !is_pedestrian")
    assert probs["c1"] == pytest.approx(0.675)
    assert probs["c2"] == pytest.approx(0.4)
    assert probs["c3"] == pytest.approx(0.375)
    res = eng.evaluate("is_car & !is_pedestrian")
    assert res.nodes == ["c1"]


def test_ranking_tau_and_candidates(city):
    res = run_query(city, "is_car", tau=0.5)
    assert res.nodes == ["c1", "c2", "c3"]  # p1 (0.2) below tau; x has no evidence
    assert [round(m.probability, 3) for m in res] == [0.9, 0.8, 0.75]
    assert run_query(city, "is_car", tau=0.85).nodes == ["c1"]
    assert run_query(city, "is_car", tau=0.8).nodes == ["c1"]  # P > tau, strictly: c2 sits at 0.8
    allres = run_query(city, "is_car", include_all=True)
    assert allres.nodes == ["c1", "c2", "c3", "p1"]
    assert not allres[-1].retrieved
    # without the evidence requirement the prior-only node scores 0.5: not above tau = 0.5, above 0.4
    assert "x" not in run_query(city, "is_car & is_stationary", require_evidence=False).nodes
    assert "x" in run_query(city, "is_car & is_stationary", tau=0.4, require_evidence=False).nodes


def test_geometric_with_negation_and_near(city):
    res = run_query(city, "is_car & !is_stationary & is_near_road_px")
    assert res.nodes == ["c3"] and res[0].probability == pytest.approx(0.75)
    # c3 is 1 m from the person: with a 5 m bound, "car near pedestrian" holds only for c3
    from sgbelief.query import RelationConfig

    res = run_query(city, "is_car & is_near_pedestrian", config=RelationConfig(near_distance=5.0))
    assert res.nodes == ["c3"]


def test_undecidable_geometry_is_zero_in_both_polarities(city):
    city.add_node("c4", centroid=(300, 0, 0), scene="s")  # no road distance attribute
    setb(city, "c4", "is_car", 9, 1)
    eng = QueryEngine(city)
    assert eng.explain("is_car & is_near_road_px", "c4").probability == 0.0
    m = eng.explain("is_car & !is_near_road_px", "c4")
    assert m.probability == 0.0 and m.components[1].value is None
    assert "undecidable" in m.explain()


def test_builder_same_answer(city):
    a = run_query(city, P("is_car") & P("is_stationary") & ~P("is_near_pedestrian"))
    b = run_query(city, "is_car & is_stationary & !is_near_pedestrian")
    assert a.nodes == b.nodes and [m.probability for m in a] == [m.probability for m in b]


def test_unknown_predicate_lists_known_and_points(city):
    with pytest.raises(QueryPredicateError) as ei:
        run_query(city, "is_car & is_statonary")
    msg = str(ei.value)
    assert ei.value.position == 9
    assert "is_stationary" in msg and "is_car" in msg and "is_near_<class>" in msg
    assert msg.splitlines()[-1].strip() == "^" * len("is_statonary")


def test_per_component_reuse_reads_each_belief_once(city):
    eng = QueryEngine(city)
    exprs = ["is_car & is_stationary", "is_car & is_near_road_px", "is_car & !is_stationary & is_near_road_px",
             "is_car & !is_pedestrian"]
    eng.evaluate_many(exprs)
    # is_car: 4 nodes with evidence, is_pedestrian: read only where is_car passes -> <= 4 + 4 reads
    assert eng.belief_reads <= 8
    before = (eng.belief_reads, eng.geometric_evals)
    eng.evaluate_many(exprs)
    assert (eng.belief_reads, eng.geometric_evals) == before  # second batch: all cached
    n_prov = city.evidence_count()
    assert city.evidence_count() == n_prov  # nothing written


def test_named_query_and_result_dict(city):
    res = run_query(city, "parked car near crossing")
    assert res.name == "parked_car_near_crossing" and res.nodes == ["c1"]
    d = res.to_dict()
    assert d["query"] == "parked_car_near_crossing"
    assert d["components"][0] == {"predicate": "is_car", "negated": False, "kind": "belief"}
    assert d["results"][0]["node"] == "c1"
    assert "c1" in res.table()


def test_scene_graph_query_method(city):
    assert city.query("is_car & is_stationary", tau=0.85).nodes == ["c1"]


def test_operator_probability_hook(city):
    eng = QueryEngine(city, probability=lambda n, p: 0.6)
    assert eng.probabilities("is_car")["c3"] == pytest.approx(0.6)


def test_precomputed_geometric_values_override(city):
    city.add_node("c2", geometric_predicates={"is_near_road_px": True})
    assert "c2" in run_query(city, "is_car & is_near_road_px").nodes

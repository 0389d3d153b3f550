"""SceneGraph API, merges, and lossless atomic persistence with clear errors on bad files (through the
public class's ``save`` / ``load``; the model class is tested in tests/test_api_scene_graph.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.errors import FormatError, UnknownNodeError, UnknownPredicateError
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.api.operators import make_operator
from sgbelief.graph.provenance import EntryStatus
from sgbelief import SceneGraph
from sgbelief.testing import conformance_table, random_stream
from sgbelief.fusion.channel import FrameLabels


def _graph() -> SceneGraph:
    g = SceneGraph()
    g.add_node("chair1", centroid=(0, 0, 0.5), bbox=((-0.3, -0.3, 0), (0.3, 0.3, 1.0)), label="chair", scene="s0")
    g.add_node("table1", centroid=(1, 0, 0.4))
    g.add_node(3)
    g.add_relation("chair1", "table1", "near", distance=0.7)
    return g


def test_nodes_relations_and_raw_networkx() -> None:
    g = _graph()
    assert len(g) == 3 and "chair1" in g and g.find_node("nope") is None
    assert g.node_attrs("chair1")["bbox"] == ((-0.3, -0.3, 0.0), (0.3, 0.3, 1.0))
    with pytest.raises(UnknownNodeError):
        g.node_attrs("nope")
    assert g.relations("chair1") == [("chair1", "table1", "near", {"relation": "near", "distance": 0.7})]
    assert g.nx.has_edge("chair1", "table1")  # the raw graph stays usable
    with pytest.raises(TypeError):
        g.add_node((1, 2))  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        g.add_node("x", bbox=((1, 1, 1), (0, 0, 0)))


def test_beliefs_and_commit_threshold_is_strict() -> None:
    g = _graph()
    assert g.belief("chair1", "is_chair").mean == 0.5
    assert g.committed("is_chair") == set()
    g.provenance.record("chair1", "is_chair", "e", 0, 1.0, 0.0)
    g.provenance.record("table1", "is_chair", "f", 0, 0.5, 0.5)  # mean exactly 0.5: not committed
    assert g.committed("is_chair") == {"chair1"}
    assert g.probability("chair1", "is_chair") == pytest.approx(2 / 3)
    assert g.predicates() == ["is_chair"]
    assert set(g.beliefs("chair1")) == {"is_chair"}


def test_vocabulary_makes_predicates_strict() -> None:
    g = SceneGraph(vocabulary=SubsumptionTable.shipped("scannet"))
    g.add_node("a")
    with pytest.raises(UnknownPredicateError, match="is_chair"):
        g.probability("a", "is_chiar")


def test_merge_nodes_migrates_beliefs_and_edges() -> None:
    g = _graph()
    g.add_node("chair2")
    g.add_relation(3, "chair2", "on")
    g.provenance.record("chair1", "is_chair", "e1", 0, 1.0, 0.0)
    g.provenance.record("chair2", "is_chair", "e2", 1, 0.75, 0.25)
    g.provenance.record("chair2", "is_table_or_desk", "e3", 2, 0.0, 1.0)
    before = g.evidence_count()
    g.merge_nodes("chair1", "chair2")
    assert g.evidence_count() == before
    assert "chair2" not in g
    assert g.belief("chair1", "is_chair").alpha == pytest.approx(2.75)
    assert g.belief("chair1", "is_table_or_desk").beta == pytest.approx(2.0)
    assert (3, "chair1", "on") in [(u, v, k) for u, v, k, _ in g.relations(relation="on")]
    assert g.node_attrs("chair1")["merged_from"] == ["chair2"]


def _run(g: SceneGraph, name: str = "comod") -> None:
    op = make_operator(name, None, conformance_table())
    for ev, labels in random_stream(200, seed=3):
        op.update(g, ev, FrameLabels(labels))


def test_save_load_is_lossless_including_queues(tmp_path: Path) -> None:
    g = _graph()
    _run(g)
    g.provenance.record("chair1", "is_car", "pending-q", g.clock, 5.0, 0.1, EntryStatus.QUARANTINED, stance=1)
    path = g.save(tmp_path / "map")
    assert path.name == "graph.json"
    h = SceneGraph.load(tmp_path / "map")
    assert h.clock == g.clock and h.meta == g.meta
    assert sorted(map(str, h.nodes())) == sorted(map(str, g.nodes()))
    assert h.node_attrs("chair1") == g.node_attrs("chair1")
    for key in g.provenance.pairs():
        assert h.provenance.alpha_beta(*key) == g.provenance.alpha_beta(*key)
        assert [e.as_tuple() for e in h.provenance.entries(*key)] == [e.as_tuple() for e in g.provenance.entries(*key)]
    assert [e.event_id for e in h.provenance.quarantine if e.status is EntryStatus.QUARANTINED] == ["pending-q"]
    assert h.relations() == g.relations()
    # saving is atomic: no temporary files left behind
    assert [p.name for p in (tmp_path / "map").iterdir()] == ["graph.json"]


def test_truncated_or_edited_files_raise_and_keep_state(tmp_path: Path) -> None:
    g = _graph()
    _run(g)
    path = g.save(tmp_path / "g.json")
    text = path.read_text()
    (tmp_path / "trunc.json").write_text(text[: len(text) // 2])
    with pytest.raises(FormatError, match="trunc.json:1"):
        SceneGraph.load(tmp_path / "trunc.json")
    doc = json.loads(text)
    doc["provenance"]["pairs"][0]["alpha"] += 1.0
    (tmp_path / "edited.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="does not equal prior"):
        SceneGraph.load(tmp_path / "edited.json")
    doc = json.loads(text)
    doc["format"] = "something.else"
    (tmp_path / "fmt.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="format"):
        SceneGraph.load(tmp_path / "fmt.json")
    doc = json.loads(text)
    doc["provenance"]["pairs"][0]["entries"][0][4] = "hacked"
    (tmp_path / "status.json").write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="unknown status"):
        SceneGraph.load(tmp_path / "status.json")
    # the graph in memory is untouched, and saving over an existing file is atomic
    assert g.evidence_count() > 0
    g.save(path)
    assert SceneGraph.load(path).evidence_count() == g.evidence_count()


def test_unserialisable_attribute_fails_before_writing(tmp_path: Path) -> None:
    g = _graph()
    g.save(tmp_path / "g.json")
    good = (tmp_path / "g.json").read_text()
    g.node_attrs("chair1")["bad"] = object()
    with pytest.raises(TypeError, match="bad"):
        g.save(tmp_path / "g.json")
    assert (tmp_path / "g.json").read_text() == good


def test_remove_node_drops_beliefs() -> None:
    g = _graph()
    g.provenance.record("chair1", "is_chair", "e1", 0, 1.0, 0.0)
    g.remove_node("chair1")
    assert "chair1" not in g and g.evidence_count() == 0


def test_probabilities_is_probability_per_node() -> None:
    from sgbelief.errors import UnknownNodeError, UnknownPredicateError

    g = SceneGraph(vocabulary={"is_car", "is_chair"})
    for n in ("a", "b", 7):
        g.add_node(n)
    g.provenance.record("a", "is_car", "e1", 0, 2.0, 0.5)
    g.provenance.record(7, "is_car", "e2", 0, 0.25, 3.0)
    nodes = ["a", "b", 7, "a"]
    assert g.probabilities(nodes, "is_car") == [g.probability(n, "is_car") for n in nodes]
    assert g.probabilities(iter(nodes), "is_chair") == [0.5] * 4
    assert g.probabilities([], "is_nothing") == []
    assert g.provenance.means(nodes, "is_car") == [g.provenance.mean(n, "is_car") for n in nodes]
    assert dict(g.provenance.means_with("is_car")) == {"a": g.probability("a", "is_car"), 7: g.probability(7, "is_car")}
    with pytest.raises(UnknownPredicateError):
        g.probabilities(["a"], "is_boat")
    with pytest.raises(UnknownNodeError):
        g.probabilities(["a", "zzz"], "is_car")
    with pytest.raises(UnknownNodeError):
        g.probabilities(["zzz"], "is_boat")  # the node is checked first, as probability() does
    with pytest.raises(UnknownNodeError):
        g.probabilities(["a", ["unhashable"]], "is_car")

    with pytest.raises(UnknownNodeError):
        g.node_attrs(["unhashable"])  # type: ignore[arg-type]


def test_bulk_reads_over_the_whole_map() -> None:
    g = SceneGraph(vocabulary={"is_car"})
    for n in ("a", "b", 7):
        g.add_node(n, label=str(n))
    g.provenance.record(7, "is_car", "e1", 0, 2.0, 0.5)
    table = g.node_attr_table()
    assert list(table) == g.nodes() and all(table[n] is g.node_attrs(n) for n in g.nodes())  # live dicts
    assert g.probabilities(None, "is_car") == [g.probability(n, "is_car") for n in g.nodes()]
    with pytest.raises(UnknownPredicateError):
        g.probabilities(None, "is_boat")
    assert SceneGraph().probabilities(None, "anything") == []  # no node: nothing is checked

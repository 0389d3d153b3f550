"""A belief's story (sgbelief.graph.story, SceneGraph.explain, ``sgbelief explain``): the counts
per status survive compaction, save/load in both formats, and files without fold summaries."""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.api.operators import make_operator
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.cli import main
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.config import OperatorConfig
from sgbelief.graph.compaction import UNKNOWN_STATUS
from sgbelief.graph.provenance_log import EntryStatus
from sgbelief.graph.story import NOT_RECORDED_OLD
from sgbelief.testing import conformance_table, random_stream

TABLE = conformance_table()
NO_COMPACTION = 1_000_000


def _run(name: str, n: int, seed: int, t_prov: int, *, engine: str = "fast", t_compact: int | None = None,
         **extra: Any) -> SceneGraph:
    config = OperatorConfig.from_mapping({"t_prov": t_prov, "t_compact": t_compact, "tau_t": 0.1, **extra})
    op, graph = make_operator(name, config, TABLE, engine=engine), SceneGraph(engine=engine, create_nodes=True)  # type: ignore[arg-type]
    for ev, labels in random_stream(n, n_nodes=5, seed=seed):
        op.update(graph, ev, FrameLabels(labels))
    return graph


def _counts(graph: SceneGraph) -> dict[Any, dict[str, int]]:
    return {key: graph.explain(*key).counts for key in graph.provenance.pairs()}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(["comod", "cal", "majority"]), seed=st.integers(0, 10_000),
       t_prov=st.sampled_from([3, 8, 25]), engine=st.sampled_from(["fast", "reference"]))
def test_counts_per_status_do_not_depend_on_compaction(name: str, seed: int, t_prov: int, engine: str) -> None:
    # the same horizon, and no pass ever runs in the second: T_prov also bounds how long a silent
    # claim's weight follows the consensus refits (sgbelief.fusion.reweigh), so it is held equal.
    # Retroactive withdrawal never reaches a compacted bucket (fusion.queues.withdraw_unadjudicated),
    # so it depends on the passes by design: the forward-only recall is compared here
    recall = {"recalled_verdicts": "unanimous"}
    compacted = _run(name, 150, seed, t_prov, engine=engine, t_compact=max(1, t_prov // 2), **recall)
    full = _run(name, 150, seed, t_prov, engine=engine, t_compact=NO_COMPACTION, **recall)
    assert full.provenance.n_compacted == 0
    assert compacted.provenance.n_compacted > 0
    assert _counts(compacted) == _counts(full)
    for key in compacted.provenance.pairs():
        story, whole = compacted.explain(*key), full.explain(*key)
        assert story.committed == whole.committed and story.sentence.split(" (")[0] == whole.sentence.split(" (")[0]
        if story.folded is not None:
            folded_ids = {e.event_id for e in full.provenance.entries(*key)}  # (an id may also have live entries)
            assert story.folded.n == sum(story.folded.counts.values())
            assert story.folded.first_event_id in folded_ids and story.folded.last_event_id in folded_ids
            assert story.folded.t_first <= story.folded.t_last


@pytest.mark.parametrize("fmt", ["json", "npz"])
@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_story_survives_save_and_load(tmp_path, fmt: str, engine: str) -> None:
    graph = _run("comod", 200, 7, 6)
    path = graph.save(tmp_path / "map", format=fmt)
    again = SceneGraph.load(path, engine=engine)  # type: ignore[arg-type]
    for key in graph.provenance.pairs():
        assert again.explain(*key).to_dict() == graph.explain(*key).to_dict()
    assert any(graph.explain(*k).folded is not None for k in graph.provenance.pairs())


def test_a_file_without_fold_summaries_loads_with_unknown_counts(tmp_path) -> None:
    graph = _run("comod", 200, 3, 6)
    path = graph.save(tmp_path / "map")
    doc = json.loads(path.read_text())
    for pair in doc["provenance"]["pairs"]:
        pair.pop("fold_summary", None)  # what version 1 files written before summaries hold
    path.write_text(json.dumps(doc))
    old = SceneGraph.load(path)
    key = next(k for k in old.provenance.pairs() if graph.explain(*k).folded is not None)
    story = old.explain(*key)
    assert story.folded is not None and story.folded.counts == {UNKNOWN_STATUS: story.folded.n}
    assert "without a record of their status" in story.sentence
    # folding more into an unknown bucket keeps the unknown part and counts the new part
    old.provenance.compact(10**9)
    counts = old.explain(*key).counts
    assert counts[UNKNOWN_STATUS] == story.folded.n and sum(counts.values()) == story.n_entries


def test_sentence_is_strict_at_tau() -> None:
    graph = SceneGraph(vocabulary=["is_car"], create_nodes=True)
    graph.add_node("a")
    story = graph.explain("a", "is_car")
    assert not story.committed and story.probability == 0.5 and "no evidence" in story.sentence
    graph.provenance.commit("a", "is_car", "e1", 0, 1.0, 1.0)  # P = 0.5 exactly: not committed
    assert graph.explain("a", "is_car").sentence.startswith("Not committed: P = 0.500 ≤ τ = 0.5")
    graph.provenance.commit("a", "is_car", "e2", 1, 0.5, 0.0)
    story = graph.explain("a", "is_car", tau=0.5)
    assert story.committed and story.sentence.startswith("Committed: P = 0.556 > τ = 0.5")
    assert [e.event_id for e in story.events] == ["e1", "e2"] and story.counts == {"committed": 2}


def test_refused_entries_are_bottom_and_not_counted() -> None:
    graph = SceneGraph(vocabulary=["is_car"], create_nodes=True)
    graph.add_node("a")
    graph.provenance.record("a", "is_car", "e1", 0, 0.0, 2.0, EntryStatus.REFUSED, -1)
    graph.provenance.commit("a", "is_car", "e2", 1, 2.0, 0.0, 1)
    story = graph.explain("a", "is_car")
    refused, committed = story.events
    assert refused.verdict == "⊥" and not refused.counted and refused.stance == "denies"
    assert refused.lambda_hat == 0.0 and refused.weight == 2.0 and not refused.recorded  # a refusal is a claim
    assert committed.verdict is None and committed.counted and committed.lambda_hat is None
    assert story.verdicts == {"⊥": 1} and "still pending" in story.sentence
    assert story.not_recorded.endswith(NOT_RECORDED_OLD)  # entries without verdict or confidence


def test_cli_prints_the_story_and_the_sentence(tmp_path, capsys) -> None:
    graph = _run("comod", 250, 11, 8)
    graph.save(tmp_path / "map")
    key = max(graph.provenance.pairs(), key=lambda k: graph.explain(*k).n_entries)
    assert main(["explain", str(tmp_path / "map"), str(key[0]), key[1]]) == 0
    out = capsys.readouterr().out
    story = graph.explain(*key)
    assert f"{key[0]!r} {key[1]}: Beta(" in out and story.sentence in out
    if story.folded is not None:
        assert "compacted (t=" in out and f"first {story.folded.first_event_id}" in out
    assert "read back from each claim's increments" in out and "c: the event's confidence" in out
    # --json: the same data, every predicate of the node when none is given
    assert main(["explain", str(tmp_path / "map"), str(key[0]), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    by_pred = {s["predicate"]: s for s in doc["stories"]}
    assert by_pred[key[1]] == json.loads(json.dumps(story.to_dict(), ensure_ascii=False))
    assert set(by_pred) == set(graph.provenance.predicates_of(key[0]))


def test_cli_errors(tmp_path, capsys) -> None:
    _run("comod", 50, 1, 8).save(tmp_path / "map")
    assert main(["explain", str(tmp_path / "map"), "no-such-node"]) == 1
    assert "no-such-node" in capsys.readouterr().err
    assert main(["explain", str(tmp_path / "map"), "n0", "--tau", "2"]) == 2

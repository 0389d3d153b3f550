"""Which events an operator admits (``check_admissible``, issue #21 items 6 and 8): an id that the
graph already holds, or a target node that it does not, is rejected before anything changes, by
every operator and engine; ``create_nodes=True`` lets evidence build its nodes."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import pytest

from sgbelief.api.operators import make_operator
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.errors import DuplicateEventError, UnknownNodeError
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.registry import OPERATOR_NAMES
from sgbelief.graph.persistence import graph_to_dict
from sgbelief.testing import conformance_table, provenance_signature, random_stream

TABLE = conformance_table()
CONFIG = OperatorConfig(tau_rev=0.02, t_prov=6, t_cor=4, t_disagree=3, calibration={"kappa_min": 0.5})
ENGINES = ["reference", "fast"]


def _state(op: Any, graph: SceneGraph) -> list[Any]:
    return [json.dumps(graph_to_dict(graph), sort_keys=True, default=repr),
            sorted(provenance_signature(graph).items(), key=repr), sorted(op.stats.items())]


def _built(name: str, engine: str, n: int = 60) -> tuple[Any, SceneGraph, list[EvidenceEvent]]:
    """An operator and a graph after ``n`` random events (nodes made by the evidence)."""
    op = make_operator(name, CONFIG, TABLE, engine=engine)  # type: ignore[arg-type]
    graph = SceneGraph(engine=engine, create_nodes=True)  # type: ignore[arg-type]
    events = []
    for ev, labels in random_stream(n, n_nodes=5, seed=3):
        op.update(graph, ev, FrameLabels(labels))
        events.append(ev)
    return op, graph, events


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", OPERATOR_NAMES)
def test_a_live_event_id_is_rejected_and_nothing_changes(name: str, engine: str) -> None:
    op, graph, events = _built(name, engine)
    live = [ev for ev in events if graph.provenance.has_event(ev.id)]
    assert live  # the stream's last events are not compacted yet
    before = _state(op, graph)
    again = dataclasses.replace(live[-1], t=graph.clock + 1)
    with pytest.raises(DuplicateEventError, match=repr(again.id)):
        op.update(graph, again)
    with pytest.raises(DuplicateEventError):
        op.update_many(graph, [(again, None)])
    assert _state(op, graph) == before
    assert graph.clock < again.t  # not even the clock moved


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["majority", "comod"])
def test_update_many_keeps_the_events_before_a_duplicate(name: str, engine: str) -> None:
    op, graph = make_operator(name, CONFIG, TABLE, engine=engine), SceneGraph(create_nodes=True)  # type: ignore[arg-type]
    first = EvidenceEvent(id="a", t=1, predicate="is_car", confidence=0.8, targets={"n": 1.0})
    second = EvidenceEvent(id="b", t=2, predicate="is_car", confidence=0.8, targets={"n": 1.0})
    with pytest.raises(DuplicateEventError):
        op.update_many(graph, [(first, None), (second, None), (dataclasses.replace(first, t=3), None)])
    assert op.stats["events"] == 2 and graph.provenance.has_event("b")


@pytest.mark.parametrize("engine", ENGINES)
def test_a_retracted_id_may_be_used_again(engine: str) -> None:
    op, graph = make_operator("majority", engine=engine), SceneGraph(create_nodes=True)  # type: ignore[arg-type]
    ev = EvidenceEvent(id="e", t=1, predicate="is_car", confidence=0.9, targets={"n": 1.0})
    op.update(graph, ev)
    op.retract(graph, "e")
    op.update(graph, dataclasses.replace(ev, t=2))
    assert graph.provenance.has_event("e")


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", OPERATOR_NAMES)
def test_an_unknown_target_node_is_an_error_unless_the_graph_creates_nodes(name: str, engine: str) -> None:
    op = make_operator(name, CONFIG, TABLE, engine=engine)  # type: ignore[arg-type]
    graph = SceneGraph(engine=engine)  # type: ignore[arg-type]
    graph.add_node("chair_1")
    # the known node comes first: a partial update would already have changed its belief
    typo = EvidenceEvent(id="e1", t=1, predicate="is_chair", confidence=0.9, targets={"chair_1": 0.5, "chiar_2": 0.5})
    before = _state(op, graph)
    with pytest.raises(UnknownNodeError, match="'chiar_2'.*create_nodes=True"):
        op.update(graph, typo)
    with pytest.raises(UnknownNodeError):
        op.update_many(graph, [(typo, FrameLabels({"chair_1": "chair"}))])
    assert _state(op, graph) == before and not graph.has_node("chiar_2")
    op.update(graph, dataclasses.replace(typo, targets={"chair_1": 1.0}))  # known nodes only: fine
    graph.create_nodes = True
    op.update(graph, dataclasses.replace(typo, id="e2", t=2))
    assert graph.has_node("chiar_2")


def test_batched_replay_follows_the_same_node_rule() -> None:
    from sgbelief._fast.batched import EventColumns, batched_replay
    from sgbelief.eval.random_stream import random_records

    cols = EventColumns.from_records(random_records(1, 50, n_nodes=4))
    with pytest.raises(UnknownNodeError):
        batched_replay(cols, "majority", graph=SceneGraph())
    graph, _ = batched_replay(cols, "majority", graph=SceneGraph(create_nodes=True))
    assert len(graph) > 0


@pytest.mark.parametrize("name", ["majority", "comod"])
def test_the_journalled_store_knows_its_ids_as_the_reference_store_does(name: str) -> None:
    """has_event on the fast store (journal records, compaction folding them unmaterialised)
    answers as the reference store does, without materialising the journal."""
    _, fast, events = _built(name, "fast", n=200)
    _, ref, _ = _built(name, "reference", n=200)
    ids = {ev.id for ev in events} | {"never"}
    assert {i for i in ids if fast.provenance.has_event(i)} == {i for i in ids if ref.provenance.has_event(i)}
    if name == "majority":  # baselines only commit: their entries are still journalled
        assert fast.provenance.journal_length > 0  # type: ignore[attr-defined]


def test_a_deferred_load_knows_its_ids_without_building_entries(tmp_path: Path) -> None:
    _, graph, events = _built("majority", "reference", n=80)
    loaded = SceneGraph.load(graph.save(tmp_path / "g.npz"))
    assert loaded.provenance.deferred  # type: ignore[attr-defined]
    live = [ev.id for ev in events if graph.provenance.has_event(ev.id)]
    assert live and all(loaded.provenance.has_event(i) for i in live)
    assert not loaded.provenance.has_event("never")
    assert loaded.provenance.deferred  # type: ignore[attr-defined]
    op = make_operator("majority")
    with pytest.raises(DuplicateEventError):
        op.update(loaded, dataclasses.replace(events[-1], t=loaded.clock + 1))

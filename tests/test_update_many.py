"""``update_many`` is ``update(..., report=False)`` event by event: the same map, provenance,
queues, stats, calibration state and queue resolutions, for any chunking of the stream, and the
same partial state when an event in the middle is rejected."""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.api.operators import make_operator
from sgbelief.errors import UnknownPredicateError
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.registry import OPERATOR_NAMES
from sgbelief.graph.persistence import graph_to_dict
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.eval.random_stream import random_records
from sgbelief.testing import conformance_table, provenance_signature, random_stream

TABLE = conformance_table()
#: short horizons so that queues time out, revisions quarantine and compaction folds in a short stream
CONFIG = OperatorConfig(tau_rev=0.02, t_prov=15, t_cor=4, t_disagree=3, calibration={"kappa_min": 0.5})


def _state(op: Any, graph: SceneGraphModel, resolutions: list[Any]) -> list[Any]:
    out = [json.dumps(graph_to_dict(graph), sort_keys=True, default=repr),
           sorted(provenance_signature(graph).items(), key=repr), sorted(op.stats.items()), resolutions]
    if hasattr(op, "calibrator_"):
        out.append(repr(op.calibrator_.summary()))
    return out


def _items(n: int, seed: int) -> list[tuple[Any, FrameLabels]]:
    return [(ev, FrameLabels(labels)) for ev, labels in random_stream(n, n_nodes=5, seed=seed)]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(OPERATOR_NAMES), seed=st.integers(0, 10_000),
       cuts=st.lists(st.integers(0, 160), max_size=8))
def test_update_many_equals_update_event_by_event(name: str, seed: int, cuts: list[int]) -> None:
    items = _items(160, seed)
    one, g_one = make_operator(name, CONFIG, TABLE), SceneGraphModel(vocabulary=TABLE.predicates, create_nodes=True)
    res_one = []
    for ev, ch in items:
        res_one += one.update(g_one, ev, ch, report=False).resolutions
    many, g_many = make_operator(name, CONFIG, TABLE), SceneGraphModel(vocabulary=TABLE.predicates, create_nodes=True)
    res_many = []
    bounds = sorted({0, len(items), *cuts})
    for a, b in zip(bounds, bounds[1:]):
        res_many += many.update_many(g_many, items[a:b])
    assert _state(many, g_many, res_many) == _state(one, g_one, res_one)
    assert many.stats["events"] == len(items)


@pytest.mark.parametrize("name", OPERATOR_NAMES)
def test_update_many_matches_reporting_updates(name: str) -> None:
    """Reports on: the same state, and the reports' resolutions are what update_many returns."""
    items = _items(200, 3)
    rep, g_rep = make_operator(name, CONFIG, TABLE), SceneGraphModel(create_nodes=True)
    res_rep = [r for ev, ch in items for r in rep.update(g_rep, ev, ch).resolutions]
    many, g_many = make_operator(name, CONFIG, TABLE), SceneGraphModel(create_nodes=True)
    res_many = many.update_many(g_many, iter(items))  # any iterable
    assert _state(many, g_many, res_many) == _state(rep, g_rep, res_rep)
    if name in ("cal", "comod"):
        assert res_many  # the short horizons do produce queue resolutions


@pytest.mark.parametrize("name", OPERATOR_NAMES)
def test_a_rejected_event_leaves_the_events_before_it_applied(name: str) -> None:
    items = _items(60, 7)
    bad = dataclasses.replace(items[40][0], predicate="is_unicorn")
    stream = items[:40] + [(bad, items[40][1])] + items[41:]
    many, g_many = make_operator(name, CONFIG, TABLE), SceneGraphModel(vocabulary=TABLE.predicates, create_nodes=True)
    with pytest.raises(UnknownPredicateError):
        many.update_many(g_many, stream)
    one, g_one = make_operator(name, CONFIG, TABLE), SceneGraphModel(vocabulary=TABLE.predicates, create_nodes=True)
    res_one = []
    for ev, ch in items[:40]:
        res_one += one.update(g_one, ev, ch, report=False).resolutions
    assert many.stats["events"] == 40
    assert _state(many, g_many, []) == _state(one, g_one, [])


class _ProtocolOnly:
    """A user operator written against the FusionOperator protocol alone (no BaseOperator):
    every member hands on to a shipped operator."""

    def __init__(self, name: str) -> None:
        self.inner = make_operator(name, CONFIG, TABLE)
        self.name = f"plain-{name}"

    config = property(lambda self: self.inner.config)
    stats = property(lambda self: self.inner.stats)
    pair_rule = property(lambda self: self.inner.pair_rule)

    def update(self, graph: SceneGraphModel, event: Any, channel: Any = None, *, report: bool = True) -> Any:
        return self.inner.update(graph, event, channel, report=report)

    def update_many(self, graph: SceneGraphModel, items: Any) -> Any:
        return self.inner.update_many(graph, items)

    def tick(self, graph: SceneGraphModel, t: int) -> Any:
        return self.inner.tick(graph, t)

    def probability(self, graph: SceneGraphModel, node: Any, predicate: str) -> float:
        return self.inner.probability(graph, node, predicate)

    def retract(self, graph: SceneGraphModel, event_id: str) -> list[str]:
        return self.inner.retract(graph, event_id)

    def merge_nodes(self, graph: SceneGraphModel, keep: Any, absorb: Any) -> None:
        self.inner.merge_nodes(graph, keep, absorb)


def test_streaming_replay_in_chunks_names_the_rejected_line(tmp_path: Any) -> None:
    """Across chunk boundaries: every run gets every record, and a record the operators reject is
    reported with its own line and id (shipped and protocol-only operators alike)."""
    from sgbelief.errors import FormatError
    from sgbelief.eval.formats import ReadStats, iter_events, write_events
    from sgbelief.eval.replay import STREAM_CHUNK, make_runs, replay, to_event

    n = 2 * STREAM_CHUNK + 37
    recs = random_records(1, n, n_nodes=8, predicates=tuple(TABLE.predicates), labels=("car", "person", None))
    runs = make_runs(["majority", "comod"], TABLE, CONFIG) + make_runs([_ProtocolOnly("cal")], TABLE, CONFIG)
    replay(recs, runs)
    assert [r.events for r in runs] == [n, n, n]
    for run, name in zip(runs, ("majority", "comod", "cal")):
        ref = make_runs([name], TABLE, CONFIG)[0]
        for i, rec in enumerate(recs):
            ref.operator.update(ref.graph, *to_event(rec, f"line{i + 1}"), report=False)
        assert graph_to_dict(run.graph) == graph_to_dict(ref.graph)
    bad = STREAM_CHUNK + 5
    path = tmp_path / "events.jsonl"
    write_events(path, recs[:bad] + [recs[bad]._replace(predicate="is_unicorn")] + recs[bad + 1:])
    for ops in (["majority", "comod"], [_ProtocolOnly("majority")]):
        stats = ReadStats()
        with pytest.raises(FormatError, match=r"rejected by .*is_unicorn") as info:
            replay(iter_events(path, stats=stats), make_runs(ops, TABLE, CONFIG), line_of=stats, source=path)
        assert info.value.line == bad + 2  # the header is line 1
        assert repr(recs[bad].id) in str(info.value)


@pytest.mark.parametrize("engine", ["streaming", "batched"])
def test_a_subclass_rule_is_what_every_path_applies(engine: str) -> None:
    """A subclass changes the rule (``pair_rule``), not one of update / update_many: update,
    update_many, the streaming replay and the batched engine all apply the subclass's rule."""
    from sgbelief.eval.replay import make_runs, replay
    from sgbelief.fusion.operators.baselines import MajorityVoteOperator
    from sgbelief.fusion.protocol import LinearRule

    class Flipped(LinearRule):
        def split(self, c: Any) -> tuple[Any, Any]:
            return 1.0 - c, c

    class Contrarian(MajorityVoteOperator):
        name = "contrarian"
        pair_rule = Flipped()

    items = _items(50, 2)
    one, g_one = Contrarian(CONFIG, TABLE), SceneGraphModel(create_nodes=True)
    for ev, ch in items:
        one.update(g_one, ev, ch)
    many, g_many = Contrarian(CONFIG, TABLE), SceneGraphModel(create_nodes=True)
    many.update_many(g_many, items)
    assert _state(many, g_many, []) == _state(one, g_one, [])
    majority, g_majority = make_operator("majority", CONFIG, TABLE), SceneGraphModel(create_nodes=True)
    majority.update_many(g_majority, items)
    assert provenance_signature(g_majority) != provenance_signature(g_many)
    recs = random_records(2, 600, n_nodes=6, predicates=tuple(TABLE.predicates), labels=("car", None))
    runs = make_runs([Contrarian(CONFIG, TABLE)], TABLE, CONFIG)
    replay(recs, runs, engine=engine)
    ref, g_ref = Contrarian(CONFIG, TABLE), SceneGraphModel(vocabulary=TABLE.predicates, create_nodes=True)
    ref.update_many(g_ref, [_to_event(r, i) for i, r in enumerate(recs)])
    assert provenance_signature(runs[0].graph) == provenance_signature(g_ref)
    assert runs[0].operator.stats == ref.stats


def _to_event(rec: Any, i: int) -> Any:
    from sgbelief.eval.replay import to_event

    return to_event(rec, f"line{i + 1}")


def test_an_operator_without_a_rule_gives_the_clear_error() -> None:
    """An operator with neither a pair_rule nor an _increment fails the same way on every path
    and engine (NotImplementedError naming the class), leaving the events before applied."""
    from sgbelief._fast.baselines import FUSED_BASELINES
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.fusion.operators.base import BaseOperator

    class Partial(BaseOperator):
        name = "partial"

        def _increment(self, graph, node, predicate, c, mass):  # noqa: ANN001, ANN202
            if c < 0.3:
                return super()._increment(graph, node, predicate, c, mass)
            return mass * c, mass * (1.0 - c)

    ok = EvidenceEvent(targets={"a": 1.0}, predicate="is_car", confidence=0.9, t=0, id="e0")
    bad = EvidenceEvent(targets={"a": 1.0}, predicate="is_car", confidence=0.2, t=1, id="e1")
    for engine in (None, FUSED_BASELINES):
        for run in (lambda op, g: op.update_many(g, [(ok, None), (bad, None)]),
                    lambda op, g: [op.update(g, e, None, report=False) for e in (ok, bad)],
                    lambda op, g: [op.update(g, e, None) for e in (ok, bad)]):
            op, g = Partial(engine=engine), SceneGraphModel(create_nodes=True)
            with pytest.raises(NotImplementedError, match="Partial"):
                run(op, g)
            assert g.provenance.alpha_beta("a", "is_car") == (1.9, 1.1) and op.stats["events"] == 1

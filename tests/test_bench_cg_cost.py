"""The cost accounting of ``benchmarks/bench_cg_harness.py --cpu-time``: the operator's map-wide
refits timed apart (``refit_timer``) and the figures with and without them (``OwnTime.split``).

No timing is asserted: the refit timer must see every refit the operator runs and leave the
operator as it was, and the split must be the arithmetic its docstring states."""

from __future__ import annotations

import random
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_cg_harness as B  # noqa: E402

from sgbelief import SceneGraph, make_operator  # noqa: E402
from sgbelief.fusion.channel import FrameLabels  # noqa: E402
from sgbelief.fusion.compatibility import SubsumptionTable  # noqa: E402
from sgbelief.fusion.events import EvidenceEvent  # noqa: E402

CLASSES = ["bed", "chair", "sofa"]


def _items(n: int, seed: int = 0) -> list:
    rng = random.Random(seed)
    return [(EvidenceEvent({f"v{rng.randrange(40)}": 1.0}, f"is_{rng.choice(CLASSES)}", rng.uniform(0.5, 0.95),
                           "det", i + 1, f"e{i}"), FrameLabels({}))
            for i in range(n)]


def _operator():
    specs = {f"is_{k}": {"positive": [k], "negative": [j for j in CLASSES if j != k]} for k in CLASSES}
    table = SubsumptionTable(specs, name="three", labels=CLASSES)
    cfg = {"calibration": {"consensus": {"method": "agreement_shift", "every": 50, "growth": 0.0}}}
    return make_operator("comod", cfg, table)


def test_refit_timer_sees_every_refit_and_undoes() -> None:
    op = _operator()
    seconds: list[float] = []
    B.refit_timer(op, seconds.append)
    op.update_many(SceneGraph(create_nodes=True), _items(260))
    assert len(seconds) == 5 and all(s >= 0.0 for s in seconds)  # at 50, 100, ..., 250 claims
    del op._refit_consensus
    assert "_refit_consensus" not in vars(op)
    op.update_many(SceneGraph(create_nodes=True), _items(60, seed=1))
    assert len(seconds) == 5  # the class's method again: nothing recorded


def test_refit_timer_leaves_the_map_unchanged() -> None:
    items = _items(260)
    plain, timed = _operator(), _operator()
    B.refit_timer(timed, lambda s: None)
    g1, g2 = SceneGraph(create_nodes=True), SceneGraph(create_nodes=True)
    plain.update_many(g1, items)
    timed.update_many(g2, items)
    assert {v: dict(g1.beliefs(v)) for v in g1.nodes()} == {v: dict(g2.beliefs(v)) for v in g2.nodes()}


def test_split_separates_the_refits() -> None:
    own = B.OwnTime()
    # frames: (own seconds, detections, refit seconds, refits); the first timed frame is left out
    own.frames = [(1.0, 100, 0.5, 2), (0.002, 10, 0.0, 0), (0.013, 10, 0.010, 1), (0.003, 10, 0.0, 0)]
    cost = {"replay_us_per_event": 50.0, "replay_refit_us_per_event": 30.0}
    out = own.split(cost)
    assert out["own_steady_us_per_detection"] == pytest.approx(300.0)  # median of 200, 300, 300
    assert out["own_mean_us_per_detection"] == pytest.approx(1e6 * 0.018 / 30)
    assert out["own_refit_us_per_detection"] == pytest.approx(1e6 * 0.010 / 30) and out["own_refits"] == 1
    assert out["replay_steady_us_per_event"] == pytest.approx(20.0)
    assert out["steady_ratio"] == pytest.approx(15.0)
    assert out["mean_ratio"] == pytest.approx(600.0 / 50.0)


def test_update_timer_counts_events_takes_out_refits_and_undoes() -> None:
    op = _operator()
    refits: list[float] = []
    B.refit_timer(op, refits.append)
    calls: list[tuple[float, int]] = []
    B.update_timer(op, lambda s, n: calls.append((s, n)), lambda: sum(refits))
    graph = SceneGraph(create_nodes=True)
    items = _items(260)
    for i in range(0, 260, 10):  # a frame's events a call, as the backend applies them
        op.update_many(graph, iter(items[i:i + 10]))  # any iterable: the timer counts what it passes on
    assert [n for _, n in calls] == [10] * 26
    assert len(refits) == 5 and all(s >= 0.0 for s, _ in calls)
    del op.update_many
    assert "update_many" not in vars(op)
    op.update_many(SceneGraph(create_nodes=True), _items(10, seed=2))
    assert len(calls) == 26  # the class's method again


def test_update_timer_leaves_the_map_unchanged() -> None:
    items = _items(200)
    plain, timed = _operator(), _operator()
    B.update_timer(timed, lambda s, n: None)
    g1, g2 = SceneGraph(create_nodes=True), SceneGraph(create_nodes=True)
    plain.update_many(g1, items)
    for i in range(0, 200, 7):
        timed.update_many(g2, items[i:i + 7])
    assert {v: dict(g1.beliefs(v)) for v in g1.nodes()} == {v: dict(g2.beliefs(v)) for v in g2.nodes()}


def test_own_time_takes_the_update_out_of_a_frame_only() -> None:
    own = B.OwnTime()
    own._add_update(1.0, 10)  # outside a per-frame merge: not counted
    own._geo = 0.0  # inside one
    own._add_refit(0.25)
    own._add_update(0.5, 4)
    own._add_update(0.25, 6)
    assert (own._update, own._update_events, own._refit, own._refit_n) == (0.75, 10, 0.25, 1)


def test_install_times_updates_and_summaries_and_uninstall_restores() -> None:
    from sgbelief.adapters.conceptgraphs import map_beliefs, new_objects

    summaries = (new_objects.geometry_summary, map_beliefs.geometry_summary)
    op = _operator()
    own = B.OwnTime()
    own.install(op)
    assert {"update_many", "_refit_consensus"} <= set(vars(op))
    assert new_objects.geometry_summary is not summaries[0] and map_beliefs.geometry_summary is not summaries[1]
    own._geo = 0.0
    assert new_objects.geometry_summary({"pcd_np": [[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]]})[0] == (1.0, 1.0, 1.0)
    op.update_many(SceneGraph(create_nodes=True), _items(20))
    assert own._summary_n == 1 and own._update_events == 20
    own.uninstall()
    assert not {"update_many", "_refit_consensus"} & set(vars(op))
    assert (new_objects.geometry_summary, map_beliefs.geometry_summary) == summaries


def test_floor_is_the_operator_and_the_summaries_per_detection() -> None:
    own = B.OwnTime()
    # per frame: (own seconds, detections, refit seconds, refits) and (update seconds without
    # refits, events, summary seconds, summaries); the first timed frame is left out
    own.frames = [(1.0, 100, 0.5, 2), (0.002, 10, 0.0, 0), (0.013, 10, 0.010, 1), (0.003, 10, 0.0, 0)]
    own.parts = [(0.3, 100, 0.1, 100), (0.0004, 10, 0.0001, 8), (0.0006, 12, 0.0002, 9), (0.0008, 10, 0.0002, 8)]
    out = own.split({"replay_us_per_event": 50.0, "replay_refit_us_per_event": 30.0})
    assert out["operator_in_loop_us_per_event"] == pytest.approx(1e6 * 0.0018 / 32)
    assert out["operator_in_loop_ratio"] == pytest.approx(1e6 * 0.0018 / 32 / 20.0)
    assert out["floor_us_per_detection"] == pytest.approx(80.0)  # median of 50, 80, 100
    assert out["floor_ratio"] == pytest.approx(4.0)
    assert out["rest_us_per_detection"] == pytest.approx(200.0)  # median of 150, 220, 200
    assert out["summaries"] == 25

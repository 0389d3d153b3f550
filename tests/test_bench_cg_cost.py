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

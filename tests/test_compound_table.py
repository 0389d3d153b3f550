"""Table 4: the intersection pool, the cross-fitting, the "–" rule, the cost, and the CLI / bench path."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.eval.compound_table import (
    MIN_N,
    assign_folds,
    compare_compounds,
    compound_cost,
    cross_fitted_probabilities,
    format_text,
    intersection,
    render_markdown,
    verifiable_outcome,
)
from sgbelief.eval.formats import EventRecord
from sgbelief.eval.sim_monolithic import MonolithicRecord
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.query.named import named_queries


def test_assign_folds_partitions_evenly_and_deterministically() -> None:
    nodes = [f"n{i}" for i in range(103)]
    f = assign_folds(nodes, 10, seed=3)
    assert set(f) == set(nodes) and set(f.values()) == set(range(10))
    sizes = [list(f.values()).count(k) for k in range(10)]
    assert max(sizes) - min(sizes) <= 1
    assert assign_folds(list(reversed(nodes)), 10, seed=3) == f  # order of the input does not matter
    assert assign_folds(nodes, 10, seed=4) != f


class _Recorder:
    """A calibrator that records what it was fitted on and predicts the mean outcome it saw."""

    made: list[_Recorder] = []

    def __init__(self) -> None:
        self.seen: list[tuple[str, str, float, int]] = []
        _Recorder.made.append(self)

    def add(self, context: str, predicate: str, c: float, y: int) -> None:
        self.seen.append((context, predicate, c, y))

    def refit_all(self) -> None:
        pass

    def calibrated_probability(self, c: float, context: str, predicate: str) -> float:
        return sum(s[3] for s in self.seen) / len(self.seen)


def test_cross_fitting_never_uses_an_elements_own_outcome() -> None:
    # element i answers two compounds with confidences unique to it: i/1000 and 0.5 + i/1000
    items = []
    for i in range(60):
        items.append((f"v{i}", "m", "q1", i / 1000, i % 2))
        items.append((f"v{i}", "m", "q2", 0.5 + i / 1000, None if i % 5 == 0 else 1))
    folds = assign_folds([it[0] for it in items], 10, seed=0)
    _Recorder.made = []
    p = cross_fitted_probabilities(items, folds, 10, calibrator=_Recorder)
    assert len(_Recorder.made) == 10 and all(x == x for x in p)
    for f, cal in enumerate(_Recorder.made):
        own = {it[3] for it in items if folds[it[0]] == f}
        seen = {s[2] for s in cal.seen}
        assert not (own & seen), f"fold {f} was calibrated on its own elements' outcomes"
        # everything verifiable outside the fold was used
        assert seen == {it[3] for it in items if folds[it[0]] != f and it[4] is not None}


def test_finest_level_gives_the_full_hierarchys_numbers() -> None:
    """cold + M reads the finest fitted slice: the default hierarchy gives the same probabilities."""
    import numpy as np

    from sgbelief.calibration.mondrian import MondrianCalibrator

    rng = np.random.default_rng(0)
    items = [(f"v{i % 300}", "m", f"q{i // 300}", float(rng.random()), int(rng.random() < 0.3)) for i in range(900)]
    folds = assign_folds([it[0] for it in items], 10, seed=0)
    assert cross_fitted_probabilities(items, folds) == cross_fitted_probabilities(items, folds, calibrator=MondrianCalibrator)


def test_verifiable_outcome() -> None:
    assert verifiable_outcome(None, [True]) is None  # the channel is undecided: no outcome
    assert verifiable_outcome(0, [None]) == 0  # not the object: the compound fails whatever the geometry
    assert verifiable_outcome(1, [True, True]) == 1
    assert verifiable_outcome(1, [True, False]) == 0
    assert verifiable_outcome(1, [None]) == 0  # an undefined relation does not hold


def test_intersection_is_the_answered_part_of_the_pool_in_pool_order() -> None:
    assert intersection(["c", "a", "b", "d"], {"a", "c", "x"}) == ["c", "a"]
    assert intersection([], {"a"}) == []


def _plans(n_small: int, n_big: int):
    qs = named_queries("kitti360")
    car_int = qs["car_at_intersection"]
    ped_int = qs["pedestrian_at_intersection"]
    big = [f"c{i:03d}" for i in range(n_big)]
    small = [f"p{i:03d}" for i in range(n_small)]
    geo = {"is_at_intersection": {v: (i % 3 == 0) for i, v in enumerate(big + small)}}
    pos_big = {v for i, v in enumerate(big) if i % 3 == 0 and i % 2 == 0}  # cars at even index are cars
    pos_small = {v for i, v in enumerate(small, start=n_big) if i % 3 == 0}
    plans = (geo, {"car_at_intersection": (car_int, big + ["unanswered"], pos_big),
                   "pedestrian_at_intersection": (ped_int, small, pos_small)})
    recs = []
    for i, v in enumerate(big):
        label = "car" if i % 2 == 0 else "building"
        recs.append(MonolithicRecord(v, "car_at_intersection", 0, 0.5 if i == 0 else 0.9 if v in pos_big else 0.3, "m",
                                     label))
    for v in small:
        recs.append(MonolithicRecord(v, "pedestrian_at_intersection", 0, 0.8, "m", "person"))
    return plans, recs, pos_big


def test_dash_rule_and_commit_rule() -> None:
    table = SubsumptionTable.shipped("kitti360")
    plans, recs, pos_big = _plans(MIN_N - 1, 40)
    op = {"car_at_intersection": set(pos_big) | {"unanswered"}, "pedestrian_at_intersection": set()}
    rows = {r.query: r for r in compare_compounds(plans, recs, table, op)}
    big, small = rows["car_at_intersection"], rows["pedestrian_at_intersection"]
    assert big.pool_n == 41 and big.n == 40  # the unanswered pool node is not in the intersection
    assert small.n == MIN_N - 1 and small.cold_m is None and small.operator is None  # "–"
    assert small.cold_raw is not None  # raw is shown, as in the paper
    assert big.cold_m is not None and big.operator is not None
    # c = 0.5 is not a commit (P > tau, strictly); c = 0.9 exactly on the positives
    assert big.cold_raw.commits == len(pos_big) - ("c000" in pos_big)
    assert big.operator.f1 == 1.0 and big.operator.commits == len(pos_big)  # 'unanswered' is outside the intersection
    assert big.pool_operator.commits == len(pos_big) + 1
    md = "\n".join(render_markdown({"operator": "comod", "config_note": "x", "tau": 0.5, "folds": 10, "min_n": MIN_N,
                                    "rows": [r.to_dict() for r in rows.values()],
                                    "cost": compound_cost(plans, [], recs)}))
    small_line = next(line for line in md.splitlines() if line.startswith("| pedestrian at intersection"))
    assert small_line.count("–") == 2
    plans20, recs20, _ = _plans(MIN_N, 40)
    rows20 = {r.query: r for r in compare_compounds(plans20, recs20, table, op)}
    assert rows20["pedestrian_at_intersection"].cold_m is not None  # n = 20 is scored


def test_cost_counts_component_reuse() -> None:
    plans, recs, _ = _plans(25, 40)
    ev = [EventRecord(0, {"c000": 1.0}, "is_car", 0.9, "m", {}), EventRecord(1, {"c000": 1.0}, "is_car", 0.9, "m", {}),
          EventRecord(2, {"p000": 1.0}, "is_pedestrian", 0.9, "m", {}), EventRecord(3, {"x": 1.0}, "is_road", 0.9, "m", {})]
    c = compound_cost(plans, ev, recs)
    assert c["operator_calls"] == 3  # is_road is no compound's component
    assert c["operator_answers"] == 41 + 25
    assert c["per_predicate"] == {"is_car": {"calls": 2, "compounds": 1}, "is_pedestrian": {"calls": 1, "compounds": 1}}
    assert c["monolithic_calls"] == len(recs) == 65 and c["monolithic_calls_per_answer"] == 1.0


@pytest.mark.slow
def test_bench_and_retrieval_print_the_same_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sgbelief.cli import main

    out = tmp_path / "bench"
    assert main(["bench", "--suite", "indoor", "--scale", "0.15", "--operators", "comod", "--no-real",
                 "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "monolithic compound prompt (Table 4 layout)" in text and "Model calls per answered compound" in text
    rep = json.loads((out / "results.json").read_text())["suites"]["indoor"]["compound_table"]
    assert rep["operator"] == "comod" and "shipped default" in rep["config_note"] and rep["swap"]["rows"]
    data = out / "data" / "indoor"
    assert (data / "monolithic.jsonl").is_file() and (data / "model_swap" / "events.jsonl").is_file()
    assert main(["retrieval", "--suite", str(data), "--operators", "comod", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc[0]["compound_table"]["rows"] == rep["rows"]
    assert doc[0]["compound_table"]["swap"]["rows"] == rep["swap"]["rows"]
    assert "cold + M" in format_text(rep)

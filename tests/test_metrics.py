from __future__ import annotations

import math

import numpy as np
import pytest

from sgbelief.eval.metrics import (
    binarize,
    brier_over_pairs,
    brier_score,
    conformal_coverage,
    conformal_quantile,
    emission_rate,
    expected_calibration_error,
    mean_iou,
    nll_prediction_sets,
    per_predicate_scores,
    reliability_bins,
    retrieval_f1,
    segmentation_iou,
    set_scores,
    without_positives,
)


def test_set_scores_hand_case():
    s = set_scores({"a", "b", "c"}, {"b", "c", "d", "e"})
    assert (s.tp, s.fp, s.fn) == (2, 1, 2)
    assert s.iou == pytest.approx(2 / 5)
    assert s.precision == pytest.approx(2 / 3)
    assert s.recall == pytest.approx(1 / 2)
    assert s.f1 == pytest.approx(2 * (2 / 3) * 0.5 / (2 / 3 + 0.5))


def test_empty_conventions():
    # no positives: IoU, recall and F1 are undefined (n/a), committed or not
    both = set_scores(set(), set())
    assert all(math.isnan(x) for x in (both.iou, both.precision, both.recall, both.f1))
    assert not both.has_positives
    nothing_committed = set_scores(set(), {"a"})
    assert (nothing_committed.iou, nothing_committed.precision, nothing_committed.recall, nothing_committed.f1) == (
        0.0, 0.0, 0.0, 0.0)
    nothing_relevant = set_scores({"a"}, set())
    assert nothing_relevant.precision == 0.0 and nothing_relevant.fp == 1
    assert all(math.isnan(x) for x in (nothing_relevant.iou, nothing_relevant.recall, nothing_relevant.f1))


def test_a_class_with_no_positives_is_left_out_of_the_mean():
    """Before: a class nobody is (is_toilet indoors) scored IoU 1.0 and lifted the mean."""
    truth = {"n1": {"is_chair": 1, "is_toilet": 0}, "n2": {"is_chair": 0, "is_toilet": 0}}
    probs = {"n1": {"is_chair": 0.9}, "n2": {"is_chair": 0.8}}
    sc = per_predicate_scores(probs, truth, ["is_chair", "is_toilet"])
    assert sc["is_chair"].iou == pytest.approx(0.5)
    assert math.isnan(sc["is_toilet"].iou)
    assert mean_iou(sc) == pytest.approx(0.5)
    assert without_positives(sc) == ["is_toilet"]
    assert math.isnan(mean_iou({"is_toilet": sc["is_toilet"]}))
    assert math.isnan(retrieval_f1({"n1"}, set()).f1)


def test_binarize_strict():
    assert binarize({"a": 0.5, "b": 0.51, "c": 0.9}, 0.5) == {"b", "c"}


def test_per_predicate_scores_and_prior():
    truth = {"n1": {"is_car": 1, "is_ped": 0}, "n2": {"is_car": 0, "is_ped": 1}, "n3": {"is_car": 1}}
    probs = {"n1": {"is_car": 0.9, "is_ped": 0.7}, "n2": {"is_car": 0.2}}  # n3 missing -> prior 0.5
    sc = per_predicate_scores(probs, truth, ["is_car", "is_ped"])
    assert (sc["is_car"].tp, sc["is_car"].fp, sc["is_car"].fn) == (1, 0, 1)
    assert sc["is_car"].iou == 0.5
    assert (sc["is_ped"].tp, sc["is_ped"].fp, sc["is_ped"].fn) == (0, 1, 1)
    assert mean_iou(sc) == pytest.approx(0.25)
    sc2 = per_predicate_scores(probs, truth, ["is_car"], prior=0.6)
    assert sc2["is_car"].tp == 2


def test_brier():
    assert brier_score([0.9, 0.2, 0.5], [1, 0, 1]) == pytest.approx((0.01 + 0.04 + 0.25) / 3)
    assert math.isnan(brier_score([], []))
    truth = {"a": {"p": 1}, "b": {"p": 0}}
    assert brier_over_pairs({"a": {"p": 0.8}}, truth, [("a", "p"), ("b", "p"), ("zz", "p")]) == pytest.approx(
        (0.04 + 0.25) / 2)


def test_reliability_bins_hand_case_and_ece_agree():
    conf = [0.05, 0.15, 0.15, 0.95, 1.0, 0.55]
    y = [0, 1, 0, 1, 1, 0]
    b = reliability_bins(conf, y, n_bins=10)
    assert b.counts.tolist() == [1, 2, 0, 0, 0, 1, 0, 0, 0, 2]
    assert b.centres[0] == pytest.approx(0.05)
    assert b.mean_confidence[1] == pytest.approx(0.15) and b.accuracy[1] == pytest.approx(0.5)
    assert b.mean_confidence[9] == pytest.approx(0.975) and b.accuracy[9] == 1.0
    assert np.isnan(b.accuracy[2])
    expected = (1 * 0.05 + 2 * 0.35 + 1 * 0.55 + 2 * 0.025) / 6
    assert b.ece == pytest.approx(expected)
    assert expected_calibration_error(conf, y) == pytest.approx(expected)
    assert expected_calibration_error([0.3, 0.3], [0, 1], n_bins=1) == pytest.approx(0.2)
    with pytest.raises(ValueError):
        reliability_bins([1.2], [1])


def test_conformal():
    assert conformal_quantile([0.1, 0.2, 0.3, 0.4], alpha=0.2) == 0.4  # ceil(5*0.8)=4
    assert conformal_quantile([0.1, 0.2, 0.3, 0.4], alpha=0.5) == 0.3  # ceil(2.5)=3
    assert conformal_quantile([0.1], alpha=0.1) == math.inf
    sets = nll_prediction_sets([0.9, 0.5, 0.01], qhat=-math.log(0.4))
    assert sets == [frozenset({1}), frozenset({0, 1}), frozenset({0})]
    cov = conformal_coverage(sets, [1, 0, 1])
    assert cov.coverage == pytest.approx(2 / 3) and cov.mean_set_size == pytest.approx(4 / 3)
    assert cov.n == 3 and cov.empty_fraction == 0.0
    assert conformal_coverage([set(), {0}], [0, 0]).empty_fraction == 0.5


def test_rates_and_retrieval():
    assert emission_rate(3, 12) == 0.25 and emission_rate(0, 0) == 0.0
    r = retrieval_f1(["a", "b"], ["b", "c", "d"])
    assert r.precision == 0.5 and r.recall == pytest.approx(1 / 3) and r.f1 == pytest.approx(0.4)


def test_segmentation_iou():
    true = ["car", "car", "road", "road", None, "person"]
    pred = ["car", "road", "road", None, "car", "car"]
    miou, per = segmentation_iou(true, pred)
    # car: tp1 fp1(person->car) fn1 -> 1/3 ; road: tp1 fp1 fn1 -> 1/3 ; person: tp0 fn1 -> 0
    assert per == {"car": pytest.approx(1 / 3), "person": 0.0, "road": pytest.approx(1 / 3)}
    assert miou == pytest.approx(2 / 9)

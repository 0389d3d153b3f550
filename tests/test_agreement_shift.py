"""The agreement shift (sgbelief.calibration.agreement_shift): the reading by hand, the EM's
equivariance and its treatment of lone claims, a deflated detector's shift learned without ground
truth, and the map consensus with ``method: agreement_shift``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import expit, logit

from scipy.stats import mannwhitneyu

from sgbelief.calibration.agreement_shift import (ContextReading, ShiftCalibration, agreement_rank_test,
                                                  fit_agreement_shift, level_log_lr, shifted_log_lr)


def test_the_shifted_reading_by_hand() -> None:
    assert shifted_log_lr(0.5, 0.0, 10.0) == 0.0
    assert shifted_log_lr(0.2, 0.0, 10.0) == pytest.approx(math.log(0.25))
    assert shifted_log_lr(0.2, math.log(4.0), 10.0) == pytest.approx(0.0)  # odds 1/4 shifted by x4
    assert shifted_log_lr(1.0, 0.0, math.log(1000.0)) == pytest.approx(math.log(1000.0))  # clipped
    assert shifted_log_lr(0.0, 2.0, math.log(1000.0)) == pytest.approx(-math.log(1000.0))


def test_one_em_iteration_by_hand() -> None:
    """Two elements, two claims each, n_iter=1. Element 0: a (c = 0.5) and b (c = 0.5); element 1: a, a
    (c = 0.5). The vote gives q0 = (1/2, 1/2), q1 = (1, 0); the outcomes q(l_i) are 1/2, 1/2, 1, 1,
    so the M-step solves 4 sigmoid(a) = 3: a = log 3. The final M-step after the E-step (p = 3/4,
    K = 2, so a claim of the other class has likelihood 1/4; pi = (3/4, 1/4)): element 0 has
    a: 3/4 * 3/4 * 1/4, b: 1/4 * 1/4 * 3/4 -> q0 = (3/4, 1/4); element 1 a: 3/4 * 9/16, b: 1/4 * 1/16
    -> q1(a) = 27/28. Outcomes 3/4, 1/4, 27/28, 27/28 sum to 2.9286: sigmoid(a) = 0.73214."""
    out = fit_agreement_shift(np.array([0, 0, 1, 1]), np.array([0, 1, 0, 0]), np.full(4, 0.5), np.zeros(4, int),
                              n_iter=1)
    a, n = out[0]
    assert n == 4
    assert expit(a) == pytest.approx((0.75 + 0.25 + 2 * 27 / 28) / 4, abs=1e-9)


def _stream(seed: int, shift: float, n_tasks: int = 40, k: int = 10, per_task: int = 6):
    """Elements of k classes; each claim's confidence c ~ U(0.1, 0.6); it names the true class with
    probability sigmoid(logit c + shift), another class uniformly otherwise."""
    rng = np.random.default_rng(seed)
    z = rng.integers(0, k, n_tasks)
    tasks, labels, conf = [], [], []
    for t in range(n_tasks):
        for _ in range(per_task):
            c = rng.uniform(0.1, 0.6)
            right = rng.random() < expit(logit(c) + shift)
            labels.append(z[t] if right else rng.choice([x for x in range(k) if x != z[t]]))
            tasks.append(t)
            conf.append(c)
    return np.array(tasks), np.array(labels), np.array(conf)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("shift", [0.0, 1.5])
def test_a_deflated_detectors_shift_is_learned_without_ground_truth(seed: int, shift: float) -> None:
    """40 elements, 10 classes, 6 claims each: the fitted shift is within 0.5 of the true one (seeded;
    the tolerance covers EM's sampling error on 240 claims)."""
    tasks, labels, conf = _stream(seed, shift)
    a, n = fit_agreement_shift(tasks, labels, conf, np.zeros(len(tasks), int))[0]
    assert n == len(tasks)
    assert a == pytest.approx(shift, abs=0.5)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), d=st.floats(-2.0, 2.0))
def test_the_shift_moves_with_the_scores(seed: int, d: float) -> None:
    """Shifting every confidence by d in log-odds shifts the fitted a by -d: the reading
    logit c + a is the same, so is the map's reading of every claim."""
    tasks, labels, conf = _stream(seed, 0.8, n_tasks=12, k=5, per_task=4)
    moved = expit(logit(conf) + d)
    ctx = np.zeros(len(tasks), int)
    a0 = fit_agreement_shift(tasks, labels, conf, ctx, tol=1e-12, n_iter=500)[0][0]
    a1 = fit_agreement_shift(tasks, labels, moved, ctx, tol=1e-12, n_iter=500)[0][0]
    assert a1 == pytest.approx(a0 - d, abs=1e-5)


def test_lone_claims_do_not_enter_the_fit() -> None:
    tasks, labels, conf = _stream(0, 1.0, n_tasks=20)
    ctx = np.zeros(len(tasks), int)
    base = fit_agreement_shift(tasks, labels, conf, ctx)
    lone_tasks = np.concatenate([tasks, 100 + np.arange(30)])
    lone = fit_agreement_shift(lone_tasks, np.concatenate([labels, np.zeros(30, int)]),
                               np.concatenate([conf, np.full(30, 0.9)]), np.zeros(len(lone_tasks), int))
    assert lone == base
    assert fit_agreement_shift(np.arange(5), np.zeros(5, int), np.full(5, 0.3), np.zeros(5, int)) == {}


def test_each_context_gets_its_own_shift() -> None:
    """Two detectors on the same elements, one deflated by 1.5 in log-odds: their shifts differ by about 1.5."""
    tasks, labels, conf = _stream(3, 1.5, n_tasks=60)
    t2, l2, c2 = _stream(3, 0.0, n_tasks=60)
    fit = fit_agreement_shift(np.concatenate([tasks, t2]), np.concatenate([labels, l2]), np.concatenate([conf, c2]),
                              np.concatenate([np.zeros(len(tasks), int), np.ones(len(t2), int)]))
    assert fit[0][0] - fit[1][0] == pytest.approx(1.5, abs=0.6)


def test_shift_calibration_answers_like_the_consensus_calibration() -> None:
    cal = ShiftCalibration(kappa_min=0.05, lr_max=1000.0)
    assert not cal.fitted
    assert cal.likelihood_ratio(0.2, (7, 3, 0)) == (pytest.approx(0.25), 0.05)  # not fitted: the raw reading
    tasks, labels, conf = _stream(1, 1.5)
    cal.fit(tasks, labels, conf, np.zeros(len(tasks), int))
    a = cal.shift(0)
    assert cal.fitted and a > 0.8
    lam, kappa = cal.likelihood_ratio(0.2, (7, 3, 0))
    assert lam == pytest.approx(0.25 * math.exp(a)) and kappa == 0.05
    c = np.array([0.05, 0.2, 0.5, 0.9])
    lams, kappas = cal.likelihood_ratios(c, [np.zeros(4, int), np.zeros(4, int), np.array([0, 0, 1, 0])])
    expected = [cal.likelihood_ratio(float(x), (0, 0, w))[0] for x, w in zip(c, [0, 0, 1, 0])]
    np.testing.assert_allclose(lams, expected, rtol=1e-12)
    assert np.all(kappas == 0.05)


def test_an_over_confident_detector_keeps_the_raw_reading() -> None:
    """A detector right less often than its scores say (true shift -1.5): the fit finds a negative
    shift, and the reading applies none (module docstring: the shift only moves claims up)."""
    tasks, labels, conf = _stream(4, -1.5, n_tasks=60)
    conf = expit(logit(conf) + 2.0)  # scores 0.23-0.92, right with probability sigmoid(logit c - 3.5)
    cal = ShiftCalibration().fit(tasks, labels, conf, np.zeros(len(tasks), int))
    assert cal.readings_[0].fitted < -1.0
    assert cal.shift(0) == 0.0
    assert cal.likelihood_ratio(0.8, (0, 0, 0))[0] == pytest.approx(4.0)


def test_the_map_consensus_with_the_shift() -> None:
    """MapConsensus(method=agreement_shift): claims of a deflated detector on a few elements; after a
    refit a silent claim reads above its raw odds, and there is no Dawid-Skene posterior to ask."""
    from sgbelief.calibration.config import CalibrationConfig
    from sgbelief.fusion.consensus import MapConsensus

    cfg = CalibrationConfig.model_validate({"consensus": {"method": "agreement_shift", "every": 1, "growth": 0.0}})
    mc = MapConsensus(cfg, frozenset({"is_a", "is_b", "is_c"}))
    assert mc.likelihood_ratio(0.3, "cell", "is_a", "det") is None  # nothing fitted yet
    rng = np.random.default_rng(0)
    i = 0
    for v in range(12):
        truth = ["is_a", "is_b", "is_c"][v % 3]
        for _ in range(5):
            right = rng.random() < 0.8
            pred = truth if right else ["is_a", "is_b", "is_c"][(v + 1) % 3]
            mc.add_claim(f"v{v}", pred, "det", float(rng.uniform(0.2, 0.45)), "cell", False, f"e{i}", t=i)
            i += 1
    mc.refit()
    lam, kappa = mc.likelihood_ratio(0.3, "cell", "is_a", "det")
    assert lam > 1.0 > 0.3 / 0.7
    assert mc.posterior("v0", "is_a") is None


# ----------------------------------------------------------------- scores that say nothing


def test_the_rank_test_by_hand() -> None:
    """Element 0: (a, 0.9), (a, 0.8), (b, 0.2); element 1: (a, 0.7), (a, 0.6). The first two claims'
    others tie (a once, b once): left out. (b, 0.2)'s others are a, a: it disagrees. Element 1's
    claims agree. The test compares [0.7, 0.6] with [0.2]. With the first claim weighing 2, the
    second's others are a (2) against b (1): it agrees too."""
    tasks, labels = np.array([0, 0, 0, 1, 1]), np.array([0, 0, 1, 0, 0])
    conf, ctx = np.array([0.9, 0.8, 0.2, 0.7, 0.6]), np.zeros(5, int)
    p, n_yes, n_no = agreement_rank_test(tasks, labels, conf, ctx)[0]
    assert (n_yes, n_no) == (2, 1)
    assert p == pytest.approx(mannwhitneyu([0.7, 0.6], [0.2], alternative="greater").pvalue)
    p2, n_yes2, n_no2 = agreement_rank_test(tasks, labels, conf, ctx, weights=np.array([2.0, 1, 1, 1, 1]))[0]
    assert (n_yes2, n_no2) == (3, 1)
    assert p2 == pytest.approx(mannwhitneyu([0.8, 0.7, 0.6], [0.2], alternative="greater").pvalue)
    # all claims agree: no disagreeing group, no evidence
    assert agreement_rank_test(np.array([0, 0]), np.array([1, 1]), np.array([0.3, 0.4]), np.zeros(2, int))[0] == (1.0, 2, 0)


def test_a_level_context_ignores_its_confidences() -> None:
    """With the offsets replaced by 0 the EM sees no confidence: any scores give the level of c = 1/2,
    and the level is the logit of the agreement rate the EM converges to."""
    tasks, labels, conf = _stream(2, 1.5)
    ctx = np.zeros(len(tasks), int)
    a = fit_agreement_shift(tasks, labels, conf, ctx, level_contexts={0})[0][0]
    a_half = fit_agreement_shift(tasks, labels, np.full(len(tasks), 0.5), ctx)[0][0]
    assert a == a_half
    assert level_log_lr(0.8, -0.5, 10.0) == 0.8 and level_log_lr(-0.3, 0.4, 10.0) == 0.4
    assert level_log_lr(12.0, 0.0, 10.0) == 10.0


def _uninformative_stream(seed: int, n_tasks: int = 40, k: int = 10, per_task: int = 6, accuracy: float = 0.7):
    """As :func:`_stream`, but each claim is right with probability ``accuracy`` whatever its score."""
    rng = np.random.default_rng(seed)
    z = rng.integers(0, k, n_tasks)
    tasks, labels, conf = [], [], []
    for t in range(n_tasks):
        for _ in range(per_task):
            right = rng.random() < accuracy
            labels.append(z[t] if right else rng.choice([x for x in range(k) if x != z[t]]))
            tasks.append(t)
            conf.append(rng.uniform(0.1, 0.6))
    return np.array(tasks), np.array(labels), np.array(conf)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scores_that_inform_are_read_and_scores_that_do_not_are_counted(seed: int) -> None:
    """240 claims at level 0.05 (seeded): a detector right with probability sigmoid(logit c + 1.5)
    passes the rank test and is read shifted; one right 70 % of the time whatever its score does not,
    and every claim reads the same, above 1/2 (the level is about logit 0.7)."""
    tasks, labels, conf = _stream(seed, 1.5)
    cal = ShiftCalibration(test_level=0.05).fit(tasks, labels, conf, np.zeros(len(tasks), int))
    r = cal.readings_[0]
    assert r.reads_scores and r.p_value < 0.05 and cal.shift(0) == max(0.0, r.fitted)
    tasks, labels, conf = _uninformative_stream(seed)
    cal = ShiftCalibration(test_level=0.05).fit(tasks, labels, conf, np.zeros(len(tasks), int))
    r = cal.readings_[0]
    assert not r.reads_scores and r.p_value >= 0.05 and cal.shift(0) == 0.0
    lams = {cal.likelihood_ratio(c, (0, 0, 0))[0] for c in (0.1, 0.3, 0.6, 0.9)}
    assert len(lams) == 1 and lams.pop() > 1.0
    assert r.fitted == pytest.approx(logit(0.7), abs=0.6)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 3)), min_size=1, max_size=30),
       st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-2.0, 2.0))
def test_the_batched_readings_are_the_scalar_ones(claims, shift, level, stated) -> None:
    """Contexts 0 (scores read, shift), 1 (one level), 2 (not fitted: raw), 3 (scores read, negative
    shift): ``likelihood_ratios`` gives what ``likelihood_ratio`` gives claim by claim."""
    cal = ShiftCalibration()
    cal.readings_ = {0: ContextReading(shift, 10, True), 1: ContextReading(level, 10, False, 0.5, stated),
                     3: ContextReading(-abs(shift), 10, True)}
    c = np.array([x for x, _ in claims])
    w = np.array([k for _, k in claims])
    lams, kappas = cal.likelihood_ratios(c, [w, w, w])
    expected = [cal.likelihood_ratio(float(x), (0, 0, int(k)))[0] for x, k in claims]
    np.testing.assert_allclose(lams, expected, rtol=1e-12)

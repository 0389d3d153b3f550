"""Conformal coverage (Prop. 1): split sets on exchangeable data, adaptive sets under drift.

Statistical tests: seeded; tolerances stated next to each assertion.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.calibration.mondrian import MondrianCalibrator
from sgbelief.calibration.config import CalibrationConfig
from sgbelief.calibration.conformal import conformal_quantile, nonconformity, prediction_set

ALPHA = 0.1


def test_nonconformity_is_negative_log_likelihood() -> None:
    assert nonconformity(0.8, 1) == pytest.approx(-math.log(0.8))
    assert nonconformity(0.8, 0) == pytest.approx(-math.log(0.2))
    assert math.isfinite(nonconformity(0.0, 1)) and math.isfinite(nonconformity(1.0, 0))


def test_finite_sample_quantile_rank() -> None:
    scores = sorted([0.1 * i for i in range(1, 20)])  # n = 19
    # ceil((19 + 1) * 0.9) = 18 -> the 18th smallest
    assert conformal_quantile(scores, 0.1) == pytest.approx(1.8)
    assert conformal_quantile(scores[:5], 0.1) == math.inf  # rank 6 > n: full set
    assert prediction_set(0.7, math.inf) == frozenset({0, 1})


def _draw(rng: np.random.Generator, n: int, shift: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    c = rng.beta(2.0, 2.0, size=n)
    p_true = np.clip(c**1.5 + shift, 0.0, 1.0)
    return c, (rng.random(n) < p_true).astype(int)


@pytest.mark.slow
def test_split_sets_cover_on_exchangeable_data() -> None:
    rng = np.random.default_rng(0)
    n_cal, n_test, reps = 200, 2000, 40
    cover = []
    for _ in range(reps):
        cal = MondrianCalibrator(CalibrationConfig(), alpha=ALPHA)
        c, y = _draw(rng, n_cal)
        for ci, yi in zip(c, y):
            cal.add("k", "p", float(ci), int(yi))
        cal.refit_all()
        tc, ty = _draw(rng, n_test)
        hits = [int(yi) in cal.prediction_set(float(ci), "k", "p").labels for ci, yi in zip(tc, ty)]
        cover.append(np.mean(hits))
    mean_cover = float(np.mean(cover))
    bound = 1 - ALPHA - 1 / (n_cal + 1)
    # tolerance 0.01: 3 standard errors of the mean over 40 calibration draws (sd of one draw ~0.02)
    assert mean_cover >= bound - 0.01, (mean_cover, bound)


def test_no_coverage_claim_outside_the_regime() -> None:
    cal = MondrianCalibrator()
    ps = cal.prediction_set(0.7, "never", "seen")
    assert ps.coverage is None and ps.labels == frozenset({0, 1}) and "no coverage claim" in ps.reason


@pytest.mark.slow
def test_adaptive_keeps_long_run_coverage_under_drift_static_does_not() -> None:
    rng = np.random.default_rng(1)
    cal = MondrianCalibrator(CalibrationConfig(adaptive_gamma=0.01), alpha=ALPHA)
    for ci, yi in zip(*_draw(rng, 300)):
        cal.add("k", "p", float(ci), int(yi))
    cal.refit_all()
    static_hits, adaptive_hits = [], []
    steps = 12000
    for t in range(steps):
        # the model drifts: its confidence says less and less about the outcome, then inverts
        shift = min(1.0, t / 4000)
        c = float(rng.beta(2, 2))
        p_true = (1 - shift) * c**1.5 + shift * (1 - c)
        y = int(rng.random() < p_true)
        static_hits.append(y in cal.prediction_set(c, "k", "p", adaptive=False).labels)
        adaptive_hits.append(y in cal.prediction_set(c, "k", "p", adaptive=True).labels)
        cal.add("k", "p", c, y)
    adaptive_cov = float(np.mean(adaptive_hits))
    static_late = float(np.mean(static_hits[steps // 2 :]))
    # Gibbs & Candes: |long-run miscoverage - alpha| <= (1 + gamma) / (gamma T) ~ 0.008 here; tolerance 0.03
    assert abs(adaptive_cov - (1 - ALPHA)) <= 0.03, adaptive_cov
    assert abs(static_late - (1 - ALPHA)) > 0.03, static_late


# ---------------------------------------------------------------------------------------------
# ConformalSlice: add_score / add_outcome, lazy merges, list and numpy paths


def _reference_window(scores: list[float], capacity: int | None) -> list[float]:
    return sorted(scores[-capacity:] if capacity is not None else scores)


@pytest.mark.parametrize("capacity", [None, 16, 100])
@pytest.mark.parametrize("small", [0, 128, 10**9])
def test_add_score_equals_pending_plus_refresh_rule(capacity: int | None, small: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """``add_score(s, min_refit, growth)`` / ``add_outcome(c, y, ...)`` == ``pending.append(s)`` then a
    refresh once the pending ones reach max(min_refit, growth * n_sorted) (the operator's old
    pair-score path); the sorted view is the last ``capacity`` committed scores, ascending, read
    after every refresh or only now and then (lazy merges), on the list and numpy paths."""
    from sgbelief.calibration import conformal
    from sgbelief.calibration.conformal import ConformalSlice

    monkeypatch.setattr(conformal, "SMALL", small)
    rng = np.random.default_rng(21)
    a, b, c_ = ConformalSlice(ALPHA, capacity), ConformalSlice(ALPHA, capacity), ConformalSlice(ALPHA, capacity)
    committed: list[float] = []
    seen: list[float] = []
    for i in range(1500):
        c = float(np.round(rng.random(), 3))
        y = int(rng.random() < c)
        s = nonconformity(c, y)
        seen.append(s)
        # the old protocol, by hand
        a.pending.append(s)
        if a.n_sorted + len(a.pending) - a.n_sorted >= max(8, 0.1 * a.n_sorted) or a.n_sorted == 0:
            a.refresh()
            committed = list(seen)
        b.add_score(s, 8, 0.1)
        c_.add_outcome(c, y, 8, 0.1)
        assert b.n_sorted == a.n_sorted == c_.n_sorted and len(b.pending) == len(a.pending) == len(c_.pending)
        if i % 7 == 0 or i > 1480:
            ref = _reference_window(committed, capacity)
            assert list(b.sorted) == list(c_.sorted) == ref and b.n_sorted == len(ref)
            for al in (0.05, 0.1, 0.5):
                assert b.threshold(al) == c_.threshold(al) == conformal_quantile(ref, al)
            assert b.coverage_of_rank(1.0) == sum(1 for v in ref if v <= 1.0)
            if capacity is not None:
                assert list(b.fifo) == (committed[-capacity:])
    assert list(a.sorted) == list(b.sorted)


def test_batches_beyond_capacity_are_dropped_unmerged() -> None:
    from sgbelief.calibration.conformal import ConformalSlice

    sl = ConformalSlice(ALPHA, capacity=20)
    scores = [float(i % 13) / 7 for i in range(200)]
    for i in range(0, 200, 50):
        for s in scores[i : i + 50]:
            sl.pending.append(s)
        sl.refresh()
        assert sl.n_sorted == 20 and sl.n_chunks <= 50
    assert list(sl.sorted) == sorted(scores[-20:]) and list(sl.fifo) == scores[-20:]


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.sampled_from([0.0, -0.0, 0.5, 1.0, 2.0, math.inf, math.nan, 1e-300]) | st.floats(-5, 5), max_size=40),
    st.lists(st.sampled_from([0.0, -0.0, 0.5, 1.0, 2.0, math.inf, math.nan, 1e-300]) | st.floats(-5, 5), min_size=1, max_size=40),
)
def test_merge_sorted_is_bitwise_the_stable_merge(base: list[float], new: list[float]) -> None:
    """merge_sorted == np.insert of the stably sorted new values after equal base values, bit for
    bit (signed zeros and NaN included), with and without a payload."""
    from sgbelief.calibration.conformal import merge_sorted

    b = np.sort(np.array(base, dtype=np.float64), kind="stable")
    nw = np.array(new, dtype=np.float64)
    order = np.argsort(nw, kind="stable")
    at = np.searchsorted(b, nw[order], side="right")
    expected = np.insert(b, at, nw[order])
    assert merge_sorted(b, nw).tobytes() == expected.tobytes()
    pb, pn = np.arange(len(b)), 1000 + np.arange(len(nw))
    m, p = merge_sorted(b, nw, (pb, pn))
    assert m.tobytes() == expected.tobytes()
    assert p.tolist() == np.insert(pb, at, pn[order]).tolist()

"""Conformal coverage (Prop. 1): split sets on exchangeable data, adaptive sets under drift.

Statistical tests: seeded; tolerances stated next to each assertion.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sgbelief.fusion.calibration import MondrianCalibrator
from sgbelief.fusion.config import CalibrationConfig
from sgbelief.fusion.conformal import conformal_quantile, nonconformity, prediction_set

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

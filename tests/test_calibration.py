"""Mondrian isotonic calibration: equals scikit-learn, amortised refits, LR of Eq. 2, shrinkage, cold start."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.isotonic import IsotonicRegression

from sgbelief.fusion.calibration import CalibrationSlice, MondrianCalibrator
from sgbelief.fusion.config import CalibrationConfig


def _data(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    c = rng.beta(2, 2, size=n)
    y = (rng.random(n) < c**2).astype(int)  # miscalibrated: true rate c^2
    return c, y


def test_isotonic_fit_equals_scikit_learn() -> None:
    c, y = _data(700)
    cal = MondrianCalibrator()
    for ci, yi in zip(c, y):
        cal.add("vlm", "is_chair", float(ci), int(yi))
    cal.refit_all()
    s = cal.slices[("vlm", "is_chair")]
    ref = IsotonicRegression(y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(c, y)
    probe = np.concatenate([c, np.linspace(-0.1, 1.1, 57)])
    ours = np.array([s.p_hat(float(x)) for x in probe])
    np.testing.assert_allclose(ours, ref.predict(probe), rtol=0, atol=1e-12)


def test_refits_are_amortised() -> None:
    c, y = _data(5000, seed=1)
    s = CalibrationSlice(alpha=0.1)
    cfg = CalibrationConfig()
    refits = 0
    for ci, yi in zip(c, y):
        s.add(float(ci), int(yi))
        if s.n - s.n_fit >= max(cfg.min_refit, cfg.refit_growth * s.n_fit) or s.n_fit == 0:
            s.refit()
            refits += 1
    # geometric schedule: O(log n) refits, not one per outcome
    assert refits < 90, refits
    assert s.n - s.n_fit <= max(cfg.min_refit, cfg.refit_growth * s.n_fit)


def test_likelihood_ratio_is_eq2_and_always_finite_positive() -> None:
    cal = MondrianCalibrator(CalibrationConfig(target_size=10))
    c, y = _data(400, seed=2)
    for ci, yi in zip(c, y):
        cal.add("k", "p", float(ci), int(yi))
    cal.refit_all()
    s = cal.slices[("k", "p")]
    for probe in [0.0, 1e-9, 0.3, 0.5, 0.9, 1.0]:
        lam, kappa = cal.likelihood_ratio(probe, "k", "p")
        assert math.isfinite(lam) and lam > 0 and kappa == 1.0
        eps = 0.5 / (s.n + 1)
        p = min(max(s.p_hat(probe), eps), 1 - eps)
        pi = min(max(s.n_pos / s.n, eps), 1 - eps)
        expected = (p / (1 - p)) * ((1 - pi) / pi)
        expected = min(max(expected, 1e-3), 1e3)
        assert lam == pytest.approx(expected, rel=1e-9)
    # a degenerate slice (all outcomes positive) still gives a finite, positive ratio
    for _ in range(30):
        cal.add("k", "all_pos", 0.9, 1)
    lam, _ = cal.likelihood_ratio(0.9, "k", "all_pos")
    assert math.isfinite(lam) and lam > 0


def test_sparse_slices_shrink_toward_predicate_and_global() -> None:
    cfg = CalibrationConfig(target_size=100, kappa_min=0.05)
    cal = MondrianCalibrator(cfg)
    rng = np.random.default_rng(3)
    for _ in range(400):  # a well-populated context
        c = float(rng.random())
        cal.add("big", "is_car", c, int(rng.random() < c))
    for c, y in [(0.9, 0), (0.8, 0), (0.95, 0), (0.7, 0), (0.2, 1)]:  # a sparse, contrarian context
        cal.add("small", "is_car", c, y)
    lam_small, kappa_small = cal.likelihood_ratio(0.9, "small", "is_car")
    lam_pool, _ = cal.likelihood_ratio(0.9, "unseen", "is_car")
    s = cal.slices[("small", "is_car")]
    lam_slice_only = math.exp(s.log_lr(0.9))
    assert kappa_small == pytest.approx(5 / 100)
    assert min(lam_slice_only, lam_pool) < lam_small < max(lam_slice_only, lam_pool)
    assert cal.likelihood_ratio(0.9, "unseen", "is_car")[1] == cfg.kappa_min


def test_cold_start_rules() -> None:
    raw = MondrianCalibrator(CalibrationConfig(cold_start="raw", kappa_min=0.1))
    lam, kappa = raw.likelihood_ratio(0.8, "k", "p")
    assert lam == pytest.approx(4.0) and kappa == 0.1
    neutral = MondrianCalibrator(CalibrationConfig(cold_start="neutral"))
    assert neutral.likelihood_ratio(0.8, "k", "p")[0] == 1.0


def test_monotone_transform_leaves_knot_values_unchanged() -> None:
    c, y = _data(600, seed=4)
    a, b = MondrianCalibrator(), MondrianCalibrator()
    for ci, yi in zip(c, y):
        a.add("k", "p", float(ci), int(yi))
        b.add("k", "p", float(ci) ** 3, int(yi))
    a.refit_all(), b.refit_all()
    sa, sb = a.slices[("k", "p")], b.slices[("k", "p")]
    np.testing.assert_allclose(sa.ky, sb.ky, atol=1e-12)
    np.testing.assert_allclose(np.array(sa.kx) ** 3, sb.kx, rtol=1e-9)
    for ci in c[:50]:
        assert a.likelihood_ratio(float(ci), "k", "p")[0] == pytest.approx(b.likelihood_ratio(float(ci) ** 3, "k", "p")[0], rel=1e-9)


def test_lr_reference_uniform_keeps_the_calibrated_posterior_odds() -> None:
    # a slice where every verified claim is correct: the confidence does not discriminate,
    # so Eq. 2 with the slice's base rate gives Lambda = 1, the uniform reference p/(1-p) > 1
    slice_ref = MondrianCalibrator(CalibrationConfig(lr_reference="slice"))
    uniform = MondrianCalibrator(CalibrationConfig(lr_reference="uniform"))
    for c in np.linspace(0.3, 0.99, 60):
        slice_ref.add("k", "p", float(c), 1)
        uniform.add("k", "p", float(c), 1)
    assert slice_ref.likelihood_ratio(0.8, "k", "p")[0] == pytest.approx(1.0)
    s = uniform.slices[("k", "p")]
    eps = 0.5 / (s.n_fit + 1)
    p = min(max(s.p_hat(0.8), eps), 1 - eps)
    assert uniform.likelihood_ratio(0.8, "k", "p")[0] == pytest.approx(p / (1 - p))


def test_sliding_window_equals_a_fresh_fit_on_the_last_outcomes() -> None:
    """With buffer_size = W, after every refit the slice holds exactly the last W outcomes:
    same knots, base rate and conformal scores as an unbounded slice fitted on that tail."""
    c, y = _data(3000, seed=4)
    w = 500
    s = CalibrationSlice(alpha=0.1, capacity=w)
    cfg = CalibrationConfig()
    checked = 0
    for i, (ci, yi) in enumerate(zip(c, y)):
        s.add(float(ci), int(yi))
        if s.n - s.n_fit >= max(cfg.min_refit, cfg.refit_growth * s.n_fit) or s.n_fit == 0:
            s.refit()
            tail_c, tail_y = c[max(0, i + 1 - w) : i + 1], y[max(0, i + 1 - w) : i + 1]
            ref = CalibrationSlice(alpha=0.1)
            for cj, yj in zip(tail_c, tail_y):
                ref.add(float(cj), int(yj))
            ref.refit()
            assert s.n == ref.n == len(tail_c) and s.n_pos == ref.n_pos
            assert s.kx == ref.kx and s.ky == ref.ky
            np.testing.assert_array_equal(s.conformal.sorted, ref.conformal.sorted)
            checked += 1
    assert s.n_seen == 3000 and s.n <= w + max(cfg.min_refit, cfg.refit_growth * w)
    assert checked > 20


def test_calibrator_buffer_is_bounded_by_buffer_size() -> None:
    cal = MondrianCalibrator(CalibrationConfig(buffer_size=256))
    c, y = _data(5000, seed=5)
    for ci, yi in zip(c, y):
        cal.add("k", "p", float(ci), int(yi))
    cal.refit_all()
    for key in (("k", "p"), ("*", "p"), ("*", "*")):
        s = cal.slices[key]
        assert s.n == 256 and s.n_seen == 5000
        assert len(s.fc) == len(s.sx0) + len(s.sx1) == s.conformal.n_sorted == 256
    assert cal.n_outcomes() == 256 and cal.n_outcomes(seen=True) == 5000
    lam, kappa = cal.likelihood_ratio(0.7, "k", "p")
    assert math.isfinite(lam) and lam > 0 and kappa == 1.0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 20), min_size=1, max_size=60), st.data())
def test_remove_sorted_removes_one_occurrence_each(values: list[int], data: st.DataObject) -> None:
    from sgbelief.fusion.conformal import remove_sorted

    base = np.sort(np.array(values, dtype=np.float64) / 4)
    k = data.draw(st.integers(0, len(values)))
    idx = data.draw(st.permutations(range(len(values))))[:k]
    removed = base[list(idx)] if k else np.empty(0)
    out = remove_sorted(base, removed)
    expected = np.delete(base, list(idx)) if k else base
    np.testing.assert_array_equal(out, np.sort(expected))
    with pytest.raises(ValueError):
        remove_sorted(base, np.array([99.0]))

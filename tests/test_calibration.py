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
from sgbelief.fusion.conformal import nonconformity


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


@pytest.mark.parametrize("reference", ["slice", "uniform"])
def test_likelihood_ratio_is_eq2_and_always_finite_positive(reference: str) -> None:
    cal = MondrianCalibrator(CalibrationConfig(target_size=10, lr_reference=reference))
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
        pi = min(max(s.n_pos / s.n, eps), 1 - eps) if reference == "slice" else 0.5  # Beta(1, 1): odds 1
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


# ---------------------------------------------------------------------------------------------
# fast paths: the distinct-confidence fit, the small (Python list) path, lazy fits, the reference


def _sklearn_knots(c: np.ndarray, y: np.ndarray) -> tuple[list[float], list[float]]:
    ref = IsotonicRegression(y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(c, y)
    return ref.X_thresholds_.tolist(), ref.y_thresholds_.tolist()


def _odd_confidences(rng: np.random.Generator, n: int, kind: int) -> np.ndarray:
    if kind == 0:  # continuous
        return rng.random(n)
    if kind == 1:  # heavily tied (quantised)
        return np.round(rng.random(n), int(rng.integers(1, 4)))
    if kind == 2:  # chains of near-ties (< 1e-15 apart): scikit-learn's own pooling rule applies
        return rng.choice([0.25, 0.5, 0.75], n) + rng.integers(0, 8, n) * 3e-16
    return rng.choice([0.0, 1.0, 0.5, 1e-300, 1 - 2**-53], n)  # extremes


@pytest.mark.parametrize("small", [True, False])
def test_fit_is_bit_identical_to_scikit_learn_on_both_paths(small: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Knots == IsotonicRegression's X_thresholds_ / y_thresholds_ exactly (==, not isclose), on the
    Python-list path (small slices) and the numpy distinct-confidence path."""
    from sgbelief.fusion import calibration, conformal

    monkeypatch.setattr(calibration, "SMALL", 10**9 if small else 0)
    monkeypatch.setattr(conformal, "SMALL", 10**9 if small else 0)
    rng = np.random.default_rng(11)
    for trial in range(120):
        n = int(rng.integers(1, 300))
        c = _odd_confidences(rng, n, trial % 4)
        y = (rng.random(n) < np.clip(c, 0, 1)).astype(int)
        s = CalibrationSlice(alpha=0.1)
        for ci, yi in zip(c.tolist(), y.tolist()):
            s.add(ci, yi)
        s.refit()
        assert (s.kx, s.ky) == _sklearn_knots(c, y)
        assert type(s.ux) is (list if small else np.ndarray)
        np.testing.assert_array_equal(s.sx0, np.sort(c[y == 0]))
        np.testing.assert_array_equal(s.sx1, np.sort(c[y == 1]))
        assert s.n == s.n_fit == n and s.n_pos == y.sum() and s.base_rate == y.sum() / n


@pytest.mark.parametrize("capacity", [None, 16, 50, 300])
def test_small_and_numpy_paths_and_lazy_fits_agree(capacity: int | None, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same stream through the Python-list path, the numpy path and the crossing between them,
    read after every refit or only at the end (lazy fits merging many batches), gives the same
    knots, base rate, sorted outcomes, window and conformal scores, also across sliding-window
    evictions (and batches that alone overflow the window)."""
    from sgbelief.fusion import calibration, conformal

    rng = np.random.default_rng(12)
    n = 1500
    c = np.round(rng.beta(2, 2, n), 3)
    y = (rng.random(n) < c).astype(int)

    def run(small: int, read_every: bool, min_refit: int) -> list:
        monkeypatch.setattr(calibration, "SMALL", small)
        monkeypatch.setattr(conformal, "SMALL", small)
        s = CalibrationSlice(alpha=0.1, capacity=capacity, min_refit=min_refit)
        states = []
        for i, (ci, yi) in enumerate(zip(c.tolist(), y.tolist())):
            s.add(ci, yi)
            if s.n - s.n_fit >= s.refit_gap:
                s.refit()
                if read_every or i > n - 40:
                    states.append((s.kx, s.ky, s.base_rate, s.log_prior_odds, s.n, s.n_pos, s.n_seen,
                                   s.sx0.tolist(), s.sx1.tolist(), list(s.fc), list(s.fy), list(s.conformal.sorted)))
        return states

    ref = run(0, True, 8)
    assert run(10**9, True, 8) == ref  # Python lists throughout
    assert run(128, True, 8) == ref  # lists, then numpy
    lazy = run(0, False, 8)
    assert lazy == ref[len(ref) - len(lazy):]


@pytest.mark.parametrize("capacity", [16, 50, 300])
def test_batches_larger_than_the_window_equal_a_fresh_fit_on_the_tail(capacity: int) -> None:
    """Refits committing batches larger than the window, read only at the end (the older batches
    are dropped unmerged): same as a fresh fit on the last ``capacity`` outcomes."""
    c, y = _data(2000, seed=13)
    c = np.round(c, 3)
    s = CalibrationSlice(alpha=0.1, capacity=capacity, min_refit=3 * capacity + 1)
    for ci, yi in zip(c.tolist(), y.tolist()):
        s.add(ci, yi)
        if s.n - s.n_fit >= s.refit_gap:
            s.refit()
    s.refit()
    fresh = CalibrationSlice(alpha=0.1)
    for ci, yi in zip(c[-capacity:].tolist(), y[-capacity:].tolist()):
        fresh.add(ci, yi)
    fresh.refit()
    assert s.n == s.n_fit == capacity and s.n_seen == 2000
    assert (s.kx, s.ky, s.base_rate, s.n_pos) == (fresh.kx, fresh.ky, fresh.base_rate, fresh.n_pos)
    assert list(s.fc) == c[-capacity:].tolist() and list(s.conformal.fifo) == [
        nonconformity(ci, yi) for ci, yi in zip(c[-capacity:].tolist(), y[-capacity:].tolist())
    ]
    assert list(s.conformal.sorted) == list(fresh.conformal.sorted) and s.conformal.n_sorted == capacity


class _ReferenceCalibrator:
    """The calibrator of §4.1 written the slow, obvious way (the specification the fast one must
    reproduce exactly): every outcome kept, a refit fits scikit-learn's IsotonicRegression on the
    last ``buffer_size`` outcomes and sorts their scores."""

    def __init__(self, cfg: CalibrationConfig, alpha: float) -> None:
        self.cfg, self.alpha = cfg, alpha
        self.levels: dict[tuple[str, str], dict] = {}

    def _level(self, key: tuple[str, str]) -> dict:
        return self.levels.setdefault(key, {"out": [], "n_fit": 0, "kx": [], "ky": [], "lpo": 0.0, "scores": [], "alpha_t": self.alpha})

    def _refit(self, lv: dict) -> None:
        from sgbelief.fusion.conformal import nonconformity

        cap = self.cfg.buffer_size
        win = lv["out"][-cap:] if cap is not None else lv["out"]
        c = np.array([o[0] for o in win])
        y = np.array([1 if o[1] else 0 for o in win])
        lv["kx"], lv["ky"] = _sklearn_knots(c, y)
        n = len(win)
        lv["n_fit"] = n
        eps = 0.5 / (n + 1)
        pi = min(max(y.sum() / n, eps), 1 - eps)
        lv["lpo"] = math.log(pi / (1 - pi))
        lv["scores"] = sorted(nonconformity(ci, yi) for ci, yi in win)

    def add(self, k: str, p: str, c: float, y: int) -> None:
        from sgbelief.fusion.conformal import conformal_quantile, nonconformity

        levels = [self._level(key) for key in ((k, p), ("*", p), ("*", "*"))]
        first = levels[0]
        if first["n_fit"] > 0 and k != "*":
            a = first["alpha_t"]
            q = conformal_quantile(first["scores"], a) if a > 0 else math.inf
            err = 0 if nonconformity(c, y) <= q else 1
            first["alpha_t"] += self.cfg.adaptive_gamma * (self.alpha - err)
        for lv in levels:  # (a "*" context: its slice is the predicate pool, which gets the outcome twice)
            lv["out"].append((c, y))
            pending = len(lv["out"]) - lv.get("seen_fit", 0)
            if pending >= max(self.cfg.min_refit, self.cfg.refit_growth * lv["n_fit"]) or lv["n_fit"] == 0:
                lv["seen_fit"] = len(lv["out"])
                self._refit(lv)

    def _log_lr(self, lv: dict, c: float) -> float:
        kx, ky = lv["kx"], lv["ky"]
        i = int(np.searchsorted(kx, c, side="right"))
        if i == 0:
            pr = ky[0]
        elif i >= len(kx):
            pr = ky[-1]
        else:
            x0, x1 = kx[i - 1], kx[i]
            pr = ky[i] if x1 == x0 else ky[i - 1] + (ky[i] - ky[i - 1]) * (c - x0) / (x1 - x0)
        eps = 0.5 / (lv["n_fit"] + 1)
        pr = min(max(pr, eps), 1 - eps)
        lo = math.log(pr / (1 - pr))
        return lo - lv["lpo"] if self.cfg.lr_reference == "slice" else lo

    def likelihood_ratio(self, c: float, k: str, p: str) -> tuple[float, float]:
        cfg, t = self.cfg, self.cfg.target_size
        s, pp, g = (self.levels.get(key, {"n_fit": 0}) for key in ((k, p), ("*", p), ("*", "*")))
        m = math.log(cfg.lr_max)
        cc = min(max(c, 1e-6), 1.0 - 1e-6)
        cold = 0.0 if cfg.cold_start == "neutral" else min(max(math.log(cc / (1.0 - cc)), -m), m)
        if g["n_fit"] == 0:
            return math.exp(cold), cfg.kappa_min
        if s["n_fit"] >= t:
            log_lr = self._log_lr(s, c)
        else:
            if pp["n_fit"] >= t:
                log_lr = self._log_lr(pp, c)
            else:
                log_lr = self._log_lr(g, c)
                if g["n_fit"] < t:  # the sparse global level shrinks toward the cold-start rule
                    lg = g["n_fit"] / t
                    log_lr = lg * log_lr + (1.0 - lg) * cold
                if pp["n_fit"]:
                    lp = pp["n_fit"] / t
                    log_lr = lp * self._log_lr(pp, c) + (1.0 - lp) * log_lr
            if s["n_fit"]:
                ls = s["n_fit"] / t
                log_lr = ls * self._log_lr(s, c) + (1.0 - ls) * log_lr
        log_lr = min(max(log_lr, -m), m)
        if cfg.kappa_pooling == "pooled":
            ls, lp = min(1.0, s["n_fit"] / t), min(1.0, pp["n_fit"] / t)
            kappa = ls + (1.0 - ls) * (lp + (1.0 - lp) * min(1.0, g["n_fit"] / t))
        else:
            kappa = s["n_fit"] / t
        return math.exp(log_lr), min(max(kappa, cfg.kappa_min), 1.0)


@settings(max_examples=25, deadline=None)
@given(
    st.sampled_from([None, 16, 40, 200]),
    st.sampled_from(["slice", "uniform"]),
    st.sampled_from(["raw", "neutral"]),
    st.integers(1, 12),
    st.sampled_from([0.05, 0.1, 0.5]),
    st.integers(0, 2**32 - 1),
    st.sampled_from(["slice", "pooled"]),
)
def test_calibrator_equals_the_reference_exactly(buffer_size, lr_reference, cold_start, min_refit, growth, seed,
                                                 kappa_pooling) -> None:
    """Every Lambda_hat / kappa_hat, alpha_t, threshold and counter equals (==) the slow reference
    (scikit-learn refit on the window at the same schedule), for several contexts including "*"."""
    cfg = CalibrationConfig(buffer_size=buffer_size, lr_reference=lr_reference, cold_start=cold_start,
                            min_refit=min_refit, refit_growth=growth, target_size=30, adaptive_gamma=0.05,
                            kappa_pooling=kappa_pooling)
    rng = np.random.default_rng(seed)
    cal, ref = MondrianCalibrator(cfg, alpha=0.2), _ReferenceCalibrator(cfg, 0.2)
    quant = int(rng.integers(1, 7))
    for t in range(400):
        k, p = ["a", "b", "*"][int(rng.integers(0, 3))], ["p", "q"][int(rng.integers(0, 2))]
        c = round(float(rng.beta(2, 2)), quant)
        y = int(rng.random() < c)
        if t % 3 == 0:
            for qk, qp in ((k, p), ("a", "q"), ("z", "p"), ("*", "*")):
                probe = float(rng.random())
                assert cal.likelihood_ratio(probe, qk, qp) == ref.likelihood_ratio(probe, qk, qp)
        cal.add(k, p, c, y)
        ref.add(k, p, c, y)
    for key, lv in ref.levels.items():
        s = cal.slices[key]
        assert (s.n_fit, s.kx, s.ky, s.log_prior_odds) == (lv["n_fit"], lv["kx"], lv["ky"], lv["lpo"])
        assert s.n_seen == len(lv["out"]) and s.conformal.alpha_t == lv["alpha_t"]
        assert list(s.conformal.sorted) == lv["scores"]
        for a in (0.05, 0.2, 0.5):
            assert s.conformal.threshold(a) == conformal_quantile_ref(lv["scores"], a)


def conformal_quantile_ref(scores: list[float], alpha: float) -> float:
    n = len(scores)
    rank = math.ceil((n + 1) * (1.0 - alpha))
    return -math.inf if alpha >= 1 else math.inf if rank > n or n == 0 else -math.inf if rank < 1 else scores[rank - 1]


def test_counters_and_pending_views() -> None:
    s = CalibrationSlice(alpha=0.1, capacity=20)
    for i in range(57):
        s.add(i / 60, i % 3 == 0)
        if s.n - s.n_fit >= s.refit_gap:
            s.refit()
    pend = len(s.c)
    assert s.n == s.n_fit + pend and s.n_seen == 57 and s.n_fit == 20
    assert list(s.y) == [int(i % 3 == 0) for i in range(57 - pend, 57)]
    assert s.n_pos == sum(1 for i in range(57 - pend - 20, 57) if i % 3 == 0)  # window + pending
    assert len(s.conformal.pending) == pend and s.conformal.n == s.n
    with pytest.raises(ZeroDivisionError):
        CalibrationSlice(alpha=0.1).refit()


def test_pickled_calibrator_continues_identically() -> None:
    """A calibrator copied mid-stream (pickle, deepcopy) with pending outcomes and unmerged
    batches gives the same results as the original from there on."""
    import copy
    import pickle

    cfg = CalibrationConfig(buffer_size=64, target_size=40)
    cal = MondrianCalibrator(cfg, alpha=0.1)
    rng = np.random.default_rng(14)
    stream = [(["a", "b"][int(rng.integers(0, 2))], ["p", "q"][int(rng.integers(0, 2))], round(float(rng.random()), 3)) for _ in range(900)]
    for k, p, c in stream[:450]:
        cal.add(k, p, c, int(rng.random() < c))
    clones = [pickle.loads(pickle.dumps(cal)), copy.deepcopy(cal)]
    for k, p, c in stream[450:]:
        y = int(rng.random() < c)
        for m in (cal, *clones):
            m.add(k, p, c, y)
        assert len({m.likelihood_ratio(c, k, p) for m in (cal, *clones)}) == 1
    assert cal.summary() == clones[0].summary() == clones[1].summary()


@pytest.mark.parametrize("n", [20, 400])
def test_nan_confidences_fit_as_before(n: int) -> None:
    """NaN confidences (sorted last, pooled into the last point by ``_make_unique``) give the knots
    of ``_isotonic_knots`` on the sorted outcomes (NaN always takes the numpy path)."""
    from sgbelief.fusion.calibration import _isotonic_knots

    rng = np.random.default_rng(15)
    c = np.round(rng.random(n), 2)
    c[rng.random(n) < 0.1] = np.nan
    y = (rng.random(n) < 0.5).astype(int)
    s = CalibrationSlice(alpha=0.1)
    for ci, yi in zip(c.tolist(), y.tolist()):
        s.add(ci, yi)
    s.refit()
    x = np.concatenate((np.sort(c[y == 0]), np.sort(c[y == 1])))
    order = np.argsort(x, kind="stable")
    kx, ky = _isotonic_knots(x[order], np.concatenate((np.zeros((y == 0).sum()), np.ones((y == 1).sum())))[order])
    assert np.array_equal(s.kx, kx, equal_nan=True) and np.array_equal(s.ky, ky, equal_nan=True)
    assert s.n == n and len(s.sx0) + len(s.sx1) == n

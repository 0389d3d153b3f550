"""Mondrian isotonic calibration: equals scikit-learn, amortised refits, LR of Eq. 2, shrinkage, cold start.

Calibrator-level tests run with both isotonic stores: the reference refit (the default) and the
fast incremental merge the fast engine injects (``STORES``). The fast store's own paths are tested
in tests/test_fast_isotonic.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.isotonic import IsotonicRegression

from sgbelief._fast.isotonic import IncrementalIsotonic
from sgbelief.calibration.config import CalibrationConfig
from sgbelief.calibration.conformal import nonconformity
from sgbelief.calibration.isotonic import RefitIsotonic
from sgbelief.calibration.mondrian import (
    DEFAULT_GROUPS,
    MondrianCalibrator,
    by_context_and_predicate,
    by_predicate,
    cold_start_log_lr,
)
from sgbelief.calibration.slice import CalibrationSlice

STORES = pytest.mark.parametrize("store", [RefitIsotonic, IncrementalIsotonic], ids=["reference", "fast"])


def _data(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    c = rng.beta(2, 2, size=n)
    y = (rng.random(n) < c**2).astype(int)  # miscalibrated: true rate c^2
    return c, y


@STORES
def test_isotonic_fit_equals_scikit_learn(store) -> None:
    c, y = _data(700)
    cal = MondrianCalibrator(isotonic=store)
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


@STORES
@pytest.mark.parametrize("reference", ["slice", "uniform"])
def test_likelihood_ratio_is_eq2_and_always_finite_positive(reference: str, store) -> None:
    cal = MondrianCalibrator(CalibrationConfig(target_size=10, lr_reference=reference), isotonic=store)
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


@STORES
def test_sliding_window_equals_a_fresh_fit_on_the_last_outcomes(store) -> None:
    """With buffer_size = W, after every refit the slice holds exactly the last W outcomes:
    same knots, base rate and conformal scores as an unbounded slice fitted on that tail."""
    c, y = _data(3000, seed=4)
    w = 500
    s = CalibrationSlice(alpha=0.1, capacity=w, isotonic=store)
    cfg = CalibrationConfig()
    checked = 0
    for i, (ci, yi) in enumerate(zip(c, y)):
        s.add(float(ci), int(yi))
        if s.n - s.n_fit >= max(cfg.min_refit, cfg.refit_growth * s.n_fit) or s.n_fit == 0:
            s.refit()
            tail_c, tail_y = c[max(0, i + 1 - w) : i + 1], y[max(0, i + 1 - w) : i + 1]
            ref = CalibrationSlice(alpha=0.1, isotonic=store)
            for cj, yj in zip(tail_c, tail_y):
                ref.add(float(cj), int(yj))
            ref.refit()
            assert s.n == ref.n == len(tail_c) and s.n_pos == ref.n_pos
            assert s.kx == ref.kx and s.ky == ref.ky
            np.testing.assert_array_equal(s.conformal.sorted, ref.conformal.sorted)
            checked += 1
    assert s.n_seen == 3000 and s.n <= w + max(cfg.min_refit, cfg.refit_growth * w)
    assert checked > 20


@STORES
def test_calibrator_buffer_is_bounded_by_buffer_size(store) -> None:
    cal = MondrianCalibrator(CalibrationConfig(buffer_size=256), isotonic=store)
    c, y = _data(5000, seed=5)
    for ci, yi in zip(c, y):
        cal.add("k", "p", float(ci), int(yi))
    cal.refit_all()
    for key in (("k", "p"), ("*", "p"), ("*", "*")):
        s = cal.slices[key]
        assert s.n == 256 and s.n_seen == 5000
        assert len(s.window_confidences) == len(s.sorted_negatives) + len(s.sorted_positives) == s.conformal.n_sorted == 256
    assert cal.n_outcomes() == 256 and cal.n_outcomes(seen=True) == 5000
    lam, kappa = cal.likelihood_ratio(0.7, "k", "p")
    assert math.isfinite(lam) and lam > 0 and kappa == 1.0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 20), min_size=1, max_size=60), st.data())
def test_remove_sorted_removes_one_occurrence_each(values: list[int], data: st.DataObject) -> None:
    from sgbelief.calibration.conformal import remove_sorted

    base = np.sort(np.array(values, dtype=np.float64) / 4)
    k = data.draw(st.integers(0, len(values)))
    idx = data.draw(st.permutations(range(len(values))))[:k]
    removed = base[list(idx)] if k else np.empty(0)
    out = remove_sorted(base, removed)
    expected = np.delete(base, list(idx)) if k else base
    np.testing.assert_array_equal(out, np.sort(expected))
    with pytest.raises(ValueError):
        remove_sorted(base, np.array([99.0]))


def _sklearn_knots(c: np.ndarray, y: np.ndarray) -> tuple[list[float], list[float]]:
    ref = IsotonicRegression(y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(c, y)
    return ref.X_thresholds_.tolist(), ref.y_thresholds_.tolist()


@STORES
@pytest.mark.parametrize("capacity", [16, 50, 300])
def test_batches_larger_than_the_window_equal_a_fresh_fit_on_the_tail(capacity: int, store) -> None:
    """Refits committing batches larger than the window, read only at the end (the older batches
    are dropped unmerged): same as a fresh fit on the last ``capacity`` outcomes."""
    c, y = _data(2000, seed=13)
    c = np.round(c, 3)
    s = CalibrationSlice(alpha=0.1, capacity=capacity, min_refit=3 * capacity + 1, isotonic=store)
    for ci, yi in zip(c.tolist(), y.tolist()):
        s.add(ci, yi)
        if s.n - s.n_fit >= s.refit_gap:
            s.refit()
    s.refit()
    fresh = CalibrationSlice(alpha=0.1, isotonic=store)
    for ci, yi in zip(c[-capacity:].tolist(), y[-capacity:].tolist()):
        fresh.add(ci, yi)
    fresh.refit()
    assert s.n == s.n_fit == capacity and s.n_seen == 2000
    assert (s.kx, s.ky, s.base_rate, s.n_pos) == (fresh.kx, fresh.ky, fresh.base_rate, fresh.n_pos)
    assert list(s.window_confidences) == c[-capacity:].tolist() and list(s.conformal.fifo) == [
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
        from sgbelief.calibration.conformal import conformal_quantile

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
    st.sampled_from([RefitIsotonic, IncrementalIsotonic]),
    st.sampled_from([None, 16, 40, 200]),
    st.sampled_from(["slice", "uniform"]),
    st.sampled_from(["raw", "neutral"]),
    st.integers(1, 12),
    st.sampled_from([0.05, 0.1, 0.5]),
    st.integers(0, 2**32 - 1),
    st.sampled_from(["slice", "pooled"]),
)
def test_calibrator_equals_the_reference_exactly(store, buffer_size, lr_reference, cold_start, min_refit, growth, seed,
                                                 kappa_pooling) -> None:
    """Every Lambda_hat / kappa_hat, alpha_t, threshold and counter equals (==) the slow reference
    (scikit-learn refit on the window at the same schedule), for several contexts including "*"."""
    cfg = CalibrationConfig(buffer_size=buffer_size, lr_reference=lr_reference, cold_start=cold_start,
                            min_refit=min_refit, refit_growth=growth, target_size=30, adaptive_gamma=0.05,
                            kappa_pooling=kappa_pooling)
    rng = np.random.default_rng(seed)
    cal, ref = MondrianCalibrator(cfg, alpha=0.2, isotonic=store), _ReferenceCalibrator(cfg, 0.2)
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


@STORES
def test_pickled_calibrator_continues_identically(store) -> None:
    """A calibrator copied mid-stream (pickle, deepcopy) with pending outcomes and unmerged
    batches gives the same results as the original from there on."""
    import copy
    import pickle

    cfg = CalibrationConfig(buffer_size=64, target_size=40)
    cal = MondrianCalibrator(cfg, alpha=0.1, isotonic=store)
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


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_confidences_are_rejected_and_change_nothing(bad: float) -> None:
    """No isotonic fit is defined on NaN or infinite confidences (scikit-learn refuses them): the
    calibrator raises at once, naming the slice, and holds what it held before."""
    cal = MondrianCalibrator(CalibrationConfig(target_size=5))
    for i in range(20):
        cal.add("k", "p", i / 20, i % 2)
    before = cal.summary()
    with pytest.raises(ValueError, match="'k'/'p': confidence must be finite"):
        cal.add("k", "p", bad, 1)
    assert cal.summary() == before


# ---------------------------------------------------------------------------------------------
# the Mondrian grouping: groups= (crepes' bins=, MAPIE's groups=)


@STORES
def test_default_groups_are_the_paper_hierarchy(store) -> None:
    rng = np.random.default_rng(21)
    a, b = MondrianCalibrator(isotonic=store), MondrianCalibrator(groups=DEFAULT_GROUPS, isotonic=store)
    for _ in range(300):
        k, p, c = ["x", "y", "*"][int(rng.integers(0, 3))], ["p", "q"][int(rng.integers(0, 2))], round(float(rng.random()), 2)
        y = int(rng.random() < c)
        a.add(k, p, c, y)
        b.add(k, p, c, y)
        assert a.likelihood_ratio(c, k, p) == b.likelihood_ratio(c, k, p)
    assert a.summary() == b.summary()
    assert set(a.slices) == {("x", "p"), ("x", "q"), ("y", "p"), ("y", "q"), ("*", "p"), ("*", "q"), ("*", "*")}


@STORES
@pytest.mark.parametrize("kappa_pooling", ["slice", "pooled"])
def test_a_two_level_grouping_shrinks_toward_its_own_pool_then_the_cold_start(store, kappa_pooling: str) -> None:
    """groups=(per (context, predicate), per predicate): no global pool, so a predicate with no
    outcome yet gets the cold-start rule even when another predicate is well calibrated, and a
    sparse slice shrinks toward its predicate pool, which shrinks toward the cold-start rule."""
    cfg = CalibrationConfig(target_size=40, kappa_pooling=kappa_pooling)
    cal = MondrianCalibrator(cfg, groups=(by_context_and_predicate, by_predicate), isotonic=store)
    rng = np.random.default_rng(22)
    for _ in range(200):
        c = float(rng.random())
        cal.add("big", "is_car", c, int(rng.random() < c))
    for c, y in [(0.9, 0), (0.8, 0), (0.3, 1)]:
        cal.add("small", "is_chair", c, y)
    assert set(cal.slices) == {("big", "is_car"), ("*", "is_car"), ("small", "is_chair"), ("*", "is_chair")}
    m = math.log(cfg.lr_max)
    # an unseen predicate: the cold-start rule at kappa_min (the global level of the default would answer)
    assert cal.likelihood_ratio(0.8, "big", "is_table") == (math.exp(cold_start_log_lr(0.8, "raw", m)), cfg.kappa_min)
    assert MondrianCalibrator(cfg).likelihood_ratio(0.8, "big", "is_table")[1] == cfg.kappa_min
    # the sparse slice: l_s log L_s + (1 - l_s) [l_p log L_p + (1 - l_p) log L_cold]
    s, p = cal.slices[("small", "is_chair")], cal.slices[("*", "is_chair")]
    ls, lp = s.n_fit / 40, p.n_fit / 40
    inner = lp * p.log_lr(0.85, False) + (1 - lp) * cold_start_log_lr(0.85, "raw", m)
    lam, kappa = cal.likelihood_ratio(0.85, "small", "is_chair")
    assert lam == pytest.approx(math.exp(ls * s.log_lr(0.85, False) + (1 - ls) * inner), rel=1e-12)
    assert kappa == pytest.approx(max(ls if kappa_pooling == "slice" else ls + (1 - ls) * lp, cfg.kappa_min))
    # a full-weight slice answers alone
    big = cal.slices[("big", "is_car")]
    assert cal.likelihood_ratio(0.7, "big", "is_car") == (pytest.approx(math.exp(big.log_lr(0.7, False))), 1.0)
    assert cal.in_regime("small", "is_chair") and not cal.in_regime("small", "is_car")
    assert cal.n_outcomes("*", "is_car") == 200 and cal.prediction_set(0.7, "small", "is_chair").claims_coverage


def test_a_custom_grouping_by_predicate_family() -> None:
    """Any key function works: here predicates pooled by family before the global pool, and the
    pool keys are the calibrator's slice keys."""
    family = {"is_car": "vehicle", "is_truck": "vehicle", "is_person": "agent"}

    def by_family(context: str, predicate: str) -> tuple[str, str]:
        return ("family", family[predicate])

    cal = MondrianCalibrator(CalibrationConfig(target_size=30), groups=(by_context_and_predicate, by_family, DEFAULT_GROUPS[-1]))
    rng = np.random.default_rng(23)
    for _ in range(120):
        c = float(rng.random())
        cal.add("vlm", "is_car", c, int(rng.random() < c))
    cal.add("vlm", "is_truck", 0.6, 1)
    assert cal.slices[("family", "vehicle")].n == 121 and ("family", "agent") not in cal.slices
    truck = cal.likelihood_ratio(0.9, "vlm", "is_truck")
    person = cal.likelihood_ratio(0.9, "vlm", "is_person")
    assert truck != person  # the truck borrows the vehicle pool's fit, the person only the global one
    assert "family|vehicle" in cal.summary()
    with pytest.raises(ValueError, match="at least one Mondrian level"):
        MondrianCalibrator(groups=())


def test_the_old_modules_re_export_with_a_deprecation_warning() -> None:
    import importlib

    from sgbelief.calibration import conformal, isotonic, mondrian, slice
    from sgbelief.fusion import rules

    old_cal = importlib.import_module("sgbelief.fusion.calibration")
    old_conf = importlib.import_module("sgbelief.fusion.conformal")
    for module, name, new in [
        (old_cal, "MondrianCalibrator", mondrian.MondrianCalibrator),
        (old_cal, "CalibrationSlice", slice.CalibrationSlice),
        (old_cal, "calibrated_log_lr", isotonic.calibrated_log_lr),
        (old_cal, "CalibrationConfig", CalibrationConfig),
        (old_cal, "ConformalSlice", conformal.ConformalSlice),
        (old_conf, "nonconformity", conformal.nonconformity),
        (old_conf, "ConformalSlice", conformal.ConformalSlice),
    ]:
        with pytest.warns(DeprecationWarning, match=f"removed in sgbelief 0.2.0.*import {name} from sgbelief.calibration"):
            assert getattr(module, name) is new
    with pytest.raises(AttributeError):
        old_cal.no_such_name  # noqa: B018
    assert rules.calibrated_log_lr is isotonic.calibrated_log_lr  # Eq. 2 keeps its old import path, silently

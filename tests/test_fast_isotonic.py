"""The incremental isotonic merge (sgbelief._fast.isotonic) equals the reference refit.

Tolerance: 0 (``==``). The fitted values are means of pooled blocks; ``pava`` forms each block's
sum with scipy's floating-point operations in scipy's order, and the distinct-confidence points
carry exactly scikit-learn's means and weights, so the knots are the reference's bit for bit.
(``sgbelief.testing.check_isotonic_matches_reference`` takes an ``atol`` for stores that sum in
another order.)
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import isotonic_regression
from sklearn.isotonic import IsotonicRegression

from sgbelief._fast import isotonic as fast_iso
from sgbelief._fast.isotonic import IncrementalIsotonic, pava
from sgbelief.calibration import conformal
from sgbelief.calibration.isotonic import RefitIsotonic
from sgbelief.calibration.slice import CalibrationSlice
from sgbelief.testing import check_isotonic_matches_reference


@contextmanager
def _small(value: int):
    """Set the list-path limit of the fast store and of the conformal scores (and restore them)."""
    old = fast_iso.SMALL, conformal.SMALL
    fast_iso.SMALL = conformal.SMALL = value
    try:
        yield
    finally:
        fast_iso.SMALL, conformal.SMALL = old


# ------------------------------------------------------------------------------------- PAVA
_value = st.sampled_from([0.0, 0.25, 1 / 3, 0.5, 2 / 3, 1.0]) | st.floats(0.0, 1.0)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(_value, st.integers(1, 9) | st.floats(0.5, 50.0)), min_size=1, max_size=80))
def test_pava_equals_scipy_bit_for_bit(points: list[tuple[float, float]]) -> None:
    values = [v for v, _ in points]
    weights = [float(w) for _, w in points]
    want = isotonic_regression(np.array(values), weights=np.array(weights), increasing=True).x.tolist()
    assert pava(values, weights) == want


def test_pava_is_isotonic_and_pools_violators() -> None:
    assert pava([], []) == []
    assert pava([1.0, 0.0], [1.0, 1.0]) == [0.5, 0.5]
    assert pava([0.0, 1.0, 0.0, 1.0], [1.0, 1.0, 1.0, 1.0]) == [0.0, 0.5, 0.5, 1.0]
    assert pava([1.0, 0.0, 0.0], [2.0, 1.0, 1.0]) == [0.5, 0.5, 0.5]


# -------------------------------------------------------------------------- fast == reference
def _confidences(kind: int) -> st.SearchStrategy[float]:
    if kind == 0:  # continuous
        return st.floats(0.0, 1.0)
    if kind == 1:  # heavily tied (quantised)
        return st.integers(0, 20).map(lambda k: k / 20)
    if kind == 2:  # chains of near-ties (< 1e-15 apart): scikit-learn's own pooling rule applies
        return st.tuples(st.sampled_from([0.25, 0.5, 0.75]), st.integers(0, 7)).map(lambda t: t[0] + t[1] * 3e-16)
    return st.sampled_from([0.0, 1.0, 0.5, 1e-300, 1 - 2**-53])  # extremes


@st.composite
def _streams(draw: st.DrawFn) -> list[tuple[float, int]]:
    kind = draw(st.integers(0, 3))
    return draw(st.lists(st.tuples(_confidences(kind), st.integers(0, 1)), min_size=1, max_size=400))


@settings(max_examples=80, deadline=None)
@given(
    stream=_streams(),
    capacity=st.sampled_from([None, 16, 50, 300]),
    batch_sizes=st.lists(st.integers(1, 90), min_size=1, max_size=4),
    small=st.sampled_from([0, 128, 10**9]),
)
def test_fast_store_equals_the_reference_refit(stream, capacity, batch_sizes, small) -> None:
    """After every batch (ties, near-ties and extremes; windows that evict; the list path, the
    numpy path and the crossing between them): same held outcomes, same knots."""
    with _small(small):
        check_isotonic_matches_reference(stream, IncrementalIsotonic, capacity=capacity, batch_sizes=batch_sizes)


def test_the_check_compares_functions_with_a_tolerance() -> None:
    """``atol > 0`` compares p_hat pointwise: a store whose values differ by less passes, more fails."""

    class Nudged(RefitIsotonic):
        __slots__ = ()

        def knots(self):  # type: ignore[override]
            kx, ky = super().knots()
            return kx, [v * (1 - 1e-13) for v in ky]

    rng = np.random.default_rng(0)
    stream = [(float(c), int(rng.random() < c)) for c in rng.random(200)]
    check_isotonic_matches_reference(stream, Nudged, batch_sizes=(17,), atol=1e-12)
    with pytest.raises(AssertionError):
        check_isotonic_matches_reference(stream, Nudged, batch_sizes=(17,))


# ------------------------------------------------------------- the slice with the fast store
def _sklearn_knots(c: np.ndarray, y: np.ndarray) -> tuple[list[float], list[float]]:
    ref = IsotonicRegression(y_min=0.0, y_max=1.0, out_of_bounds="clip").fit(c, y)
    return ref.X_thresholds_.tolist(), ref.y_thresholds_.tolist()


def _odd_confidences(rng: np.random.Generator, n: int, kind: int) -> np.ndarray:
    if kind == 0:
        return rng.random(n)
    if kind == 1:
        return np.round(rng.random(n), int(rng.integers(1, 4)))
    if kind == 2:
        return rng.choice([0.25, 0.5, 0.75], n) + rng.integers(0, 8, n) * 3e-16
    return rng.choice([0.0, 1.0, 0.5, 1e-300, 1 - 2**-53], n)


@pytest.mark.parametrize("small", [True, False])
def test_fit_is_bit_identical_to_scikit_learn_on_both_paths(small: bool) -> None:
    """Knots == IsotonicRegression's X_thresholds_ / y_thresholds_ exactly, on the Python-list path
    (small slices) and the numpy distinct-confidence path."""
    rng = np.random.default_rng(11)
    with _small(10**9 if small else 0):
        for trial in range(120):
            n = int(rng.integers(1, 300))
            c = _odd_confidences(rng, n, trial % 4)
            y = (rng.random(n) < np.clip(c, 0, 1)).astype(int)
            s = CalibrationSlice(alpha=0.1, isotonic=IncrementalIsotonic)
            for ci, yi in zip(c.tolist(), y.tolist()):
                s.add(ci, yi)
            s.refit()
            assert (s.kx, s.ky) == _sklearn_knots(c, y)
            assert type(s.store.ux) is (list if small else np.ndarray)
            np.testing.assert_array_equal(s.sorted_negatives, np.sort(c[y == 0]))
            np.testing.assert_array_equal(s.sorted_positives, np.sort(c[y == 1]))
            assert s.n == s.n_fit == n and s.n_pos == y.sum() and s.base_rate == y.sum() / n


@pytest.mark.parametrize("capacity", [None, 16, 50, 300])
def test_small_and_numpy_paths_and_lazy_fits_agree(capacity: int | None) -> None:
    """The same stream through the Python-list path, the numpy path and the crossing between them,
    read after every refit or only at the end (lazy fits merging many batches), gives the same
    knots, base rate, sorted outcomes, window and conformal scores as the reference store, also
    across sliding-window evictions (and batches that alone overflow the window)."""
    rng = np.random.default_rng(12)
    n = 1500
    c = np.round(rng.beta(2, 2, n), 3)
    y = (rng.random(n) < c).astype(int)

    def run(store, small: int, read_every: bool, min_refit: int) -> list:
        with _small(small):
            s = CalibrationSlice(alpha=0.1, capacity=capacity, min_refit=min_refit, isotonic=store)
            states = []
            for i, (ci, yi) in enumerate(zip(c.tolist(), y.tolist())):
                s.add(ci, yi)
                if s.n - s.n_fit >= s.refit_gap:
                    s.refit()
                    if read_every or i > n - 40:
                        states.append((s.kx, s.ky, s.base_rate, s.log_prior_odds, s.n, s.n_pos, s.n_seen,
                                       s.sorted_negatives.tolist(), s.sorted_positives.tolist(), list(s.window_confidences),
                                       list(s.window_labels), list(s.conformal.sorted)))
        return states

    ref = run(RefitIsotonic, 0, True, 8)
    assert run(IncrementalIsotonic, 0, True, 8) == ref  # numpy throughout
    assert run(IncrementalIsotonic, 10**9, True, 8) == ref  # Python lists throughout
    assert run(IncrementalIsotonic, 128, True, 8) == ref  # lists, then numpy
    lazy = run(IncrementalIsotonic, 0, False, 8)
    assert lazy == ref[len(ref) - len(lazy):]

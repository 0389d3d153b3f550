"""BetaBelief: moments, interval, closed-form KL against numerical integration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, stats

from sgbelief.graph.belief import BetaBelief, beta_kl

pos = st.floats(min_value=0.2, max_value=60.0, allow_nan=False)


def test_prior_is_uniform() -> None:
    b = BetaBelief.prior()
    assert (b.alpha, b.beta) == (1.0, 1.0)
    assert b.mean == 0.5 and b.ess == 2.0
    assert not b.committed(0.5)  # a pair at its prior is never committed


@given(pos, pos)
def test_moments_match_scipy(a: float, b: float) -> None:
    bel = BetaBelief(a, b)
    ref = stats.beta(a, b)
    assert bel.mean == pytest.approx(ref.mean(), rel=1e-12)
    assert bel.variance == pytest.approx(ref.var(), rel=1e-9)
    lo, hi = bel.interval(0.9)
    assert lo == pytest.approx(ref.ppf(0.05), rel=1e-7, abs=1e-12)
    assert hi == pytest.approx(ref.ppf(0.95), rel=1e-7, abs=1e-12)


@pytest.mark.parametrize("a1,b1,a2,b2", [(1, 1, 1.8333, 1.1667), (2, 5, 3, 4), (10, 1, 1, 10), (0.7, 0.9, 4.0, 2.5)])
def test_kl_matches_numerical_integration(a1: float, b1: float, a2: float, b2: float) -> None:
    p, q = stats.beta(a1, b1), stats.beta(a2, b2)

    def integrand(x: float) -> float:
        return p.pdf(x) * (p.logpdf(x) - q.logpdf(x))

    numeric, _ = integrate.quad(integrand, 0, 1, limit=200)
    assert beta_kl(a1, b1, a2, b2) == pytest.approx(numeric, rel=1e-6, abs=1e-8)


@given(pos, pos)
@settings(max_examples=50)
def test_kl_is_zero_on_self_and_nonnegative(a: float, b: float) -> None:
    bel = BetaBelief(a, b)
    assert bel.kl(bel) == pytest.approx(0.0, abs=1e-10)
    assert bel.kl(BetaBelief(a + 1.0, b)) >= 0.0


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_rejects_invalid_parameters(bad: float) -> None:
    with pytest.raises(ValueError, match="alpha"):
        BetaBelief(bad, 1.0)


def test_interval_level_validated() -> None:
    with pytest.raises(ValueError):
        BetaBelief(2, 3).interval(1.5)
    assert np.isfinite(BetaBelief(2, 3).interval(0.5)).all()

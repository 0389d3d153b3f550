"""The step functions of Algorithm 1 (sgbelief.fusion.rules) against hand-computed values."""

from __future__ import annotations

import math

import pytest
from scipy.special import betaln, digamma

from sgbelief.fusion.compatibility import Verdict
from sgbelief.fusion import rules
from sgbelief.fusion.rules import (
    calibrated_log_lr,
    claim_asserts,
    claim_increments,
    evidence_weight,
    kl_upper_bound,
    revision_kl_exceeds,
    stance_of,
    stratified_context,
    support_stratum,
    verdict,
    verification_increments,
)


def test_verdict_sign_rule() -> None:
    assert verdict(None, True) is Verdict.NO_CLAIM
    assert verdict(1, True) is Verdict.CORROBORATES  # asserts phi, geometry agrees
    assert verdict(0, True) is Verdict.CONTRADICTS  # asserts phi, geometry says not phi
    assert verdict(0, False) is Verdict.CORROBORATES  # denies phi, geometry agrees
    assert verdict(1, False) is Verdict.CONTRADICTS
    # the sign: raw c >= 0.5 (paper), or the calibrated Lambda_hat (default)
    assert claim_asserts(0.5) and not claim_asserts(0.49)
    assert claim_asserts(0.4, lam=3.0)  # an underconfident model's 0.4 that calibrates to odds 3
    assert not claim_asserts(0.9, lam=0.5)
    assert claim_asserts(0.6, lam=1.0) and not claim_asserts(0.4, lam=1.0)  # neutral: raw sign


def test_support_stratum_saturates() -> None:
    assert [support_stratum(n, 4) for n in range(7)] == [0, 1, 2, 3, 3, 3, 3]
    assert [support_stratum(n, 1) for n in range(3)] == [0, 0, 0]
    assert stratified_context("llava", 2, 4) == "llava|s2"
    assert stratified_context("llava", 0, 1) == "llava"


def test_calibrated_log_lr_eq2() -> None:
    # p_hat 0.8 against the uniform prior: odds 4
    assert calibrated_log_lr(0.8, 0.01, 0.0) == pytest.approx(math.log(4.0))
    # against a slice base rate of 0.8 (odds 4) the same p_hat carries no evidence
    assert calibrated_log_lr(0.8, 0.01, math.log(4.0)) == pytest.approx(0.0)
    # clipping keeps it finite
    assert calibrated_log_lr(1.0, 0.01, 0.0) == pytest.approx(math.log(0.99 / 0.01))
    assert calibrated_log_lr(0.0, 0.01, 0.0) == pytest.approx(math.log(0.01 / 0.99))


def test_weight_and_eq4_increments() -> None:
    assert evidence_weight(1.0, 0.5, 0.8) == pytest.approx(0.4)
    # Lambda = 3, w T = 1: (3/4, 1/4); the paper's "Lambda ~ 5 moves the mean by ~0.1" from Beta(1, 1)
    assert claim_increments(3.0, 1.0) == pytest.approx((0.75, 0.25))
    da, db = claim_increments(5.0, 1.0)
    assert (1 + da) / (2 + da + db) - 0.5 == pytest.approx(1 / 9)
    assert verification_increments(1, 0.7) == (0.7, 0.0)
    assert verification_increments(0, 0.7) == (0.0, 0.7)
    assert (stance_of(2.0), stance_of(0.5), stance_of(1.0)) == (1, -1, 0)


def _kl(a: float, b: float, da: float, db: float) -> float:
    a2, b2 = a + da, b + db
    return betaln(a2, b2) - betaln(a, b) - da * digamma(a) - db * digamma(b) + (da + db) * digamma(a + b)


@pytest.mark.parametrize("a,b,da,db", [(1, 1, 1, 0), (1, 1, 0.75, 0.25), (2, 5, 3, 0), (10, 1, 0, 4), (1.5, 1.5, 0.01, 0.0)])
def test_revision_test_is_the_exact_kl(a: float, b: float, da: float, db: float) -> None:
    kl = _kl(a, b, da, db)
    assert kl <= kl_upper_bound(a, b, da, db) + 1e-12
    for tau in (kl * 0.9, kl * 1.1, 0.5):
        assert revision_kl_exceeds(a, b, da, db, tau) == (kl > tau)
    # hand value: KL(Beta(1, 1) || Beta(2, 1)) = ln B(2, 1) - ln B(1, 1) - psi(1) + psi(2) = ln(1/2) + 1
    assert _kl(1, 1, 1, 0) == pytest.approx(math.log(0.5) + 1.0)


def test_exclusive_marginal_by_hand() -> None:
    """Beta(a, b + the rivals' alpha above the prior): stool with Beta(4, 2) (four claims at 0.75,
    unit weight), chair with Beta(2.7, 1.3) (two at 0.85), prior alpha 1. Independent means rank
    chair first (0.675 > 0.667); the coupled ones stool (4 / 7.7 = 0.519 > 2.7 / 7 = 0.386)."""
    stool = rules.exclusive_marginal(4.0, 2.0, [2.7], 1.0)
    chair = rules.exclusive_marginal(2.7, 1.3, [4.0], 1.0)
    assert stool == pytest.approx((4.0, 3.7)) and chair == pytest.approx((2.7, 4.3))
    assert 2.7 / 4.0 > 4.0 / 6.0 and stool[0] / sum(stool) > chair[0] / sum(chair)
    assert rules.exclusive_marginal(2.0, 1.0, [], 1.0) == (2.0, 1.0)

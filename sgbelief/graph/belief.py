"""Beta beliefs over one (element, predicate) pair (paper §3, Def. 1)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy import special as _sp

#: The uniform prior Beta(1, 1) every (element, predicate) pair starts from.
PRIOR_ALPHA: float = 1.0
PRIOR_BETA: float = 1.0


def beta_kl(a1: float, b1: float, a2: float, b2: float) -> float:
    r"""Closed-form KL divergence :math:`D_{KL}(\mathrm{Beta}(a_1,b_1)\,\|\,\mathrm{Beta}(a_2,b_2))`.

    .. math::
        \ln B(a_2,b_2) - \ln B(a_1,b_1) + (a_1-a_2)\psi(a_1) + (b_1-b_2)\psi(b_1)
        + (a_2-a_1+b_2-b_1)\psi(a_1+b_1)

    This is the revision test statistic of §4.3 (``D_KL(B || B') > tau_rev``).
    """
    return float(
        _sp.betaln(a2, b2)
        - _sp.betaln(a1, b1)
        + (a1 - a2) * _sp.digamma(a1)
        + (b1 - b2) * _sp.digamma(b1)
        + (a2 - a1 + b2 - b1) * _sp.digamma(a1 + b1)
    )


@dataclass(frozen=True, slots=True)
class BetaBelief:
    """An immutable Beta(alpha, beta) belief about one predicate of one map element.

    ``mean`` = alpha / (alpha + beta) is the probability the predicate holds and
    ``ess`` = alpha + beta the effective sample size (§3, Def. 1).
    """

    alpha: float = PRIOR_ALPHA
    beta: float = PRIOR_BETA

    def __post_init__(self) -> None:
        for name in ("alpha", "beta"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"BetaBelief.{name} must be a finite number > 0, got {value!r}")

    @classmethod
    def prior(cls) -> BetaBelief:
        """The uniform prior Beta(1, 1)."""
        return cls(PRIOR_ALPHA, PRIOR_BETA)

    @property
    def mean(self) -> float:
        """Posterior mean alpha / (alpha + beta)."""
        return self.alpha / (self.alpha + self.beta)

    @property
    def ess(self) -> float:
        """Effective sample size alpha + beta."""
        return self.alpha + self.beta

    @property
    def variance(self) -> float:
        """alpha beta / ((alpha + beta)^2 (alpha + beta + 1))."""
        s = self.alpha + self.beta
        return self.alpha * self.beta / (s * s * (s + 1.0))

    @property
    def mode(self) -> float | None:
        """(alpha - 1) / (alpha + beta - 2) when alpha, beta > 1; None when the mode is at a boundary or not unique."""
        if self.alpha > 1.0 and self.beta > 1.0:
            return (self.alpha - 1.0) / (self.alpha + self.beta - 2.0)
        return None

    def interval(self, level: float = 0.9) -> tuple[float, float]:
        """Equal-tailed credible interval holding ``level`` of the posterior mass."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1), got {level!r}")
        tail = (1.0 - level) / 2.0
        lo, hi = _sp.betaincinv(self.alpha, self.beta, [tail, 1.0 - tail])
        return float(lo), float(hi)

    def kl(self, other: BetaBelief) -> float:
        """KL(self || other), closed form (see :func:`beta_kl`)."""
        return beta_kl(self.alpha, self.beta, other.alpha, other.beta)

    def updated(self, d_alpha: float, d_beta: float) -> BetaBelief:
        """The belief after adding pseudo-count increments (Eq. 3 / Eq. 4)."""
        return BetaBelief(self.alpha + d_alpha, self.beta + d_beta)

    def committed(self, tau: float = 0.5) -> bool:
        """True when the mean is strictly above the commit threshold tau."""
        return self.mean > tau

    def __repr__(self) -> str:
        return f"BetaBelief(alpha={self.alpha:.6g}, beta={self.beta:.6g}, mean={self.mean:.4f})"

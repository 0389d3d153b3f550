"""The four baselines of Table 1: the fusion practice deployed mapping systems use today.

Three of them are pair-local (:data:`~sgbelief.fusion.protocol.PairRule`): each states its rule
once, as a small frozen rule object, and every engine (the reference steps, the fused streaming
loop, the batched waves) applies that object. ``refined`` keeps a window per pair (operator state)
and gives its increments per target (:meth:`RefinedOperator._increment`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

from sgbelief.fusion.operators.base import BaseOperator
from sgbelief.fusion.protocol import LinearRule, ResetRule
from sgbelief.fusion.rules import claim_asserts
from sgbelief.graph.scene_graph import SceneGraphModel


@dataclass(frozen=True)
class MajorityVoteRule(LinearRule):
    """Majority vote weighted by raw confidence: T(v) c votes for phi, T(v) (1 - c) against::

        d_alpha = T(v) c,   d_beta = T(v) (1 - c)
    """

    def split(self, c: Any) -> tuple[Any, Any]:
        return c, 1.0 - c


@dataclass(frozen=True)
class NaiveBayesRule(LinearRule):
    """Naive Bayes with a fixed reliability r: the raw confidence seen through a symmetric channel,
    p = r c + (1 - r)(1 - c), Lambda = p / (1 - p), then Eq. 3 with w = T(v)::

        d_alpha = T(v) p,   d_beta = T(v) (1 - p)
    """

    reliability: float

    def split(self, c: Any) -> tuple[Any, Any]:
        r = self.reliability
        p = r * c + (1.0 - r) * (1.0 - c)
        return p, 1.0 - p


@dataclass(frozen=True)
class OverwriteRule(ResetRule):
    """The latest decisive claim wins: Beta(alpha_0 + s, beta_0) when the claim asserts phi
    (c >= 0.5), Beta(alpha_0, beta_0 + s) otherwise (s = ``strength``)::

        a = [c >= 0.5],   (alpha*, beta*) = (alpha_0 + s a, beta_0 + s (1 - a))

    (s a is s or 0.0 exactly, so this is the two cases bit for bit.)
    """

    strength: float

    def target(self, c: Any, prior_alpha: float, prior_beta: float) -> tuple[Any, Any]:
        asserts = claim_asserts(c) * 1.0  # 1.0 or 0.0 (a float array for an array of claims)
        s = self.strength
        return prior_alpha + s * asserts, prior_beta + s * (1.0 - asserts)


class OverwriteOperator(BaseOperator):
    """Overwrite: the latest decisive claim wins (:class:`OverwriteRule`).

    Each event sets B(v, phi) to a high-confidence belief in the claim's direction
    (s = ``baselines.overwrite.strength``, default 9 -> mean 0.91). Represents label
    assignment by the most recent detection. Recorded as the increment new - old, so Eq. 4 holds.
    """

    name = "overwrite"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.pair_rule = OverwriteRule(self.config.baselines.overwrite.strength)


class MajorityVoteOperator(BaseOperator):
    """Majority vote weighted by raw confidence (ConceptGraphs' practice, no calibration;
    :class:`MajorityVoteRule`). The belief mean is the confidence-weighted vote share; phi commits
    when it exceeds tau."""

    name = "majority"
    pair_rule = MajorityVoteRule()


class NaiveBayesOperator(BaseOperator):
    """Naive Bayes with a fixed assumed reliability r (Kimera-Semantics style; :class:`NaiveBayesRule`).
    Parameter: ``baselines.naive_bayes.reliability`` (default 0.8)."""

    name = "naive_bayes"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.pair_rule = NaiveBayesRule(self.config.baselines.naive_bayes.reliability)


class RefinedOperator(BaseOperator):
    """Refined baseline: temporal-majority windowed filter with a minimum support.

    Keeps the last W claims at each (v, phi) (W = ``window``); while fewer than ``min_support``
    claims have arrived the belief stays at the prior, otherwise it is
    Beta(alpha_0 + #pos, beta_0 + #neg) over the window (claims with c >= 0.5 vote for phi),
    so phi commits when the window's majority asserts it. Windows are operator state.
    """

    name = "refined"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        #: per (v, phi): [the last W votes (1: c >= 0.5), how many of them are 1]
        self._windows: dict[tuple[Any, str], list[Any]] = {}
        cfg = self.config.baselines.refined
        self._window, self._min_support = cfg.window, cfg.min_support

    def _increment(self, graph: SceneGraphModel, node: Any, predicate: str, c: float, mass: float) -> tuple[float, float]:
        key = (node, predicate)
        state = self._windows.get(key)
        if state is None:
            state = self._windows[key] = [deque(maxlen=self._window), 0]
        win, pos = state
        vote = 1 if claim_asserts(c) else 0
        if len(win) == self._window:
            pos -= win[0]  # the vote the append below pushes out
        win.append(vote)
        pos += vote
        state[1] = pos
        prov = graph.provenance
        a, b = prov.alpha_beta(node, predicate)
        n = len(win)
        if n < self._min_support:
            ta, tb = prov.prior_alpha, prov.prior_beta
        else:
            ta, tb = prov.prior_alpha + pos, prov.prior_beta + (n - pos)
        return ta - a, tb - b

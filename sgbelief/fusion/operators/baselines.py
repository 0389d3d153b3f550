"""The four baselines of Table 1: the fusion practice deployed mapping systems use today."""

from __future__ import annotations

from collections import deque
from typing import Any

from sgbelief.fusion.operators.base import BaseOperator
from sgbelief.graph.scene_graph import SceneGraph


class OverwriteOperator(BaseOperator):
    """Overwrite: the latest decisive claim wins.

    Each event sets B(v, phi) to a high-confidence belief in the claim's direction:
    Beta(alpha_0 + s, beta_0) when c >= 0.5, Beta(alpha_0, beta_0 + s) otherwise
    (s = ``baselines.overwrite.strength``, default 9 -> mean 0.91). Represents label
    assignment by the most recent detection. Recorded as the increment new - old, so Eq. 5 holds.
    """

    name = "overwrite"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._strength = self.config.baselines.overwrite.strength

    def _increment(self, graph: SceneGraph, node: Any, predicate: str, c: float, mass: float) -> tuple[float, float]:
        prov = graph.provenance
        pa, pb = prov.prior_alpha, prov.prior_beta
        log = prov._pairs.get((node, predicate))  # = prov.alpha_beta, without the method call
        a, b = (pa, pb) if log is None else (log.alpha, log.beta)
        if c >= 0.5:
            return pa + self._strength - a, pb - b
        return pa - a, pb + self._strength - b


class MajorityVoteOperator(BaseOperator):
    """Majority vote weighted by raw confidence (ConceptGraphs' practice, no calibration).

    Each claim adds T(v) c votes for phi and T(v) (1 - c) against: alpha += T c, beta += T (1 - c).
    The belief mean is the confidence-weighted vote share; phi commits when it exceeds tau.
    """

    name = "majority"

    def _split(self, c: float) -> tuple[float, float]:
        return c, 1.0 - c


class NaiveBayesOperator(BaseOperator):
    """Naive Bayes with a fixed assumed reliability r (Kimera-Semantics style).

    The raw confidence is taken as a calibrated probability seen through a symmetric channel
    of reliability r: p = r c + (1 - r)(1 - c), likelihood ratio Lambda = p / (1 - p), and the
    fractional pseudo-count update of Eq. 4 with w = 1: alpha += T p, beta += T (1 - p).
    Parameter: ``baselines.naive_bayes.reliability`` (default 0.8).
    """

    name = "naive_bayes"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._reliability = self.config.baselines.naive_bayes.reliability

    def _split(self, c: float) -> tuple[float, float]:
        r = self._reliability
        p = r * c + (1.0 - r) * (1.0 - c)
        return p, 1.0 - p


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

    def _increment(self, graph: SceneGraph, node: Any, predicate: str, c: float, mass: float) -> tuple[float, float]:
        key = (node, predicate)
        state = self._windows.get(key)
        if state is None:
            state = self._windows[key] = [deque(maxlen=self._window), 0]
        win, pos = state
        vote = 1 if c >= 0.5 else 0
        if len(win) == self._window:
            pos -= win[0]  # the vote the append below pushes out
        win.append(vote)
        pos += vote
        state[1] = pos
        prov = graph.provenance
        log = prov._pairs.get(key)
        a, b = (prov.prior_alpha, prov.prior_beta) if log is None else (log.alpha, log.beta)
        n = len(win)
        if n < self._min_support:
            ta, tb = prov.prior_alpha, prov.prior_beta
        else:
            ta, tb = prov.prior_alpha + pos, prov.prior_beta + (n - pos)
        return ta - a, tb - b

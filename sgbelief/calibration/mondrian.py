"""Mondrian calibration of foundation-model confidences against the geometric channel (§4.1).

Outcomes (c, y) enter a streaming buffer whenever the geometric channel is decisive for the
claimed predicate (y = 1: its label is in phi's positive set, y = 0: in the negative set). The
buffer is sliced by a hierarchy of groupings, finest first, that ends at the cold-start rule. The
default is the paper's: per (context kappa, predicate phi), then per phi, then globally; crepes
calls the grouping ``bins=``, MAPIE ``groups=``. Each slice (:class:`CalibrationSlice`) holds

- an isotonic calibrator p_hat(y = 1 | c), refitted when the slice has grown by ``refit_growth``
  (amortised O(log n) fits per outcome), queried by bisection over its knots, O(log n);
- the calibrated likelihood ratio of Eq. 2 (:func:`~sgbelief.calibration.isotonic.calibrated_log_lr`);
- the nonconformity scores of Eq. 1 for split and adaptive conformal sets (:mod:`.conformal`).

Shrinkage toward the coarser levels, with l = min(1, n / target_size) per level (n its fitted
outcomes) and L_cold the cold-start rule::

    log Lambda = l_1 log L_1 + (1 - l_1) [l_2 log L_2 + (1 - l_2) [ ... [l_k log L_k + (1 - l_k) log L_cold]]]

so a level with full weight makes the coarser ones irrelevant, and a sparse coarsest level is
itself shrunk toward the cold-start rule. kappa_hat(e) = clip(n_1 / target_size, kappa_min, 1)
(``kappa_pooling: slice``, the paper) or clip(l_1 + (1 - l_1) [l_2 + (1 - l_2) [... l_k]], kappa_min, 1)
(``pooled``: the share of the shrunk estimate that rests on fitted data). Cold start: Lambda =
c / (1 - c) ("raw", the model taken at its word) or 1 ("neutral"), at the minimal weight kappa_min
when no level has an outcome. The derivations are in ``docs/method.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Sequence
from typing import Any

from sgbelief.calibration.config import CalibrationConfig
from sgbelief.calibration.conformal import PredictionSet, no_coverage, nonconformity, prediction_set
from sgbelief.calibration.isotonic import IsotonicStoreFactory, RefitIsotonic
from sgbelief.calibration.slice import CalibrationSlice

__all__ = [
    "DEFAULT_GROUPS",
    "GroupKey",
    "MondrianCalibrator",
    "by_context_and_predicate",
    "by_predicate",
    "cold_start_log_lr",
    "global_pool",
]

_exp = math.exp
_log = math.log

#: a Mondrian level: maps a claim's (context, predicate) to the key of its slice at that level
GroupKey = Callable[[str, str], Hashable]


def by_context_and_predicate(context: str, predicate: str) -> tuple[str, str]:
    """The finest default level: one slice per (context, predicate)."""
    return (context, predicate)


def by_predicate(context: str, predicate: str) -> tuple[str, str]:
    """The per-predicate pool ``("*", predicate)``."""
    return ("*", predicate)


def global_pool(context: str, predicate: str) -> tuple[str, str]:
    """The global pool ``("*", "*")``."""
    return ("*", "*")


#: the paper's hierarchy: (context, predicate) -> predicate -> global (-> the cold-start rule)
DEFAULT_GROUPS: tuple[GroupKey, ...] = (by_context_and_predicate, by_predicate, global_pool)


def cold_start_log_lr(c: float, rule: str, log_lr_max: float) -> float:
    """log Lambda of the cold-start rule, where the calibration hierarchy ends.

    ``"raw"``: the model taken at its word, log(c / (1 - c)) with c clipped to [1e-6, 1 - 1e-6]
    and the result to [-log_lr_max, log_lr_max]; ``"neutral"``: 0 (Lambda = 1).
    """
    if rule == "neutral":
        return 0.0
    cc = min(max(c, 1e-6), 1.0 - 1e-6)
    lo = _log(cc / (1.0 - cc))
    return log_lr_max if lo > log_lr_max else -log_lr_max if lo < -log_lr_max else lo


#: stands for a level that does not exist yet (never fitted) in the query cache
_NO_SLICE = CalibrationSlice(0.0)


class MondrianCalibrator:
    """The streaming calibration buffer C, sliced by a hierarchy of Mondrian groupings.

    Parameters
    ----------
    config : CalibrationConfig, optional
        The knobs (target size, kappa_min, lr_max, refit schedule, cold start, ...).
    alpha : float
        The conformal miscoverage level.
    groups : sequence of GroupKey
        The Mondrian levels, finest first: each maps (context, predicate) to the key of its slice;
        the hierarchy ends at the cold-start rule. Default :data:`DEFAULT_GROUPS`. Keys are the
        keys of :attr:`slices` (two levels giving the same key share one slice, which then gets
        each outcome once per level). The finest level's slice takes the adaptive conformal step
        and answers :meth:`prediction_set` and :meth:`in_regime`. Module-level functions keep the
        calibrator picklable.
    isotonic : IsotonicStoreFactory
        Makes each slice's store of outcomes and isotonic fit: the reference
        :class:`~sgbelief.calibration.isotonic.RefitIsotonic` (default) or the incremental merge
        the fast engine passes in (``sgbelief._fast.isotonic.IncrementalIsotonic``); same knots.

    Examples
    --------
    Two levels, per (context, predicate) then per predicate, then the cold-start rule:

    >>> cal = MondrianCalibrator(groups=(by_context_and_predicate, by_predicate))
    >>> cal.add("vlm_a", "is_car", 0.9, 1)
    >>> sorted(cal.slices)
    [('*', 'is_car'), ('vlm_a', 'is_car')]
    """

    def __init__(
        self,
        config: CalibrationConfig | None = None,
        alpha: float = 0.1,
        *,
        groups: Sequence[GroupKey] = DEFAULT_GROUPS,
        isotonic: IsotonicStoreFactory = RefitIsotonic,
    ) -> None:
        if not groups:
            raise ValueError("groups: at least one Mondrian level is needed")
        self.config = config or CalibrationConfig()
        self.alpha = alpha
        self.groups: tuple[GroupKey, ...] = tuple(groups)
        self.isotonic = isotonic
        self.slices: dict[Hashable, CalibrationSlice] = {}
        self.frozen = False
        self._gamma = self.config.adaptive_gamma
        self._log_lr_max = math.log(self.config.lr_max)
        self._ref = self.config.lr_reference == "slice"
        self._target = self.config.target_size
        #: (slices finest first, the slice taking the adaptive step or None) per (context, predicate) that added outcomes
        self._levels: dict[tuple[str, str], tuple[tuple[CalibrationSlice, ...], CalibrationSlice | None]] = {}
        #: the slices per queried (context, predicate), ``_NO_SLICE`` for missing ones (reset when a slice is created)
        self._query: dict[tuple[str, str], tuple[CalibrationSlice, ...]] = {}

    # ------------------------------------------------------------------ data
    def _slice(self, key: Hashable) -> CalibrationSlice:
        s = self.slices.get(key)
        if s is None:
            cfg = self.config
            s = self.slices[key] = CalibrationSlice(
                self.alpha, cfg.buffer_size, min_refit=cfg.min_refit, refit_growth=cfg.refit_growth, isotonic=self.isotonic
            )
            self._query.clear()
        return s

    def _make_levels(self, context: str, predicate: str) -> tuple[tuple[CalibrationSlice, ...], CalibrationSlice | None]:
        slices = tuple(self._slice(g(context, predicate)) for g in self.groups)
        finest = slices[0]
        # the finest slice takes the adaptive step, unless it is also a pool (a "*" context: its
        # slice is the predicate pool)
        adaptive = None if any(s is finest for s in slices[1:]) else finest
        lv = self._levels[(context, predicate)] = (slices, adaptive)
        return lv

    def add(self, context: str, predicate: str, c: float, y: int) -> None:
        """Append one verification outcome to its slice at every level (Alg. 1's outcome loop).

        The adaptive conformal level of the finest slice is updated first with this outcome (was
        y in the set the slice would have produced for c?):
        :meth:`~sgbelief.calibration.conformal.ConformalSlice.observe`.

        Parameters
        ----------
        context, predicate : str
            The claim's Mondrian coordinates.
        c : float
            The claim's raw confidence (finite).
        y : int
            The geometric channel's outcome, 1 or 0.

        Raises
        ------
        ValueError
            If ``c`` is NaN or infinite (nothing is added).
        """
        if self.frozen:
            return
        if c - c != 0.0:  # NaN or +-inf: no isotonic fit is defined on it
            raise ValueError(f"calibration outcome {context!r}/{predicate!r}: confidence must be finite, got {c!r}")
        lv = self._levels.get((context, predicate))
        if lv is None:
            lv = self._make_levels(context, predicate)
        slices, adaptive = lv
        score = nonconformity(c, y)  # Eq. 1, the same at every level
        if adaptive is not None and adaptive.n_fit > 0:
            adaptive.conformal.observe(score, self.alpha, self._gamma)
        for s in slices:  # CalibrationSlice.add_scored, inlined (three levels per outcome)
            cs = s.c
            cs.append(c)
            s.y.append(y)
            s.pending_scores.append(score)
            if len(cs) >= s.refit_gap:
                s.refit()

    def refit_all(self) -> None:
        """Commit every slice's pending outcomes."""
        for s in self.slices.values():
            if s.c:
                s.refit()

    def n_outcomes(self, context: str = "*", predicate: str = "*", *, seen: bool = False) -> int:
        """Outcomes held in the finest slice of (context, predicate) (``seen=True``: ever added,
        including those slid out). The defaults name the global pool."""
        s = self.slices.get(self.groups[0](context, predicate))
        if s is None:
            return 0
        return s.n_seen if seen else s.n

    # --------------------------------------------------------------- queries
    def _query_levels(self, context: str, predicate: str) -> tuple[CalibrationSlice, ...]:
        get = self.slices.get
        lv = self._query[(context, predicate)] = tuple(get(g(context, predicate), _NO_SLICE) for g in self.groups)
        return lv

    def likelihood_ratio(self, c: float, context: str, predicate: str) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) for a claim with raw confidence c: Eq. 2 with shrinkage.

        Parameters
        ----------
        c : float
            The claim's raw confidence.
        context, predicate : str
            The claim's Mondrian coordinates.

        Returns
        -------
        tuple of float
            Lambda_hat in [1 / lr_max, lr_max] and kappa_hat in [kappa_min, 1].
        """
        levels = self._query.get((context, predicate))
        if levels is None:
            levels = self._query_levels(context, predicate)
        target = self._target
        m = self._log_lr_max
        finest = levels[0]
        if finest.n_fit >= target and levels[-1].n_fit:  # full weight: the finest slice alone, kappa = 1
            log_lr = finest.log_lr(c, self._ref)
            return _exp(m if log_lr > m else -m if log_lr < -m else log_lr), 1.0
        cfg = self.config
        if levels[-1].n_fit == 0:  # nothing fitted yet
            return _exp(cold_start_log_lr(c, cfg.cold_start, m)), cfg.kappa_min
        ref = self._ref
        # the finest level with full weight (n >= target_size) ends the hierarchy there:
        # 1 * x + 0 * y == x, so the coarser levels are not evaluated
        top = len(levels)
        for i, s in enumerate(levels):
            if s.n_fit >= target:
                top = i
                break
        log_lr = levels[top].log_lr(c, ref) if top < len(levels) else cold_start_log_lr(c, cfg.cold_start, m)
        for s in reversed(levels[:top]):
            n = s.n_fit
            if n:
                w = n / target
                log_lr = w * s.log_lr(c, ref) + (1.0 - w) * log_lr
        if log_lr > m:
            log_lr = m
        elif log_lr < -m:
            log_lr = -m
        if cfg.kappa_pooling == "pooled":
            kappa = min(1.0, levels[-1].n_fit / target)
            for s in reversed(levels[:-1]):
                w = min(1.0, s.n_fit / target)
                kappa = w + (1.0 - w) * kappa
        else:
            kappa = finest.n_fit / target
        if kappa > 1.0:
            kappa = 1.0
        elif kappa < cfg.kappa_min:
            kappa = cfg.kappa_min
        return _exp(log_lr), kappa

    def calibrated_probability(self, c: float, context: str, predicate: str) -> float:
        """p_hat(y = 1 | c) of the finest fitted level (c itself when none is fitted)."""
        for g in self.groups:
            s = self.slices.get(g(context, predicate))
            if s is not None and s.n_fit:
                return s.p_hat(c)
        return c

    def in_regime(self, context: str, predicate: str) -> bool:
        """(phi, kappa) is calibratable: at least one verification outcome in its finest slice (Property 1)."""
        s = self.slices.get(self.groups[0](context, predicate))
        return s is not None and s.n_fit > 0

    def prediction_set(self, c: float, context: str, predicate: str, *, adaptive: bool = False) -> PredictionSet:
        """Event-level (1 - alpha) set over {0, 1} for a claim (c, kappa, phi), or no coverage claim.

        Parameters
        ----------
        c : float
            The claim's raw confidence.
        context, predicate : str
            The claim's Mondrian coordinates (the finest slice's scores are used).
        adaptive : bool
            Use the adaptive level alpha_t instead of alpha.
        """
        s = self.slices.get(self.groups[0](context, predicate))
        if s is None or s.n_fit == 0:
            return no_coverage(f"no verification outcome yet for context {context!r}, predicate {predicate!r}")
        conf = s.conformal
        level = conf.alpha_t if adaptive else self.alpha
        q = conf.threshold(level) if level > 0 else math.inf
        return PredictionSet(prediction_set(c, q), 1.0 - self.alpha, conf.n_sorted)

    def summary(self) -> dict[str, Any]:
        """Per slice: outcomes held and seen, base rate, knots, adaptive level (keys ``context|predicate``)."""
        return {
            _key_name(k): {"n": s.n, "n_seen": s.n_seen, "base_rate": s.base_rate, "knots": len(s.kx), "alpha_t": s.conformal.alpha_t}
            for k, s in sorted(self.slices.items(), key=lambda kv: _key_parts(kv[0]))
        }


def _key_parts(key: Hashable) -> tuple[str, ...]:
    return tuple(map(str, key)) if isinstance(key, tuple) else (str(key),)


def _key_name(key: Hashable) -> str:
    return "|".join(_key_parts(key))

"""U_cal and U_comod: the calibrated commit gate and the co-modulated operator (Alg. 1, Eq. 2-5)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from scipy import special as _sp

from sgbelief.fusion import queues
from sgbelief.fusion.calibration import MondrianCalibrator
from sgbelief.errors import UnknownPredicateError
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.conformal import ConformalSlice, PredictionSet, no_coverage, prediction_set
from sgbelief.fusion.operators.base import BaseOperator
from sgbelief.fusion.protocol import Action, QueueResolution, TargetOutcome, UpdateReport, make_report
from sgbelief.graph.provenance import EntryStatus

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.channel import GeometricChannel
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.graph.scene_graph import SceneGraph

_betaln = _sp.betaln
_digamma = _sp.digamma
_COMMITTED = EntryStatus.COMMITTED
_QUARANTINED = EntryStatus.QUARANTINED
_REFUSED = EntryStatus.REFUSED
_NO_CLAIM = Verdict.NO_CLAIM
_CORR = Verdict.CORROBORATES
_CONTRA = Verdict.CONTRADICTS
_BELOW = Action.BELOW_THRESHOLD
_A_COMMITTED = Action.COMMITTED
_A_QUARANTINED = Action.QUARANTINED
_A_REFUSED = Action.REFUSED
_lgamma = math.lgamma


def _digamma_estimate(x: float) -> float:
    """psi(x) for x > 0 in pure Python (absolute error < 1e-10): recurrence up to x >= 6, then
    the asymptotic series. A scalar call of ``scipy.special.digamma`` costs several times more."""
    r = 0.0
    while x < 6.0:
        r -= 1.0 / x
        x += 1.0
    f = 1.0 / (x * x)
    return r + math.log(x) - 0.5 / x - f * (1 / 12 - f * (1 / 120 - f * (1 / 252 - f * (1 / 240 - f / 132))))


def kl_upper_bound(a: float, b: float, da: float, db: float) -> float:
    """An upper bound on KL(Beta(a, b) || Beta(a + da, b + db)) for da, db >= 0 (§4.3 revision test).

    The KL between members of an exponential family is the Bregman divergence of its log-partition
    A(a, b) = ln B(a, b), so with delta = (da, db) and the Hessian H of A,
    KL = int_0^1 (1 - s) delta^T H((a, b) + s delta) delta ds, and
    delta^T H delta = da^2 psi'(a) + db^2 psi'(b) - (da + db)^2 psi'(a + b) <= da^2 psi'(a) + db^2 psi'(b).
    psi' decreases, so along the path (arguments >= a, b) it is at most its value at (a, b), and
    psi'(x) = sum_k 1 / (x + k)^2 < 1 / x^2 + 1 / x. Hence
    KL <= (da^2 (1/a + 1/a^2) + db^2 (1/b + 1/b^2)) / 2.
    """
    ia = 1.0 / a
    ib = 1.0 / b
    return 0.5 * (da * da * ia * (1.0 + ia) + db * db * ib * (1.0 + ib))


def revision_kl_exceeds(a: float, b: float, da: float, db: float, tau_rev: float) -> bool:
    """True when KL(Beta(a, b) || Beta(a + da, b + db)) > tau_rev (the revision test of §4.3).

    KL = ln B(a', b') - ln B(a, b) - da psi(a) - db psi(b) + (da + db) psi(a + b).
    It is first estimated with ``math.lgamma`` and a pure-Python digamma (several times cheaper
    than ``scipy.special``); only when the estimate is within a safe margin of ``tau_rev`` (far
    above the estimate's error, which scales with (a + b) log(a + b) for lgamma and with da + db
    for digamma) is the KL recomputed with ``betaln`` / ``digamma``, so the decision is always
    the one the exact formula gives. Before either, the bound of :func:`kl_upper_bound` settles
    most calls (non-negative increments on a belief that already holds some evidence).
    """
    a2, b2 = a + da, b + db
    margin = 1e-8 * (1.0 + a2 + b2 + da + db)
    if da >= 0.0 and db >= 0.0 and kl_upper_bound(a, b, da, db) < tau_rev - 2.0 * margin:
        return False
    dig = (da + db) * _digamma_estimate(a + b) - da * _digamma_estimate(a) - db * _digamma_estimate(b)
    est = (_lgamma(a2) + _lgamma(b2) - _lgamma(a2 + b2)) - (_lgamma(a) + _lgamma(b) - _lgamma(a + b)) + dig
    if abs(est - tau_rev) > margin:
        return est > tau_rev
    exact = _betaln(a2, b2) - _betaln(a, b) - da * _digamma(a) - db * _digamma(b) + (da + db) * _digamma(a + b)
    return exact > tau_rev


class CalibratedOperator(BaseOperator):
    """U_cal: per-class calibrated commit gate with revision quarantine and provenance.

    For each targeted v with T(v) > tau_T (Alg. 1):

    1. Lambda_hat, kappa_hat from the Mondrian isotonic calibrator of (kappa, phi) (Eq. 2);
    2. candidate increments (Eq. 4) with w = w0 kappa_hat T(v)::

           d_alpha = w Lambda / (1 + Lambda),   d_beta = w / (1 + Lambda)

    3. the event first acts on the revisions pending at (v, phi) (corroborate / disconfirm),
       then the revision test: commit when KL(B || B') <= tau_rev, else quarantine in Q;
    4. after all targets, every decisive geometric label (y = 1 positive set, y = 0 negative
       set) is appended to the calibration buffer (so an event never calibrates itself).

    U_cal consults the geometric channel only for calibration, never to refuse a claim.
    """

    name = "cal"
    check_compatibility = False

    def __init__(
        self,
        config: OperatorConfig | dict[str, Any] | str | None = None,
        vocabulary: SubsumptionTable | None = None,
    ) -> None:
        super().__init__(config, vocabulary)
        cfg = self.config
        import sklearn.isotonic  # noqa: F401  (pay the import here, not inside the first timed update)

        self.calibrator_ = MondrianCalibrator(cfg.calibration, alpha=cfg.alpha)
        #: pair-level conformal scores s(p_v, y) per predicate (Property 1 on beliefs)
        self.pair_conformal_: dict[str, ConformalSlice] = {}

    # ------------------------------------------------------------- time
    def _timeouts(self, graph: SceneGraph, t: int) -> list[QueueResolution]:
        cfg = self.config
        prov = graph.provenance
        if queues.nothing_expires(prov, t, t_cor=cfg.t_cor, t_disagree=cfg.t_disagree):
            return []
        out = queues.expire(prov, t, t_cor=cfg.t_cor, k=cfg.k, t_disagree=cfg.t_disagree)
        if out:
            self._count(out)
        return out

    # ----------------------------------------------------------- update
    def update(
        self,
        graph: SceneGraph,
        event: EvidenceEvent,
        channel: GeometricChannel | None = None,
        *,
        report: bool = True,
    ) -> UpdateReport:
        """Apply one event (Alg. 1). ``report=False`` skips building the per-target outcomes
        (the returned report then has ``targets == ()``); the map, queues, provenance, stats and
        calibration state are the same either way."""
        if not report:
            res = self._apply(graph, ((event, channel),), None)
            return make_report((event.id, event.t, event.predicate, (), tuple(res) if res else ()))
        reports: list[UpdateReport] = []
        self._apply(graph, ((event, channel),), reports)
        return reports[0]

    def update_many(
        self, graph: SceneGraph, items: Iterable[tuple[EvidenceEvent, GeometricChannel | None]]
    ) -> list[QueueResolution]:
        """Apply (event, channel) pairs in order, exactly as ``update(graph, event, channel,
        report=False)`` on each would (map, queues, provenance, stats and calibration state after
        every event), with the per-call set-up done once; returns the queue resolutions in order.
        When an event is rejected, the events before it stay applied (``stats["events"]`` counts
        them) and the error propagates. A subclass that overrides ``update`` (and not this method)
        gets its own ``update`` on each event."""
        if type(self).update is not CalibratedOperator.update:
            return self._update_each(graph, items)
        return self._apply(graph, items, None)

    def _apply(
        self,
        graph: SceneGraph,
        items: Iterable[tuple[EvidenceEvent, GeometricChannel | None]],
        reports: list[UpdateReport] | None,
    ) -> list[QueueResolution]:
        """Alg. 1 for each (event, channel) in order; appends one report per event to ``reports``
        (with per-target outcomes) unless it is None. Returns every event's queue resolutions."""
        report = reports is not None
        vocab = graph.vocabulary
        cfg = self.config
        tau_t, tau_rev, w0 = cfg.tau_t, cfg.tau_rev, cfg.w0
        prov = graph.provenance
        record = prov.record
        commit = prov.commit
        pairs_get = prov._pairs.get
        pending_map = prov._pending_by_pair  # pairs with entries waiting in Q or Q_bot
        prior_a, prior_b = prov.prior_alpha, prov.prior_beta
        gnx = graph.nx._node  # the node dict: a membership test without a Python-level __contains__
        tables = self.vocabulary.outcome_tables() if self.vocabulary is not None else None
        comod = self.check_compatibility
        min_refit, refit_growth = cfg.calibration.min_refit, cfg.calibration.refit_growth
        calibrator = self.calibrator_
        tick = self.tick
        out: list[QueueResolution] = []
        n_events = n_targets = n_below = n_committed = n_quarantined = n_refused = 0
        try:
            for event, channel in items:
                pred, c, ctx, eid, t = event.predicate, event.confidence, event.context, event.id, event.t
                if vocab is not None and pred not in vocab:
                    raise UnknownPredicateError(pred, vocab)
                resolutions = tick(graph, t) if t > graph.clock else []
                # committed entries go to the store's journal (materialised on demand, folded by
                # compaction without objects) unless the timeline is live: then the next refusal or
                # quarantine would materialise the journal anyway, and recording directly is cheaper
                direct = bool(prov._timeline)
                outcome_of = tables.get(pred) if tables is not None else None
                label_of = None
                if channel is not None and outcome_of is not None:
                    label_of = channel.labels.get if type(channel) is FrameLabels else channel.label
                frame = label_of is not None and type(channel) is FrameLabels
                claim_pos = c >= 0.5
                e_targets = e_below = e_committed = e_quarantined = e_refused = 0
                lam = kappa = -1.0
                new_outcomes: list[int] = []
                outcomes: list[TargetOutcome] = []
                pair_slice: ConformalSlice | None = None  # this predicate's pair-level scores, fetched once
                for node, mass in event.targets.items():
                    e_targets += 1
                    if mass <= tau_t and not report:
                        e_below += 1
                        continue
                    if label_of is None:
                        y = None
                    else:
                        label = label_of(node) if frame else label_of(node, t)  # type: ignore[call-arg]
                        y = outcome_of.get(label) if label is not None else None  # type: ignore[union-attr]
                    if y is None:
                        verdict = _NO_CLAIM
                    else:
                        verdict = _CORR if (y == 1) == claim_pos else _CONTRA
                    if mass <= tau_t:
                        e_below += 1
                        outcomes.append(TargetOutcome(node, mass, verdict, _BELOW))
                        continue
                    if node not in gnx:
                        graph.ensure_node(node)
                    key = (node, pred)
                    log = pairs_get(key)
                    if log is None:
                        a, b = prior_a, prior_b
                    else:
                        a, b = log.alpha, log.beta
                    if y is not None:
                        new_outcomes.append(y)
                        if pair_slice is None:
                            pair_slice = self._pair_slice(pred)
                        pair_slice.add_outcome(a / (a + b), y, min_refit, refit_growth)
                    if lam < 0.0:
                        lam, kappa = calibrator.likelihood_ratio(c, ctx, pred)
                    w = w0 * kappa * mass
                    da = w * lam / (1.0 + lam)
                    db = w / (1.0 + lam)
                    if comod and verdict is _CONTRA:
                        # Property 2: refused and logged, never committed; geometry's stance opposes the claim
                        stance = -1 if claim_pos else 1
                        had_pending = key in pending_map
                        record(node, pred, eid, t, da, db, _REFUSED, stance)
                        if had_pending:  # otherwise the only pending entry is this refused one
                            resolutions += queues.quarantine_feedback(prov, node, pred, stance, eid, t)
                        e_refused += 1
                        if report:
                            outcomes.append(TargetOutcome(node, mass, verdict, _A_REFUSED, 0.0, 0.0))
                        continue
                    stance = 1 if lam > 1.0 else -1 if lam < 1.0 else 0
                    if key in pending_map:
                        fb = queues.quarantine_feedback(prov, node, pred, stance, eid, t)
                        if fb:
                            resolutions += fb
                            a, b = prov.alpha_beta(node, pred)
                    # revision test: KL(Beta(a, b) || Beta(a + da, b + db)) > tau_rev (§4.3); the bound
                    # settles it without special functions when it is far below tau_rev
                    if kl_upper_bound(a, b, da, db) < tau_rev - 2e-8 * (1.0 + a + b + 2.0 * (da + db)):
                        exceeds = False
                    else:
                        exceeds = revision_kl_exceeds(a, b, da, db, tau_rev)
                    if exceeds:
                        record(node, pred, eid, t, da, db, _QUARANTINED, stance)
                        e_quarantined += 1
                        if report:
                            outcomes.append(TargetOutcome(node, mass, verdict, _A_QUARANTINED, 0.0, 0.0))
                    else:
                        if direct:
                            record(node, pred, eid, t, da, db, _COMMITTED, stance)
                        else:
                            commit(node, pred, eid, t, da, db, stance)
                        e_committed += 1
                        if report:
                            outcomes.append(TargetOutcome(node, mass, verdict, _A_COMMITTED, da, db))
                    if comod and verdict is _CORR and key in pending_map:
                        resolutions += queues.resolve_disagreements(prov, node, pred, t)
                n_events += 1
                n_targets += e_targets
                n_below += e_below
                n_committed += e_committed
                n_quarantined += e_quarantined
                n_refused += e_refused
                if new_outcomes:
                    add = calibrator.add
                    for y in new_outcomes:
                        add(ctx, pred, c, y)
                if resolutions:
                    self._count([r for r in resolutions if r.kind in ("corroborated", "discarded", "resolved")])
                    out += resolutions
                if report:
                    reports.append(make_report((eid, t, pred, tuple(outcomes), tuple(resolutions))))  # type: ignore[union-attr]
        finally:
            if n_events:
                self._add_totals(n_events, n_targets, n_below, n_committed, n_quarantined, n_refused)
        return out

    def _pair_slice(self, predicate: str) -> ConformalSlice:
        """The pair-level conformal scores of a predicate (created on first use)."""
        sl = self.pair_conformal_.get(predicate)
        if sl is None:
            sl = self.pair_conformal_[predicate] = ConformalSlice(self.config.alpha, self.config.calibration.buffer_size)
        return sl

    def _pair_score(self, predicate: str, p: float, y: int) -> None:
        """Record s(p_v, y) (Eq. 1 on the belief mean) for the pair-level sets of Property 1."""
        cfg = self.config.calibration
        self._pair_slice(predicate).add_outcome(p, y, cfg.min_refit, cfg.refit_growth)

    # ---------------------------------------------------------- reading
    def prediction_set(self, graph: SceneGraph, node: Any, predicate: str) -> PredictionSet:
        """(1 - alpha) prediction set over {0, 1} for y*_{v, phi} (Property 1), or "no coverage claim".

        The calibratable regime R: phi is verifiable by the geometric channel (in the subsumption
        table) and its buffer holds at least one verification outcome. The set is
        {y : s(p_v, y) <= q_hat} with p_v the belief mean and q_hat the split-conformal quantile of
        past scores s(p, y) recorded whenever the geometric channel verified a pair of phi.
        """
        if self.vocabulary is None or predicate not in self.vocabulary:
            return no_coverage(f"predicate {predicate!r} is not verifiable by the geometric channel")
        sl = self.pair_conformal_.get(predicate)
        if sl is None or sl.n_sorted == 0:
            return no_coverage(f"no verification outcome yet for predicate {predicate!r}")
        q = sl.threshold(self.config.alpha)
        p = graph.probability(node, predicate)
        return PredictionSet(prediction_set(p, q), 1.0 - self.config.alpha, sl.n_sorted)

    def event_prediction_set(self, event: EvidenceEvent, *, adaptive: bool = False) -> PredictionSet:
        """Event-level conformal set for a claim's outcome (Eq. 1 scores of its (kappa, phi) slice)."""
        return self.calibrator_.prediction_set(event.confidence, event.context, event.predicate, adaptive=adaptive)

    def likelihood_ratio(self, event: EvidenceEvent) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) the operator would use for this event now."""
        return self.calibrator_.likelihood_ratio(event.confidence, event.context, event.predicate)

    def freeze_calibration(self) -> None:
        """Stop learning from new outcomes (e.g. to replay with a fixed calibration)."""
        self.calibrator_.refit_all()
        self.calibrator_.frozen = True


class CoModulatedOperator(CalibratedOperator):
    """U_comod: U_cal plus the per-event conflict-drop window (§4.2, Alg. 1 lines 4-9).

    A claim the geometric channel contradicts at (v, t) (verdict ⊥, sign-flipped for c < 0.5)
    is refused: logged with status ``refused`` in the disagreement queue Q⊥ and never committed
    (Property 2). A later T at the same (v, phi) within T_disagree resolves it without
    committing it; otherwise it expires after T_disagree; an explicit confirmation may override.
    """

    name = "comod"
    check_compatibility = True



"""U_cal and U_comod: the calibrated commit gate and the co-modulated operator (Alg. 1, Eq. 2-5)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from scipy import special as _sp

from sgbelief.fusion import queues
from sgbelief.fusion.calibration import MondrianCalibrator
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.conformal import ConformalSlice, PredictionSet, no_coverage, nonconformity, prediction_set
from sgbelief.fusion.operators.base import BaseOperator
from sgbelief.fusion.protocol import Action, QueueResolution, TargetOutcome, UpdateReport
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
        out = queues.expire(graph.provenance, t, t_cor=cfg.t_cor, k=cfg.k, t_disagree=cfg.t_disagree)
        if out:
            self._count(out)
        return out

    # ----------------------------------------------------------- update
    def update(
        self, graph: SceneGraph, event: EvidenceEvent, channel: GeometricChannel | None = None
    ) -> UpdateReport:
        self._check(graph, event)
        t = event.t
        resolutions = self.tick(graph, t) if t > graph.clock else []
        cfg = self.config
        tau_t, tau_rev, w0 = cfg.tau_t, cfg.tau_rev, cfg.w0
        pred, c, ctx, eid = event.predicate, event.confidence, event.context, event.id
        prov = graph.provenance
        outcome_of = self.vocabulary.outcome_tables().get(pred) if self.vocabulary is not None else None
        claim_pos = c >= 0.5
        comod = self.check_compatibility
        stats = self.stats
        stats["events"] += 1
        lam = kappa = -1.0
        new_outcomes: list[int] = []
        outcomes: list[TargetOutcome] = []
        for node, mass in event.targets.items():
            stats["targets"] += 1
            label = channel.label(node, t) if (channel is not None and outcome_of is not None) else None
            y = outcome_of.get(label) if (label is not None and outcome_of is not None) else None
            if y is None:
                verdict = _NO_CLAIM
            else:
                verdict = _CORR if (y == 1) == claim_pos else _CONTRA
            if mass <= tau_t:
                stats["below_tau_t"] += 1
                outcomes.append(TargetOutcome(node, mass, verdict, Action.BELOW_THRESHOLD))
                continue
            if node not in graph.nx:
                graph.ensure_node(node)
            a, b = prov.alpha_beta(node, pred)
            if y is not None:
                new_outcomes.append(y)
                self._pair_score(pred, a / (a + b), y)
            if lam < 0.0:
                lam, kappa = self.calibrator_.likelihood_ratio(c, ctx, pred)
            w = w0 * kappa * mass
            da = w * lam / (1.0 + lam)
            db = w / (1.0 + lam)
            if comod and verdict is _CONTRA:
                # Property 2: refused and logged, never committed; geometry's stance opposes the claim
                stance = -1 if claim_pos else 1
                prov.record(node, pred, eid, t, da, db, _REFUSED, stance=stance)
                resolutions += queues.quarantine_feedback(prov, node, pred, stance, eid, t)
                stats["refused"] += 1
                outcomes.append(TargetOutcome(node, mass, verdict, Action.REFUSED, 0.0, 0.0))
                continue
            stance = 1 if lam > 1.0 else -1 if lam < 1.0 else 0
            if prov._pending_by_pair:
                fb = queues.quarantine_feedback(prov, node, pred, stance, eid, t)
                if fb:
                    resolutions += fb
                    a, b = prov.alpha_beta(node, pred)
            # revision test: KL(Beta(a, b) || Beta(a + da, b + db)) (§4.3)
            a2, b2 = a + da, b + db
            d_kl = (
                _betaln(a2, b2) - _betaln(a, b)
                - da * _digamma(a) - db * _digamma(b) + (da + db) * _digamma(a + b)
            )
            if d_kl <= tau_rev:
                prov.record(node, pred, eid, t, da, db, _COMMITTED, stance=stance)
                stats["committed"] += 1
                outcomes.append(TargetOutcome(node, mass, verdict, Action.COMMITTED, da, db))
            else:
                prov.record(node, pred, eid, t, da, db, _QUARANTINED, stance=stance)
                stats["quarantined"] += 1
                outcomes.append(TargetOutcome(node, mass, verdict, Action.QUARANTINED, 0.0, 0.0))
            if comod and verdict is _CORR and prov._pending_by_pair:
                resolutions += queues.resolve_disagreements(prov, node, pred, t)
        if new_outcomes:
            add = self.calibrator_.add
            for y in new_outcomes:
                add(ctx, pred, c, y)
        if resolutions:
            self._count([r for r in resolutions if r.kind in ("corroborated", "discarded", "resolved")])
        return UpdateReport(eid, t, pred, tuple(outcomes), tuple(resolutions))

    def _pair_score(self, predicate: str, p: float, y: int) -> None:
        sl = self.pair_conformal_.get(predicate)
        if sl is None:
            sl = self.pair_conformal_[predicate] = ConformalSlice(self.config.alpha)
        sl.pending.append(nonconformity(p, y))
        n = sl.n_sorted + len(sl.pending)
        cfg = self.config.calibration
        if n - sl.n_sorted >= max(cfg.min_refit, cfg.refit_growth * sl.n_sorted) or sl.n_sorted == 0:
            sl.refresh()

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



"""U_cal and U_comod: the calibrated commit gate and the co-modulated operator (Alg. 1, Eq. 2-5).

:meth:`CalibratedOperator._apply_reference` is Algorithm 1 written as its named steps over the
pure functions of :mod:`sgbelief.fusion.rules`; it is the reference, and the engine an operator
built here runs by default. ``sgbelief.make_operator(name, ..., engine="fast")`` (the public
default) injects the same algorithm fused into one loop (:mod:`sgbelief._fast.calibrated`), proven
identical by ``tests/test_engines.py``. The method options and their derivations are in
``docs/method.md``; ``cal_paper`` / ``comod_paper`` are the paper's own settings.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING, Any

from sgbelief.calibration.conformal import ConformalSlice, PredictionSet, no_coverage, prediction_set
from sgbelief.calibration.isotonic import RefitIsotonic
from sgbelief.calibration.mondrian import MondrianCalibrator
from sgbelief.fusion import queues
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig, paper_variant, resolve_config
from sgbelief.fusion.operators.base import BaseOperator, OperatorEngine
from sgbelief.fusion.protocol import COUNTED_RESOLUTIONS as _COUNTED_KINDS
from sgbelief.fusion.protocol import Action, Items, QueueResolution, TargetOutcome, UpdateReport, make_report
from sgbelief.fusion.consensus import MapConsensus
from sgbelief.fusion.label_memory import LabelMemory
from sgbelief.fusion.reweigh import reweigh_silent_claims
from sgbelief.fusion.rules import (  # noqa: F401  (kl_upper_bound, revision_kl_exceeds: re-exported)
    ENTRY_VERDICT,
    adjudication,
    claim_asserts,
    claim_increments,
    consensus_agrees,
    consensus_cell,
    evidence_weight,
    exclusion_increments,
    kl_upper_bound,
    label_observations,
    revision_kl_exceeds,
    stance_of,
    standing,
    stratified_context,
    support_stratum,
    targeting,
    verdict,
    verification_increments,
)
from sgbelief.graph.provenance import EntryRecord, EntryStatus, EntryVerdict

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.calibration.agreement_shift import ContextReading
    from sgbelief.fusion.channel import GeometricChannel
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.graph.entry_log import EntryLog
    from sgbelief.graph.scene_graph import SceneGraphModel

_CONTRA = Verdict.CONTRADICTS
_CORR = Verdict.CORROBORATES


class CalibratedOperator(BaseOperator):
    """U_cal: per-class calibrated commit gate with revision quarantine and provenance.

    For each targeted v with T(v) > tau_T (Alg. 1):

    1. the claim's support stratum (earlier claims at (v, phi)) refines its Mondrian cell;
    2. Lambda_hat, kappa_hat from the Mondrian isotonic calibrator of that cell (Eq. 2);
    3. candidate increments (Eq. 3) with w = w0 kappa_hat T(v)::

           d_alpha = w Lambda / (1 + Lambda),   d_beta = w / (1 + Lambda)

    4. the event first acts on the revisions pending at (v, phi) (corroborate / disconfirm),
       then the revision test: commit when KL(B || B') <= tau_rev, else quarantine in Q;
    5. after all targets, every decisive geometric label (y = 1 positive set, y = 0 negative
       set) is appended to the calibration buffer (so an event never calibrates itself).

    U_cal consults the geometric channel only for calibration, never to refuse a claim.
    ``engine``: an :class:`~sgbelief.fusion.operators.base.OperatorEngine`; None or ``"reference"``
    run the named steps; ``sgbelief.make_operator(..., engine="fast")`` passes the fused loop
    (same results). The calibrator's isotonic store is the engine's ``isotonic`` when it has one
    (the fused engine's incremental merge), else the reference refit (same knots).
    """

    name = "cal"
    #: refuse claims the geometric channel contradicts (Property 2): comod
    check_compatibility = False

    def __init__(
        self,
        config: OperatorConfig | dict[str, Any] | str | None = None,
        vocabulary: SubsumptionTable | None = None,
        *,
        engine: OperatorEngine | str | None = None,
    ) -> None:
        super().__init__(self._settings(resolve_config(config)), vocabulary, engine=engine)
        cfg = self.config
        import sklearn.isotonic  # noqa: F401  (pay the import here, not inside the first timed update)

        # the engine's isotonic store (the fused engine injects its incremental merge; same knots)
        isotonic = getattr(self.engine, "isotonic", RefitIsotonic)
        self.calibrator_ = MondrianCalibrator(cfg.calibration, alpha=cfg.alpha, isotonic=isotonic)
        #: pair-level conformal scores s(p_v, y) per predicate (Property 1 on beliefs)
        self.pair_conformal_: dict[str, ConformalSlice] = {}
        #: claims applied so far per (v, phi), per provenance store (the support of the next claim)
        self._claims: dict[int, tuple[EntryLog, dict[tuple[Any, str], int]]] = {}
        #: the time of the last label observation per (v, psi), per provenance store (once per frame)
        self._label_seen: dict[int, tuple[EntryLog, dict[tuple[Any, str], int]]] = {}
        #: the map-wide consensus (claim table, labels, its calibration) per provenance store
        self._consensus: dict[int, tuple[EntryLog, MapConsensus]] = {}
        #: the channel's labels of each element so far, per provenance store (recalled verdicts)
        self._memory: dict[int, tuple[EntryLog, LabelMemory]] = {}
        #: freeze_calibration() also stops the consensus' refits
        self._consensus_frozen = False
        # the vocabulary whose exclusive classes ``consensus_classes`` holds (see there)
        self._classes_of: tuple[SubsumptionTable | None, frozenset[str]] | None = None

    @classmethod
    def _settings(cls, config: OperatorConfig) -> OperatorConfig:
        """The config the operator runs with (the paper variants override the method options)."""
        return config

    @property
    def observes_geometry(self) -> bool:
        """A decisive geometric label also enters the belief at the claimed pair (comod with
        ``geometric_evidence: verdict`` or ``label``)."""
        return self.check_compatibility and self.config.geometric_evidence in ("verdict", "label")

    @property
    def weighs_labels(self) -> bool:
        """A decisive label's observation counts its reliability under the consensus
        (``calibration.consensus.label_weights: reliability``; MapConsensus.verdict_reliability)."""
        return self.observes_geometry and self.config.calibration.consensus.label_weights == "reliability"

    @property
    def observes_label(self) -> bool:
        """A decisive geometric label also observes the predicates it asserts (``geometric_evidence: label``)."""
        return self.check_compatibility and self.config.geometric_evidence == "label"

    @property
    def consensus_classes(self) -> frozenset[str]:
        """The exclusive classes of the operator's vocabulary (the consensus' latent classes), when
        the consensus is on; empty otherwise. Follows the vocabulary: a backend that learns its class
        list after building the operator sets ``operator.vocabulary`` then, and the consensus runs
        from the next claim on."""
        vocab = self.vocabulary
        held = self._classes_of
        if held is None or held[0] is not vocab:
            on = self.config.calibration.consensus.method != "none" and vocab is not None
            held = self._classes_of = (vocab, vocab.exclusive_predicates() if on else frozenset())  # type: ignore[union-attr]
        return held[1]

    @property
    def recalls_verdicts(self) -> bool:
        """comod refuses a claim its element's earlier labels unanimously contradict (``recalled_verdicts``)."""
        return self.check_compatibility and self.config.recalled_verdicts != "none" and self.vocabulary is not None

    @property
    def withdraws_unadjudicated(self) -> bool:
        """comod also withdraws the claims an element committed before its labels, once they all
        contradict them (``recalled_verdicts: retroactive``)."""
        return self.recalls_verdicts and self.config.recalled_verdicts == "retroactive"

    @property
    def weighs_contested(self) -> bool:
        """comod may weigh, not refuse, a claim its frame's label contradicts where the element's
        labels both assert and deny the predicate (``contested_labels: weigh`` or ``consensus``)."""
        return self.recalls_verdicts and self.config.contested_labels != "refuse"

    @property
    def excludes_rivals(self) -> bool:
        """A committed claim also counts against the classes that exclude it (``exclusive_evidence: rivals``)."""
        return self.config.exclusive_evidence == "rivals" and self.vocabulary is not None

    @property
    def claims_property2(self) -> bool:
        """Property 2 holds exactly: no ⊥ event changes the belief at its (v, phi). True for a
        refusing operator that does not also observe the geometric label (``comod_paper``,
        ``geometric_evidence: none``) nor withdraw earlier claims (``recalled_verdicts:
        retroactive``) nor weigh claims at elements the channel contradicted itself about
        (``contested_labels: weigh`` or ``consensus``); with the first two a refused claim's own increments still
        never enter, but the label's observation, or the withdrawal of the pair's earlier unseen
        claims (both against the claim), does; with the third a ⊥ claim at a contested element is
        weighed, not refused."""
        return self.check_compatibility and not self.observes_geometry and not self.withdraws_unadjudicated \
            and not self.weighs_contested

    # ------------------------------------------------------------- time
    def _timeouts(self, graph: SceneGraphModel, t: int) -> list[QueueResolution]:
        cfg = self.config
        prov = graph.provenance
        if queues.nothing_expires(prov, t, t_cor=cfg.t_cor, t_disagree=cfg.t_disagree):
            return []
        out = queues.expire(prov, t, t_cor=cfg.t_cor, k=cfg.k, t_disagree=cfg.t_disagree)
        if out:
            self._count(out)
        return out

    # ----------------------------------------------------------- update
    def _apply_reference(self, graph: SceneGraphModel, items: Items, reports: list[UpdateReport] | None) -> list[QueueResolution]:
        """Algorithm 1, step by step, for each (event, channel) in order (the reference path)."""
        out: list[QueueResolution] = []
        for event, channel in items:
            self._check(graph, event)
            resolutions = self.tick(graph, event.t) if event.t > graph.clock else []
            consensus = self._consensus_of(graph.provenance) if event.predicate in self.consensus_classes else None
            if consensus is not None and consensus.due():  # batched: never per event over the map
                resolutions += self._refit_consensus(graph.provenance, consensus, event.t)
            memory = self._label_memory_of(graph.provenance) if self.recalls_verdicts else None
            recall_table = self.vocabulary.outcome_tables().get(event.predicate) if memory is not None else None  # type: ignore[union-attr]
            outcomes: list[TargetOutcome] = []
            verified: list[tuple[int, str]] = []  # (y, calibration context) for step 5
            tally: Counter[Action] = Counter()  # targets per action (below tau_T, committed, quarantined, refused)
            for node, mass in event.targets.items():
                label = self._geometric_label(channel, node, event)
                y = self._outcome(event.predicate, label)
                if memory is not None and label is not None and memory.add(node, event.t, label) \
                        and self.withdraws_unadjudicated:  # a new label may judge the element's earlier claims
                    resolutions += self._withdraw_judged(graph.provenance, memory, node, event.t)
                if mass <= self.config.tau_t:  # discarded; its verdict is only reported
                    tally[Action.BELOW_THRESHOLD] += 1
                    if consensus is not None and label is not None:  # the channel still saw v
                        consensus.add_label(node, event.t, label)
                    context = self._context(event, self._claims_so_far(graph.provenance, node, event.predicate))
                    v = verdict(y, self._asserts(event, context))
                    outcomes.append(TargetOutcome(node, mass, v, Action.BELOW_THRESHOLD))
                    continue
                graph.ensure_node(node)
                if label is not None and self.observes_label:  # pairs other than (v, phi), before the claim's entries
                    self._observe_label(graph, event, node, mass, label)
                if consensus is not None and label is not None:
                    consensus.add_label(node, event.t, label)
                recalled = memory.recalled(node, recall_table) if recall_table is not None and y is None else None  # type: ignore[union-attr]
                if recall_table is not None and y is None and recalled is None and channel is not None \
                        and self.withdraws_unadjudicated:  # (no channel: no label will ever judge it)
                    memory.hold(node, event.predicate, recall_table)  # type: ignore[union-attr]
                contested = y is not None and recall_table is not None and self.weighs_contested \
                    and memory.contested(node, recall_table)  # type: ignore[union-attr]
                action, v, da, db, res = self._apply_target(graph, event, node, mass, y, verified, label, consensus,
                                                            recalled, contested)
                resolutions += res
                tally[action] += 1
                outcomes.append(TargetOutcome(node, mass, v, action, da, db))
            self._add_totals(1, tally.total(), tally[Action.BELOW_THRESHOLD], tally[Action.COMMITTED],
                             tally[Action.QUARANTINED], tally[Action.REFUSED])
            self._feed_calibration(event, verified)
            if resolutions:
                self._count([r for r in resolutions if r.kind in _COUNTED_KINDS])
                out += resolutions
            if reports is not None:
                reports.append(make_report((event.id, event.t, event.predicate, tuple(outcomes), tuple(resolutions))))
        return out

    def _apply_target(
        self, graph: SceneGraphModel, event: EvidenceEvent, node: Any, mass: float, y: int | None,
        verified: list[tuple[int, str]], label: str | None = None, consensus: MapConsensus | None = None,
        recalled: int | None = None, contested: bool = False,
    ) -> tuple[Action, Verdict, float, float, list[QueueResolution]]:
        """Alg. 1 lines 4-19 for one target with T(v) > tau_T: (action, verdict, d_alpha, d_beta, resolutions).
        ``recalled``: the outcome the element's earlier labels agree on when this frame's label decides
        nothing (only its ⊥ counts: the claim is refused; it is not a calibration outcome).
        ``contested``: the element's labels both assert and deny the predicate
        (:func:`~sgbelief.fusion.rules.labels_contested`): a ⊥ of this frame's label is recorded
        but, with ``contested_labels: weigh``, or ``consensus`` when the consensus sides with the
        claim (:func:`~sgbelief.fusion.rules.consensus_agrees`), refuses nothing, and the claim is
        weighed as ``cal`` weighs it."""
        cfg, prov, pred = self.config, graph.provenance, event.predicate
        n_strata = cfg.calibration.support_strata
        stratum = support_stratum(self._next_claim(prov, node, pred), n_strata)
        context = stratified_context(event.context, stratum, n_strata)  # the claim's Mondrian cell
        lam, kappa = self._likelihood_ratio(event, context, stratum, node, mass, y, label, consensus)  # Eq. 2
        asserts = claim_asserts(event.confidence, lam if cfg.verdict_sign == "calibrated" else None)
        v = verdict(y, asserts)
        if recalled is not None and y is None and verdict(recalled, asserts) is _CONTRA:
            v = _CONTRA
        code, c = ENTRY_VERDICT[v], event.confidence  # what each entry records of the event
        a, b = prov.alpha_beta(node, pred)
        resolutions: list[QueueResolution] = []
        if y is not None:
            verified.append((y, context))
            self._pair_slice(pred).add_outcome(a / (a + b), y, cfg.calibration.min_refit, cfg.calibration.refit_growth)
            if self.observes_geometry:  # counts the label's reliability (consensus.label_weights)
                r = 1.0 if consensus is None or not self.weighs_labels else consensus.verdict_reliability(pred, label, y)
                ga, gb = verification_increments(y, cfg.w0 * mass * r)
                prov.append(EntryRecord(node=node, predicate=pred, event_id=event.id, t=event.t, d_alpha=ga,
                                        d_beta=gb, status=EntryStatus.COMMITTED, stance=1 if y == 1 else -1,
                                        verdict=EntryVerdict.GEOMETRIC, confidence=c))
                a, b = a + ga, b + gb
        da, db = claim_increments(lam, evidence_weight(cfg.w0, kappa, mass))  # Eq. 3
        # the channel contradicted itself at v: this frame's label refuses nothing (contested_labels)
        weighed = contested and v is _CONTRA and (cfg.contested_labels == "weigh" or consensus_agrees(
            asserts, consensus.posterior(node, pred) if consensus is not None else None))
        if self.check_compatibility and v is _CONTRA and not weighed:  # refusal (Property 2)
            stance = -1 if asserts else 1  # geometry's stance opposes the claim
            prov.append(EntryRecord(node=node, predicate=pred, event_id=event.id, t=event.t, d_alpha=da, d_beta=db,
                                    status=EntryStatus.REFUSED, stance=stance, verdict=code, confidence=c))
            resolutions += queues.quarantine_feedback(prov, node, pred, stance, event.id, event.t)
            return Action.REFUSED, v, 0.0, 0.0, resolutions
        stance = stance_of(lam)
        fb = queues.quarantine_feedback(prov, node, pred, stance, event.id, event.t)
        if fb:
            resolutions += fb
            a, b = prov.alpha_beta(node, pred)
        if revision_kl_exceeds(a, b, da, db, cfg.tau_rev):  # revision: quarantine in Q
            prov.append(EntryRecord(node=node, predicate=pred, event_id=event.id, t=event.t, d_alpha=da, d_beta=db,
                                    status=EntryStatus.QUARANTINED, stance=stance, verdict=code, confidence=c))
            action, da, db = Action.QUARANTINED, 0.0, 0.0
        else:
            prov.append(EntryRecord(node=node, predicate=pred, event_id=event.id, t=event.t, d_alpha=da, d_beta=db,
                                    status=EntryStatus.COMMITTED, stance=stance, verdict=code, confidence=c))
            action = Action.COMMITTED
            if self.excludes_rivals and da > 0.0:
                self._exclude_rivals(prov, node, pred, event, da)
        if self.check_compatibility and v is _CORR:  # later agreement resolves pending ⊥ at (v, phi)
            resolutions += queues.resolve_disagreements(prov, node, pred, event.t)
        return action, v, da, db, resolutions

    def _withdraw_judged(self, prov: EntryLog, memory: LabelMemory, node: Any, t: int) -> list[QueueResolution]:
        """After a new label of v (:meth:`LabelMemory.judged`): the predicates whose claims at v came
        while no decisive label had judged them and that v's labels now unanimously deny have those
        claims withdrawn (:func:`~sgbelief.fusion.queues.withdraw_unadjudicated`); predicates
        withdrawn earlier that a label now asserts have them reinstated
        (:func:`~sgbelief.fusion.queues.reinstate_withdrawn`). From a withdrawal on, the recalled
        verdict refuses such claims as they come, as long as the labels stay unanimous."""
        denied, reinstated = memory.judged(node, self.vocabulary.outcome_tables())  # type: ignore[union-attr]
        out: list[QueueResolution] = []
        for pred in reinstated:
            out += queues.reinstate_withdrawn(prov, node, pred, t)
        for pred in denied:
            out += queues.withdraw_unadjudicated(prov, node, pred, t)
        return out

    def _likelihood_ratio(self, event: EvidenceEvent, context: str, stratum: int, node: Any, mass: float,
                          y: int | None, label: str | None, consensus: MapConsensus | None) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) of a claim (Eq. 2): from §4.1's calibrator, or, for a claim the
        channel cannot adjudicate while the consensus is on, from the consensus calibration of its
        cell (context, stratum, adjudication, standing; docs/method.md §8). The claim then joins
        the consensus' table."""
        c, pred = event.confidence, event.predicate
        if consensus is None:
            return self.calibrator_.likelihood_ratio(c, context, pred)
        n_same, n_others, max_other = consensus.standing_counts(node, pred, self.vocabulary.exclusive_with(pred))  # type: ignore[union-attr]
        cell = consensus_cell(event.context, stratum, adjudication(label, y), standing(n_same, n_others, max_other),
                              targeting(mass))
        found = consensus.likelihood_ratio(c, cell, pred, event.context) if y is None else None
        consensus.add_claim(node, pred, event.context, c, cell, y is not None, event.id, mass, event.t)
        return found if found is not None else self.calibrator_.likelihood_ratio(c, context, pred)

    def _refit_consensus(self, prov: EntryLog, consensus: MapConsensus, t: int) -> list[QueueResolution]:
        """Refit the map's consensus; with ``silent_weights: current`` its committed silent claims of
        the last T_prov steps then take the new calibration
        (:func:`~sgbelief.fusion.reweigh.reweigh_silent_claims`), each entry that changed reported
        as a ``reweighed`` resolution at time ``t``."""
        consensus.refit()
        if self.config.calibration.consensus.silent_weights != "current":
            return []
        return [QueueResolution(eid, node, pred, "reweighed", t)
                for eid, node, pred in reweigh_silent_claims(prov, consensus, self.config.w0, t - self.config.t_prov)]

    def _consensus_of(self, prov: EntryLog) -> MapConsensus:
        """The consensus of one provenance store (created on first use)."""
        held = self._consensus.get(id(prov))
        if held is None or held[0] is not prov or held[1].exclusive is not self.consensus_classes:
            # (a new vocabulary starts a new consensus: its latent classes are the vocabulary's)
            vocab = self.vocabulary
            held = self._consensus[id(prov)] = (prov, MapConsensus(self.config.calibration, self.consensus_classes,
                                                                      vocab.asserted_tables(),  # type: ignore[union-attr]
                                                                      vocab.outcome_tables()))  # type: ignore[union-attr]
            held[1].frozen = self._consensus_frozen
        return held[1]

    def _context(self, event: EvidenceEvent, n_prior_claims: int) -> str:
        """The calibration context of a claim with ``n_prior_claims`` earlier claims at its pair."""
        n = self.config.calibration.support_strata
        return stratified_context(event.context, support_stratum(n_prior_claims, n), n)

    def _asserts(self, event: EvidenceEvent, context: str) -> bool:
        """The claim's sign (:func:`~sgbelief.fusion.rules.claim_asserts`) in calibration context ``context``."""
        if self.config.verdict_sign == "raw":
            return claim_asserts(event.confidence)
        lam, _ = self.calibrator_.likelihood_ratio(event.confidence, context, event.predicate)
        return claim_asserts(event.confidence, lam)

    def _geometric_label(self, channel: GeometricChannel | None, node: Any, event: EvidenceEvent) -> str | None:
        """The geometric label at (v, t), asked only when the claimed predicate is verifiable."""
        if channel is None or self.vocabulary is None or event.predicate not in self.vocabulary.outcome_tables():
            return None
        return channel.label(node, event.t)

    def _outcome(self, predicate: str, label: str | None) -> int | None:
        """y of a geometric label for ``predicate`` (1, 0, or None: ∅)."""
        if label is None or self.vocabulary is None:
            return None
        return self.vocabulary.outcome_tables()[predicate].get(label)

    def _observe_label(self, graph: SceneGraphModel, event: EvidenceEvent, node: Any, mass: float, label: str) -> None:
        """``geometric_evidence: label``: the label is one observation (y = 1) of every other
        predicate it asserts at v (:func:`~sgbelief.fusion.rules.label_observations`), committed
        under the claim's event id; once per (v, psi, t)."""
        prov = graph.provenance
        seen = self._label_seen_of(prov)
        ga, gb = verification_increments(1, self.config.w0 * mass)
        for psi in label_observations(self.vocabulary.asserted_by(label), event.predicate, node, event.t, seen):
            prov.append(EntryRecord(node=node, predicate=psi, event_id=event.id, t=event.t, d_alpha=ga, d_beta=gb,
                                    status=EntryStatus.COMMITTED, stance=1, verdict=EntryVerdict.GEOMETRIC,
                                    confidence=event.confidence))

    def _exclude_rivals(self, prov: EntryLog, node: Any, pred: str, event: EvidenceEvent, d_alpha: float) -> None:
        """``exclusive_evidence: rivals``: the committed claim's d_alpha is evidence against each class
        that excludes ``pred`` and already has a belief at v (:func:`~sgbelief.fusion.rules.exclusion_increments`)."""
        ea, eb = exclusion_increments(d_alpha)
        for psi in self.vocabulary.exclusive_with(pred):  # type: ignore[union-attr]
            if (node, psi) in prov:
                prov.append(EntryRecord(node=node, predicate=psi, event_id=event.id, t=event.t, d_alpha=ea,
                                        d_beta=eb, status=EntryStatus.COMMITTED, stance=-1,
                                        verdict=EntryVerdict.EXCLUSION, confidence=event.confidence))

    def _feed_calibration(self, event: EvidenceEvent, verified: list[tuple[int, str]]) -> None:
        """Alg. 1 line 21: the event's verification outcomes join the buffer after all its targets."""
        for y, context in verified:
            self.calibrator_.add(context, event.predicate, event.confidence, y)

    # ---------------------------------------------------------- support
    def _claims_of(self, prov: EntryLog) -> dict[tuple[Any, str], int]:
        """The claim counts of one provenance store (created on first use)."""
        held = self._claims.get(id(prov))
        if held is None or held[0] is not prov:
            held = self._claims[id(prov)] = (prov, {})
        return held[1]

    def _claims_in_log(self, prov: EntryLog, node: Any, predicate: str) -> int:
        """Claims a pair's log already holds (a graph loaded from disk): its distinct event ids,
        a compacted entry counting the entries it folded."""
        n = 0
        ids = set()
        for entry in prov.entries(node, predicate):
            if entry.status is EntryStatus.COMPACTED:
                n += entry.n_folded
            elif entry.verdict is not None and not entry.verdict.is_claim:
                continue  # an observation (geometric, or a rival's claim), not a claim of this pair
            elif entry.event_id not in ids:
                ids.add(entry.event_id)
                n += 1
        return n

    def _label_memory_of(self, prov: EntryLog) -> LabelMemory:
        """The channel's labels of each element, per provenance store (created on first use)."""
        held = self._memory.get(id(prov))
        if held is None or held[0] is not prov:
            held = self._memory[id(prov)] = (prov, LabelMemory(self.config.recall_min_labels))
        return held[1]

    def _label_seen_of(self, prov: EntryLog) -> dict[tuple[Any, str], int]:
        """(v, psi) -> the last time a label observation was recorded there, per provenance store."""
        held = self._label_seen.get(id(prov))
        if held is None or held[0] is not prov:
            held = self._label_seen[id(prov)] = (prov, {})
        return held[1]

    def _claims_so_far(self, prov: EntryLog, node: Any, predicate: str) -> int:
        """Claims applied at (v, phi) so far (counted from the log the first time a pair is seen)."""
        n = self._claims_of(prov).get((node, predicate))
        if n is None:
            n = self._claims_in_log(prov, node, predicate) if (node, predicate) in prov else 0
        return n

    def _next_claim(self, prov: EntryLog, node: Any, predicate: str) -> int:
        """Earlier claims at (v, phi), counting this one for the next."""
        n = self._claims_so_far(prov, node, predicate)
        self._claims_of(prov)[(node, predicate)] = n + 1
        return n

    # ---------------------------------------------------------- reading
    def _pair_slice(self, predicate: str) -> ConformalSlice:
        """The pair-level conformal scores of a predicate (created on first use)."""
        sl = self.pair_conformal_.get(predicate)
        if sl is None:
            sl = self.pair_conformal_[predicate] = ConformalSlice(self.config.alpha, self.config.calibration.buffer_size)
        return sl

    def prediction_set(self, graph: SceneGraphModel, node: Any, predicate: str) -> PredictionSet:
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
        """(Lambda_hat, kappa_hat) the operator would use for this event now (first-claim stratum
        when claims are stratified by support)."""
        n = self.config.calibration.support_strata
        return self.calibrator_.likelihood_ratio(event.confidence, stratified_context(event.context, 0, n), event.predicate)

    def score_readings(self, graph: SceneGraphModel) -> dict[str, ContextReading]:
        """{detector context: how its confidences are read} of the map's consensus under
        ``calibration.consensus.method: agreement_shift`` (:mod:`sgbelief.calibration.agreement_shift`:
        the fitted a_w, whether the scores are read or counted at one level, the rank test's p-value);
        empty before the first fit or under another method."""
        held = self._consensus.get(id(graph.provenance))
        if held is None or held[0] is not graph.provenance:
            return {}
        return held[1].score_readings()

    def refit_consensus(self, graph: SceneGraphModel) -> list[QueueResolution]:
        """Refit the map's consensus now, outside an update, if any claim arrived or any element
        was merged since its last fit. For a mapper's own map-wide passes, whose cost already grows
        with the map: ConceptGraphs' periodic and end-of-run merges change which claims share an
        object after the last claim has arrived, and its labels are read after them. Returns the
        resolutions of the claims it reweighed."""
        held = self._consensus.get(id(graph.provenance))
        if held is None or held[0] is not graph.provenance or not held[1].changed_since_fit():
            return []
        return self._refit_consensus(graph.provenance, held[1], graph.clock)

    def freeze_calibration(self) -> None:
        """Stop learning from new outcomes (e.g. to replay with a fixed calibration)."""
        self.calibrator_.refit_all()
        self.calibrator_.frozen = True
        self._consensus_frozen = True
        for _prov, consensus in self._consensus.values():
            consensus.frozen = True

    def merge_nodes(self, graph: SceneGraphModel, keep: Any, absorb: Any) -> None:
        """Merge ``absorb`` into ``keep``: the graph's merge, plus the per-element state: the claim
        counts (the support stratum of keep's next claim counts absorb's claims too), the label
        observations' frame marks and the consensus' claim table."""
        if keep == absorb:
            return
        prov = graph.provenance
        preds = list(graph.beliefs(absorb)) if absorb in graph else []
        graph.merge_nodes(keep, absorb)
        held = self._claims.get(id(prov))
        if held is not None and held[0] is prov:
            for pred in preds:  # recounted from the merged log at keep's next claim
                held[1].pop((absorb, pred), None)
                held[1].pop((keep, pred), None)
        seen = self._label_seen.get(id(prov))
        if seen is not None and seen[0] is prov:
            for pred in preds:
                t = seen[1].pop((absorb, pred), None)
                if t is not None and t > seen[1].get((keep, pred), -1):
                    seen[1][(keep, pred)] = t
        cons = self._consensus.get(id(prov))
        if cons is not None and cons[0] is prov:
            cons[1].merge_elements(keep, absorb)
        memory = self._memory.get(id(prov))
        if memory is not None and memory[0] is prov:
            memory[1].merge(keep, absorb)

    def retract(self, graph: SceneGraphModel, event_id: str) -> list[str]:
        """Retract an event exactly (cascading within T_cor); the retracted claims no longer count
        toward their pairs' support."""
        retracted = super().retract(graph, event_id)
        self._claims.pop(id(graph.provenance), None)  # recounted from the logs on next use
        held = self._consensus.get(id(graph.provenance))
        if held is not None and held[0] is graph.provenance:
            held[1].drop_events(set(retracted))
        self._label_seen.pop(id(graph.provenance), None)
        return retracted


class CoModulatedOperator(CalibratedOperator):
    """U_comod: U_cal plus the per-event conflict-drop window (§4.2, Alg. 1 lines 4-9).

    A claim the geometric channel contradicts at (v, t) (verdict ⊥, sign-flipped for c < 0.5)
    is refused: logged with status ``refused`` in the disagreement queue Q⊥ and never committed
    (Property 2). A later ⊤ at the same (v, phi) within T_disagree resolves it without
    committing it; otherwise it expires after T_disagree; an explicit confirmation may override.
    With ``geometric_evidence: verdict`` (the default) the decisive geometric label itself is one
    observation of y at (v, phi), committed under the claim's event id; with ``label`` (the
    ConceptGraphs backend's default) it is also one observation (y = 1) of each other predicate the
    label asserts at v, once per (v, psi, t), so a sofa the detector keeps calling ``tv`` is
    observed as a sofa (docs/method.md §3).
    """

    name = "comod"
    check_compatibility = True


class PaperCalibratedOperator(CalibratedOperator):
    """``cal_paper``: U_cal with the paper's own settings (:data:`~sgbelief.fusion.config.PAPER_SETTINGS`)."""

    name = "cal_paper"

    @classmethod
    def _settings(cls, config: OperatorConfig) -> OperatorConfig:
        return paper_variant(config)


class PaperCoModulatedOperator(CoModulatedOperator):
    """``comod_paper``: U_comod with the paper's own settings (refusal only, slice-referenced
    Lambda_hat, no support strata)."""

    name = "comod_paper"

    @classmethod
    def _settings(cls, config: OperatorConfig) -> OperatorConfig:
        return paper_variant(config)

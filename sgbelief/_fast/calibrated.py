"""Private: Algorithm 1 for ``cal`` / ``comod`` fused into one loop (the ``engine="fast"`` path).

This is :meth:`CalibratedOperator._apply_reference
<sgbelief.fusion.operators.calibrated.CalibratedOperator._apply_reference>` with the step
functions of :mod:`sgbelief.fusion.rules` inlined and the per-event set-up hoisted, and with
committed entries sent to the provenance store's journal. It reads private state of the operator,
the store and the graph. Its results (map, provenance, queues, stats, calibration state) equal the
reference path's: ``tests/test_engines.py`` checks that by hypothesis
(``sgbelief.testing.check_fast_matches_reference``). :data:`FUSED_CALIBRATED` is the engine object
``sgbelief.make_operator(..., engine="fast")`` passes to the calibrated operators. Measurements
behind its shape are in docs/performance.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sgbelief._fast.isotonic import IncrementalIsotonic
from sgbelief._fast.nx_nodes import node_table
from sgbelief.calibration.conformal import ConformalSlice
from sgbelief.errors import DuplicateEventError, UnknownNodeError, UnknownPredicateError
from sgbelief.fusion import queues
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import Verdict
from sgbelief.fusion.protocol import COUNTED_RESOLUTIONS as _COUNTED_KINDS
from sgbelief.fusion.protocol import Action, Items, QueueResolution, TargetOutcome, UpdateReport, make_report
from sgbelief.fusion.rules import (
    adjudication,
    consensus_agrees,
    consensus_cell,
    kl_upper_bound,
    revision_kl_exceeds,
    standing,
)
from sgbelief.graph.provenance import EntryRecord, EntryStatus, EntryVerdict

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.operators.calibrated import CalibratedOperator
    from sgbelief.graph.scene_graph import SceneGraphModel

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
# the verdict codes entries record (rules.ENTRY_VERDICT, without hashing an Enum per target)
_E_NO_CLAIM, _E_CORR = EntryVerdict.NO_CLAIM, EntryVerdict.CORROBORATES
_E_CONTRA, _E_GEO = EntryVerdict.CONTRADICTS, EntryVerdict.GEOMETRIC
_E_EXCL = EntryVerdict.EXCLUSION


class FusedCalibratedEngine:
    """The fused loop as an :class:`~sgbelief.fusion.operators.base.OperatorEngine` of the calibrated family."""

    name = "fast"
    #: the calibrator's isotonic store under this engine: the incremental merge (same knots as the reference refit)
    isotonic = IncrementalIsotonic

    def apply(self, op: CalibratedOperator, graph: SceneGraphModel, items: Items,
              reports: list[UpdateReport] | None) -> list[QueueResolution]:
        return apply_fused(op, graph, items, reports)

    def __repr__(self) -> str:
        return "FusedCalibratedEngine()"

    def __reduce__(self) -> str:
        return "FUSED_CALIBRATED"  # copies and pickles are the module's one engine object


#: the engine object of ``engine="fast"`` for cal / comod (and their paper variants)
FUSED_CALIBRATED = FusedCalibratedEngine()


def apply_fused(
    op: CalibratedOperator,
    graph: SceneGraphModel,
    items: Items,
    reports: list[UpdateReport] | None,
) -> list[QueueResolution]:
    """Alg. 1 for each (event, channel) in order; appends one report per event to ``reports``
    (with per-target outcomes) unless it is None. Returns every event's queue resolutions."""
    report = reports is not None
    vocab = graph.vocabulary
    cfg = op.config
    tau_t, tau_rev, w0 = cfg.tau_t, cfg.tau_rev, cfg.w0
    prov = graph.provenance
    append = prov.append
    commit = prov.commit
    pairs_get = prov.pair_index().get
    pending_map = prov.pending_index()  # pairs with entries waiting in Q or Q_bot
    prior_a, prior_b = prov.prior_alpha, prov.prior_beta
    timeline = prov.timeline_view()  # the built entries a compaction scans (live)
    gnx = node_table(graph.nx)  # a membership test without a Python-level __contains__
    has_event = prov.has_event
    create_nodes = graph.create_nodes
    tables = op.vocabulary.outcome_tables() if op.vocabulary is not None else None
    comod = op.check_compatibility
    geo = op.observes_geometry
    weighs_labels = op.weighs_labels
    asserted = op.vocabulary.asserted_tables() if op.observes_label else None  # type: ignore[union-attr]
    label_seen = op._label_seen_of(prov) if asserted is not None else None
    n_strata = cfg.calibration.support_strata
    cal_sign = cfg.verdict_sign == "calibrated"
    top = n_strata - 1
    claims = op._claims_of(prov)
    claims_get = claims.get
    min_refit, refit_growth = cfg.calibration.min_refit, cfg.calibration.refit_growth
    calibrator = op.calibrator_
    consensus_classes = op.consensus_classes
    rivals_of = op.vocabulary.exclusive_with if op.excludes_rivals else None  # type: ignore[union-attr]
    exclusive_with = op.vocabulary.exclusive_with if consensus_classes else None  # type: ignore[union-attr]
    tick = op.tick
    memory = op._label_memory_of(prov) if op.recalls_verdicts else None  # recalled verdicts (fusion.label_memory)
    withdraws, withdraw_judged = op.withdraws_unadjudicated, op._withdraw_judged  # recalled_verdicts: retroactive
    weighs_contested = op.weighs_contested  # contested_labels: weigh or consensus
    weighs_all_contested = weighs_contested and cfg.contested_labels == "weigh"
    out: list[QueueResolution] = []
    n_events = n_targets = n_below = n_committed = n_quarantined = n_refused = 0
    try:
        for event, channel in items:
            pred, c, ctx, eid, t = event.predicate, event.confidence, event.context, event.id, event.t
            if vocab is not None and pred not in vocab:
                raise UnknownPredicateError(pred, vocab)
            # the rest of fusion.operators.base.check_admissible, inlined
            if has_event(eid):
                raise DuplicateEventError(eid)
            if not create_nodes:
                for node in event.targets:
                    if node not in gnx:
                        raise UnknownNodeError(node, eid)
            resolutions = tick(graph, t) if t > graph.clock else []
            cons = op._consensus_of(prov) if pred in consensus_classes else None
            if cons is not None:
                if cons.due():
                    resolutions += op._refit_consensus(prov, cons, t)
                rivals = exclusive_with(pred)  # type: ignore[misc]
            outcome_of = tables.get(pred) if tables is not None else None
            label_of = None
            if channel is not None and outcome_of is not None:
                label_of = channel.labels.get if type(channel) is FrameLabels else channel.label
            frame = label_of is not None and type(channel) is FrameLabels
            recall_of = tables.get(pred) if memory is not None else None  # type: ignore[union-attr]
            raw_pos = c >= 0.5
            e_targets = e_below = e_committed = e_quarantined = e_refused = 0
            # per stratum of this event: (context, Lambda_hat, kappa_hat), computed on first use
            by_stratum: list[tuple[str, float, float] | None] = [None] * n_strata
            new_outcomes: list[tuple[int, str]] = []
            outcomes: list[TargetOutcome] = []
            pair_slice: ConformalSlice | None = None  # this predicate's pair-level scores, fetched once
            for node, mass in event.targets.items():
                e_targets += 1
                if mass <= tau_t and not report:
                    e_below += 1
                    if label_of is not None and (cons is not None or memory is not None):  # the channel still saw v
                        lab = label_of(node) if frame else label_of(node, t)  # type: ignore[call-arg]
                        if lab is not None:
                            if cons is not None:
                                cons.add_label(node, t, lab)
                            if memory is not None and memory.add(node, t, lab) and withdraws:
                                resolutions += withdraw_judged(prov, memory, node, t)
                    continue
                label = None
                if label_of is None:
                    y = None
                else:
                    label = label_of(node) if frame else label_of(node, t)  # type: ignore[call-arg]
                    y = outcome_of.get(label) if label is not None else None  # type: ignore[union-attr]
                    if memory is not None and label is not None and memory.add(node, t, label) and withdraws:
                        resolutions += withdraw_judged(prov, memory, node, t)
                key = (node, pred)
                log = pairs_get(key)
                if n_strata > 1:
                    n_prev = claims_get(key)
                    if n_prev is None:
                        n_prev = 0 if log is None else op._claims_in_log(prov, node, pred)
                    stratum = n_prev if n_prev < top else top
                else:
                    stratum = 0
                cached = by_stratum[stratum]
                if cached is None:
                    sctx = f"{ctx}|s{stratum}" if n_strata > 1 else ctx
                    lam_s, kappa_s = calibrator.likelihood_ratio(c, sctx, pred)
                    cached = by_stratum[stratum] = (sctx, lam_s, kappa_s)
                sctx, lam, kappa = cached
                if mass <= tau_t:  # discarded; its verdict is only reported
                    e_below += 1
                    if cons is not None and label is not None:  # the channel still saw v
                        cons.add_label(node, t, label)
                    if y is None:
                        verdict = _NO_CLAIM
                    else:
                        pos = raw_pos
                        if cal_sign and lam != 1.0:
                            pos = lam > 1.0
                        verdict = _CORR if (y == 1) == pos else _CONTRA
                    outcomes.append(TargetOutcome(node, mass, verdict, _BELOW))
                    continue
                if n_strata > 1:
                    claims[key] = n_prev + 1
                if cons is not None:  # the consensus' calibration for a claim the channel cannot adjudicate
                    if label is not None:
                        cons.add_label(node, t, label)
                    n_same, n_others, max_other = cons.standing_counts(node, pred, rivals)
                    cell = consensus_cell(ctx, stratum, adjudication(label, y), standing(n_same, n_others, max_other),
                                          "whole" if mass >= 0.5 else "part")  # rules.targeting
                    found = cons.likelihood_ratio(c, cell, pred, ctx) if y is None else None
                    cons.add_claim(node, pred, ctx, c, cell, y is not None, eid, mass, t)
                    if found is not None:
                        lam, kappa = found
                claim_pos = (lam > 1.0) if (cal_sign and lam != 1.0) else raw_pos
                if y is None:
                    verdict, code = _NO_CLAIM, _E_NO_CLAIM
                    if recall_of is not None:  # the element's earlier labels (rules.recalled_outcome): only ⊥ acts
                        y_rec = memory.recalled(node, recall_of)  # type: ignore[union-attr]
                        if y_rec is not None and (y_rec == 1) != claim_pos:
                            verdict, code = _CONTRA, _E_CONTRA
                        elif y_rec is None and withdraws and label_of is not None:  # (no channel: nothing to hold)
                            memory.hold(node, pred, recall_of)  # type: ignore[union-attr]
                elif (y == 1) == claim_pos:
                    verdict, code = _CORR, _E_CORR
                else:
                    verdict, code = _CONTRA, _E_CONTRA
                if node not in gnx:
                    graph.ensure_node(node)
                if asserted is not None and label is not None:
                    # rules.label_observations, inlined: the label observes what it asserts (not pred)
                    for psi in asserted.get(label, ()):
                        if psi != pred and label_seen.get((node, psi)) != t:  # type: ignore[union-attr]
                            label_seen[(node, psi)] = t  # type: ignore[index]
                            if timeline:
                                append(EntryRecord(node=node, predicate=psi, event_id=eid, t=t, d_alpha=w0 * mass,
                                                   d_beta=0.0, status=_COMMITTED, stance=1, verdict=_E_GEO,
                                                   confidence=c))
                            else:
                                commit(node, psi, eid, t, w0 * mass, 0.0, 1, _E_GEO, c)
                if log is None:
                    a, b = prior_a, prior_b
                else:
                    a, b = log.alpha, log.beta
                if y is not None:
                    new_outcomes.append((y, sctx))
                    if pair_slice is None:
                        pair_slice = op._pair_slice(pred)
                    pair_slice.add_outcome(a / (a + b), y, min_refit, refit_growth)
                    if geo:  # the decisive label as one observation of y (rules.verification_increments)
                        gw = w0 * mass
                        if weighs_labels and cons is not None:  # its reliability (consensus.label_weights)
                            gw *= cons.verdict_reliability(pred, label, y)
                        ga, gb = (gw, 0.0) if y == 1 else (0.0, gw)
                        if timeline:
                            append(EntryRecord(node=node, predicate=pred, event_id=eid, t=t, d_alpha=ga, d_beta=gb,
                                               status=_COMMITTED, stance=1 if y == 1 else -1, verdict=_E_GEO,
                                               confidence=c))
                        else:
                            commit(node, pred, eid, t, ga, gb, 1 if y == 1 else -1, _E_GEO, c)
                        a += ga
                        b += gb
                w = w0 * kappa * mass
                da = w * lam / (1.0 + lam)
                db = w / (1.0 + lam)
                if comod and verdict is _CONTRA and not (  # contested labels (rules.labels_contested)
                        weighs_contested and y is not None and recall_of is not None
                        and memory.contested(node, recall_of)  # type: ignore[union-attr]
                        and (weighs_all_contested or consensus_agrees(
                            claim_pos, cons.posterior(node, pred) if cons is not None else None))):
                    # Property 2: refused and logged, never committed; geometry's stance opposes the claim
                    stance = -1 if claim_pos else 1
                    had_pending = key in pending_map
                    append(EntryRecord(node=node, predicate=pred, event_id=eid, t=t, d_alpha=da, d_beta=db,
                                       status=_REFUSED, stance=stance, verdict=code, confidence=c))
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
                # the bound settles the revision test without special functions when far below tau_rev
                if kl_upper_bound(a, b, da, db) < tau_rev - 2e-8 * (1.0 + a + b + 2.0 * (da + db)):
                    exceeds = False
                else:
                    exceeds = revision_kl_exceeds(a, b, da, db, tau_rev)
                if exceeds:
                    append(EntryRecord(node=node, predicate=pred, event_id=eid, t=t, d_alpha=da, d_beta=db,
                                       status=_QUARANTINED, stance=stance, verdict=code, confidence=c))
                    e_quarantined += 1
                    if report:
                        outcomes.append(TargetOutcome(node, mass, verdict, _A_QUARANTINED, 0.0, 0.0))
                else:
                    # committed entries go to the journal unless the timeline is live: then the next
                    # refusal or quarantine would materialise the journal anyway
                    if timeline:
                        append(EntryRecord(node=node, predicate=pred, event_id=eid, t=t, d_alpha=da, d_beta=db,
                                           status=_COMMITTED, stance=stance, verdict=code, confidence=c))
                    else:
                        commit(node, pred, eid, t, da, db, stance, code, c)
                    if rivals_of is not None and da > 0.0:
                        # rules.exclusion_increments, inlined: d_alpha against each rival class held at v
                        for psi in rivals_of(pred):
                            if pairs_get((node, psi)) is not None:
                                if timeline:
                                    append(EntryRecord(node=node, predicate=psi, event_id=eid, t=t, d_alpha=0.0,
                                                       d_beta=da, status=_COMMITTED, stance=-1, verdict=_E_EXCL,
                                                       confidence=c))
                                else:
                                    commit(node, psi, eid, t, 0.0, da, -1, _E_EXCL, c)
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
                for y, sctx in new_outcomes:
                    add(sctx, pred, c, y)
            if resolutions:
                op._count([r for r in resolutions if r.kind in _COUNTED_KINDS])
                out += resolutions
            if report:
                reports.append(make_report((eid, t, pred, tuple(outcomes), tuple(resolutions))))  # type: ignore[union-attr]
    finally:
        if n_events:
            op._add_totals(n_events, n_targets, n_below, n_committed, n_quarantined, n_refused)
    return out

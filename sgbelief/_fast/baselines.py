"""Private: the baselines' step fused into one loop (the ``engine="fast"`` path of the BaseOperator family).

This is :meth:`BaseOperator._apply_reference <sgbelief.fusion.operators.base.BaseOperator._apply_reference>`
with the per-call set-up hoisted and the operator's rule applied inline by its kind: a
:class:`~sgbelief.fusion.protocol.LinearRule` is split once per event (d_alpha = T p, d_beta = T q
per target), a :class:`~sgbelief.fusion.protocol.ResetRule`'s target is computed once per event
and the pair's belief read from the store directly; without a rule the operator's ``_increment``
is called per target. It reads private state of the graph and the store. Results (map,
provenance, stats, reports) equal the reference's: ``tests/test_engines.py`` checks that by
hypothesis. :data:`FUSED_BASELINES` is the engine object ``sgbelief.make_operator(...,
engine="fast")`` passes to every :class:`~sgbelief.fusion.operators.base.BaseOperator` outside
the calibrated family.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sgbelief._fast.nx_nodes import node_table
from sgbelief.errors import DuplicateEventError, UnknownNodeError, UnknownPredicateError
from sgbelief.fusion.protocol import (
    Action,
    Items,
    LinearRule,
    QueueResolution,
    ResetRule,
    TargetOutcome,
    UpdateReport,
    make_report,
)

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.operators.base import BaseOperator
    from sgbelief.graph.scene_graph import SceneGraphModel

_BELOW = Action.BELOW_THRESHOLD
_COMMITTED = Action.COMMITTED
_IGNORED = Action.IGNORED


class FusedBaselineEngine:
    """The fused loop as an :class:`~sgbelief.fusion.operators.base.OperatorEngine`."""

    name = "fast"

    def apply(self, op: BaseOperator, graph: SceneGraphModel, items: Items,
              reports: list[UpdateReport] | None) -> list[QueueResolution]:
        return apply_fused(op, graph, items, reports)

    def __repr__(self) -> str:
        return "FusedBaselineEngine()"

    def __reduce__(self) -> str:
        return "FUSED_BASELINES"  # copies and pickles are the module's one engine object


#: the engine object of ``engine="fast"`` for the baselines (and user rules on BaseOperator)
FUSED_BASELINES = FusedBaselineEngine()


def apply_fused(op: BaseOperator, graph: SceneGraphModel, items: Items, reports: list[UpdateReport] | None) -> list[QueueResolution]:
    """The baselines' step for each (event, channel) in order; appends one report per event to
    ``reports`` (with per-target outcomes) unless it is None. Returns the queue resolutions."""
    report = reports is not None
    rule = op.pair_rule
    linear = isinstance(rule, LinearRule)
    reset = isinstance(rule, ResetRule)
    if rule is not None and not (linear or reset):
        raise TypeError(f"{type(op).__name__}.pair_rule must be a LinearRule or a ResetRule, got {type(rule).__name__}")
    split = rule.split if linear else None  # type: ignore[union-attr]
    target = rule.target if reset else None  # type: ignore[union-attr]
    increment = op._increment
    verdict_of = op._verdict
    vocab = graph.vocabulary
    tau_t = op.config.tau_t
    prov = graph.provenance
    commit = prov.commit
    pairs_get = prov.pair_index().get
    prior_a, prior_b = prov.prior_alpha, prov.prior_beta
    gnx = node_table(graph.nx)  # a membership test without a Python-level __contains__
    has_event = prov.has_event
    create_nodes = graph.create_nodes
    tick = op.tick
    out: list[QueueResolution] = []
    n_events = n_targets = n_below = n_committed = 0
    p = q = ta = tb = 0.0
    try:
        for event, channel in items:
            pred, c, t, eid = event.predicate, event.confidence, event.t, event.id
            if vocab is not None and pred not in vocab:
                raise UnknownPredicateError(pred, vocab)
            # the rest of fusion.operators.base.check_admissible, inlined
            if has_event(eid):
                raise DuplicateEventError(eid)
            if not create_nodes:
                for node in event.targets:
                    if node not in gnx:
                        raise UnknownNodeError(node, eid)
            resolutions = tick(graph, t) if t > graph.clock else None
            if linear:
                p, q = split(c)  # type: ignore[misc]
            elif reset:
                ta, tb = target(c, prior_a, prior_b)  # type: ignore[misc]
            label_of = channel.label if (report and channel is not None) else None
            outcomes: list[TargetOutcome] = []
            e_targets = e_below = e_committed = 0
            for node, mass in event.targets.items():
                e_targets += 1
                if report:
                    v = verdict_of(label_of(node, t) if label_of is not None else None, pred, c)
                if mass <= tau_t:
                    e_below += 1
                    if report:
                        outcomes.append(TargetOutcome(node, mass, v, _BELOW))
                    continue
                if node not in gnx:
                    graph.ensure_node(node)
                if linear:
                    da = mass * p
                    db = mass * q
                elif reset:
                    log = pairs_get((node, pred))
                    if log is None:
                        da = ta - prior_a
                        db = tb - prior_b
                    else:
                        da = ta - log.alpha
                        db = tb - log.beta
                else:
                    inc = increment(graph, node, pred, c, mass)
                    if inc is None:
                        if report:
                            outcomes.append(TargetOutcome(node, mass, v, _IGNORED))
                        continue
                    da, db = inc
                commit(node, pred, eid, t, da, db, 1 if da > db else -1 if da < db else 0)
                e_committed += 1
                if report:
                    outcomes.append(TargetOutcome(node, mass, v, _COMMITTED, da, db))
            n_events += 1
            n_targets += e_targets
            n_below += e_below
            n_committed += e_committed
            if resolutions:
                out += resolutions
            if report:
                reports.append(make_report((eid, t, pred, tuple(outcomes), tuple(resolutions) if resolutions else ())))  # type: ignore[union-attr]
    finally:
        if n_events:
            op._add_totals(n_events, n_targets, n_below, n_committed)
    return out

"""Shared machinery of the operators: engines, time ticks, the targeting filter, stats.

An operator applies events through an *engine*: an object with ``apply(op, graph, items, reports)``
(:class:`OperatorEngine`). The reference engine (the default here) runs each family's readable
steps, :meth:`BaseOperator._apply_reference`; the fused loops of :mod:`sgbelief._fast` are injected
by the public wiring, ``sgbelief.make_operator(name, ..., engine="fast")``, and are proven
identical to the reference (``tests/test_engines.py``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from sgbelief.errors import DuplicateEventError, UnknownNodeError, UnknownPredicateError
from sgbelief.fusion import queues
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig, resolve_config
from sgbelief.fusion.operators.compaction import CompactionSchedule
from sgbelief.fusion.protocol import (
    Action,
    Items,
    PairRule,
    QueueResolution,
    TargetOutcome,
    UpdateReport,
    increment_stance,
    make_report,
    new_stats,
)
from sgbelief.fusion.rules import claim_asserts, verdict
from sgbelief.graph.compaction import compact
from sgbelief.graph.retraction import retract

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.channel import GeometricChannel
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.graph.scene_graph import SceneGraphModel

_NO_CLAIM = Verdict.NO_CLAIM


def check_admissible(graph: SceneGraphModel, event: EvidenceEvent) -> None:
    """Reject an event before it changes anything in ``graph``. It is inadmissible when

    - its predicate is outside the graph's vocabulary (:class:`UnknownPredicateError`);
    - the graph's provenance already holds an event with its id (:class:`DuplicateEventError`):
      ids are unique within a graph, so that ``retract(id)`` names one event (checked against
      the events with live entries; ids folded away by compaction are not remembered);
    - a target node is not in the graph and the graph does not ``create_nodes``
      (:class:`UnknownNodeError`: a mistyped id must not make a ghost node).

    Every engine applies this rule to each event before its first change (the fused loops of
    :mod:`sgbelief._fast` inline it).
    """
    vocab = graph.vocabulary
    if vocab is not None and event.predicate not in vocab:
        raise UnknownPredicateError(event.predicate, vocab)
    if graph.provenance.has_event(event.id):
        raise DuplicateEventError(event.id)
    if not graph.create_nodes:
        for node in event.targets:
            if node not in graph.nx:
                raise UnknownNodeError(node, event.id)


class OperatorEngine(Protocol):
    """How an operator applies (event, channel) pairs: the reference steps or a fused loop.

    ``apply(op, graph, items, reports)`` applies ``items`` in order to ``graph`` with ``op``'s
    rule and state, appends one report per event to ``reports`` (per-target outcomes included)
    unless it is None, and returns every event's queue resolutions in order. When an event is
    rejected, the events before it stay applied (``op.stats["events"]`` counts them).
    """

    name: str

    def apply(self, op: Any, graph: SceneGraphModel, items: Items, reports: list[UpdateReport] | None) -> list[QueueResolution]: ...


class ReferenceEngine:
    """The named steps of each operator family (:meth:`BaseOperator._apply_reference`)."""

    name = "reference"

    def apply(self, op: Any, graph: SceneGraphModel, items: Items, reports: list[UpdateReport] | None) -> list[QueueResolution]:
        return op._apply_reference(graph, items, reports)

    def __repr__(self) -> str:
        return "ReferenceEngine()"

    def __reduce__(self) -> str:
        return "REFERENCE"  # copies and pickles are the module's one engine object


REFERENCE = ReferenceEngine()


def resolve_engine(engine: OperatorEngine | str | None) -> OperatorEngine:
    """The engine an operator runs with: None or ``"reference"`` give :data:`REFERENCE`; an engine
    object is taken as given. The fused engines live above this layer, so ``"fast"`` is chosen by
    :func:`sgbelief.make_operator` (which passes the engine object), not here."""
    if engine is None or engine == "reference":
        return REFERENCE
    if isinstance(engine, str):
        raise ValueError(
            f"engine={engine!r}: an operator class takes an engine object or 'reference'; for the fused "
            f"engine use sgbelief.make_operator(name, config, vocabulary, engine='fast')"
        )
    if not callable(getattr(engine, "apply", None)):
        raise TypeError(f"engine must have an apply(op, graph, items, reports) method, got {type(engine).__name__}")
    return engine


class BaseOperator:
    """Common base of the six operators (all implement :class:`~sgbelief.fusion.protocol.FusionOperator`).

    A subclass states its update rule in one of two ways: ``pair_rule``, a
    :data:`~sgbelief.fusion.protocol.PairRule` (the baselines whose increments depend only on the
    claim and the pair's own belief; the batched engine applies the same rule), or, with
    ``pair_rule = None``, :meth:`_increment`, called per target (a rule with its own state, such as
    ``refined``). The calibrated family replaces the whole step (:meth:`_apply_reference`).
    ``vocabulary`` (a SubsumptionTable) is needed for verdicts and calibration outcomes;
    baselines only use it to report the verdict they ignore.
    """

    name = "base"
    #: the operator's pair-local rule, or None (then :meth:`_increment` gives each target's increments)
    pair_rule: PairRule | None = None

    def __init__(
        self,
        config: OperatorConfig | dict[str, Any] | str | None = None,
        vocabulary: SubsumptionTable | None = None,
        *,
        engine: OperatorEngine | str | None = None,
    ) -> None:
        self.config = resolve_config(config)
        self.vocabulary = vocabulary
        self.engine = resolve_engine(engine)
        self.stats: dict[str, int] = new_stats()
        self._schedule_of: tuple[OperatorConfig, CompactionSchedule] | None = None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"

    # ---------------------------------------------------------------- time
    @property
    def schedule(self) -> CompactionSchedule:
        """The compaction schedule of the current config (derived once per config: configs are immutable)."""
        held = self._schedule_of
        cfg = self.config
        if held is None or held[0] is not cfg:
            held = self._schedule_of = (cfg, CompactionSchedule.of(cfg))
        return held[1]

    def tick(self, graph: SceneGraphModel, t: int) -> list[QueueResolution]:
        """Advance to time t: queue timeouts, then a compaction pass (entries older than T_prov are
        folded) on the first tick of each compaction epoch (:class:`CompactionSchedule`)."""
        if t <= graph.clock:
            return []
        graph.clock = t
        out = self._timeouts(graph, t)
        schedule = self.schedule
        if schedule.advance(graph.meta, t):
            self.stats["compacted"] += compact(graph.provenance, schedule.horizon(t))
        return out

    def _timeouts(self, graph: SceneGraphModel, t: int) -> list[QueueResolution]:
        """Queue entries that time out at t (the baselines hold no queue)."""
        return []

    def _add_totals(
        self, n_events: int, n_targets: int, n_below: int, n_committed: int, n_quarantined: int = 0, n_refused: int = 0
    ) -> None:
        """Count events and what happened to their targets."""
        stats = self.stats
        stats["events"] += n_events
        stats["targets"] += n_targets
        if n_below:
            stats["below_tau_t"] += n_below
        if n_committed:
            stats["committed"] += n_committed
        if n_quarantined:
            stats["quarantined"] += n_quarantined
        if n_refused:
            stats["refused"] += n_refused

    def _count(self, resolutions: list[QueueResolution]) -> None:
        stats = self.stats
        for r in resolutions:
            stats[r.kind] = stats.get(r.kind, 0) + 1

    # -------------------------------------------------------------- update
    def update(
        self,
        graph: SceneGraphModel,
        event: EvidenceEvent,
        channel: GeometricChannel | None = None,
        *,
        report: bool = True,
    ) -> UpdateReport:
        """Apply one event. ``report=False`` skips building the per-target outcomes (the returned
        report then has ``targets == ()``); the map, queues, provenance, stats and any calibration
        state are the same either way."""
        if not report:
            res = self.engine.apply(self, graph, ((event, channel),), None)
            return make_report((event.id, event.t, event.predicate, (), tuple(res) if res else ()))
        reports: list[UpdateReport] = []
        self.engine.apply(self, graph, ((event, channel),), reports)
        return reports[0]

    def update_many(self, graph: SceneGraphModel, items: Items) -> list[QueueResolution]:
        """Apply (event, channel) pairs in order, exactly as ``update(graph, event, channel,
        report=False)`` on each would (same map, provenance, queues and stats after every event),
        with the per-call set-up done once. Returns the queue resolutions of all the events, in
        order (what their reports' ``resolutions`` would hold). When an event is rejected, the
        events before it stay applied (``stats["events"]`` counts them) and the error propagates.
        ``update`` and ``update_many`` are one engine call: a subclass changes the rule
        (``pair_rule`` / :meth:`_increment`), not one of the two."""
        return self.engine.apply(self, graph, items, None)

    def _check(self, graph: SceneGraphModel, event: EvidenceEvent) -> None:
        check_admissible(graph, event)

    def _verdict(self, label: str | None, predicate: str, c: float) -> Verdict:
        """compat(phi, label) with the sign rule (:func:`sgbelief.fusion.rules.verdict`)."""
        if label is None or self.vocabulary is None:
            return _NO_CLAIM
        return verdict(self.vocabulary.outcome(predicate, label), claim_asserts(c))

    def _apply_reference(self, graph: SceneGraphModel, items: Items, reports: list[UpdateReport] | None) -> list[QueueResolution]:
        """The baselines' step for each (event, channel) in order: every target with T(v) > tau_T
        gets the rule's increments (:meth:`_target_increments`), committed; the verdict is only
        reported (baselines ignore it)."""
        tau_t = self.config.tau_t
        prov = graph.provenance
        out: list[QueueResolution] = []
        for event, channel in items:
            self._check(graph, event)
            pred, c, t = event.predicate, event.confidence, event.t
            resolutions = self.tick(graph, t) if t > graph.clock else []
            outcomes: list[TargetOutcome] = []
            n_targets = n_below = n_committed = 0
            for node, mass in event.targets.items():
                n_targets += 1
                label = channel.label(node, t) if channel is not None and reports is not None else None
                v = self._verdict(label, pred, c)
                if mass <= tau_t:
                    n_below += 1
                    outcomes.append(TargetOutcome(node, mass, v, Action.BELOW_THRESHOLD))
                    continue
                graph.ensure_node(node)
                inc = self._target_increments(graph, node, pred, c, mass)
                if inc is None:
                    outcomes.append(TargetOutcome(node, mass, v, Action.IGNORED))
                    continue
                da, db = inc
                prov.commit(node, pred, event.id, t, da, db, increment_stance(da, db))
                n_committed += 1
                outcomes.append(TargetOutcome(node, mass, v, Action.COMMITTED, da, db))
            self._add_totals(1, n_targets, n_below, n_committed)
            out += resolutions
            if reports is not None:
                reports.append(make_report((event.id, t, pred, tuple(outcomes), tuple(resolutions))))
        return out

    def _target_increments(
        self, graph: SceneGraphModel, node: Any, predicate: str, c: float, mass: float
    ) -> tuple[float, float] | None:
        """The increments of one target with T(v) > tau_T: the pair rule's, else :meth:`_increment`'s."""
        rule = self.pair_rule
        if rule is None:
            return self._increment(graph, node, predicate, c, mass)
        prov = graph.provenance
        return rule.increments(c, mass, prov.alpha_beta(node, predicate), (prov.prior_alpha, prov.prior_beta))

    def _increment(self, graph: SceneGraphModel, node: Any, predicate: str, c: float, mass: float) -> tuple[float, float] | None:
        """The increments (d_alpha, d_beta) of one target, or None when the rule ignores the claim
        (the rule of an operator without ``pair_rule``)."""
        raise NotImplementedError(f"{type(self).__name__} defines neither a pair_rule nor _increment")

    # ------------------------------------------------------------ reading
    def probability(self, graph: SceneGraphModel, node: Any, predicate: str) -> float:
        """Posterior mean of B(v, phi)."""
        return graph.probability(node, predicate)

    # ------------------------------------------------------- user actions
    def retract(self, graph: SceneGraphModel, event_id: str) -> list[str]:
        """Retract an event exactly (cascading to corroborating events within T_cor)."""
        return retract(graph.provenance, event_id, cascade_window=self.config.t_cor)

    def merge_nodes(self, graph: SceneGraphModel, keep: Any, absorb: Any) -> None:
        """Merge element ``absorb`` into ``keep`` (``graph.merge_nodes``: provenance and beliefs
        move, every entry counted once). The baselines keep nothing per element besides the graph."""
        graph.merge_nodes(keep, absorb)

    def confirm(self, graph: SceneGraphModel, event_id: str, *, accept: bool = True) -> list[QueueResolution]:
        """Explicit operator confirmation of a queued (quarantined or refused) event."""
        out = queues.confirm(graph.provenance, event_id, accept=accept, t=max(graph.clock, 0))
        self._count(out)
        return out

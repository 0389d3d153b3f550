"""Shared machinery of the operators: time ticks, compaction schedule, targeting filter, stats."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from sgbelief.errors import UnknownPredicateError
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig, resolve_config
from sgbelief.fusion.protocol import Action, QueueResolution, TargetOutcome, UpdateReport, make_report
from sgbelief.fusion import queues
from sgbelief.fusion.rules import verdict

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.channel import GeometricChannel
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.graph.scene_graph import SceneGraph

_NO_CLAIM = Verdict.NO_CLAIM


class BaseOperator:
    """Common base of the six operators (all implement :class:`~sgbelief.fusion.protocol.FusionOperator`).

    Subclasses implement :meth:`_increment` (baselines) or override :meth:`update`.
    ``vocabulary`` (a SubsumptionTable) is needed for verdicts and calibration outcomes;
    baselines only use it to report the verdict they ignore.
    """

    name = "base"

    def __init__(
        self,
        config: OperatorConfig | dict[str, Any] | str | None = None,
        vocabulary: SubsumptionTable | None = None,
    ) -> None:
        self.config = resolve_config(config)
        self.vocabulary = vocabulary
        self.stats: dict[str, int] = {
            "events": 0,
            "targets": 0,
            "committed": 0,
            "refused": 0,
            "quarantined": 0,
            "released": 0,
            "corroborated": 0,
            "discarded": 0,
            "resolved": 0,
            "expired": 0,
            "below_tau_t": 0,
            "compacted": 0,
        }
        cls = type(self)
        #: the lean path may apply _split directly (the subclass did not override _increment)
        self._linear = cls._increment is BaseOperator._increment and cls._split is not BaseOperator._split
        self._has_timeouts = cls._timeouts is not BaseOperator._timeouts
        self._tick_config: OperatorConfig | None = None
        self._interval = 0

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"

    # ---------------------------------------------------------------- time
    def tick(self, graph: SceneGraph, t: int) -> list[QueueResolution]:
        """Advance to time t: queue timeouts, then a compaction pass (entries older than T_prov are
        folded) every ``compaction_interval`` steps (T_prov by default; Alg. 1, last lines)."""
        if t <= graph.clock:
            return []
        graph.clock = t
        cfg = self.config
        out = self._timeouts(graph, t) if self._has_timeouts else []
        if cfg is not self._tick_config:  # derived once per config (configs are immutable)
            self._tick_config = cfg
            self._interval = cfg.compaction_interval
        interval = self._interval
        epoch = t // interval
        meta = graph.meta
        last = meta.get("compaction_epoch", 0)
        saved_interval = meta.get("compaction_interval", cfg.t_prov)
        if saved_interval != interval:  # the graph was compacted under another interval
            last = last * saved_interval // interval
        if epoch > last:
            meta["compaction_epoch"] = epoch
            if interval != cfg.t_prov:
                meta["compaction_interval"] = interval
            elif "compaction_interval" in meta:
                del meta["compaction_interval"]
            self.stats["compacted"] += graph.provenance.compact(t - cfg.t_prov)
        return out

    def _timeouts(self, graph: SceneGraph, t: int) -> list[QueueResolution]:
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
    def _check(self, graph: SceneGraph, event: EvidenceEvent) -> None:
        vocab = graph.vocabulary
        if vocab is not None and event.predicate not in vocab:
            raise UnknownPredicateError(event.predicate, vocab)

    def _verdict(self, label: str | None, predicate: str, c: float) -> Verdict:
        """compat(phi, label) with the sign rule (:func:`sgbelief.fusion.rules.verdict`)."""
        if label is None or self.vocabulary is None:
            return _NO_CLAIM
        return verdict(self.vocabulary.outcome(predicate, label), c >= 0.5)

    def update(
        self,
        graph: SceneGraph,
        event: EvidenceEvent,
        channel: GeometricChannel | None = None,
        *,
        report: bool = True,
    ) -> UpdateReport:
        """Apply one event with the subclass's increment rule (baselines ignore the verdict).

        ``report=False`` skips building the per-target outcomes (the returned report has
        ``targets == ()``); the map, provenance and stats are the same either way.
        """
        if not report:
            res = self._update_lean(graph, ((event, channel),))
            return make_report((event.id, event.t, event.predicate, (), tuple(res) if res else ()))
        pred, c, t, eid = event.predicate, event.confidence, event.t, event.id
        vocab = graph.vocabulary
        if vocab is not None and pred not in vocab:
            raise UnknownPredicateError(pred, vocab)
        resolutions = self.tick(graph, t) if t > graph.clock else []
        tau_t = self.config.tau_t
        commit = graph.provenance.commit
        gnx = graph.nx._node  # the node dict: a membership test without a Python-level __contains__
        increment = self._increment
        label_of = channel.label if channel is not None else None
        verdict_of = self._verdict
        outcomes = []
        n_targets = n_below = n_committed = 0
        for node, mass in event.targets.items():
            n_targets += 1
            label = label_of(node, t) if label_of is not None else None
            v = verdict_of(label, pred, c)
            if mass <= tau_t:
                n_below += 1
                outcomes.append(TargetOutcome(node, mass, v, Action.BELOW_THRESHOLD))
                continue
            if node not in gnx:
                graph.ensure_node(node)
            inc = increment(graph, node, pred, c, mass)
            if inc is None:
                outcomes.append(TargetOutcome(node, mass, v, Action.IGNORED))
                continue
            da, db = inc
            commit(node, pred, eid, t, da, db, 1 if da > db else -1 if da < db else 0)
            n_committed += 1
            outcomes.append(TargetOutcome(node, mass, v, Action.COMMITTED, da, db))
        self._add_totals(1, n_targets, n_below, n_committed)
        return make_report((eid, t, pred, tuple(outcomes), tuple(resolutions)))

    def update_many(
        self, graph: SceneGraph, items: Iterable[tuple[EvidenceEvent, GeometricChannel | None]]
    ) -> list[QueueResolution]:
        """Apply (event, channel) pairs in order, exactly as ``update(graph, event, channel,
        report=False)`` on each would (same map, provenance, queues and stats after every event),
        with the per-call set-up done once. Returns the queue resolutions of all the events, in
        order (what their reports' ``resolutions`` would hold). When an event is rejected, the
        events before it stay applied (``stats["events"]`` counts them) and the error propagates.

        Baselines ignore the channel: the verdict only feeds per-target reports. A subclass that
        overrides ``update`` (and not ``update_many``) gets its own ``update`` on each event.
        """
        if type(self).update is not BaseOperator.update:
            return self._update_each(graph, items)
        return self._update_lean(graph, items)

    def _update_each(
        self, graph: SceneGraph, items: Iterable[tuple[EvidenceEvent, GeometricChannel | None]]
    ) -> list[QueueResolution]:
        """``update_many`` through ``self.update`` (protocol signature) on each event."""
        out: list[QueueResolution] = []
        for event, channel in items:
            res = self.update(graph, event, channel).resolutions
            if res:
                out += res
        return out

    def _update_lean(
        self, graph: SceneGraph, items: Iterable[tuple[EvidenceEvent, GeometricChannel | None]]
    ) -> list[QueueResolution]:
        """The report-free update of each event, with the subclass's increment rule."""
        vocab = graph.vocabulary
        tau_t = self.config.tau_t
        commit = graph.provenance.commit
        gnx = graph.nx._node  # the node dict: a membership test without a Python-level __contains__
        linear = self._linear  # a linear rule: d_alpha = T p, d_beta = T q for every target
        split_of = self._split
        increment = self._increment
        tick = self.tick
        out: list[QueueResolution] = []
        n_events = n_targets = n_below = n_committed = 0
        try:
            for event, _channel in items:
                pred, c, t, eid = event.predicate, event.confidence, event.t, event.id
                if vocab is not None and pred not in vocab:
                    raise UnknownPredicateError(pred, vocab)
                if t > graph.clock:
                    res = tick(graph, t)
                    if res:
                        out += res
                split = split_of(c) if linear else None  # None: this claim takes the general rule
                lin = split is not None
                if lin:
                    p, q = split  # type: ignore[misc]
                e_targets = e_below = e_committed = 0
                for node, mass in event.targets.items():
                    e_targets += 1
                    if mass <= tau_t:
                        e_below += 1
                        continue
                    if node not in gnx:
                        graph.ensure_node(node)
                    if lin:
                        da = mass * p
                        db = mass * q
                    else:
                        inc = increment(graph, node, pred, c, mass)
                        if inc is None:
                            continue
                        da, db = inc
                    commit(node, pred, eid, t, da, db, 1 if da > db else -1 if da < db else 0)
                    e_committed += 1
                n_events += 1
                n_targets += e_targets
                n_below += e_below
                n_committed += e_committed
        finally:
            if n_events:
                self._add_totals(n_events, n_targets, n_below, n_committed)
        return out

    def _increment(self, graph: SceneGraph, node: Any, predicate: str, c: float, mass: float) -> tuple[float, float] | None:
        """The increments (d_alpha, d_beta) of one target, or None when the rule ignores the claim."""
        split = self._split(c)
        if split is None:
            raise NotImplementedError(f"{type(self).__name__} defines neither _increment nor _split")
        return mass * split[0], mass * split[1]

    def _split(self, c: float) -> tuple[float, float] | None:
        """(p, q) when the rule is linear in the targeting mass (d_alpha = T p, d_beta = T q for
        every target, whatever the belief), else None. Computed once per event on the lean path."""
        return None

    # ------------------------------------------------------------ reading
    def probability(self, graph: SceneGraph, node: Any, predicate: str) -> float:
        """Posterior mean of B(v, phi)."""
        return graph.probability(node, predicate)

    # ------------------------------------------------------- user actions
    def retract(self, graph: SceneGraph, event_id: str) -> list[str]:
        """Retract an event exactly (cascading to corroborating events within T_cor)."""
        return graph.provenance.retract(event_id, cascade_window=self.config.t_cor)

    def confirm(self, graph: SceneGraph, event_id: str, *, accept: bool = True) -> list[QueueResolution]:
        """Explicit operator confirmation of a queued (quarantined or refused) event."""
        out = queues.confirm(graph.provenance, event_id, accept=accept, t=max(graph.clock, 0))
        self._count(out)
        return out

"""The FusionOperator protocol every operator implements: its report types, its counters and the
pair-local rules an operator may declare (what the batched engine applies in waves)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from enum import Enum
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, runtime_checkable

from sgbelief.fusion.compatibility import Verdict

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.channel import GeometricChannel
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.graph.scene_graph import SceneGraphModel


class Action(str, Enum):
    """What an operator did with one targeted element of an event."""

    COMMITTED = "committed"  #: increments applied to the belief
    REFUSED = "refused"  #: ⊥: not committed, routed to the disagreement queue (comod only)
    QUARANTINED = "quarantined"  #: revision: held in the quarantine Q
    BELOW_THRESHOLD = "below_tau_t"  #: targeting mass <= tau_T: discarded
    IGNORED = "ignored"  #: the operator's rule does not use this event (e.g. overwrite on low c)


class TargetOutcome(NamedTuple):
    """What happened to one targeted element: its mass, the geometric verdict, the action and the
    increments committed (0 unless committed)."""

    node: Any
    mass: float
    verdict: Verdict
    action: Action
    d_alpha: float = 0.0
    d_beta: float = 0.0


class QueueResolution(NamedTuple):
    """A queued event leaving its queue: kind in corroborated / released / discarded /
    resolved / expired / confirmed / dismissed; or, outside the queues, a belief that changed
    without an event targeting it: withdrawn / reinstated (recalled verdicts) and reweighed (a
    silent claim weighed again after a consensus refit, ``sgbelief.fusion.reweigh``)."""

    event_id: str | None
    node: Any
    predicate: str
    kind: str
    t: int


class UpdateReport(NamedTuple):
    """Per targeted node: the verdict, the action and the increments; plus queue resolutions.

    The report types are immutable named tuples: one is built per event (and one per target when
    reports are on), and a tuple is several times cheaper to build than a frozen dataclass.
    """

    event_id: str
    t: int
    predicate: str
    targets: tuple[TargetOutcome, ...]
    resolutions: tuple[QueueResolution, ...] = ()

    def actions(self) -> dict[Any, Action]:
        return {o.node: o.action for o in self.targets}


#: ``make_report((event_id, t, predicate, targets, resolutions))``: an UpdateReport built without
#: NamedTuple's Python-level ``__new__`` (about half the cost; the operators build one per event)
make_report: Callable[[tuple[str, int, str, tuple[TargetOutcome, ...], tuple[QueueResolution, ...]]], UpdateReport]
make_report = partial(tuple.__new__, UpdateReport)  # type: ignore[assignment]

#: (event, geometric channel) pairs, in stream order: what ``update_many`` applies
Items = Iterable[tuple["EvidenceEvent", "GeometricChannel | None"]]

#: the counters every operator's ``stats`` holds (queue resolutions may add ``confirmed`` and
#: ``dismissed``): events applied, targets seen, what happened to them, queue exits, entries compacted
STAT_KEYS: tuple[str, ...] = (
    "events", "targets", "committed", "refused", "quarantined", "released", "corroborated", "discarded",
    "resolved", "expired", "withdrawn", "reinstated", "below_tau_t", "compacted",
)


#: the resolution kinds an operator's ``stats`` counts as they happen (the queues' timeouts count
#: themselves); ``reweighed`` (entries weighed again after a consensus refit) is outside STAT_KEYS
COUNTED_RESOLUTIONS: frozenset[str] = frozenset({"corroborated", "discarded", "resolved", "withdrawn", "reinstated",
                                                 "reweighed"})


def new_stats() -> dict[str, int]:
    """Every counter of :data:`STAT_KEYS` at zero."""
    return dict.fromkeys(STAT_KEYS, 0)


def increment_stance(d_alpha: Any, d_beta: Any) -> Any:
    """The stance of committed increments: +1 when they favour phi (d_alpha > d_beta), -1 when they
    favour not-phi, 0 when neutral. Floats give an int, float arrays an int array."""
    return (d_alpha > d_beta) * 1 - (d_alpha < d_beta) * 1


# ----------------------------------------------------------------------------- pair-local rules
class LinearRule(ABC):
    """A rule linear in the targeting mass, whatever the belief (Eq. 3 with w = T(v))::

        (p, q) = split(c),   d_alpha = T(v) p,   d_beta = T(v) q

    (p = Lambda / (1 + Lambda), q = 1 / (1 + Lambda) for a likelihood ratio Lambda of the claim).
    ``split`` is written with arithmetic only, so it takes a float or a float array alike.
    """

    @abstractmethod
    def split(self, c: Any) -> tuple[Any, Any]:
        """(p, q) of a claim of confidence ``c`` (a float, or an array of them)."""

    def increments(self, c: float, mass: float, belief: tuple[float, float], prior: tuple[float, float]) -> tuple[float, float]:
        """(d_alpha, d_beta) of one target (the belief and the prior are not used)."""
        p, q = self.split(c)
        return mass * p, mass * q


class ResetRule(ABC):
    """A rule that sets the belief to a target chosen by the claim, recorded as the increment
    target - current so that Eq. 4 holds::

        (alpha*, beta*) = target(c, alpha_0, beta_0),   (d_alpha, d_beta) = (alpha* - alpha, beta* - beta)

    ``target`` is written with arithmetic only, so it takes a float or a float array alike.
    """

    @abstractmethod
    def target(self, c: Any, prior_alpha: float, prior_beta: float) -> tuple[Any, Any]:
        """(alpha*, beta*) after a claim of confidence ``c`` (a float, or an array of them)."""

    def increments(self, c: float, mass: float, belief: tuple[float, float], prior: tuple[float, float]) -> tuple[float, float]:
        """(d_alpha, d_beta) of one target whose current belief is ``belief``."""
        ta, tb = self.target(c, *prior)
        return ta - belief[0], tb - belief[1]


#: a pair-local rule: the increments of a claim at (v, phi) depend only on the claim, the target's
#: mass and that pair's own belief, so claims at different pairs can be applied in any interleaving
PairRule = LinearRule | ResetRule


# ----------------------------------------------------------------------------- the protocol
@runtime_checkable
class FusionOperator(Protocol):
    """An update operator U : M x E -> M (Def. 3) with time ticks for its queues.

    Every code path (``sgbelief replay`` / ``bench``, the ConceptGraphs backend, the batched
    engine) uses an operator through these members only, so an operator written against this
    protocol behaves as a :class:`~sgbelief.fusion.operators.base.BaseOperator` subclass would;
    :func:`sgbelief.testing.check_fusion_operator` checks the whole contract.

    - ``name``: the operator's name (reports, the CLI, result tables);
    - ``config``: its :class:`~sgbelief.fusion.config.OperatorConfig` (tau_T, horizons, ...);
    - ``stats``: its counters, every key of :data:`STAT_KEYS`; ``stats["events"]`` counts the
      events applied (a caller locates a rejected event with it);
    - ``pair_rule``: the operator's :data:`PairRule` when its update of every event is exactly the
      streaming engine's with that rule (targets with T(v) <= tau_T discarded, the compaction
      schedule of ``config``, nothing else in its state), else None. A rule lets the batched engine
      apply a stream in waves (:func:`sgbelief._fast.batched.batched_replay`), with the same result;
    - ``update(graph, event, channel, *, report=True)`` applies one event (it first advances time
      to ``event.t``) and reports what happened to each targeted element; ``report=False`` leaves
      the report's ``targets`` empty, the state is the same;
    - ``update_many(graph, items)`` applies (event, channel) pairs in order exactly as
      ``update(..., report=False)`` on each would, and returns their queue resolutions in order;
      when an event is rejected, the events before it stay applied and the error propagates;
    - ``tick(graph, t)`` advances time without evidence (queue timeouts, compaction);
    - ``probability(graph, node, predicate)`` is the operator's probability that the predicate holds;
    - ``retract(graph, event_id)`` removes an event's entries exactly and returns the retracted ids;
    - ``merge_nodes(graph, keep, absorb)`` merges element ``absorb`` into ``keep``
      (``graph.merge_nodes``) and moves whatever the operator keeps per element with it (claim
      counts, the consensus' claim table), so later claims at ``keep`` see the merged history.
    """

    name: str
    config: OperatorConfig
    stats: dict[str, int]
    pair_rule: PairRule | None

    def update(
        self, graph: SceneGraphModel, event: EvidenceEvent, channel: GeometricChannel | None = None, *, report: bool = True
    ) -> UpdateReport: ...

    def update_many(self, graph: SceneGraphModel, items: Items) -> list[QueueResolution]: ...

    def tick(self, graph: SceneGraphModel, t: int) -> list[QueueResolution]: ...

    def probability(self, graph: SceneGraphModel, node: Any, predicate: str) -> float: ...

    def retract(self, graph: SceneGraphModel, event_id: str) -> list[str]: ...

    def merge_nodes(self, graph: SceneGraphModel, keep: Any, absorb: Any) -> None: ...

"""The FusionOperator protocol every operator implements, and its report types."""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, runtime_checkable

from sgbelief.fusion.compatibility import Verdict

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.fusion.channel import GeometricChannel
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.graph.scene_graph import SceneGraph


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
    resolved / expired / confirmed / dismissed."""

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


@runtime_checkable
class FusionOperator(Protocol):
    """An update operator U : M x E -> M (Def. 3) with time ticks for its queues.

    - ``update(graph, event, channel)`` applies one evidence event and reports what happened
      to each targeted element (it first advances time to ``event.t``);
    - ``tick(graph, t)`` advances time without evidence (queue timeouts, compaction);
    - ``probability(graph, node, predicate)`` is the operator's probability that the predicate holds.
    """

    name: str

    def update(
        self, graph: SceneGraph, event: EvidenceEvent, channel: GeometricChannel | None = None
    ) -> UpdateReport: ...

    def tick(self, graph: SceneGraph, t: int) -> list[QueueResolution]: ...

    def probability(self, graph: SceneGraph, node: Any, predicate: str) -> float: ...

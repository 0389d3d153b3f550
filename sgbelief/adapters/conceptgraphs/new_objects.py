"""A map object seen for the first time: its node, its geometry and its own claims.

Most detections of a ConceptGraphs frame match no map object and become new objects (77-83 % at
10 detections a frame in the harness of ``benchmarks/bench_cg_harness.py``), so this is the
adapter's most frequent path. :class:`NewObjectRegistration` is the half of
:class:`~.map_beliefs.MapBeliefs` that takes it (which inherits it, as it inherits the reading half
from :class:`~.labels_out.LabelReader`): a new node id from the identity map, a graph node holding
the object's centroid and box, and the object's own claims routed to that node alone with mass 1.

:meth:`NewObjectRegistration._route_own` is a private fast path of
:meth:`MapBeliefs.route_detection` for the one target ``{node: 1.0}`` (no targeting distribution to
filter, no loop over targets); ``tests/test_cg_new_objects.py`` holds it to the general routing
with hypothesis (the same events, in the same order, and the same per-node bookkeeping).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from sgbelief.adapters.conceptgraphs.claims import Claim, EventChannel
from sgbelief.adapters.conceptgraphs.geometry import geometry_summary
from sgbelief.errors import InvalidEventError
from sgbelief.fusion.events import EvidenceEvent, next_event_id

__all__ = ["NewObjectRegistration"]


class NewObjectRegistration:
    """Registration of a map object on first sight (see the module doc). The attributes it reads
    are set by :class:`~.map_beliefs.MapBeliefs`."""

    # attributes MapBeliefs provides
    graph: Any
    identity: Any
    tau_t: float
    label_key: str
    context: str
    table: Any
    confidence_map: Any
    channel: Any
    channel_fn: Any
    labels: Any
    fresh_geometry: set[int]
    _null: Any
    _names_per_node: dict[Any, Counter[tuple[int | None, str]]]
    _preds_per_node: dict[Any, set[str]]
    _detections_per_node: Counter[Any]
    _changed: set[Any]
    _pending: list[tuple[Any, Any, str]]
    _has_channel: bool
    _routed_detections: int
    _batch_open: bool
    _skip_reports: bool
    keep_reports: bool

    def route_detection(self, det: dict, targets: Any) -> int:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def flush(self) -> None:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def claims_of(self, obj: Any) -> list[Claim]:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def _predicate(self, class_name: str) -> str | None:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def _register_new(self, obj: dict, fp: Any) -> Any:
        """A new node for ``obj`` (``fp``: the fingerprint :meth:`IdentityMap.find` computed), its
        geometry summary in the graph, and ``obj``'s own claims routed to it with mass 1."""
        node = self.identity.register(obj, fp)
        graph = self.graph
        if node not in graph:
            centroid, bbox = geometry_summary(obj)
            graph.add_node(node, centroid=centroid, bbox=bbox, source="conceptgraphs")
            self.fresh_geometry.add(id(obj))
        if self.tau_t < 1.0:
            self._route_own(obj, node)
        else:  # the mass of 1 is dropped (tau_T >= 1): the general routing
            self.route_detection(obj, {node: 1.0})
        return node

    def _route_own(self, det: dict, node: Any) -> int:
        """``route_detection(det, {node: 1.0})`` when tau_T < 1 (the mass is kept): every claim of
        ``det`` an event on ``node`` alone. Returns the number of events queued."""
        geo = det.pop(self.label_key, None) if isinstance(det, dict) else None
        targets = {node: 1.0}
        claims = self.claims_of(det)
        geo_labels = geo if isinstance(geo, list) else None
        names_per_node, preds_per_node = self._names_per_node, self._preds_per_node
        counts = names_per_node.get(node)
        n_events = 0
        for k, claim in enumerate(claims):
            name = claim.class_name
            pred = self._predicate(name)
            key = (claim.class_id, name)
            if counts is None:
                counts = names_per_node[node] = Counter()
            counts[key] = counts.get(key, 0) + 1
            if pred is None:
                continue
            preds = preds_per_node.get(node)
            if preds is None:
                preds_per_node[node] = {pred}
            else:
                preds.add(pred)
            self._queue_claim(det, k, claim, pred, targets, geo, geo_labels)
            n_events += 1
        per_node = self._detections_per_node
        per_node[node] = per_node.get(node, 0) + len(claims)
        self._changed.add(node)
        self._routed_detections += len(claims)
        if not (self._batch_open and self._skip_reports and not self.keep_reports):  # not self._batched
            self.flush()
        return n_events

    def _queue_claim(self, det: dict, k: int, claim: Claim, pred: str, targets: dict[Any, float], geo: Any,
                     geo_labels: list[Any] | None) -> None:
        """Queue claim ``k`` of ``det`` (predicate ``pred``) as one event on ``targets``, with its
        channel: the per-claim half that :meth:`MapBeliefs.route_detection` and :meth:`_route_own`
        share. Raises InvalidEventError for a negative time or a confidence outside [0, 1]."""
        conf = claim.confidence
        if self.confidence_map is not None:
            conf = _checked_confidence(self.confidence_map(conf))
        label = geo if geo_labels is None else (geo_labels[k] if k < len(geo_labels) else None)
        if label is not None:
            self._has_channel = True
        table = self.table
        if table is not None and pred not in table:
            channel: Any = self._null  # no verification possible for this predicate
        else:
            channel = EventChannel(label, det, self.channel, self.channel_fn, k, self.labels.resolve)
        if claim.t < 0:
            raise InvalidEventError("t", f"must be a non-negative integer time step, got {claim.t!r}")
        if not 0.0 <= conf <= 1.0:  # NaN
            raise InvalidEventError("confidence", f"must be finite and in [0, 1], got {conf!r}")
        self._pending.append((EvidenceEvent.trusted(targets, pred, conf, self.context, claim.t, next_event_id()),
                              channel, claim.class_name))


def _checked_confidence(value: Any) -> float:
    """A ``confidence_map`` result as an event confidence: a finite number in [0, 1]."""
    c = float(value)
    if not 0.0 <= c <= 1.0:  # also rejects NaN
        raise InvalidEventError("confidence", f"confidence_map gave {value!r}: must be finite and in [0, 1]")
    return c

"""The belief bookkeeping behind the ConceptGraphs backend: map objects to nodes, detections to
evidence events, beliefs to labels. Nothing here knows ConceptGraphs' function signatures or how
they are swapped in (:mod:`.generation_main`, :mod:`.generation_ali_dev`, :mod:`.patching`)."""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from sgbelief.adapters.conceptgraphs.channel_labels import LabelResolver
from sgbelief.adapters.conceptgraphs.claims import (
    DEFAULT_LABEL_KEY,
    Claim,
    DetectionLabelFn,
    read_claims,
)
from sgbelief.adapters.conceptgraphs.geometry import geometry_summary
from sgbelief.adapters.conceptgraphs.identity import IdentityMap
from sgbelief.adapters.conceptgraphs.labels_out import LabelReader
from sgbelief.adapters.conceptgraphs.new_objects import NewObjectRegistration
from sgbelief.adapters.conceptgraphs.summary import (
    LOW_CONFIDENCE_MIN_CLAIMS,
    BackendSummary,
    ClaimCounts,
    low_confidence_note,
)
from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary
from sgbelief.errors import LowConfidenceWarning, warn_at_caller
from sgbelief.fusion.operators.calibrated import CalibratedOperator

__all__ = ["DEFAULT_LABEL_KEY", "BackendSummary", "Claim", "DetectionLabelFn", "MapBeliefs"]

class MapBeliefs(NewObjectRegistration, LabelReader):
    """The belief side of a ConceptGraphs map: which graph node each map object is, the evidence its
    detections routed there, and the label the beliefs give it.

    It takes resolved parts (an operator instance, a :class:`ClassVocabulary`, a scene graph);
    :class:`~sgbelief.adapters.conceptgraphs.backend.ConceptGraphsBackend` builds them from names and
    adds the installation into ConceptGraphs. The per-generation replacement functions
    (:mod:`.generation_main`, :mod:`.generation_ali_dev`) call the methods below.

    Args:
        operator: a FusionOperator instance.
        vocabulary: the :class:`ClassVocabulary` mapping class names to predicates; None: not known
            yet (:meth:`set_vocabulary` gives it before the first claim, else :meth:`vocabulary_needed`).
        graph: the scene graph the beliefs live in.
        seed_from_graph: the graph may already hold evidence the backend did not route (a graph
            handed in by the caller): a node's pre-existing beliefs are read once, on first use.
        context: the context tag kappa (detector / VLM and prompt version) of every event.
        channel: optional geometric channel: a GeometricChannel (``label(node, t)``), or a callable
            ``fn(detection, node, t) -> str | None``.  A detection's own ``label_key`` entry wins.
        label_key: detection-dict key holding a per-detection geometric label (popped from the dict
            before ConceptGraphs' merge sees it, since the original merges reject unknown keys).
        unknown_label / unknown_class_id: label written when no predicate commits (``abstain``,
            the default) or the claimed classes tie.
        abstain: write ``unknown_label`` whenever no predicate commits (default True); False writes
            the claimed class of highest probability instead.
        tau / tau_t: commit threshold and targeting-mass threshold (default: the operator config).
        on_filter: ``"mark"`` (node kept with ``cg_filtered=True``) or ``"remove"``.
        confidence_map: optional map of the detector's raw confidence before it enters an event.
        class_names: class names by class id (learned from the detections when absent).
        label_rule: the class written when the committed predicate covers several class names
            (``is_table_or_desk``: table, desk): ``"most_frequent"`` (default: the name detected most
            often on this object, ties to the first seen), ``"first"`` (the first name detected), or a
            mapping predicate -> class name (e.g. ``{"is_table_or_desk": "table"}``; predicates not in
            it fall back to most frequent). A mapped name that is a known class id keeps that id.
        targeting: ``"merge"`` (default) or ``"spread"``, where a matched detection's claims go
            (:meth:`targets_for`).
    """

    def __init__(
        self,
        operator: Any,
        vocabulary: ClassVocabulary | None,
        graph: Any,
        *,
        seed_from_graph: bool = False,
        context: str = "conceptgraphs",
        channel: Any = None,
        label_key: str = DEFAULT_LABEL_KEY,
        unknown_label: str = "unknown",
        unknown_class_id: int = -1,
        tau: float | None = None,
        tau_t: float | None = None,
        on_filter: str = "mark",
        confidence_map: Callable[[float], float] | None = None,
        class_names: Sequence[str] | None = None,
        label_rule: str | Mapping[str, str] = "most_frequent",
        abstain: bool = True,
        targeting: str = "merge",
    ) -> None:
        from sgbelief.fusion.channel import NullChannel
        from sgbelief.fusion.operators.base import BaseOperator

        self.operator = operator
        #: the operator's own vocabulary is the backend's (set again whenever the vocabulary is)
        self._share_table = getattr(operator, "vocabulary", None) is None
        self.vocabulary: ClassVocabulary | None = None
        self.table: Any = None
        #: resolves, counts and checks the geometric labels (channel_labels.LabelResolver)
        self.labels = LabelResolver(None)
        self._predicate_cache: dict[str, str | None] = {}
        if vocabulary is not None:
            self.set_vocabulary(vocabulary)
        cfg = getattr(operator, "config", None)
        self.tau = float(tau if tau is not None else getattr(cfg, "tau", 0.5))
        self.tau_t = float(tau_t if tau_t is not None else getattr(cfg, "tau_t", 0.1))
        self.context = context
        self.graph = graph
        # a graph handed in may already hold evidence the backend did not route (see _predicates_of)
        self._external_graph = bool(seed_from_graph)
        self._null = NullChannel()
        self.channel_fn: DetectionLabelFn | None = None
        self.channel: Any = None
        if channel is not None:
            if hasattr(channel, "label"):
                self.channel = channel
            elif callable(channel):
                self.channel_fn = channel
            else:
                raise TypeError("channel must be a GeometricChannel (label(node, t)) or a callable")
        self.label_key = label_key
        self.unknown_label = unknown_label
        self.unknown_class_id = unknown_class_id
        self.abstain = bool(abstain)
        if targeting not in ("merge", "spread"):
            raise ValueError(f"targeting must be 'merge' or 'spread', not {targeting!r}")
        #: "merge": a detection's claims go whole to the object its geometry merges into; "spread":
        #: over the candidates by association score (targets_for)
        self.targeting = targeting
        if on_filter not in ("mark", "remove"):
            raise ValueError("on_filter must be 'mark' or 'remove'")
        self.on_filter = on_filter
        self.confidence_map = confidence_map
        self.identity = IdentityMap()
        self.class_names: dict[int, str] = dict(enumerate(class_names)) if class_names else {}
        self._names_per_node: dict[Any, Counter[tuple[int | None, str]]] = {}
        #: predicates the backend routed to each node (O(1) label reads; the graph has no per-node index)
        self._preds_per_node: dict[Any, set[str]] = {}
        #: predicates only the geometric labels asserted at each node (candidates when no claimed one commits)
        self._label_preds_per_node: dict[Any, set[str]] = {}
        #: the (resolved) labels the channel gave at each node, counted: a merged predicate writes
        #: the channel's own name (table, not desk, for is_table_or_desk)
        self._labels_per_node: dict[Any, Counter[str]] = {}
        self._seeded: set[Any] = set()
        #: per detector class name: claims and what the channel said of them (summary())
        self._claim_counts: dict[str, ClaimCounts] = {}
        #: claims counted with a confidence below 0.5 (evidence against their class), and whether
        #: the user was told that most claims are (LowConfidenceWarning, once)
        self._claims_below_half = 0
        self._claims_counted = 0
        self._low_confidence_warned = False
        #: a channel is configured (or a detection carried its own label): checked within 20 frames
        self._has_channel = self.channel is not None or self.channel_fn is not None
        #: the operator learns the detector's score shift from agreement (no channel needed): the
        #: low-confidence warning has nothing to warn of, the summary reports the shift instead
        cfg = getattr(operator, "config", None)
        self._reads_scores_shifted = cfg is not None and cfg.calibration.consensus.method == "agreement_shift"
        self._detections_per_node: Counter[Any] = Counter()
        self._routed_detections = 0
        self._last_t = None
        #: nodes whose beliefs may have changed since the last take_changed_nodes(): the targets of
        #: routed events, the node a merge kept, and the nodes of queue resolutions
        self._changed: set[Any] = set()
        self.reports: list[Any] = []
        self.keep_reports = False
        #: when a list: every routed (event, {node: label}) is appended (benchmarks replay them)
        self.event_log: list[tuple[Any, dict[Any, str]]] | None = None
        self.active = True
        if isinstance(label_rule, str):
            if label_rule not in ("most_frequent", "first"):
                raise ValueError("label_rule must be 'most_frequent', 'first' or a mapping predicate -> class name")
            self.label_rule: str | dict[str, str] = label_rule
        else:
            self.label_rule = dict(label_rule)
        # sgbelief's own operators take report=False (no per-target reports nobody reads); any other
        # FusionOperator gets the protocol's update(graph, event, channel)
        self._skip_reports = isinstance(operator, BaseOperator)
        #: routed events waiting for flush(): (event, channel, class name)
        self._pending: list[tuple[Any, Any, str]] = []
        self._batch_open = False
        #: id(obj) -> (obj, node) resolved in the current frame (frame_lookups), else None
        self._frame_nodes: dict[int, tuple[Any, Any]] | None = None
        #: ids of the dicts whose geometry was read when their node was added, since the last
        #: per-frame sync (their geometry is current unless merged into since: see sync_labels)
        self.fresh_geometry: set[int] = set()

    @property
    def _batched(self) -> bool:
        """Events are queued and applied per frame: inside :meth:`batch`, with sgbelief's operators
        and no per-event reports kept. Elsewhere each routed detection is applied at once."""
        return self._batch_open and self._skip_reports and not self.keep_reports

    @contextlib.contextmanager
    def batch(self) -> Iterator[None]:
        """Queue the events routed inside (a per-frame merge) and apply them in one ``update_many``
        call at the latest when it ends (:meth:`flush`)."""
        if self._batch_open:
            yield
            return
        self._batch_open = True
        try:
            yield
        finally:
            self._batch_open = False
        self.flush()

    # ------------------------------------------------------------------ vocabulary
    def set_vocabulary(self, vocabulary: ClassVocabulary) -> None:
        """Use ``vocabulary`` from now on (its table also becomes the operator's, when the operator
        had none of its own). Claims already routed keep the predicates they were given."""
        self.vocabulary = vocabulary
        self.table = vocabulary.table()
        if self._share_table:
            self.operator.vocabulary = self.table
        self.labels.set_table(self.table)
        self._predicate_cache.clear()

    def vocabulary_needed(self, class_name: str) -> ClassVocabulary:
        """Called when a claim arrives before any vocabulary was given; returns the one to use.
        :class:`~sgbelief.adapters.conceptgraphs.backend.ConceptGraphsBackend` derives it from the
        class names; here it is an error."""
        raise ValueError(f"claim of class {class_name!r} routed before the backend has a vocabulary")

    # ------------------------------------------------------------------ reading CG dicts
    def claims_of(self, obj: Mapping[str, Any]) -> list[Claim]:
        """The per-detection (class, confidence, frame) history stored in a CG object dict."""
        return read_claims(obj, self.class_names)

    # ------------------------------------------------------------------ identity
    def node_of(self, obj: Mapping[str, Any]) -> Any | None:
        """The graph node standing for a map object (None for a detection never added to the map)."""
        node = self.identity.lookup(obj)  # type: ignore[arg-type]
        if node is None:
            return None
        return self.identity.resolve(node)

    def ensure_node(self, obj: dict) -> Any:
        """Node of map object ``obj``, registering it (and replaying its history) on first sight."""
        identity = self.identity
        node, fp = identity.find(obj)
        if node is not None:
            if identity.is_absorbed(node):
                return identity.resolve(node)
            if node in self.graph:
                return node
        return self._register_new(obj, fp)  # the fingerprint find computed, not a second one

    @contextlib.contextmanager
    def frame_lookups(self) -> Iterator[None]:
        """Inside: :meth:`frame_node` resolves each object to its node once (a per-frame merge asks
        for the same objects as targets, then again in its label sync). Whatever moves an object to
        another node (:meth:`migrate`, :meth:`mark_filtered`) forgets what was resolved."""
        if self._frame_nodes is not None:
            yield
            return
        self._frame_nodes = {}
        try:
            yield
        finally:
            self._frame_nodes = None

    def frame_node(self, obj: dict) -> Any:
        """:meth:`ensure_node`, memoised per object inside :meth:`frame_lookups` (the same node:
        nothing in a frame's routing moves an object to another node)."""
        memo = self._frame_nodes
        if memo is None:
            return self.ensure_node(obj)
        hit = memo.get(id(obj))
        if hit is not None and hit[0] is obj:  # the object is held, so its id() is not reused
            return hit[1]
        node = self.ensure_node(obj)
        memo[id(obj)] = (obj, node)
        return node

    # ------------------------------------------------------------------ evidence
    def route_detection(self, det: dict, targets: Mapping[Any, float]) -> int:
        """Turn every per-detection claim of ``det`` into an EvidenceEvent on ``targets``.

        Returns the number of events emitted.  Targets with mass <= tau_T are discarded; the
        detection's own geometric label (``label_key``) is consumed and removed from the dict.
        The events are queued and applied in one ``update_many`` call by :meth:`flush` (at the end
        of the per-frame merge, and before anything reads or merges the beliefs), in the order they
        were routed: the map is the one event-by-event updates give.
        """
        geo = det.pop(self.label_key, None) if isinstance(det, dict) else None
        tau_t = self.tau_t
        targets = {n: float(m) for n, m in targets.items() if float(m) > tau_t}
        claims = self.claims_of(det)
        geo_labels = geo if isinstance(geo, list) else None
        names_per_node = self._names_per_node
        preds_per_node = self._preds_per_node
        n_events = 0
        for k, claim in enumerate(claims):
            name = claim.class_name
            pred = self._predicate(name)
            key = (claim.class_id, name)
            for node in targets:
                counts = names_per_node.get(node)
                if counts is None:
                    counts = names_per_node[node] = Counter()
                counts[key] += 1
                if pred is not None:
                    preds = preds_per_node.get(node)
                    if preds is None:
                        preds_per_node[node] = {pred}
                    else:
                        preds.add(pred)
            if pred is None or not targets:
                continue
            # the event is built from checked parts (targets above tau_T, masses from a normalised
            # row, a clipped confidence): no re-validation per claim
            self._queue_claim(det, k, claim, pred, targets, geo, geo_labels)
            n_events += 1
        changed = self._changed
        for node in targets:
            self._detections_per_node[node] += len(claims)
            changed.add(node)
        self._routed_detections += len(claims)
        if not (self._batch_open and self._skip_reports and not self.keep_reports):  # not self._batched
            self.flush()
        return n_events

    def flush(self) -> None:
        """Apply the queued events (one ``update_many`` call), then note what each did: queue
        resolutions, the labels the channel gave, the per-class counts of :meth:`summary`."""
        pending = self._pending
        if not pending:
            return
        self._pending = []
        self._apply(pending)
        null, log, has_channel = self._null, self.event_log, self._has_channel
        for event, channel, name in pending:
            answers = None if channel is null else channel.answers
            self._count_claim(name, event.predicate, event.confidence, answers)
            if answers:
                # comod observes what the geometric label asserts (geometric_evidence: label): a
                # label is a candidate class of its node even when no detection named it
                self._note_label_predicates(answers)
            if log is not None:
                log.append((event, dict(answers) if answers else {}))
            if has_channel and channel is not null and channel.asked:
                self.labels.note_frame(event.t)

    def _apply(self, pending: list[tuple[Any, Any, str]]) -> None:
        """The operator's update of the queued (event, channel) pairs, in order."""
        op, graph = self.operator, self.graph
        if self._batched:
            resolutions = op.update_many(graph, [(event, channel) for event, channel, _ in pending])
            if resolutions:
                self._note_resolutions(resolutions)
        else:
            for event, channel, _name in pending:
                if not self._skip_reports and self._last_t is not None and event.t > self._last_t:
                    resolved = op.tick(graph, event.t)
                    if resolved:
                        self._note_resolutions(resolved)
                self._last_t = event.t if self._last_t is None else max(self._last_t, event.t)
                report = op.update(graph, event, channel) if self.keep_reports or not self._skip_reports \
                    else op.update(graph, event, channel, report=False)
                if report.resolutions:
                    self._note_resolutions(report.resolutions)
                if self.keep_reports:
                    self.reports.append(report)

    def _count_claim(self, class_name: str, pred: str, conf: float, answers: Mapping[Any, str] | None) -> None:
        """Count one routed claim for :meth:`summary`: verified, refused or unverifiable, by the
        verdict of the first label the channel gave for it (and the claim's raw sign)."""
        counts = self._claim_counts.get(class_name)
        if counts is None:
            counts = self._claim_counts[class_name] = ClaimCounts()
        counts.claims += 1
        self._claims_counted += 1
        if conf < 0.5:
            self._claims_below_half += 1
        if not answers:
            counts.unverifiable += 1
            return
        y = self.table.outcome(pred, next(iter(answers.values()))) if self.table is not None else None
        if y is None:
            counts.unverifiable += 1
        elif (y == 1) == (conf >= 0.5):
            counts.verified += 1
        else:
            counts.refused += 1

    def _note_label_predicates(self, answers: Mapping[Any, str]) -> None:
        """Note the predicates each answered label asserts as its node's geometric candidates."""
        table = self.table
        if table is None:
            return
        for node, label in answers.items():
            asserted = table.asserted_by(label)
            if asserted:
                preds = self._label_preds_per_node.get(node)
                if preds is None:
                    self._label_preds_per_node[node] = set(asserted)
                    self._labels_per_node[node] = Counter((label,))
                else:
                    preds.update(asserted)
                    self._labels_per_node[node][label] += 1

    def _note_resolutions(self, resolutions: Iterable[Any]) -> None:
        """A queued event left its queue (released, corroborated, ...): its node's beliefs may move."""
        changed = self._changed
        for res in resolutions:
            changed.add(res.node)

    def refit_consensus(self) -> None:
        """After ConceptGraphs' overlap-merge pass: refit the operator's map consensus on the
        merged objects (:meth:`CalibratedOperator.refit_consensus`; its O(claims) rides on the
        pass's own O(objects^2) overlap matrix); the nodes whose claims it reweighed are
        relabelled with the pass's other changes."""
        op = self.operator
        if isinstance(op, CalibratedOperator):
            self.flush()
            self._note_resolutions(op.refit_consensus(self.graph))

    def take_changed_nodes(self) -> set[Any]:
        """Nodes whose beliefs may have changed since the previous call (then forgotten): targets of
        routed events, nodes that absorbed a merge, nodes of queue resolutions. The per-frame merges
        relabel exactly these, so a frame's label work follows its detections, not the map's size."""
        self.flush()
        changed, self._changed = self._changed, set()
        return changed

    def targets_for(self, row: Any, best: int, objects: Sequence[dict], threshold: float,
                    touched: set[int] | None = None,
                    candidates: Sequence[int] | Mapping[int, float] | None = None) -> dict[Any, float]:
        """Targeting distribution T for one detection from its row of association scores.

        Under ``targeting="merge"`` the object ConceptGraphs merges the detection into, ``best``
        (the row's argmax), gets T = 1: the claim describes the pixels that become part of that
        object. Under ``"spread"`` every object whose score is above ``threshold`` (finite scores
        when it is -inf) is a candidate; T(v) is proportional to max(score, 0) over the
        candidates, and the argmax alone gets mass 1 when no candidate has a positive score.  The
        caller drops T(v) <= tau_T.
        ``touched``: the list positions of the targeted objects are added to it. ``candidates``:
        the positive candidates when the caller found them for the whole frame, as positions or as
        position -> score (:func:`~.generation_base.candidate_matrix`; then ``row`` is not read).
        """
        if self.targeting == "merge":
            if touched is not None:
                touched.add(best)
            return {self.frame_node(objects[best]): 1.0}
        if isinstance(candidates, dict):
            pos: Mapping[int, float] = candidates
        else:
            scores = row if type(row) is np.ndarray and row.dtype == np.float64 else \
                np.asarray(row.detach().cpu().numpy() if hasattr(row, "detach") else row, dtype=float)
            scores = scores.ravel()
            if candidates is None:
                n = min(len(scores), len(objects))
                s = scores[:n]
                # candidates found in numpy: the per-detection cost does not grow with the map's size
                candidates = np.flatnonzero(np.isfinite(s) & (s > threshold) & (s > 0)).tolist()
            pos = {j: float(scores[j]) for j in candidates}
        node_of = self.frame_node
        if len(pos) <= 1 or best not in pos:
            if touched is not None:
                touched.add(best)
            return {node_of(objects[best]): 1.0}
        if touched is not None:
            touched.update(pos)
        total = sum(pos.values())
        out: dict[Any, float] = {}
        for j, s in pos.items():
            node = node_of(objects[j])
            out[node] = out.get(node, 0.0) + s / total
        return out

    def migrate(self, keep_obj: dict, absorb_obj: dict) -> None:
        """``absorb_obj`` (a map object or a fresh detection) is being merged into ``keep_obj``."""
        self.flush()
        if self._frame_nodes:
            self._frame_nodes.clear()  # objects may now stand for another node
        keep = self.ensure_node(keep_obj)
        raw = self.identity.lookup(absorb_obj)
        if raw is None:
            # a detection (or an object never seen): its claims are new evidence for `keep`
            self.route_detection(absorb_obj, {keep: 1.0})
            return
        if self.identity.is_absorbed(raw):
            return  # already merged away once: its evidence lives elsewhere, count it once
        if raw not in self.graph:
            self.route_detection(absorb_obj, {keep: 1.0})
            return
        if raw == keep:
            return
        if self._external_graph:  # pick up evidence the caller's graph held before the merge moves it
            self._predicates_of(raw)
            self._predicates_of(keep)
        self.operator.merge_nodes(self.graph, keep, raw)
        self._detections_per_node[keep] += self._detections_per_node.pop(raw, 0)
        names = self._names_per_node.setdefault(keep, Counter())
        names.update(self._names_per_node.pop(raw, Counter()))
        self._preds_per_node.setdefault(keep, set()).update(self._preds_per_node.pop(raw, ()))
        self._label_preds_per_node.setdefault(keep, set()).update(self._label_preds_per_node.pop(raw, ()))
        self._labels_per_node.setdefault(keep, Counter()).update(self._labels_per_node.pop(raw, Counter()))
        self.identity.absorb(raw, keep)
        self._changed.add(keep)

    def refresh_geometry(self, obj: Mapping[str, Any]) -> None:
        """Copy the object's current centroid / box into its node."""
        self.refresh_node_geometry(self.node_of(obj), obj)

    def refresh_node_geometry(self, node: Any, obj: Mapping[str, Any]) -> None:
        """:meth:`refresh_geometry` when the caller has resolved ``obj``'s node already (the label
        sync, right after :meth:`ensure_node`): one geometry summary, no second identity look-up."""
        graph = self.graph
        if node is None or node not in graph:
            return
        centroid, bbox = geometry_summary(obj)
        attrs = graph.nx.nodes[node]
        if centroid is not None:
            attrs["centroid"] = centroid
        if bbox is not None:
            attrs["bbox"] = bbox

    def mark_filtered(self, obj: Mapping[str, Any]) -> None:
        self.flush()
        if self._frame_nodes:
            self._frame_nodes.clear()
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return
        if self.on_filter == "remove":
            self.graph.remove_node(node)
            self._preds_per_node.pop(node, None)
            self._label_preds_per_node.pop(node, None)
            self._labels_per_node.pop(node, None)
        else:
            self.graph.nx.nodes[node]["cg_filtered"] = True
        self.identity.retire(node)

    # ------------------------------------------------------------------ labels out
    def _predicate(self, class_name: str) -> str | None:
        """``vocabulary.predicate`` memoised per class name (called for every claim and label read)."""
        try:
            return self._predicate_cache[class_name]
        except KeyError:
            vocab = self.vocabulary
            if vocab is None or getattr(self, "_growing", False):
                vocab = self.vocabulary_needed(class_name)
                if vocab is not self.vocabulary:
                    self.set_vocabulary(vocab)
            pred = self._predicate_cache[class_name] = vocab.predicate(class_name)
            return pred

    def _predicates_of(self, node: Any) -> set[str]:
        """Predicates with evidence at ``node``: those the backend routed there, kept per node so a
        label read costs O(predicates of the node) instead of a scan of every pair in the graph.
        With a graph passed in by the caller, the node's pre-existing beliefs are added once."""
        preds = self._preds_per_node.get(node)
        if preds is None:
            preds = self._preds_per_node[node] = set()
        if self._external_graph and node not in self._seeded:
            self._seeded.add(node)
            if node in self.graph:
                preds.update(self.graph.beliefs(node))
        return preds

    # ------------------------------------------------------------------ per frame
    def end_frame(self) -> None:
        """Called by the patched per-frame merge functions once per frame (after the merge).

        Applies the frame's queued events; :class:`~sgbelief.adapters.conceptgraphs.backend.
        ConceptGraphsBackend` adds its garbage-collector checkpoints here. Warns once
        (:class:`~sgbelief.errors.LowConfidenceWarning`) when most claims so far have a confidence
        below 0.5 and no channel can calibrate them."""
        self.flush()
        if not self._low_confidence_warned and not self._has_channel and not self._reads_scores_shifted:
            note = low_confidence_note(self._claims_counted, self._claims_below_half, self._has_channel,
                                       LOW_CONFIDENCE_MIN_CLAIMS)
            if note is not None:
                self._low_confidence_warned = True
                warn_at_caller(f"ConceptGraphsBackend: {note}", LowConfidenceWarning)

    def evidence_count(self) -> int:
        self.flush()
        return int(self.graph.evidence_count())

    @property
    def routed_detections(self) -> int:
        """Per-detection claims routed so far (each detection counted once)."""
        return self._routed_detections

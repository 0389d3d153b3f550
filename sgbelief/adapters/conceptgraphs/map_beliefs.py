"""The belief bookkeeping behind the ConceptGraphs backend: map objects to nodes, detections to
evidence events, beliefs to labels. Nothing here knows ConceptGraphs' function signatures or how
they are swapped in (:mod:`.generation_main`, :mod:`.generation_ali_dev`, :mod:`.patching`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from sgbelief.adapters.conceptgraphs.channel_labels import LabelResolver
from sgbelief.adapters.conceptgraphs.claims import (
    DEFAULT_LABEL_KEY,
    Claim,
    DetectionLabelFn,
    EventChannel,
    read_claims,
)
from sgbelief.adapters.conceptgraphs.geometry import geometry_summary
from sgbelief.adapters.conceptgraphs.identity import IdentityMap
from sgbelief.adapters.conceptgraphs.summary import BackendSummary, ClaimCounts, ClassSummary
from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary, normalise_class_name

__all__ = ["DEFAULT_LABEL_KEY", "BackendSummary", "Claim", "DetectionLabelFn", "MapBeliefs"]

class MapBeliefs:
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
        unknown_label / unknown_class_id: label written when no predicate commits.
        tau / tau_t: commit threshold and targeting-mass threshold (default: the operator config).
        on_filter: ``"mark"`` (node kept with ``cg_filtered=True``) or ``"remove"``.
        confidence_map: optional map of the detector's raw confidence before it enters an event.
        class_names: class names by class id (learned from the detections when absent).
        label_rule: the class written when the committed predicate covers several class names
            (``is_table_or_desk``: table, desk): ``"most_frequent"`` (default: the name detected most
            often on this object, ties to the first seen), ``"first"`` (the first name detected), or a
            mapping predicate -> class name (e.g. ``{"is_table_or_desk": "table"}``; predicates not in
            it fall back to most frequent). A mapped name that is a known class id keeps that id.
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
        #: a channel is configured (or a detection carried its own label): checked within 20 frames
        self._has_channel = self.channel is not None or self.channel_fn is not None
        self._detections_per_node: Counter[Any] = Counter()
        self._routed_detections = 0
        self._last_t = None
        #: nodes whose beliefs may have changed since the last take_changed_nodes(): the targets of
        #: routed events, the node a merge kept, and the nodes of queue resolutions
        self._changed: set[Any] = set()
        self.reports: list[Any] = []
        self.keep_reports = False
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
        node = self.identity.lookup(obj)
        if node is not None:
            if self.identity.is_absorbed(node):
                return self.identity.resolve(node)
            if node in self.graph:
                return node
        node = self.identity.register(obj)
        self._add_graph_node(node, obj)
        self.route_detection(obj, {node: 1.0})
        return node

    def _add_graph_node(self, node: Any, obj: Mapping[str, Any]) -> None:
        if node in self.graph:
            return
        centroid, bbox = geometry_summary(obj)
        self.graph.add_node(node, centroid=centroid, bbox=bbox, source="conceptgraphs")

    # ------------------------------------------------------------------ evidence
    def route_detection(self, det: dict, targets: Mapping[Any, float]) -> int:
        """Turn every per-detection claim of ``det`` into an EvidenceEvent on ``targets``.

        Returns the number of events emitted.  Targets with mass <= tau_T are discarded; the
        detection's own geometric label (``label_key``) is consumed and removed from the dict.
        """
        from sgbelief.fusion.events import EvidenceEvent

        geo = det.pop(self.label_key, None) if isinstance(det, dict) else None
        targets = {n: float(m) for n, m in targets.items() if float(m) > self.tau_t}
        claims = self.claims_of(det)
        n_events = 0
        geo_labels = geo if isinstance(geo, list) else [geo] * len(claims)
        for k, claim in enumerate(claims):
            pred = self._predicate(claim.class_name)
            for node in targets:
                counts = self._names_per_node.get(node)
                if counts is None:
                    counts = self._names_per_node[node] = Counter()
                counts[(claim.class_id, claim.class_name)] += 1
                if pred is not None:
                    preds = self._preds_per_node.get(node)
                    if preds is None:
                        self._preds_per_node[node] = {pred}
                    else:
                        preds.add(pred)
            if pred is None or not targets:
                continue
            conf = self.confidence_map(claim.confidence) if self.confidence_map else claim.confidence
            label = geo_labels[k] if k < len(geo_labels) else None
            if label is not None:
                self._has_channel = True
            if self.table is not None and pred not in self.table:
                channel: Any = self._null  # no verification possible for this predicate
            else:
                channel = EventChannel(label, det, self.channel, self.channel_fn, k, self.labels.resolve)
            if self._last_t is not None and claim.t > self._last_t:
                resolved = self.operator.tick(self.graph, claim.t)
                if resolved:
                    self._note_resolutions(resolved)
            self._last_t = claim.t if self._last_t is None else max(self._last_t, claim.t)
            event = EvidenceEvent(targets=targets, predicate=pred, confidence=float(conf),
                                  context=self.context, t=int(claim.t))
            if self._skip_reports and not self.keep_reports:
                report = self.operator.update(self.graph, event, channel, report=False)
            else:
                report = self.operator.update(self.graph, event, channel)
            if report.resolutions:
                self._note_resolutions(report.resolutions)
            self._count_claim(claim.class_name, pred, float(conf), channel)
            if channel is not self._null and channel.answers:
                # comod observes what the geometric label asserts (geometric_evidence: label): a
                # label is a candidate class of its node even when no detection named it
                self._note_label_predicates(channel.answers)
            if self._has_channel and channel is not self._null and channel.asked:
                self.labels.note_frame(int(claim.t))
            if self.keep_reports:
                self.reports.append(report)
            n_events += 1
        changed = self._changed
        for node in targets:
            self._detections_per_node[node] += len(claims)
            changed.add(node)
        self._routed_detections += len(claims)
        return n_events

    def _count_claim(self, class_name: str, pred: str, conf: float, channel: Any) -> None:
        """Count one routed claim for :meth:`summary`: verified, refused or unverifiable, by the
        verdict of the first label the channel gave for it (and the claim's raw sign)."""
        counts = self._claim_counts.get(class_name)
        if counts is None:
            counts = self._claim_counts[class_name] = ClaimCounts()
        counts.claims += 1
        answers = None if channel is self._null else channel.answers
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

    def take_changed_nodes(self) -> set[Any]:
        """Nodes whose beliefs may have changed since the previous call (then forgotten): targets of
        routed events, nodes that absorbed a merge, nodes of queue resolutions. The per-frame merges
        relabel exactly these, so a frame's label work follows its detections, not the map's size."""
        changed, self._changed = self._changed, set()
        return changed

    def targets_for(self, row: Any, best: int, objects: Sequence[dict], threshold: float,
                    touched: set[int] | None = None) -> dict[Any, float]:
        """Targeting distribution T for one detection from its row of association scores.

        Every object whose score is above ``threshold`` (finite scores when it is -inf) is a
        candidate; T(v) is proportional to max(score, 0) over the candidates, and the argmax
        alone gets mass 1 when no candidate has a positive score.  The caller drops T(v) <= tau_T.
        ``touched``: the list positions of the targeted objects are added to it.
        """
        scores = np.asarray(row.detach().cpu().numpy() if hasattr(row, "detach") else row, dtype=float).ravel()
        n = min(len(scores), len(objects))
        s = scores[:n]
        # candidates found in numpy: the per-detection cost does not grow with the map's size
        cand = np.flatnonzero(np.isfinite(s) & (s > threshold) & (s > 0)).tolist()
        pos = {j: float(s[j]) for j in cand}
        if len(pos) <= 1 or best not in pos:
            if touched is not None:
                touched.add(best)
            return {self.ensure_node(objects[best]): 1.0}
        if touched is not None:
            touched.update(pos)
        total = sum(pos.values())
        out: dict[Any, float] = {}
        for j, s in pos.items():
            node = self.ensure_node(objects[j])
            out[node] = out.get(node, 0.0) + s / total
        return out

    def migrate(self, keep_obj: dict, absorb_obj: dict) -> None:
        """``absorb_obj`` (a map object or a fresh detection) is being merged into ``keep_obj``."""
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
        self.graph.merge_nodes(keep, raw)
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
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return
        centroid, bbox = geometry_summary(obj)
        attrs = self.graph.nx.nodes[node]
        if centroid is not None:
            attrs["centroid"] = centroid
        if bbox is not None:
            attrs["bbox"] = bbox

    def mark_filtered(self, obj: Mapping[str, Any]) -> None:
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
    def beliefs(self, obj: Mapping[str, Any]) -> dict[str, Any]:
        """{predicate: BetaBelief} of a map object (empty for an object the backend never saw)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return {}
        return dict(self.graph.beliefs(node))

    def probability(self, obj: Mapping[str, Any], predicate: str) -> float:
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return 0.5
        return float(self.operator.probability(self.graph, node, predicate))

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

    def committed_predicate(self, node: Any) -> str | None:
        """The predicate with the highest committed probability (> tau), or None.

        The candidates are the predicates the node's detections claimed. Only when none of them
        commits are the predicates that the geometric labels alone asserted considered (comod,
        ``geometric_evidence: label``): a sofa the detector always calls ``tv`` is labelled
        ``sofa``, while one stray label of a segmenter does not outrank a class the detector
        keeps naming and the geometry keeps confirming. Under independent Beta(1, 1) beliefs, a
        single observation (mean 2/3) would otherwise outrank a well-supported class with a few
        contradictions. The probability is the operator's (``FusionOperator.probability``), for
        every operator."""
        best = self._best_committed(sorted(self._predicates_of(node)), node)
        if best is None:
            extra = self._label_preds_per_node.get(node)
            if extra:
                best = self._best_committed(sorted(extra), node)
        return best

    def _best_committed(self, preds: Iterable[str], node: Any) -> str | None:
        best, best_p = None, self.tau
        probability = self.operator.probability
        graph = self.graph
        for pred in preds:
            p = float(probability(graph, node, pred))
            if p > best_p:
                best, best_p = pred, p
        return best

    def _class_for(self, node: Any, pred: str | None) -> tuple[int | None, str] | None:
        if pred is None:
            return None
        counts = self._names_per_node.get(node)
        if not counts:
            return None
        predicate = self._predicate
        rule = self.label_rule
        if rule == "first":
            for key in counts:  # Counter keeps first-seen order
                if predicate(key[1]) == pred:
                    return key
            return self._class_named_by(pred)
        if not isinstance(rule, str) and pred in rule:
            name = rule[pred]
            for key in counts:
                if key[1] == name:
                    return key
            cid = next((i for i, n in self.class_names.items() if n == name), None)
            return (cid, name)
        if self._covers_several(pred):  # a merged predicate: the channel's own name, when it has one
            own = self._channel_class(node, pred, counts)
            if own is not None:
                return own
        best, best_n = None, 0
        for key, n in counts.items():  # most frequent; ties keep first-seen order
            if n > best_n and predicate(key[1]) == pred:
                best, best_n = key, n
        return best if best is not None else self._class_named_by(pred)

    def _covers_several(self, pred: str) -> bool:
        """Whether ``pred`` stands for several class names (a merged group: table, desk, ...)."""
        table = self.table
        spec = table.specs.get(pred) if table is not None else None
        return spec is not None and len(spec.aliases) > 1

    def _channel_class(self, node: Any, pred: str, counts: Counter[tuple[int | None, str]]) -> tuple[int | None, str] | None:
        """(class id, name) of the label the channel gave most often at ``node`` among those naming
        ``pred``'s classes (the detector's spelling and id when a claim used that name), or None."""
        seen = self._labels_per_node.get(node)
        vocab = self.vocabulary
        if not seen or vocab is None:
            return None
        for label, _n in seen.most_common():
            if vocab.predicate(label) != pred:
                continue
            key = normalise_class_name(label)
            for cid, name in counts:
                if normalise_class_name(name) == key:
                    return (cid, name)
            cid = next((i for i, n in sorted(self.class_names.items()) if normalise_class_name(n) == key), None)
            return (cid, self.class_names[cid] if cid is not None else label)
        return None

    def _class_named_by(self, pred: str) -> tuple[int | None, str] | None:
        """(class id, name) for a predicate no detection of the node named (the geometric labels
        committed it): the first class of the class list whose predicate it is."""
        predicate = self._predicate
        for cid, name in sorted(self.class_names.items()):
            if predicate(name) == pred:
                return (cid, name)
        return None

    def committed_class(self, node: Any) -> tuple[int | None, str] | None:
        """(class id, class name) of the node's committed predicate under ``label_rule``, or None
        when nothing commits."""
        return self._class_for(node, self.committed_predicate(node))

    def label_of(self, obj: Mapping[str, Any]) -> str | None:
        """Class name from the beliefs (``unknown_label`` when nothing commits; None if unseen)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return None
        hit = self.committed_class(node)
        return self.unknown_label if hit is None else hit[1]

    def class_id_of(self, obj: Mapping[str, Any]) -> int | None:
        """Class id from the beliefs (``unknown_class_id`` when nothing commits; None if unseen)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return None
        hit = self.committed_class(node)
        if hit is None or hit[0] is None:
            return self.unknown_class_id
        return hit[0]

    # ------------------------------------------------------------------ per frame
    def end_frame(self) -> None:
        """Called by the patched per-frame merge functions once per frame (after the merge).

        Nothing to do for the bookkeeping itself; :class:`~sgbelief.adapters.conceptgraphs.backend.
        ConceptGraphsBackend` adds its garbage-collector checkpoints here."""

    def summary(self, objects: Sequence[Mapping[str, Any]] | None = None) -> BackendSummary:
        """What the backend did, over ``objects`` (a map object list) or every live node it tracks:
        objects labelled and left ``unknown``, and per detector class the claims (verified, refused,
        unverifiable by the channel) and the objects whose vote is that class (committed, unknown,
        written label differing from the vote). See :class:`~.summary.BackendSummary`."""
        if objects is not None:
            nodes = [n for n in (self.node_of(o) for o in objects) if n is not None and n in self.graph]
        else:
            nodes = [n for n in self.graph.nodes() if n in self._names_per_node]
        attrs = self.graph.nx.nodes
        filtered = sum(1 for n in nodes if attrs[n].get("cg_filtered"))
        live = [n for n in nodes if not attrs[n].get("cg_filtered")]
        per_class: dict[str, dict[str, int]] = {
            name: {"claims": c.claims, "verified": c.verified, "refused": c.refused, "unverifiable": c.unverifiable}
            for name, c in self._claim_counts.items()}
        differing: list[dict[str, Any]] = []
        labelled = 0
        for n in live:
            hit = self.committed_class(n)
            labelled += hit is not None
            names = self._names_per_node.get(n)
            vote = _vote(names) if names else None
            if vote is None:
                continue
            row = per_class.setdefault(vote, {})
            key = "committed" if hit is not None else "unknown"
            row[key] = row.get(key, 0) + 1
            written = self.unknown_label if hit is None else hit[1]
            if written != vote:
                row["differ"] = row.get("differ", 0) + 1
                differing.append({"node": str(n), "vote": vote, "label": written})
        vocab = self.vocabulary
        return BackendSummary(objects=len(live), labelled=labelled, unknown=len(live) - labelled,
                              filtered=filtered, detections=self._routed_detections,
                              events=self.evidence_count(),
                              classes={k: ClassSummary(**v) for k, v in sorted(per_class.items())},
                              differing=differing, channel=self.labels.report() if self._has_channel else {},
                              vocabulary=getattr(vocab, "name", "") if vocab is not None else "")

    def evidence_count(self) -> int:
        return int(self.graph.evidence_count())

    @property
    def routed_detections(self) -> int:
        """Per-detection claims routed so far (each detection counted once)."""
        return self._routed_detections


def _vote(names: Counter[tuple[int | None, str]]) -> str:
    """ConceptGraphs' majority class name of an object's claims (ties to the first seen)."""
    best, best_n = "", 0
    for (_cid, name), n in names.items():
        if n > best_n:
            best, best_n = name, n
    return best

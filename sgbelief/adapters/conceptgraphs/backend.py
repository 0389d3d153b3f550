"""ConceptGraphsBackend: belief fusion behind ConceptGraphs' mapping functions."""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from sgbelief._fast import gc as gc_tuning
from sgbelief.adapters.conceptgraphs.identity import IdentityMap
from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary

#: detection-dict key a segmenter-running pipeline may set to the geometric label of that detection
DEFAULT_LABEL_KEY = "geometric_label"

DetectionLabelFn = Callable[[dict, Any, int], "str | None"]


class Claim(NamedTuple):
    """One per-detection claim read from a ConceptGraphs object dict."""

    class_id: int | None
    class_name: str
    confidence: float
    t: int


class _EventChannel:
    """Geometric channel for one event: the detection's own label first, then the configured channel.

    A configured channel with ``label_detection(detection, index, t)`` (a :class:`DetectionChannel`
    such as :class:`~sgbelief.fusion.channel.LabelImageChannel`) is asked about entry ``index`` of
    the detection dict; any other channel through ``label(node, t)``.
    """

    __slots__ = ("_label", "_detection", "_fallback", "_fn", "_index")

    def __init__(self, label: str | None, detection: dict | None, fallback: Any, fn: DetectionLabelFn | None,
                 index: int = 0) -> None:
        self._label = label
        self._detection = detection
        self._fallback = fallback
        self._fn = fn
        self._index = index

    def label(self, node: Any, t: int) -> str | None:
        if self._label is not None:
            return self._label
        if self._fn is not None and self._detection is not None:
            value = self._fn(self._detection, node, t)
            if value is not None:
                return value
        fallback = self._fallback
        if fallback is not None:
            by_detection = getattr(fallback, "label_detection", None)
            if by_detection is not None and self._detection is not None:
                value = by_detection(self._detection, self._index, t)
                if value is not None:
                    return value
            return fallback.label(node, t)
        return None


class BackendSummary(NamedTuple):
    """Counts over the backend's live map objects (see :meth:`ConceptGraphsBackend.summary`)."""

    objects: int  #: live (not merged away, not filtered) objects the backend tracks
    labelled: int  #: objects whose label comes from a committed predicate
    unknown: int  #: objects left unknown: nothing commits (``unknown_label`` / ``unknown_class_id``)
    filtered: int  #: objects ConceptGraphs filtered (marked ``cg_filtered``)
    detections: int  #: per-detection claims routed
    events: int  #: evidence entries in the graph


class ConceptGraphsBackend:
    """Routes every ConceptGraphs detection into a :class:`~sgbelief.graph.scene_graph.SceneGraph`.

    Args:
        operator: operator name (``comod``, ``cal``, ``majority``, ...) or a FusionOperator instance.
        vocabulary: a :class:`ClassVocabulary`, a path to ``configs/conceptgraphs/*.yaml`` or None
            (shipped ScanNet vocabulary).
        context: the context tag kappa (detector / VLM and prompt version) of every event.
        channel: optional geometric channel: a GeometricChannel (``label(node, t)``), or a callable
            ``fn(detection, node, t) -> str | None``.  A detection's own ``label_key`` entry wins.
        label_key: detection-dict key holding a per-detection geometric label (popped from the dict
            before ConceptGraphs' merge sees it, since the original merges reject unknown keys).
        unknown_label / unknown_class_id: label written when no predicate commits.
        tau / tau_t: commit threshold and targeting-mass threshold (default: the operator config).
        on_filter: ``"mark"`` (node kept with ``cg_filtered=True``) or ``"remove"``.
        confidence_map: optional map of the detector's raw confidence before it enters an event.
        gc_checkpoints: call :meth:`gc_checkpoint` once per frame (after the patched per-frame
            merge), so CPython's full collections never rescan the whole map.
        label_rule: the class written when the committed predicate covers several class names
            (``is_table_or_desk``: table, desk): ``"most_frequent"`` (default: the name detected most
            often on this object, ties to the first seen), ``"first"`` (the first name detected), or a
            mapping predicate -> class name (e.g. ``{"is_table_or_desk": "table"}``; predicates not in
            it fall back to most frequent). A mapped name that is a known class id keeps that id.
    """

    def __init__(
        self,
        operator: str | Any = "comod",
        vocabulary: ClassVocabulary | str | Path | None = None,
        context: str = "conceptgraphs",
        channel: Any = None,
        *,
        graph: Any = None,
        operator_config: Any = None,
        label_key: str = DEFAULT_LABEL_KEY,
        unknown_label: str = "unknown",
        unknown_class_id: int = -1,
        tau: float | None = None,
        tau_t: float | None = None,
        on_filter: str = "mark",
        confidence_map: Callable[[float], float] | None = None,
        class_names: Sequence[str] | None = None,
        gc_checkpoints: bool = False,
        label_rule: str | Mapping[str, str] = "most_frequent",
    ) -> None:
        from sgbelief.fusion.channel import NullChannel
        from sgbelief.graph.scene_graph import SceneGraph

        if isinstance(vocabulary, ClassVocabulary):
            self.vocabulary = vocabulary
        elif vocabulary is None:
            self.vocabulary = ClassVocabulary.default()
        else:
            self.vocabulary = ClassVocabulary.from_yaml(vocabulary)
        self.table = self.vocabulary.table()
        if isinstance(operator, str):
            from sgbelief.api.operators import make_operator

            self.operator = make_operator(operator, config=operator_config, vocabulary=self.table)
            self.operator_name = operator
        else:
            self.operator = operator
            self.operator_name = type(operator).__name__
        cfg = getattr(self.operator, "config", None)
        self.tau = float(tau if tau is not None else getattr(cfg, "tau", 0.5))
        self.tau_t = float(tau_t if tau_t is not None else getattr(cfg, "tau_t", 0.1))
        self.context = context
        self.graph = graph if graph is not None else SceneGraph()
        # a graph handed in may already hold evidence the backend did not route (see _predicates_of)
        self._external_graph = graph is not None
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
        self._predicate_cache: dict[str, str | None] = {}
        self._seeded: set[Any] = set()
        self._detections_per_node: Counter[Any] = Counter()
        self._routed_detections = 0
        self._last_t = None
        self._pending_targets: dict[int, dict[Any, float]] = {}
        self._last_match: tuple[Any, Any, float] | None = None
        #: list indices of the map objects a patched per-frame merge touched (their labels are re-read)
        self._touched_idx: set[int] = set()
        #: map-list length after the last label sync; objects appended beyond it by the script itself
        #: (the first frame's ``extend``) are registered at the next per-frame merge
        self._synced_len = 0
        self.reports: list[Any] = []
        self.keep_reports = False
        self._patcher: Any = None
        self.active = True
        self.gc_checkpoints = bool(gc_checkpoints)
        self._froze = False
        if isinstance(label_rule, str):
            if label_rule not in ("most_frequent", "first"):
                raise ValueError("label_rule must be 'most_frequent', 'first' or a mapping predicate -> class name")
            self.label_rule: str | dict[str, str] = label_rule
        else:
            self.label_rule = dict(label_rule)
        from sgbelief.fusion.operators.base import BaseOperator

        # sgbelief's own operators can skip building per-target reports nobody reads, and their
        # probability is the belief mean (read straight from the provenance store)
        self._lean_update = isinstance(self.operator, BaseOperator)
        self._mean_is_probability = (self._lean_update
                                     and type(self.operator).probability is BaseOperator.probability)

    # ------------------------------------------------------------------ reading CG dicts
    def claims_of(self, obj: Mapping[str, Any]) -> list[Claim]:
        """The per-detection (class, confidence, frame) history stored in a CG object dict."""
        ids, confs, frames = _seq(obj.get("class_id")), _seq(obj.get("conf")), _seq(obj.get("image_idx"))
        names = obj.get("class_name")
        n = max(len(ids), len(confs))
        out: list[Claim] = []
        for k in range(n):
            cid = _as_int(ids[k]) if k < len(ids) else None
            if isinstance(names, list) and k < len(names):
                name = str(names[k])
            elif cid is not None and cid in self.class_names:
                name = self.class_names[cid]
            elif isinstance(names, str) and (n == 1 or not ids):
                name = names
            elif cid is not None:
                name = str(cid)
            else:
                continue
            if cid is not None and cid >= 0 and name != str(cid):
                self.class_names.setdefault(cid, name)
            conf = _as_float(confs[k]) if k < len(confs) and confs[k] is not None else 1.0
            t = _as_int(frames[k]) if k < len(frames) else 0
            out.append(Claim(cid, name, min(max(conf, 0.0), 1.0), t if t is not None else 0))
        return out

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
        centroid, bbox = _geometry_summary(obj)
        if node in self.graph:
            return
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
            if self.table is not None and pred not in self.table:
                channel: Any = self._null  # no verification possible for this predicate
            else:
                channel = _EventChannel(label, det, self.channel, self.channel_fn, k)
            if self._last_t is not None and claim.t > self._last_t:
                self.operator.tick(self.graph, claim.t)
            self._last_t = claim.t if self._last_t is None else max(self._last_t, claim.t)
            event = EvidenceEvent(targets=targets, predicate=pred, confidence=float(conf),
                                  context=self.context, t=int(claim.t))
            if self._lean_update and not self.keep_reports:
                report = self.operator.update(self.graph, event, channel, report=False)
            else:
                report = self.operator.update(self.graph, event, channel)
            if self.keep_reports:
                self.reports.append(report)
            n_events += 1
        for node in targets:
            self._detections_per_node[node] += len(claims)
        self._routed_detections += len(claims)
        return n_events

    def targets_for(self, row: Any, best: int, objects: Sequence[dict], threshold: float) -> dict[Any, float]:
        """Targeting distribution T for one detection from its row of association scores.

        Every object whose score is above ``threshold`` (finite scores when it is -inf) is a
        candidate; T(v) is proportional to max(score, 0) over the candidates, and the argmax
        alone gets mass 1 when no candidate has a positive score.  The caller drops T(v) <= tau_T.
        """
        scores = np.asarray(row.detach().cpu().numpy() if hasattr(row, "detach") else row, dtype=float).ravel()
        n = min(len(scores), len(objects))
        s = scores[:n]
        # candidates found in numpy: the per-detection cost does not grow with the map's size
        cand = np.flatnonzero(np.isfinite(s) & (s > threshold) & (s > 0)).tolist()
        pos = {j: float(s[j]) for j in cand}
        touched = self._touched_idx
        if len(pos) <= 1 or best not in pos:
            touched.add(best)
            return {self.ensure_node(objects[best]): 1.0}
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
        self.identity.absorb(raw, keep)

    def refresh_geometry(self, obj: Mapping[str, Any]) -> None:
        """Copy the object's current centroid / box into its node."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return
        centroid, bbox = _geometry_summary(obj)
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
            pred = self._predicate_cache[class_name] = self.vocabulary.predicate(class_name)
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
        """The predicate with the highest committed probability (> tau), or None."""
        best, best_p = None, self.tau
        preds = sorted(self._predicates_of(node))
        if self._mean_is_probability:
            alpha_beta = self.graph.provenance.alpha_beta
            for pred in preds:
                a, b = alpha_beta(node, pred)
                p = a / (a + b)  # the belief mean, as ProvenanceStore.mean computes it
                if p > best_p:
                    best, best_p = pred, p
            return best
        for pred in preds:
            p = float(self.operator.probability(self.graph, node, pred))
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
            return None
        if not isinstance(rule, str) and pred in rule:
            name = rule[pred]
            for key in counts:
                if key[1] == name:
                    return key
            cid = next((i for i, n in self.class_names.items() if n == name), None)
            return (cid, name)
        best, best_n = None, 0
        for key, n in counts.items():  # most frequent; ties keep first-seen order
            if n > best_n and predicate(key[1]) == pred:
                best, best_n = key, n
        return best

    def label_of(self, obj: Mapping[str, Any]) -> str | None:
        """Class name from the beliefs (``unknown_label`` when nothing commits; None if unseen)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return None
        hit = self._class_for(node, self.committed_predicate(node))
        return self.unknown_label if hit is None else hit[1]

    def class_id_of(self, obj: Mapping[str, Any]) -> int | None:
        """Class id from the beliefs (``unknown_class_id`` when nothing commits; None if unseen)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return None
        hit = self._class_for(node, self.committed_predicate(node))
        if hit is None or hit[0] is None:
            return self.unknown_class_id
        return hit[0]

    # ------------------------------------------------------------------ garbage collector
    def gc_checkpoint(self) -> None:
        """Collect the cyclic garbage made since the last checkpoint, then freeze what survives.

        CPython's generation-2 collection re-traverses every tracked object; a map holds several per
        provenance entry (live for T_prov steps), so its pauses grow with objects x history (about
        3 s at 5,000 objects x 500 detections). Frozen objects (``gc.freeze()``) are skipped, and
        reference counting still frees them; each checkpoint only scans what is new since the
        previous one. Cycles that become garbage after being frozen wait for ``gc.unfreeze()``
        (done by :meth:`uninstall`). See docs/performance.md, "ConceptGraphs per-frame cost".
        """
        gc_tuning.checkpoint()
        self._froze = True

    def end_frame(self) -> None:
        """Called by the patched per-frame merge functions: the per-frame housekeeping hook."""
        if self.gc_checkpoints:
            self.gc_checkpoint()

    def summary(self, objects: Sequence[Mapping[str, Any]] | None = None) -> BackendSummary:
        """Counts of labelled and ``unknown`` objects (nothing commits), over ``objects`` (a map
        object list) or every live node the backend tracks."""
        if objects is not None:
            nodes = [n for n in (self.node_of(o) for o in objects) if n is not None and n in self.graph]
        else:
            nodes = [n for n in self.graph.nodes() if n in self._names_per_node]
        attrs = self.graph.nx.nodes
        filtered = sum(1 for n in nodes if attrs[n].get("cg_filtered"))
        live = [n for n in nodes if not attrs[n].get("cg_filtered")]
        labelled = sum(1 for n in live if self._class_for(n, self.committed_predicate(n)) is not None)
        return BackendSummary(objects=len(live), labelled=labelled, unknown=len(live) - labelled,
                              filtered=filtered, detections=self._routed_detections,
                              events=self.evidence_count())

    def evidence_count(self) -> int:
        return int(self.graph.evidence_count())

    @property
    def routed_detections(self) -> int:
        """Per-detection claims routed so far (each detection counted once)."""
        return self._routed_detections

    # ------------------------------------------------------------------ functions & patching
    def functions(self, generation: str = "main") -> Any:
        """ConceptGraphs-signature functions for ``generation`` (``main`` or ``ali-dev``)."""
        from sgbelief.adapters.conceptgraphs.functions import make_functions

        return make_functions(self, generation)

    def install(self, *modules: Any, generation: str | None = None, fix_list_kwargs: bool = True) -> None:
        """Swap the belief-routing functions into ConceptGraphs' (already imported) modules."""
        from sgbelief.adapters.conceptgraphs.patching import Patcher

        if self._patcher is not None:
            raise RuntimeError("backend already installed; call uninstall() first")
        patcher = Patcher(self, extra_modules=modules, generation=generation, fix_list_kwargs=fix_list_kwargs)
        patcher.install()
        self._patcher = patcher
        self.active = True

    def uninstall(self) -> None:
        """Restore every name swapped by :meth:`install` (and unfreeze what :meth:`gc_checkpoint` froze)."""
        if self._patcher is not None:
            self._patcher.uninstall()
            self._patcher = None
        if self._froze:
            gc_tuning.release_checkpoints()
            self._froze = False

    @contextlib.contextmanager
    def patch(self, *modules: Any, generation: str | None = None, fix_list_kwargs: bool = True) -> Iterator[ConceptGraphsBackend]:
        """Context manager form of :meth:`install` / :meth:`uninstall`."""
        self.install(*modules, generation=generation, fix_list_kwargs=fix_list_kwargs)
        try:
            yield self
        finally:
            self.uninstall()

    @property
    def generation(self) -> str | None:
        return None if self._patcher is None else self._patcher.generation

    def save(self, path: str | Path) -> Path:
        """Save the belief graph (SceneGraph JSON)."""
        return self.graph.save(path)


def _seq(value: Any) -> list[Any]:
    """A per-detection field as a list (None -> []; numpy arrays have no truth value)."""
    if value is None:
        return []
    if isinstance(value, list):
        return value
    return list(value)


def _as_int(value: Any) -> int | None:
    if type(value) is int:
        return value
    try:
        return int(np.asarray(value).item())
    except (TypeError, ValueError):
        return None


def _as_float(value: Any) -> float:
    if type(value) is float:
        return value
    return float(np.asarray(value).item())


def _geometry_summary(obj: Mapping[str, Any]) -> tuple[Any, Any]:
    pts = None
    pcd = obj.get("pcd")
    if pcd is not None and hasattr(pcd, "points"):
        pts = np.asarray(pcd.points)
    elif obj.get("pcd_np") is not None:
        pts = np.asarray(obj["pcd_np"])
    if pts is None or pts.size == 0:
        return None, None
    pts = pts.reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centroid = tuple(float(x) for x in pts.mean(axis=0))
    return centroid, (tuple(float(x) for x in lo), tuple(float(x) for x in hi))

"""A frame's detections routed before its geometric merges give what routing each detection right
before its own merge gave (issue #34).

The per-frame merges (``main``: ``merge_detections_to_objects``; ``ali-dev``: ``merge_obj_matches``)
route every detection of the frame first, then run ConceptGraphs' side of the frame (the tracker's
record of each new object, the geometric merges) in row order. The references below are the loops
as they were before: route a detection, merge it, route the next. Hypothesis draws frames (new
objects, matches with one or two candidates, objects the script appended itself, detections with
their own geometric label, a channel that reads the dict it is asked about, a merge that returns
the same dict or a new one) and checks that the saved graph (beliefs, provenance, node attributes;
event ids renamed in order of appearance), the labels, the map objects and the order of
ConceptGraphs' calls are the same.
"""

from __future__ import annotations

import json
import re
import uuid
from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
from sgbelief.adapters.conceptgraphs.generation_ali_dev import AliDevGeneration
from sgbelief.adapters.conceptgraphs.generation_base import NEG_INF, as_numpy, candidate_matrix, counter_update
from sgbelief.adapters.conceptgraphs.generation_main import MainGeneration
from sgbelief.graph.persistence import graph_to_dict

CLASSES = ["chair", "table", "sofa", "stool"]
EVENT_ID = re.compile(r'"e\d+"')


class InterleavedMain(MainGeneration):
    """``main`` with the loop as it was: each detection routed right before its merge."""

    def _assign(self, detection_list: Any, objects: Any, agg_sim: Any, threshold: float, merge_one: Any) -> Any:
        backend = self.backend
        touched = self.frame_start(objects)
        scores = as_numpy(agg_sim)
        n_rows = scores.shape[0]
        if scores.shape[1]:
            best_of, max_of = scores.argmax(axis=1).tolist(), scores.max(axis=1).tolist()
            cands = candidate_matrix(scores[:, :min(scores.shape[1], len(objects))], threshold)
        else:
            best_of, max_of, cands = [0] * n_rows, [NEG_INF] * n_rows, None
        for i in range(n_rows):
            det = detection_list[i]
            top = max_of[i]
            if top <= threshold or top == NEG_INF:
                objects.append(det)
                backend.frame_node(det)
                touched.add(len(objects) - 1)
                continue
            j = best_of[i]
            targets = backend.targets_for(scores[i], j, objects, threshold, touched,
                                          candidates=None if cands is None else cands[i])
            backend.route_detection(det, targets)
            if id(objects[j]) in backend.queued_dicts:  # a queued claim still reads this dict: apply first
                backend.flush()
            objects[j] = merge_one(objects[j], det)
            self.merged.add(id(objects[j]))
        self.sync_labels(objects, touched)
        backend.end_frame()
        return objects


class InterleavedAliDev(AliDevGeneration):
    """``ali-dev`` with the loop as it was: each detection routed right before its merge."""

    def _merge_obj_matches(self, detection_list: Any, objects: Any, match_indices: list, downsample_voxel_size: float,
                           dbscan_remove_noise: bool, dbscan_eps: float, dbscan_min_points: int,
                           spatial_sim_type: str, device: Any) -> Any:
        backend = self.backend
        last = self.last_match
        sims = None
        if last is not None and last[1] is match_indices:
            sims = as_numpy(last[0]) if last[3] is None else np.asarray(last[3], dtype=float)
        thr = last[2] if sims is not None else NEG_INF
        n_before = len(objects)
        touched = self.frame_start(objects)
        cands = candidate_matrix(sims[:, :n_before], thr) if sims is not None and sims.ndim == 2 else None
        tracker = self.helper("tracker")
        count_before = getattr(tracker, "curr_object_count", 0) if tracker is not None else 0
        for i, j in enumerate(match_indices):
            det = detection_list[i]
            if j is None:
                if tracker is not None:
                    counter_update(lambda: tracker.object_dict.update(
                        {"id": det["id"], "first_discovered": tracker.curr_frame_idx}))
                objects.append(det)
                backend.frame_node(det)
                touched.add(len(objects) - 1)
                continue
            if sims is not None:
                targets = backend.targets_for(sims[i][:n_before], j, objects, thr, touched,
                                              candidates=None if cands is None else cands[i])
            else:
                targets = {backend.frame_node(objects[j]): 1.0}
                touched.add(j)
            backend.route_detection(det, targets)
            if id(objects[j]) in backend.queued_dicts:  # a queued claim still reads this dict: apply first
                backend.flush()
            objects[j] = self.geo_merge(objects[j], det, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                                        dbscan_min_points, spatial_sim_type, device, False)
            self.merged.add(id(objects[j]))
        if tracker is not None:
            counter_update(lambda: tracker.increment_total_merges(len(match_indices) - match_indices.count(None)))
            counter_update(lambda: tracker.increment_total_objects(len(objects) - count_before))
        self.sync_labels(objects, touched)
        backend.end_frame()
        return objects


class Tracker:
    """ConceptGraphs' MappingTracker as far as the merges use it; records every call in order."""

    def __init__(self, log: list) -> None:
        self.log = log
        self.curr_frame_idx = 0
        self.curr_object_count = 0
        self.object_dict = self

    def update(self, entry: dict) -> None:
        self.log.append(("new", str(entry["id"])))

    def increment_total_merges(self, n: int) -> None:
        self.log.append(("merges", n))

    def increment_total_objects(self, n: int) -> None:
        self.log.append(("objects", n))


def _det(k: int, t: int, cls: int, conf: float, label: str | None, uid: bool) -> dict:
    rng = np.random.default_rng(k)
    d: dict[str, Any] = {"image_idx": [t], "mask_idx": [k], "color_path": [f"f{t}.jpg"], "class_id": [cls],
                         "class_name": [CLASSES[cls]], "conf": [conf], "num_detections": 1,
                         "pcd_np": rng.random((4, 3)) + k}
    if uid:
        d = {"id": uuid.UUID(int=k + 1), **d}
    if label is not None:
        d["geometric_label"] = label
    return d


def _merge(log: list, fresh: bool) -> Any:
    """A geometric merge: per-detection lists concatenated, points stacked; ``fresh``: returns a new dict."""

    def merge(obj1: dict, obj2: dict) -> dict:
        log.append(("merge", obj1["mask_idx"][0], obj2["mask_idx"][0]))
        for key in ("image_idx", "mask_idx", "color_path", "class_id", "class_name", "conf"):
            if isinstance(obj1[key], list):  # ali-dev's class_name is the object's label, kept
                obj1[key] = obj1[key] + list(obj2[key])
        obj1["num_detections"] += obj2["num_detections"]
        obj1["pcd_np"] = np.vstack([obj1["pcd_np"], obj2["pcd_np"]])
        return dict(obj1) if fresh else obj1

    return merge


#: a detection: (matched object or None, second candidate or None, class, confidence, own label)
det_st = st.tuples(st.one_of(st.none(), st.integers(0, 9)), st.one_of(st.none(), st.integers(0, 9)),
                   st.integers(0, 3), st.sampled_from([0.3, 0.6, 0.9]),
                   st.one_of(st.none(), st.sampled_from(CLASSES)))
frames_st = st.lists(st.lists(det_st, min_size=1, max_size=6), min_size=1, max_size=4)


def _track_queued_dicts(backend: ConceptGraphsBackend) -> None:
    """The bookkeeping the interleaved loops relied on: ``backend.queued_dicts`` holds the ids of
    the dicts whose claims are queued (their channels read them when the queue is applied)."""
    queued: set[int] = set()
    route, route_own, flush = backend.route_detection, backend._route_own, backend.flush

    def routed(det: dict, targets: Any) -> int:
        n = route(det, targets)
        if n and backend._pending:
            queued.add(id(det))
        return n

    def routed_own(det: dict, node: Any) -> int:  # a new object's own claims (the registration's path)
        n = route_own(det, node)
        if n and backend._pending:
            queued.add(id(det))
        return n

    def flushed() -> None:
        queued.clear()
        flush()

    backend.queued_dicts = queued  # type: ignore[attr-defined]
    backend.route_detection = routed  # type: ignore[method-assign]
    backend._route_own = routed_own  # type: ignore[method-assign]
    backend.flush = flushed  # type: ignore[method-assign]


def _channel(det: dict, node: Any, t: int) -> str | None:
    """A channel reading the dict it is asked about (a map object's last class, after a merge too)."""
    names = det.get("class_name")
    return names[-1] if names and len(names) % 2 else None


def _run(generation: str, interleaved: bool, frames: list, n_start: int, fresh: bool, channel: bool,
         uid: bool, targeting: str = "merge") -> tuple:
    backend = ConceptGraphsBackend("comod", context="t", class_names=CLASSES, print_summary=False,
                                   channel=_channel if channel else None, targeting=targeting)
    if interleaved:
        _track_queued_dicts(backend)
    log: list = []
    merge = _merge(log, fresh)
    k = 0
    objects: list[dict] = []
    for _ in range(n_start):  # appended by the script itself: registered at the first per-frame merge
        objects.append(_det(k, 0, k % len(CLASSES), 0.8, None, uid))
        k += 1
    if generation == "main":
        cls = InterleavedMain if interleaved else MainGeneration
        f = cls(backend, {"merge_obj2_into_obj1": lambda cfg, a, b, run_dbscan=True: merge(a, b)})
    else:
        cls = InterleavedAliDev if interleaved else AliDevGeneration

        def ali_merge(obj1: dict, obj2: dict, **_: Any) -> dict:
            return merge(obj1, obj2)

        f = cls(backend, {"merge_obj2_into_obj1": ali_merge}, {"tracker": Tracker(log)})
    labels = []
    for t, frame in enumerate(frames, start=1):
        n = len(objects)
        if not n:  # as the scripts do: the first detections seed the map without a per-frame merge
            objects.extend(_det(k + i, t, c, conf, None, uid) for i, (_, _, c, conf, _) in enumerate(frame))
            k += len(frame)
            continue
        scores = np.full((len(frame), n), NEG_INF)
        dets = []
        for i, (j, j2, c, conf, label) in enumerate(frame):
            if j is not None and n:
                scores[i, j % n] = 1.5
                if j2 is not None and j2 % n != j % n:
                    scores[i, j2 % n] = 1.2
            dets.append(_det(k, t, c, conf, label, uid))
            k += 1
        if generation == "main":
            objects = f.merge_detections_to_objects(None, dets, objects, scores)
        else:
            match = f.match_detections_to_objects(scores, 0.0)
            objects = f.merge_obj_matches(detection_list=dets, objects=objects, match_indices=match,
                                          downsample_voxel_size=0.01, dbscan_remove_noise=False, dbscan_eps=0.1,
                                          dbscan_min_points=5, spatial_sim_type="iou", device="cpu")
        labels.append([backend.label_of(o) for o in objects])
    backend.flush()
    names: dict[str, str] = {}
    saved = EVENT_ID.sub(lambda m: names.setdefault(m.group(0), f'"ev{len(names)}"'),
                         json.dumps(graph_to_dict(backend.graph), sort_keys=True, default=str))
    mapped = [{key: (v.tolist() if isinstance(v, np.ndarray) else v) for key, v in o.items() if key != "id"}
              for o in objects]
    return saved, labels, repr(mapped), log, repr(backend.summary(objects))


@settings(max_examples=120, deadline=None)
@given(frames=frames_st, n_start=st.integers(0, 4), fresh=st.booleans(), channel=st.booleans(), uid=st.booleans(),
       generation=st.sampled_from(["main", "ali-dev"]), targeting=st.sampled_from(["merge", "spread"]))
def test_routing_the_frame_before_its_merges_equals_routing_each_detection_before_its_merge(
        frames: list, n_start: int, fresh: bool, channel: bool, uid: bool, generation: str, targeting: str) -> None:
    uid = uid or generation == "ali-dev"  # ali-dev's detections carry a uuid
    plain = _run(generation, True, frames, n_start, fresh, channel, uid, targeting)
    deferred = _run(generation, False, frames, n_start, fresh, channel, uid, targeting)
    assert deferred[0] == plain[0]  # graph: beliefs, provenance, node attributes
    assert deferred[1:] == plain[1:]  # labels, map objects, ConceptGraphs' calls in order


def test_a_frame_routes_every_detection_before_the_first_merge() -> None:
    backend = ConceptGraphsBackend("comod", context="t", class_names=CLASSES, print_summary=False)
    order: list = []
    route, route_own = backend.route_detection, backend._route_own

    def routed(det: dict, targets: Any) -> int:
        order.append(("route", det["mask_idx"][0]))
        return route(det, targets)

    def routed_own(det: dict, node: Any) -> int:  # a new object's own claims
        order.append(("route", det["mask_idx"][0]))
        return route_own(det, node)

    backend.route_detection = routed  # type: ignore[method-assign]
    backend._route_own = routed_own  # type: ignore[method-assign]
    f = MainGeneration(backend, {"merge_obj2_into_obj1": lambda cfg, a, b, run_dbscan=True:
                                 order.append(("merge", b["mask_idx"][0])) or a})
    objects = [_det(k, 0, 0, 0.8, None, False) for k in range(2)]
    objects = f.merge_detections_to_objects(None, objects[:0], objects, np.zeros((0, 2)))  # registers the map
    order.clear()
    dets = [_det(10 + i, 1, 1, 0.7, None, False) for i in range(3)]
    f.merge_detections_to_objects(None, dets, objects, np.array([[1.5, NEG_INF], [NEG_INF, NEG_INF], [NEG_INF, 1.5]]))
    assert order == [("route", 10), ("route", 11), ("route", 12), ("merge", 10), ("merge", 12)]

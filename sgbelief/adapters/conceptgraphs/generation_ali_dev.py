"""Replacements for ConceptGraphs' ``ali-dev`` branch (``streamlined_mapping.py`` /
``rerun_realtime_mapping.py``): explicit keyword parameters, ``match_detections_to_objects`` +
``merge_obj_matches``, labels in ``obj['class_name']``.

Each method keeps ConceptGraphs' signature and return contract, does the geometric work through the
captured original (else through :mod:`.geometry`) and routes every detection's claims into the
beliefs. Map objects are replaced in the list by :class:`BeliefLabelledObject`, which holds the
belief label, so the script's per-frame ``Counter`` relabel loop cannot overwrite it.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from sgbelief.adapters.conceptgraphs import geometry as geo
from sgbelief.adapters.conceptgraphs.generation_base import (
    NEG_INF,
    BeliefLabelledObject,
    GenerationFunctions,
    as_numpy,
    candidate_matrix,
    counter_update,
    same_list_type,
)


class AliDevGeneration(GenerationFunctions):
    """ConceptGraphs ``ali-dev``: ``merge_obj2_into_obj1(obj1, obj2, downsample_voxel_size, ...)`` and friends."""

    generation = "ali-dev"
    replaced_names = ("merge_obj2_into_obj1", "match_detections_to_objects", "merge_obj_matches",
                      "merge_detections_to_objects", "merge_overlap_objects", "merge_objects", "filter_objects")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        #: (agg_sim, match indices, threshold, agg_sim as a numpy array or None) of the last match
        #: call, read by merge_obj_matches
        self.last_match: tuple[Any, list, float, Any] | None = None
        #: node -> the labelled object standing for it in the map list (weak: dropped objects go)
        self.labelled: weakref.WeakValueDictionary[Any, BeliefLabelledObject] = weakref.WeakValueDictionary()

    def write_labels(self, objects: Any, seen: list[tuple[int, Any]], changed: set[Any]) -> None:
        """Adopt the objects just registered as :class:`BeliefLabelledObject` and relabel them,
        then relabel the other objects whose beliefs changed (a merge, a queue resolution)."""
        backend = self.backend
        labelled = self.labelled
        graph = backend.graph
        for k, node in seen:
            obj = objects[k]
            if not isinstance(obj, BeliefLabelledObject):
                obj = BeliefLabelledObject(obj, backend)
                backend.identity.rebind(obj, node)
                objects[k] = obj
            labelled[node] = obj
            obj.set_belief_label(backend.node_label(node) if node in graph else None)
            changed.discard(node)
        for node in changed:
            obj = labelled.get(node)
            if obj is not None:
                obj.set_belief_label(backend.label_of(obj))

    def geo_merge(self, obj1: dict, obj2: dict, downsample_voxel_size: float, dbscan_remove_noise: bool,
                  dbscan_eps: float, dbscan_min_points: int, spatial_sim_type: str, device: Any,
                  run_dbscan: bool) -> dict:
        """The geometric merge of ``obj2`` into ``obj1`` only (no beliefs)."""
        orig = self.original("merge_obj2_into_obj1")
        if orig is not None:
            return orig(obj1=obj1, obj2=obj2, downsample_voxel_size=downsample_voxel_size,
                        dbscan_remove_noise=dbscan_remove_noise, dbscan_eps=dbscan_eps,
                        dbscan_min_points=dbscan_min_points, spatial_sim_type=spatial_sim_type,
                        device=device, run_dbscan=run_dbscan)
        return geo.merge_into(obj1, obj2, voxel=downsample_voxel_size, dbscan=dbscan_remove_noise, eps=dbscan_eps,
                              min_points=dbscan_min_points, spatial_sim_type=spatial_sim_type, device=device,
                              run_dbscan=run_dbscan, strict_keys=True)

    def merge_obj2_into_obj1(self, obj1: dict, obj2: dict, downsample_voxel_size: float, dbscan_remove_noise: bool,
                             dbscan_eps: float, dbscan_min_points: int, spatial_sim_type: str, device: Any,
                             run_dbscan: bool = True) -> dict:
        """ConceptGraphs ``ali-dev`` signature; obj2's claims (or node) migrate into obj1's node."""
        self.backend.migrate(obj1, obj2)
        out = self.geo_merge(obj1, obj2, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                             dbscan_min_points, spatial_sim_type, device, run_dbscan)
        self.backend.refresh_geometry(out)
        return out

    def match_detections_to_objects(self, agg_sim: Any, detection_threshold: float = NEG_INF) -> list[int | None]:
        """Index of the best object per detection, or None when its best score <= threshold.

        ConceptGraphs' own loop asks torch for each row's max and argmax; here the matrix is
        converted once (kept for :meth:`merge_obj_matches`) and reduced row-wise in numpy, in the
        matrix's own dtype (a float32 score equal to the threshold compares as it does in torch;
        ties and NaN rows give the first index, as torch's argmax does)."""
        scores = as_numpy(agg_sim, keep_dtype=True)
        if scores.ndim != 2 or scores.shape[1] == 0:  # torch's own errors for what it rejects
            out: list[int | None] = []
            for i in range(agg_sim.shape[0]):
                if agg_sim[i].max() <= detection_threshold:
                    out.append(None)
                else:
                    out.append(int(agg_sim[i].argmax().item()))
            self.last_match = (agg_sim, out, float(detection_threshold), None)
            return out
        best = scores.argmax(axis=1).tolist()
        below = (scores.max(axis=1) <= scores.dtype.type(detection_threshold)).tolist()
        out = [None if b else j for j, b in zip(best, below)]
        self.last_match = (agg_sim, out, float(detection_threshold), scores)
        return out

    def merge_obj_matches(self, detection_list: Any, objects: Any, match_indices: list, downsample_voxel_size: float,
                          dbscan_remove_noise: bool, dbscan_eps: float, dbscan_min_points: int,
                          spatial_sim_type: str, device: Any) -> Any:
        """Merge matched detections (beliefs spread with the scores of the last match call)."""
        backend = self.backend
        # the frame's events in one update_many call; each object resolved to its node once
        with backend.batch(), backend.frame_lookups():
            return self._merge_obj_matches(detection_list, objects, match_indices, downsample_voxel_size,
                                           dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type,
                                           device)

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
        # the targeting candidates of every row at once (see MapBeliefs.targets_for)
        cands = candidate_matrix(sims[:, :n_before], thr) if (
            backend.targeting == "spread" and sims is not None and sims.ndim == 2) else None
        tracker = self.helper("tracker")
        count_before = getattr(tracker, "curr_object_count", 0) if tracker is not None else 0
        rows: list[tuple[int | None, dict]] = []  # (match, detection), in row order
        for i, j in enumerate(match_indices):
            det = detection_list[i]
            rows.append((j, det))
            if j is None:
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

        def record_new(det: dict) -> None:  # as ConceptGraphs' merge_obj_matches does
            counter_update(lambda: tracker.object_dict.update(
                {"id": det["id"], "first_discovered": tracker.curr_frame_idx}))

        self.merge_pass(objects, rows,
                        lambda o, d: self.geo_merge(o, d, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                                                    dbscan_min_points, spatial_sim_type, device, False),
                        record_new if tracker is not None else None)
        if tracker is not None:  # ConceptGraphs' MappingTracker counters, updated as the original does
            counter_update(lambda: tracker.increment_total_merges(len(match_indices) - match_indices.count(None)))
            counter_update(lambda: tracker.increment_total_objects(len(objects) - count_before))
        self.sync_labels(objects, touched)
        backend.end_frame()
        return objects

    def merge_detections_to_objects(self, downsample_voxel_size: float, dbscan_remove_noise: bool, dbscan_eps: float,
                                    dbscan_min_points: int, spatial_sim_type: str, device: Any, match_method: str,
                                    phys_bias: float, detection_list: Any, objects: Any, agg_sim: Any) -> Any:
        return self.assign(detection_list, objects, agg_sim, NEG_INF, lambda o, d: self.geo_merge(
            o, d, downsample_voxel_size, dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type,
            device, False))

    def merge_overlap_objects(self, merge_overlap_thresh: float, merge_visual_sim_thresh: float,
                              merge_text_sim_thresh: float, objects: Any, overlap_matrix: Any,
                              downsample_voxel_size: float, dbscan_remove_noise: bool, dbscan_eps: float,
                              dbscan_min_points: int, spatial_sim_type: str, device: Any,
                              map_edges: Any = None) -> tuple[Any, list]:
        return self.overlap_merge_loop(
            objects, overlap_matrix, merge_overlap_thresh, merge_visual_sim_thresh, merge_text_sim_thresh,
            lambda a, b: self.geo_merge(a, b, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                                        dbscan_min_points, spatial_sim_type, device, True), use_text=False)

    def merge_objects(self, merge_overlap_thresh: float, merge_visual_sim_thresh: float, merge_text_sim_thresh: float,
                      objects: Any, downsample_voxel_size: float, dbscan_remove_noise: bool, dbscan_eps: float,
                      dbscan_min_points: int, spatial_sim_type: str, device: Any, do_edges: bool = False,
                      map_edges: Any = None) -> Any:
        if len(objects) == 0 or merge_overlap_thresh <= 0:
            return objects
        compute = self.helper("compute_overlap_matrix_general")
        overlap = (compute(objects_a=objects, objects_b=None, downsample_voxel_size=downsample_voxel_size)
                   if compute is not None else geo.overlap_matrix(objects, downsample_voxel_size))
        objects, index_updates = self.merge_overlap_objects(
            merge_overlap_thresh, merge_visual_sim_thresh, merge_text_sim_thresh, objects, overlap,
            downsample_voxel_size, dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type, device,
            map_edges=map_edges)
        if do_edges:
            map_edges.merge_update_indices(index_updates)
            map_edges.update_objects_list(objects)
            return objects, map_edges
        return objects

    def filter_objects(self, obj_min_points: int, obj_min_detections: int, objects: Any, map_edges: Any = None) -> Any:
        before = list(objects)
        orig = self.original("filter_objects")
        if orig is not None:
            out = orig(obj_min_points, obj_min_detections, objects, map_edges=map_edges)
        else:
            keep, index_map = [], {}
            for idx, obj in enumerate(objects):
                if len(obj["pcd"].points) >= obj_min_points and obj["num_detections"] >= obj_min_detections:
                    keep.append(obj)
                    index_map[idx] = len(keep) - 1
            out = same_list_type(objects)(keep)
            if map_edges and index_map:
                map_edges.update_indices(index_map, out)
        self.mark_removed(before, out)
        return out

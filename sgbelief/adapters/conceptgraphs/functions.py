"""Drop-in replacements for ConceptGraphs' mapping functions, one set per code generation.

``main`` (classic ``cfslam_pipeline_batch.py``): functions take ``cfg`` first.
``ali-dev`` (``streamlined_mapping.py`` / ``rerun_realtime_mapping.py``): explicit keyword params.
Each function keeps ConceptGraphs' signature and return contract, does the geometric work through
the original function when one was captured (else through :mod:`.geometry`), and routes every
detection's claim into the backend's belief graph.
"""

from __future__ import annotations

import copy
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from sgbelief.adapters.conceptgraphs import geometry as geo
from sgbelief.adapters.conceptgraphs.geometry import cfg_get

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.adapters.conceptgraphs.backend import ConceptGraphsBackend

NEG_INF = float("-inf")


class BeliefLabelledObject(dict):
    """An ``ali-dev`` map object whose ``class_name`` always holds the belief label.

    Writes to ``class_name`` (the pipeline's per-frame ``Counter`` relabel loop) are replaced by the
    label from the beliefs while the backend is active.  Copies and pickles are plain dicts, so
    saved maps never reference sgbelief.
    """

    __slots__ = ("_sgb_backend",)

    def __setitem__(self, key: Any, value: Any) -> None:
        backend = getattr(self, "_sgb_backend", None)
        if key == "class_name" and backend is not None and backend.active:
            label = backend.label_of(self)
            if label is not None:
                value = label
        dict.__setitem__(self, key, value)

    def __reduce_ex__(self, protocol: Any) -> Any:
        return (dict, (dict(self),))

    def __copy__(self) -> dict:
        return dict(self)

    def __deepcopy__(self, memo: dict) -> dict:
        return copy.deepcopy(dict(self), memo)


def _class_id_scalar(class_ids: Any, cid: int) -> Any:
    """``cid`` as the numpy scalar type ``np.unique(np.asarray(class_ids))`` would give (int64 if not integral)."""
    dtype = getattr(class_ids, "dtype", None)
    if not isinstance(dtype, np.dtype):  # a list (or a torch tensor, whose dtype is not numpy's)
        try:
            dtype = np.asarray(class_ids[0]).dtype
        except (IndexError, KeyError, TypeError):
            dtype = np.dtype(np.int64)
    return dtype.type(cid) if dtype.kind in "iu" else np.int64(cid)


def _log_only(fn: Any) -> None:
    """Run a ConceptGraphs logging-counter update; a tracker of another shape is not an error."""
    try:
        fn()
    except (AttributeError, KeyError, TypeError):
        pass


def _list_type(objects: Any) -> Any:
    from sgbelief.adapters.conceptgraphs.standins import MapObjectList

    cls = type(objects)
    return cls if issubclass(cls, list) and cls is not list else MapObjectList


def make_functions(backend: ConceptGraphsBackend, generation: str, originals: dict[str, Any] | None = None) -> SimpleNamespace:
    """Build the replacement functions for ``generation`` ('main' or 'ali-dev')."""
    if generation not in ("main", "ali-dev"):
        raise ValueError("generation must be 'main' or 'ali-dev'")

    def original(name: str) -> Any:
        if originals is not None and name in originals:
            return originals[name]
        patcher = backend._patcher
        return None if patcher is None else patcher.originals.get(name)

    def helper(name: str) -> Any:
        patcher = backend._patcher
        return None if patcher is None else patcher.helper(name)

    # ---------------------------------------------------------------- shared pieces
    def sync_labels(objects: Any, indices: Any = None) -> None:
        """Write the belief label into ``ali-dev`` objects' ``class_name`` (adopting the dict).

        ``indices``: only these list positions (the objects a frame's detections touched); the
        per-frame merges pass them, so a frame costs O(its detections), not O(map size)."""
        positions = range(len(objects)) if indices is None else sorted(i for i in indices if i < len(objects))
        backend._synced_len = len(objects)
        for k in positions:
            obj = objects[k]
            node = backend.ensure_node(obj)
            backend.refresh_geometry(obj)
            if generation != "ali-dev":
                continue
            if not isinstance(obj, BeliefLabelledObject):
                new = BeliefLabelledObject(obj)
                new._sgb_backend = backend
                backend.identity.rebind(new, node)
                objects[k] = new
                obj = new
            label = backend.label_of(obj)
            if label is not None:
                dict.__setitem__(obj, "class_name", label)

    def frame_start(objects: Any) -> set[int]:
        """The touched-index set for a per-frame merge, seeded with objects the script appended itself."""
        touched = backend._touched_idx
        touched.clear()
        start = backend._synced_len if backend._synced_len <= len(objects) else 0
        touched.update(range(start, len(objects)))
        return touched

    def mark_removed(before: list, after: Any) -> None:
        kept = {id(o) for o in after}
        for obj in before:
            if id(obj) not in kept:
                backend.mark_filtered(obj)

    # ---------------------------------------------------------------- geometry only
    def geo_merge_main(cfg: Any, obj1: dict, obj2: dict, run_dbscan: bool) -> dict:
        orig = original("merge_obj2_into_obj1")
        if orig is not None:
            return orig(cfg, obj1, obj2, run_dbscan=run_dbscan)
        return geo.merge_into(
            obj1, obj2, voxel=cfg_get(cfg, "downsample_voxel_size", 0.025),
            dbscan=bool(cfg_get(cfg, "dbscan_remove_noise", False)), eps=cfg_get(cfg, "dbscan_eps", 0.1),
            min_points=cfg_get(cfg, "dbscan_min_points", 10), spatial_sim_type=cfg_get(cfg, "spatial_sim_type", "iou"),
            device=cfg_get(cfg, "device", None), run_dbscan=run_dbscan, strict_keys=False)

    def geo_merge_ali(obj1: dict, obj2: dict, downsample_voxel_size: float, dbscan_remove_noise: bool,
                      dbscan_eps: float, dbscan_min_points: int, spatial_sim_type: str, device: Any,
                      run_dbscan: bool) -> dict:
        orig = original("merge_obj2_into_obj1")
        if orig is not None:
            return orig(obj1=obj1, obj2=obj2, downsample_voxel_size=downsample_voxel_size,
                        dbscan_remove_noise=dbscan_remove_noise, dbscan_eps=dbscan_eps,
                        dbscan_min_points=dbscan_min_points, spatial_sim_type=spatial_sim_type,
                        device=device, run_dbscan=run_dbscan)
        return geo.merge_into(obj1, obj2, voxel=downsample_voxel_size, dbscan=dbscan_remove_noise, eps=dbscan_eps,
                              min_points=dbscan_min_points, spatial_sim_type=spatial_sim_type, device=device,
                              run_dbscan=run_dbscan, strict_keys=True)

    def assign(detection_list: Any, objects: Any, agg_sim: Any, threshold: float, merge_one: Any) -> Any:
        """Shared association loop: new object when the row has no candidate, else spread + merge."""
        touched = frame_start(objects)
        for i in range(agg_sim.shape[0]):
            row = agg_sim[i]
            det = detection_list[i]
            if float(row.max()) <= threshold or float(row.max()) == NEG_INF:
                objects.append(det)
                backend.ensure_node(det)
                touched.add(len(objects) - 1)
                continue
            j = int(row.argmax())
            targets = backend.targets_for(row, j, objects, threshold)
            backend.route_detection(det, targets)
            objects[j] = merge_one(objects[j], det)
        sync_labels(objects, touched)
        backend.end_frame()
        return objects

    def overlap_merge_loop(objects: Any, overlap: np.ndarray, ratio_thresh: float, visual_thresh: float,
                           text_thresh: float, merge_one: Any, use_text: bool) -> tuple[Any, list]:
        x, y = np.asarray(overlap).nonzero()
        ratios = np.asarray(overlap)[x, y]
        order = np.argsort(ratios)[::-1]
        kept = np.ones(len(objects), dtype=bool)
        for i, j, ratio in zip(x[order], y[order], ratios[order]):
            if not ratio > ratio_thresh:
                break
            vis = geo.cosine(objects[i]["clip_ft"], objects[j]["clip_ft"])
            txt = geo.cosine(objects[i]["text_ft"], objects[j]["text_ft"]) if use_text else vis
            if vis > visual_thresh and txt > text_thresh and kept[j]:
                # as in ConceptGraphs, i is not checked for an earlier merge; the backend's
                # tombstones make sure its evidence still migrates only once
                backend.migrate(objects[j], objects[i])
                objects[j] = merge_one(objects[j], objects[i])
                kept[i] = False
        index_updates: list[int | None] = []
        cur = 0
        for keep in kept:
            index_updates.append(cur if keep else None)
            cur += int(keep)
        before = list(objects)
        new = _list_type(objects)([o for o, k in zip(objects, kept) if k])
        for obj, keep in zip(before, kept):
            if not keep:
                backend.identity.retire(backend.identity.lookup(obj) or "")
        sync_labels(new)
        return new, index_updates

    # ---------------------------------------------------------------- labels out (both)
    def get_most_common_class(self: Any) -> list:
        """Per object: class id from the beliefs (``unknown_class_id`` when nothing commits).

        Objects the backend never saw fall back to ConceptGraphs' majority vote.
        """
        classes = []
        for d in self:
            cid = backend.class_id_of(d) if backend.active else None
            if cid is None:
                values, counts = np.unique(np.asarray(d["class_id"]), return_counts=True)
                classes.append(values[np.argmax(counts)])
            else:
                # the dtype the vote would return, from one element: the per-frame cost must not
                # grow with the object's detection history
                classes.append(_class_id_scalar(d["class_id"], cid))
        return classes

    ns = SimpleNamespace(generation=generation, get_most_common_class=get_most_common_class,
                         sync_labels=sync_labels)

    if generation == "main":
        def merge_obj2_into_obj1(cfg, obj1, obj2, run_dbscan=True):  # noqa: ANN001, ANN202
            """ConceptGraphs ``main`` signature; obj2's claims (or node) migrate into obj1's node."""
            backend.migrate(obj1, obj2)
            out = geo_merge_main(cfg, obj1, obj2, run_dbscan)
            backend.refresh_geometry(out)
            return out

        def merge_detections_to_objects(cfg, detection_list, objects, agg_sim):  # noqa: ANN001, ANN202
            """Rows of -inf add a new object; otherwise merge into the argmax, beliefs spread over candidates."""
            return assign(detection_list, objects, agg_sim, NEG_INF,
                          lambda o, d: geo_merge_main(cfg, o, d, False))

        def merge_overlap_objects(cfg, objects, overlap_matrix):  # noqa: ANN001, ANN202
            new, _ = overlap_merge_loop(
                objects, overlap_matrix, cfg_get(cfg, "merge_overlap_thresh"), cfg_get(cfg, "merge_visual_sim_thresh"),
                cfg_get(cfg, "merge_text_sim_thresh"), lambda a, b: geo_merge_main(cfg, a, b, True), use_text=True)
            return new

        def merge_objects(cfg, objects):  # noqa: ANN001, ANN202
            if cfg_get(cfg, "merge_overlap_thresh", 0) > 0:
                compute = helper("compute_overlap_matrix")
                overlap = compute(cfg, objects) if compute is not None else geo.overlap_matrix(
                    objects, cfg_get(cfg, "downsample_voxel_size", 0.025))
                objects = merge_overlap_objects(cfg, objects, overlap)
            return objects

        def filter_objects(cfg, objects):  # noqa: ANN001, ANN202
            before = list(objects)
            orig = original("filter_objects")
            if orig is not None:
                out = orig(cfg, objects)
            else:
                out = _list_type(objects)([o for o in objects if len(o["pcd"].points) >= cfg_get(cfg, "obj_min_points")
                                           and o["num_detections"] >= cfg_get(cfg, "obj_min_detections")])
            mark_removed(before, out)
            return out

        ns.merge_obj2_into_obj1 = merge_obj2_into_obj1
        ns.merge_detections_to_objects = merge_detections_to_objects
        ns.merge_overlap_objects = merge_overlap_objects
        ns.merge_objects = merge_objects
        ns.filter_objects = filter_objects
        return ns

    # ---------------------------------------------------------------- ali-dev
    def merge_obj2_into_obj1(obj1, obj2, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,  # noqa: ANN001, ANN202
                             dbscan_min_points, spatial_sim_type, device, run_dbscan=True):
        """ConceptGraphs ``ali-dev`` signature; obj2's claims (or node) migrate into obj1's node."""
        backend.migrate(obj1, obj2)
        out = geo_merge_ali(obj1, obj2, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                            dbscan_min_points, spatial_sim_type, device, run_dbscan)
        backend.refresh_geometry(out)
        return out

    def match_detections_to_objects(agg_sim, detection_threshold=float("-inf")):  # noqa: ANN001, ANN202
        """Index of the best object per detection, or None when its best score <= threshold."""
        out: list[int | None] = []
        for i in range(agg_sim.shape[0]):
            if agg_sim[i].max() <= detection_threshold:
                out.append(None)
            else:
                out.append(int(agg_sim[i].argmax().item()))
        backend._last_match = (agg_sim, out, float(detection_threshold))
        return out

    def merge_obj_matches(detection_list, objects, match_indices, downsample_voxel_size,  # noqa: ANN001, ANN202
                          dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type, device):
        """Merge matched detections (beliefs spread with the scores of the last match call)."""
        last = backend._last_match
        sims = last[0] if last is not None and last[1] is match_indices else None
        thr = last[2] if sims is not None else NEG_INF
        n_before = len(objects)
        touched = frame_start(objects)
        tracker = helper("tracker")
        count_before = getattr(tracker, "curr_object_count", 0) if tracker is not None else 0
        for i, j in enumerate(match_indices):
            det = detection_list[i]
            if j is None:
                if tracker is not None:  # as ConceptGraphs' merge_obj_matches does
                    _log_only(lambda: tracker.object_dict.update(
                        {"id": det["id"], "first_discovered": tracker.curr_frame_idx}))
                objects.append(det)
                backend.ensure_node(det)
                touched.add(len(objects) - 1)
                continue
            if sims is not None:
                targets = backend.targets_for(sims[i][:n_before], j, objects, thr)
            else:
                targets = {backend.ensure_node(objects[j]): 1.0}
                touched.add(j)
            backend.route_detection(det, targets)
            objects[j] = geo_merge_ali(objects[j], det, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                                       dbscan_min_points, spatial_sim_type, device, False)
        if tracker is not None:  # ConceptGraphs' MappingTracker counters, updated as the original does
            _log_only(lambda: tracker.increment_total_merges(len(match_indices) - match_indices.count(None)))
            _log_only(lambda: tracker.increment_total_objects(len(objects) - count_before))
        sync_labels(objects, touched)
        backend.end_frame()
        return objects

    def merge_detections_to_objects(downsample_voxel_size, dbscan_remove_noise, dbscan_eps, dbscan_min_points,  # noqa: ANN001, ANN202
                                    spatial_sim_type, device, match_method, phys_bias, detection_list, objects,
                                    agg_sim):
        return assign(detection_list, objects, agg_sim, NEG_INF, lambda o, d: geo_merge_ali(
            o, d, downsample_voxel_size, dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type,
            device, False))

    def merge_overlap_objects(merge_overlap_thresh, merge_visual_sim_thresh, merge_text_sim_thresh, objects,  # noqa: ANN001, ANN202
                              overlap_matrix, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                              dbscan_min_points, spatial_sim_type, device, map_edges=None):
        return overlap_merge_loop(
            objects, overlap_matrix, merge_overlap_thresh, merge_visual_sim_thresh, merge_text_sim_thresh,
            lambda a, b: geo_merge_ali(a, b, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,
                                       dbscan_min_points, spatial_sim_type, device, True), use_text=False)

    def merge_objects(merge_overlap_thresh, merge_visual_sim_thresh, merge_text_sim_thresh, objects,  # noqa: ANN001, ANN202
                      downsample_voxel_size, dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type,
                      device, do_edges=False, map_edges=None):
        if len(objects) == 0 or merge_overlap_thresh <= 0:
            return objects
        compute = helper("compute_overlap_matrix_general")
        overlap = (compute(objects_a=objects, objects_b=None, downsample_voxel_size=downsample_voxel_size)
                   if compute is not None else geo.overlap_matrix(objects, downsample_voxel_size))
        objects, index_updates = merge_overlap_objects(
            merge_overlap_thresh, merge_visual_sim_thresh, merge_text_sim_thresh, objects, overlap,
            downsample_voxel_size, dbscan_remove_noise, dbscan_eps, dbscan_min_points, spatial_sim_type, device,
            map_edges=map_edges)
        if do_edges:
            map_edges.merge_update_indices(index_updates)
            map_edges.update_objects_list(objects)
            return objects, map_edges
        return objects

    def filter_objects(obj_min_points, obj_min_detections, objects, map_edges=None):  # noqa: ANN001, ANN202
        before = list(objects)
        orig = original("filter_objects")
        if orig is not None:
            out = orig(obj_min_points, obj_min_detections, objects, map_edges=map_edges)
        else:
            keep, index_map = [], {}
            for idx, obj in enumerate(objects):
                if len(obj["pcd"].points) >= obj_min_points and obj["num_detections"] >= obj_min_detections:
                    keep.append(obj)
                    index_map[idx] = len(keep) - 1
            out = _list_type(objects)(keep)
            if map_edges and index_map:
                map_edges.update_indices(index_map, out)
        mark_removed(before, out)
        return out

    ns.merge_obj2_into_obj1 = merge_obj2_into_obj1
    ns.match_detections_to_objects = match_detections_to_objects
    ns.merge_obj_matches = merge_obj_matches
    ns.merge_detections_to_objects = merge_detections_to_objects
    ns.merge_overlap_objects = merge_overlap_objects
    ns.merge_objects = merge_objects
    ns.filter_objects = filter_objects
    return ns

"""Replacements for ConceptGraphs' ``main`` branch (``cfslam_pipeline_batch.py``): ``cfg`` first.

Each method keeps ConceptGraphs' signature and return contract, does the geometric work through the
captured original (else through :mod:`.geometry`) and routes every detection's claims into the
beliefs. Labels leave through :meth:`get_most_common_class`, computed on demand.
"""

from __future__ import annotations

from typing import Any

from sgbelief.adapters.conceptgraphs import geometry as geo
from sgbelief.adapters.conceptgraphs.generation_base import NEG_INF, GenerationFunctions, same_list_type
from sgbelief.adapters.conceptgraphs.geometry import cfg_get


class MainGeneration(GenerationFunctions):
    """ConceptGraphs ``main``: ``merge_obj2_into_obj1(cfg, obj1, obj2, run_dbscan)`` and friends."""

    generation = "main"
    replaced_names = ("merge_obj2_into_obj1", "merge_detections_to_objects", "merge_overlap_objects",
                      "merge_objects", "filter_objects")

    def geo_merge(self, cfg: Any, obj1: dict, obj2: dict, run_dbscan: bool) -> dict:
        """The geometric merge of ``obj2`` into ``obj1`` only (no beliefs)."""
        orig = self.original("merge_obj2_into_obj1")
        if orig is not None:
            return orig(cfg, obj1, obj2, run_dbscan=run_dbscan)
        return geo.merge_into(
            obj1, obj2, voxel=cfg_get(cfg, "downsample_voxel_size", 0.025),
            dbscan=bool(cfg_get(cfg, "dbscan_remove_noise", False)), eps=cfg_get(cfg, "dbscan_eps", 0.1),
            min_points=cfg_get(cfg, "dbscan_min_points", 10), spatial_sim_type=cfg_get(cfg, "spatial_sim_type", "iou"),
            device=cfg_get(cfg, "device", None), run_dbscan=run_dbscan, strict_keys=False)

    def merge_obj2_into_obj1(self, cfg: Any, obj1: dict, obj2: dict, run_dbscan: bool = True) -> dict:
        """ConceptGraphs ``main`` signature; obj2's claims (or node) migrate into obj1's node."""
        self.backend.migrate(obj1, obj2)
        out = self.geo_merge(cfg, obj1, obj2, run_dbscan)
        self.backend.refresh_geometry(out)
        return out

    def merge_detections_to_objects(self, cfg: Any, detection_list: Any, objects: Any, agg_sim: Any) -> Any:
        """Rows of -inf add a new object; otherwise merge into the argmax, the claims routed by
        ``targeting`` (whole to the argmax, or spread over the candidates)."""
        return self.assign(detection_list, objects, agg_sim, NEG_INF,
                           lambda o, d: self.geo_merge(cfg, o, d, False))

    def merge_overlap_objects(self, cfg: Any, objects: Any, overlap_matrix: Any) -> Any:
        new, _ = self.overlap_merge_loop(
            objects, overlap_matrix, cfg_get(cfg, "merge_overlap_thresh"), cfg_get(cfg, "merge_visual_sim_thresh"),
            cfg_get(cfg, "merge_text_sim_thresh"), lambda a, b: self.geo_merge(cfg, a, b, True), use_text=True)
        return new

    def merge_objects(self, cfg: Any, objects: Any) -> Any:
        if cfg_get(cfg, "merge_overlap_thresh", 0) > 0:
            compute = self.helper("compute_overlap_matrix")
            overlap = compute(cfg, objects) if compute is not None else geo.overlap_matrix(
                objects, cfg_get(cfg, "downsample_voxel_size", 0.025))
            objects = self.merge_overlap_objects(cfg, objects, overlap)
        return objects

    def filter_objects(self, cfg: Any, objects: Any) -> Any:
        before = list(objects)
        orig = self.original("filter_objects")
        if orig is not None:
            out = orig(cfg, objects)
        else:
            out = same_list_type(objects)([o for o in objects if len(o["pcd"].points) >= cfg_get(cfg, "obj_min_points")
                                           and o["num_detections"] >= cfg_get(cfg, "obj_min_detections")])
        self.mark_removed(before, out)
        return out

"""A stand-in ``conceptgraph`` package (main generation) for the adapter tests.

Module layout and names follow ConceptGraphs: ``conceptgraph.slam.{slam_classes,utils,mapping}`` and
a pipeline module that binds the functions with ``from ... import``.  The functions implement the
original behaviour (majority vote, no beliefs); the geometric work uses sgbelief's implementation.
"""

from __future__ import annotations

import sys
import types

import numpy as np

from sgbelief.adapters.conceptgraphs import geometry as geo

NAMES = ("conceptgraph", "conceptgraph.slam", "conceptgraph.slam.slam_classes", "conceptgraph.slam.utils",
         "conceptgraph.slam.mapping", "conceptgraph.slam.cfslam_pipeline_batch")


class DetectionList(list):
    """Like ConceptGraphs' own: a bare list subclass (rejects keyword arguments)."""

    def get_most_common_class(self):
        out = []
        for d in self:
            values, counts = np.unique(np.asarray(d["class_id"]), return_counts=True)
            out.append(values[np.argmax(counts)])
        return out


class MapObjectList(DetectionList):
    pass


def merge_obj2_into_obj1(cfg, obj1, obj2, run_dbscan=True):
    return geo.merge_into(obj1, obj2, voxel=cfg.downsample_voxel_size, dbscan=cfg.dbscan_remove_noise,
                          eps=cfg.dbscan_eps, min_points=cfg.dbscan_min_points,
                          spatial_sim_type=cfg.spatial_sim_type, device=cfg.device, run_dbscan=run_dbscan)


def merge_overlap_objects(cfg, objects, overlap_matrix):
    x, y = overlap_matrix.nonzero()
    ratio = overlap_matrix[x, y]
    order = np.argsort(ratio)[::-1]
    kept = np.ones(len(objects), dtype=bool)
    for i, j, r in zip(x[order], y[order], ratio[order]):
        if r > cfg.merge_overlap_thresh:
            if geo.cosine(objects[i]["clip_ft"], objects[j]["clip_ft"]) > cfg.merge_visual_sim_thresh and \
                    geo.cosine(objects[i]["text_ft"], objects[j]["text_ft"]) > cfg.merge_text_sim_thresh:
                if kept[j]:
                    objects[j] = merge_obj2_into_obj1(cfg, objects[j], objects[i], run_dbscan=True)
                    kept[i] = False
        else:
            break
    return MapObjectList([o for o, k in zip(objects, kept) if k])


def compute_overlap_matrix(cfg, objects):
    return geo.overlap_matrix(objects, cfg.downsample_voxel_size)


def merge_objects(cfg, objects):
    if cfg.merge_overlap_thresh > 0:
        objects = merge_overlap_objects(cfg, objects, compute_overlap_matrix(cfg, objects))
    return objects


def filter_objects(cfg, objects):
    return MapObjectList([o for o in objects if len(o["pcd"].points) >= cfg.obj_min_points
                          and o["num_detections"] >= cfg.obj_min_detections])


def merge_detections_to_objects(cfg, detection_list, objects, agg_sim):
    for i in range(agg_sim.shape[0]):
        if agg_sim[i].max() == float("-inf"):
            objects.append(detection_list[i])
        else:
            j = agg_sim[i].argmax()
            objects[j] = merge_obj2_into_obj1(cfg, objects[j], detection_list[i], run_dbscan=False)
    return objects


#: the class list the stand-in run loads (ConceptGraphs reads it from the dataset's classes json)
CLASSES = ["unlabelled", "chair", "table", "sofa"]


def create_or_load_colors(cfg, filename="gsa_classes_tag2text"):
    """ConceptGraphs main's loader: (class names, class colours)."""
    return list(CLASSES), {str(k): [0.5, 0.5, 0.5] for k in range(len(CLASSES))}


def install() -> dict[str, types.ModuleType]:
    """Register the stand-in modules in ``sys.modules`` and return them."""
    mods = {n: types.ModuleType(n) for n in NAMES}
    sc, ut, mp, pipe = (mods["conceptgraph.slam.slam_classes"], mods["conceptgraph.slam.utils"],
                        mods["conceptgraph.slam.mapping"], mods["conceptgraph.slam.cfslam_pipeline_batch"])
    sc.DetectionList, sc.MapObjectList = DetectionList, MapObjectList
    for name in ("merge_obj2_into_obj1", "merge_overlap_objects", "merge_objects", "filter_objects",
                 "compute_overlap_matrix", "create_or_load_colors"):
        setattr(ut, name, globals()[name])
    ut.MapObjectList = MapObjectList
    mp.merge_obj2_into_obj1 = merge_obj2_into_obj1
    mp.merge_detections_to_objects = merge_detections_to_objects
    mp.MapObjectList, mp.DetectionList = MapObjectList, DetectionList
    # the pipeline script's `from conceptgraph.slam.utils import ...` bindings
    for name in ("merge_obj2_into_obj1", "filter_objects", "merge_objects", "create_or_load_colors"):
        setattr(pipe, name, getattr(ut, name))
    pipe.merge_detections_to_objects = mp.merge_detections_to_objects
    pipe.MapObjectList, pipe.DetectionList = MapObjectList, DetectionList
    _SAVED.append({n: sys.modules[n] for n in NAMES if n in sys.modules})
    sys.modules.update(mods)
    return mods


#: the modules the stand-ins replaced (a real checkout another test imported), restored by uninstall
_SAVED: list[dict[str, types.ModuleType]] = []


def uninstall() -> None:
    for n in NAMES:
        sys.modules.pop(n, None)
    if _SAVED:
        sys.modules.update(_SAVED.pop())

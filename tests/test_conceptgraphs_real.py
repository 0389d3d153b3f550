"""The same checks against the real ``conceptgraph`` package, when it is importable (skipped otherwise)."""

from __future__ import annotations

import copy
import inspect
import sys
from collections import Counter

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("open3d")
cg_utils = pytest.importorskip("conceptgraph.slam.utils")
cg_mapping = pytest.importorskip("conceptgraph.slam.mapping")
cg_classes = pytest.importorskip("conceptgraph.slam.slam_classes")

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend  # noqa: E402
from sgbelief.adapters.conceptgraphs.standins import make_detection  # noqa: E402

GENERATION = "main" if list(inspect.signature(cg_utils.merge_obj2_into_obj1).parameters)[0] == "cfg" else "ali-dev"


def _cfg():
    from types import SimpleNamespace

    d = dict(downsample_voxel_size=0.05, dbscan_remove_noise=False, dbscan_eps=0.1, dbscan_min_points=10,
             spatial_sim_type="iou", device="cpu", merge_overlap_thresh=0.5, merge_visual_sim_thresh=0.5,
             merge_text_sim_thresh=0.5, obj_min_points=1, obj_min_detections=1)
    try:
        from omegaconf import OmegaConf

        return OmegaConf.create(d)
    except ImportError:
        return SimpleNamespace(**d)


def _stream():
    feat = np.random.default_rng(7).normal(size=16)
    r = np.random.default_rng(1).random(40)
    out = []
    for k in range(40):
        is_table = k % 2 == 0 or k % 7 == 1
        cid, conf = (1, 0.5 + 0.15 * r[k]) if is_table else (0, 0.8 + 0.15 * r[k])
        pts = 0.2 * np.random.default_rng(k).random((120, 3))
        out.append(make_detection(pts, cid, ["chair", "table"][cid], conf, k, generation=GENERATION,
                                  feature=feat, seed=k))
    return out


def _drive(stream):
    objects = cg_classes.MapObjectList()
    c = _cfg()
    for det in stream:
        if not objects:
            objects.append(det)
            continue
        dl = cg_classes.DetectionList([det])
        sims = torch.tensor([[1.5]])
        if GENERATION == "main":
            objects = cg_mapping.merge_detections_to_objects(c, dl, objects, sims)
        else:
            idx = cg_mapping.match_detections_to_objects(sims, 1.1)
            objects = cg_mapping.merge_obj_matches(dl, objects, idx, 0.05, False, 0.1, 10, "iou", "cpu")
    return objects


def test_real_package_patch_contract_labels_and_restore():
    originals = {n: getattr(cg_utils, n) for n in ("merge_obj2_into_obj1", "merge_objects", "filter_objects")}
    ref = _drive(copy.deepcopy(_stream()))
    backend = ConceptGraphsBackend("comod", class_names=["chair", "table"], channel=lambda det, node, t: "chair")
    with backend.patch():
        assert backend.generation == GENERATION
        assert cg_mapping.merge_obj2_into_obj1 is not originals["merge_obj2_into_obj1"]
        ours = _drive(copy.deepcopy(_stream()))
        assert len(ours) == len(ref) == 1
        assert list(ours[0]["class_id"]) == list(ref[0]["class_id"])
        assert ours[0]["num_detections"] == ref[0]["num_detections"]
        assert len(ours[0]["pcd"].points) == len(ref[0]["pcd"].points)
        assert backend.routed_detections == 40  # each detection routed once (comod may log a geometric
        # observation next to a claim, so the graph's evidence count can be larger)
        assert Counter(ours[0]["class_id"]).most_common(1)[0][0] == 1  # the vote says table
        if GENERATION == "main":
            assert list(ours.get_most_common_class()) == [0]
        else:
            assert ours[0]["class_name"] == "chair"
    for name, fn in originals.items():
        assert getattr(cg_utils, name) is fn
    assert all(getattr(m, "merge_obj2_into_obj1", None) in (None, originals["merge_obj2_into_obj1"])
               for n, m in list(sys.modules.items()) if n.startswith("conceptgraph") and m is not None)

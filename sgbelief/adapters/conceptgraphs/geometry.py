"""sgbelief's own implementation of ConceptGraphs' geometric merge (used when ``conceptgraph`` is absent).

Behaviour matched to ConceptGraphs' interfaces: per-detection lists are concatenated, counts are
added, the point clouds are concatenated, voxel-downsampled and (optionally) reduced to their
largest DBSCAN cluster, the box is recomputed (axis-aligned, or robust oriented for the
``*accurate`` / ``overlap`` similarity types), and ``clip_ft`` / ``text_ft`` become the
detection-count-weighted mean, L2-normalised.  Counts are read *before* they are added, so each
detection is weighted once.  torch and open3d are imported lazily.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

#: keys whose per-detection lists are concatenated by the merge
LIST_KEYS = ("image_idx", "mask_idx", "color_path", "class_id", "class_name", "mask", "xyxy", "conf",
             "n_points", "pixel_area", "contain_number", "captions")
COUNT_KEYS = ("num_detections", "num_obj_in_class")
KEEP_KEYS = ("id", "is_background", "new_counter", "curr_obj_num", "inst_color")
GEOMETRY_KEYS = ("pcd", "bbox", "clip_ft", "text_ft")


def cfg_get(cfg: Any, key: str, default: Any = None) -> Any:
    """Read ``key`` from a DictConfig, dict or attribute object."""
    if isinstance(cfg, dict):
        return cfg.get(key, default)
    try:
        return cfg[key]
    except (TypeError, KeyError, AttributeError):
        return getattr(cfg, key, default)


def geometry_summary(obj: Any) -> tuple[Any, Any]:
    """(centroid, (lo, hi) box corners) of a ConceptGraphs object's points (``pcd`` or ``pcd_np``),
    as tuples of floats, or (None, None) when it has none."""
    pts = None
    pcd = obj.get("pcd")
    if pcd is not None and (type(pcd) in _CLOUD_TYPES or _answers_bounds(pcd)):
        # an open3d cloud answers from its own buffers, without a copy into numpy (docs/performance.md)
        if not pcd.has_points():
            return None, None
        return _floats(pcd.get_center()), (_floats(pcd.get_min_bound()), _floats(pcd.get_max_bound()))
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


#: point-cloud classes whose instances answer ``get_min_bound`` / ``has_points`` (open3d's), found once
_CLOUD_TYPES: set[type] = set()


def _answers_bounds(pcd: Any) -> bool:
    """Whether ``pcd`` answers its bounds itself (an open3d cloud); the class is remembered when it
    defines both methods, so the check runs once per class, not once per summary."""
    cls = type(pcd)
    if hasattr(cls, "get_min_bound") and hasattr(cls, "has_points"):
        _CLOUD_TYPES.add(cls)
        return True
    return hasattr(pcd, "get_min_bound") and hasattr(pcd, "has_points")


def _floats(values: Any) -> tuple[float, ...]:
    """A coordinate vector as a tuple of Python floats (``tolist`` of an array: the same floats as
    ``float()`` of each element, without a generator)."""
    if type(values) is np.ndarray:
        return tuple(values.tolist())
    return tuple(float(x) for x in values)


def denoise_dbscan(pcd: Any, eps: float, min_points: int) -> Any:
    """Keep the largest DBSCAN cluster of ``pcd`` (unchanged when it would keep < 5 points)."""
    import open3d as o3d

    labels = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=min_points))
    counts = Counter(int(x) for x in labels if x != -1)
    if not counts:
        return pcd
    best = counts.most_common(1)[0][0]
    keep = labels == best
    if keep.sum() < 5:
        return pcd
    out = o3d.geometry.PointCloud()
    out.points = o3d.utility.Vector3dVector(np.asarray(pcd.points)[keep])
    if pcd.has_colors():
        out.colors = o3d.utility.Vector3dVector(np.asarray(pcd.colors)[keep])
    return out


def process_pcd(pcd: Any, voxel: float, dbscan: bool, eps: float, min_points: int, run_dbscan: bool = True) -> Any:
    """Voxel downsample, then optional DBSCAN denoising."""
    pcd = pcd.voxel_down_sample(voxel_size=voxel)
    if dbscan and run_dbscan:
        pcd = denoise_dbscan(pcd, eps, min_points)
    return pcd


def bounding_box(spatial_sim_type: str, pcd: Any) -> Any:
    """Oriented (robust) box for the accurate/overlap similarity types, axis-aligned otherwise."""
    if ("accurate" in spatial_sim_type or "overlap" in spatial_sim_type) and len(pcd.points) >= 4:
        try:
            return pcd.get_oriented_bounding_box(robust=True)
        except RuntimeError:
            return pcd.get_axis_aligned_bounding_box()
    return pcd.get_axis_aligned_bounding_box()


def _weighted_feature(f1: Any, f2: Any, n1: float, n2: float, device: Any = None) -> Any:
    import torch
    import torch.nn.functional as F

    a = f1 if isinstance(f1, torch.Tensor) else torch.as_tensor(np.asarray(f1))
    b = f2 if isinstance(f2, torch.Tensor) else torch.as_tensor(np.asarray(f2))
    if device is not None:
        a, b = a.to(device), b.to(device)
    mixed = (a * n1 + b.to(a.dtype) * n2) / (n1 + n2)
    return F.normalize(mixed, dim=0)


def merge_into(
    obj1: dict,
    obj2: dict,
    *,
    voxel: float,
    dbscan: bool,
    eps: float,
    min_points: int,
    spatial_sim_type: str,
    device: Any = None,
    run_dbscan: bool = True,
    strict_keys: bool = False,
) -> dict:
    """Merge ``obj2`` into ``obj1`` in place and return ``obj1``.

    ``strict_keys`` reproduces the ``ali-dev`` contract (ValueError on a key outside the known set);
    otherwise (``main``) lists are concatenated, ints added, and other unknown types rejected with
    NotImplementedError, as ConceptGraphs does.
    """
    known = set(LIST_KEYS) | set(COUNT_KEYS) | set(KEEP_KEYS) | set(GEOMETRY_KEYS) | {"caption"}
    if strict_keys:
        unknown = set(obj2) - known
        if unknown:
            raise ValueError(f"unhandled keys in obj2: {sorted(unknown)}")
    n1 = obj1["num_detections"]
    n2 = obj2["num_detections"]
    for key in list(obj1.keys()):
        if key in GEOMETRY_KEYS or key not in obj2:
            continue
        if key == "caption" and isinstance(obj1[key], dict):
            for k2, v2 in obj2[key].items():
                obj1[key][k2 + n1] = v2
        elif key in KEEP_KEYS:
            continue
        elif isinstance(obj1[key], list):
            obj1[key] += list(obj2[key])
        elif isinstance(obj1[key], int) and not isinstance(obj1[key], bool):
            obj1[key] += obj2[key]
        elif not strict_keys:
            raise NotImplementedError(f"cannot merge key {key!r} of type {type(obj1[key]).__name__}")
    merged = obj1["pcd"] + obj2["pcd"]
    obj1["pcd"] = process_pcd(merged, voxel, dbscan, eps, min_points, run_dbscan)
    if "n_points" in obj1 and not isinstance(obj1["n_points"], list):
        obj1["n_points"] = len(obj1["pcd"].points)
    obj1["bbox"] = bounding_box(spatial_sim_type, obj1["pcd"])
    obj1["bbox"].color = [0, 1, 0]
    obj1["clip_ft"] = _weighted_feature(obj1["clip_ft"], obj2["clip_ft"], n1, n2)
    if "text_ft" in obj1 and "text_ft" in obj2:
        obj1["text_ft"] = _weighted_feature(obj1["text_ft"], obj2["text_ft"], n1, n2, device)
    return obj1


def overlap_matrix(objects: list, voxel: float) -> np.ndarray:
    """(i, j) = fraction of points of object i within ``voxel`` of a point of object j (i != j)."""
    from scipy.spatial import cKDTree

    pts = [np.asarray(o["pcd"].points) for o in objects]
    trees = [cKDTree(p) if len(p) else None for p in pts]
    n = len(objects)
    out = np.zeros((n, n))
    for i in range(n):
        if not len(pts[i]):
            continue
        for j in range(n):
            if i == j or trees[j] is None:
                continue
            d, _ = trees[j].query(pts[i], k=1)
            out[i, j] = float((d < voxel).sum()) / len(pts[i])
    return out


def cosine(a: Any, b: Any) -> float:
    """Cosine similarity of two feature vectors (numpy or torch)."""
    x = np.asarray(a.detach().cpu().numpy() if hasattr(a, "detach") else a, dtype=float).ravel()
    y = np.asarray(b.detach().cpu().numpy() if hasattr(b, "detach") else b, dtype=float).ravel()
    den = float(np.linalg.norm(x) * np.linalg.norm(y))
    return float(x @ y) / den if den > 0 else 0.0

"""Stand-ins for ConceptGraphs' list classes and a builder for detection dicts with its real keys.

``DetectionList`` / ``MapObjectList`` are plain ``list`` subclasses that accept and ignore keyword
arguments (ConceptGraphs' scripts call ``MapObjectList(device=...)``, which its own classes reject
on Python >= 3.11).  :func:`majority_class` is ConceptGraphs' vote (most frequent id, ties to the
smallest), kept for comparisons.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np


class DetectionList(list):
    """List of detection dicts (ConceptGraphs-compatible helper methods)."""

    def __new__(cls, *args: Any, **kwargs: Any) -> DetectionList:
        return super().__new__(cls)

    def __init__(self, iterable: Iterable[Any] = (), **_ignored: Any) -> None:
        super().__init__(iterable)

    def get_values(self, key: str, idx: int | None = None) -> list:
        return [d[key] if idx is None else d[key][idx] for d in self]

    def get_stacked_values_torch(self, key: str, idx: int | None = None) -> Any:
        import torch

        values = []
        for d in self:
            v = d[key] if idx is None else d[key][idx]
            if hasattr(v, "get_box_points"):
                v = np.asarray(v.get_box_points())
            if isinstance(v, np.ndarray):
                v = torch.from_numpy(v)
            values.append(v)
        return torch.stack(values, dim=0)

    def get_stacked_values_numpy(self, key: str, idx: int | None = None) -> np.ndarray:
        return self.get_stacked_values_torch(key, idx).detach().cpu().numpy()

    def __add__(self, other: Iterable[Any]) -> DetectionList:
        out = copy.deepcopy(self)
        out.extend(other)
        return out

    def __iadd__(self, other: Iterable[Any]) -> DetectionList:
        self.extend(other)
        return self

    def slice_by_indices(self, index: Iterable[int]) -> DetectionList:
        return type(self)(self[i] for i in index)

    def slice_by_mask(self, mask: Iterable[bool]) -> DetectionList:
        return type(self)(d for d, m in zip(self, mask) if m)

    def get_most_common_class(self) -> list:
        return [majority_class(d["class_id"]) for d in self]


class MapObjectList(DetectionList):
    """List of map-object dicts."""

    def to_serializable(self) -> list[dict]:
        out = []
        for obj in self:
            s = copy.deepcopy(dict(obj))
            for key in ("clip_ft", "text_ft"):
                if key in s and hasattr(s[key], "detach"):
                    s[key] = s[key].detach().cpu().numpy()
            s["pcd_np"] = np.asarray(s["pcd"].points)
            s["bbox_np"] = np.asarray(s["bbox"].get_box_points())
            s["pcd_color_np"] = np.asarray(s["pcd"].colors)
            del s["pcd"], s["bbox"]
            out.append(s)
        return out


def majority_class(class_ids: Sequence[int]) -> Any:
    """ConceptGraphs' vote on ``main``: most frequent id, ties to the smallest."""
    values, counts = np.unique(np.asarray(class_ids), return_counts=True)
    return values[np.argmax(counts)]


def make_detection(
    points: np.ndarray,
    class_id: int,
    class_name: str,
    conf: float,
    image_idx: int,
    mask_idx: int = 0,
    *,
    generation: str = "main",
    feature: np.ndarray | None = None,
    spatial_sim_type: str = "iou",
    seed: int = 0,
) -> dict:
    """A one-detection dict with the keys ConceptGraphs' ``main`` or ``ali-dev`` pipeline produces."""
    import uuid

    import open3d as o3d
    import torch

    rng = np.random.default_rng(seed)
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.asarray(points, dtype=float))
    pcd.colors = o3d.utility.Vector3dVector(rng.random((len(points), 3)))
    if ("accurate" in spatial_sim_type or "overlap" in spatial_sim_type) and len(points) >= 4:
        bbox = pcd.get_oriented_bounding_box(robust=True)
    else:
        bbox = pcd.get_axis_aligned_bounding_box()
    bbox.color = [0, 1, 0]
    feat = rng.normal(size=16) if feature is None else np.asarray(feature, dtype=float)
    clip = torch.nn.functional.normalize(torch.as_tensor(feat, dtype=torch.float32), dim=0)
    mask = np.zeros((4, 4), dtype=bool)
    mask[1:3, 1:3] = True
    xyxy = np.array([1.0, 1.0, 3.0, 3.0])
    det: dict[str, Any] = {
        "image_idx": [image_idx],
        "mask_idx": [mask_idx],
        "color_path": [f"frame{image_idx:06d}.jpg"],
    }
    if generation == "main":
        det.update({
            "class_name": [class_name],
            "class_id": [class_id],
            "num_detections": 1,
            "mask": [mask],
            "xyxy": [xyxy],
            "conf": [np.float32(conf)],
            "n_points": [len(points)],
            "pixel_area": [int(mask.sum())],
            "contain_number": [None],
            "inst_color": rng.random(3),
            "is_background": False,
            "pcd": pcd,
            "bbox": bbox,
            "clip_ft": clip,
            "text_ft": clip.clone(),
        })
    else:
        det = {
            "id": uuid.UUID(int=int(rng.integers(1, 2**62)) * 1000 + image_idx * 10 + mask_idx),
            **det,
            "class_name": class_name,
            "class_id": [class_id],
            "captions": [{"id": str(mask_idx), "name": class_name, "caption": None}],
            "num_detections": 1,
            "mask": [mask],
            "xyxy": [xyxy],
            "conf": [np.float32(conf)],
            "n_points": len(points),
            "contain_number": [None],
            "inst_color": rng.random(3),
            "is_background": False,
            "pcd": pcd,
            "bbox": bbox,
            "clip_ft": clip,
            "num_obj_in_class": 0,
            "curr_obj_num": image_idx * 100 + mask_idx,
            "new_counter": 0,
        }
    return det

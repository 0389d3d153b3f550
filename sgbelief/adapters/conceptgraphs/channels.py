"""Geometric channels that read ConceptGraphs detection dicts: mesh labels from a detection's points."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np


class PointCloudChannel:
    """Labels a detection from its 3D points through ``points_channel.label_points(points)``.

    ``points_channel`` is e.g. :class:`sgbelief.adapters.scannet.ScanNetChannel` (ScanNet mesh labels,
    NYU40 names by default). A fresh detection's ``pcd`` holds that detection's own points; a merged
    map object's holds the object's (the offline import labels every claim of an object from it).
    The answer is cached per point cloud (identity and point count), so an object's claims cost one
    lookup. At most ``max_points`` points (evenly strided) are queried.
    """

    def __init__(self, points_channel: Any, *, max_points: int = 500, scene: Any = None,
                 map_to_mesh: Any = None) -> None:
        if not hasattr(points_channel, "label_points"):
            raise TypeError("points_channel needs a label_points(points) method (e.g. ScanNetChannel)")
        self.points_channel = points_channel
        #: 4 x 4 transform from the map's frame to the mesh's (None: the same frame)
        self.map_to_mesh = None if map_to_mesh is None else np.asarray(map_to_mesh, dtype=float).reshape(4, 4)
        self.max_points = int(max_points)
        self.scene = scene
        self._cache: dict[tuple[int, int], str | None] = {}
        self._keep: dict[int, Any] = {}

    def label_points(self, points: Any) -> str | None:
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(pts) == 0:
            return None
        if len(pts) > self.max_points:
            pts = pts[:: int(np.ceil(len(pts) / self.max_points))]
        if self.map_to_mesh is not None:
            pts = pts @ self.map_to_mesh[:3, :3].T + self.map_to_mesh[:3, 3]
        return self.points_channel.label_points(pts, self.scene) if self.scene is not None \
            else self.points_channel.label_points(pts)

    def label_detection(self, detection: Mapping[str, Any], index: int, t: int) -> str | None:
        pcd = detection.get("pcd")
        if pcd is None:
            pcd = detection.get("pcd_np")
            if pcd is None:
                return None
        pts = np.asarray(pcd.points) if hasattr(pcd, "points") else np.asarray(pcd)
        key = (id(pcd), len(pts))
        if key not in self._cache:
            if len(self._cache) > 4096:
                self._cache.clear()
                self._keep.clear()
            self._cache[key] = self.label_points(pts)
            self._keep[id(pcd)] = pcd  # hold the object so its id() is not reused while cached
        return self._cache[key]

    def label(self, node: Any, t: int) -> str | None:
        return None


def scannet_mesh_channel(scene_dir: str | Path, *, labels: Any = None, label_space: str = "nyu40",
                         max_distance: float = 0.05, first_pose: str | Path | None | bool = None,
                         **kwargs: Any) -> PointCloudChannel:
    """A :class:`PointCloudChannel` over the mesh labels of one ScanNet scene folder.

    ConceptGraphs' ScanNet loader reads the exported ``pose/*.txt`` (camera-to-mesh) and, with its
    default ``relative_pose=True``, expresses the map in the *first frame's* camera frame. The map is
    taken back to the mesh frame with that first pose: ``first_pose`` is its file (default:
    ``<scene_dir>/pose/0.txt`` when it exists; ``False``: the map is already in the mesh frame). The
    mesh is loaded without ScanNet's axis alignment (the poses are not axis-aligned).
    """
    from sgbelief.adapters.scannet import ScanNetChannel, load_scene

    scene = load_scene(scene_dir, labels, axis_align=False)
    transform = None
    if first_pose is None:
        cand = Path(scene_dir) / "pose" / "0.txt"
        first_pose = cand if cand.exists() else False
    if first_pose is not False:
        transform = np.loadtxt(str(first_pose)).reshape(4, 4)
    return PointCloudChannel(ScanNetChannel(scene, label_space=label_space, max_distance=max_distance),
                             map_to_mesh=transform, **kwargs)

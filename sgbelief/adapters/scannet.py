"""ScanNet v2 scenes: ground-truth objects from the mesh aggregation, and the indoor geometric
channel (the paper's "mesh-aggregation class labels" oracle).

A scene folder holds (names exactly as distributed by ScanNet; ``<id>`` is e.g. ``scene0000_00``)::

    <id>_vh_clean_2.ply                   mesh (vertices x y z + colours, faces), read with open3d
    <id>_vh_clean_2.0.010000.segs.json    {"segIndices": [segment id per mesh vertex], ...}
    <id>.aggregation.json                 {"segGroups": [{"objectId", "label", "segments"}, ...]}
        (or <id>_vh_clean.aggregation.json)

plus the dataset-wide label map ``scannetv2-labels.combined.tsv`` (columns include
``raw_category``, ``category``, ``nyu40id``, ``nyu40class``; looked up in the scene folder and its
parents unless given). ScanNet-20 labels are the NYU40 classes of the benchmark's 20 ids.

open3d is imported lazily, inside the functions that need it.
"""

from __future__ import annotations

import csv
import json
import warnings
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sgbelief.errors import FormatError

__all__ = [
    "LABELS_TSV",
    "SCANNET20_NYU40_IDS",
    "LabelEntry",
    "LabelMap",
    "ScanNetObject",
    "ScanNetScene",
    "ScanNetChannel",
    "load_label_map",
    "load_scene",
    "load_scenes",
    "find_label_map",
    "scene_files",
]

LABELS_TSV = "scannetv2-labels.combined.tsv"
#: NYU40 ids of the ScanNet-20 benchmark classes, in benchmark order.
SCANNET20_NYU40_IDS: tuple[int, ...] = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 14, 16, 24, 28, 33, 34, 36, 39)
LABEL_SPACES = ("nyu40", "raw", "category", "scannet20")


# --------------------------------------------------------------------------------------------
# label map
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LabelEntry:
    """One row of the label map: a raw annotation category and its mapped classes."""

    raw_category: str
    category: str
    nyu40_id: int | None
    nyu40_class: str | None
    scannet20_index: int | None  # 0..19 in SCANNET20_NYU40_IDS order, None outside the 20
    scannet20_class: str | None

    def label(self, space: str) -> str | None:
        """The label in ``space``: 'nyu40' | 'raw' | 'category' | 'scannet20'."""
        if space == "nyu40":
            return self.nyu40_class
        if space == "raw":
            return self.raw_category
        if space == "category":
            return self.category
        if space == "scannet20":
            return self.scannet20_class
        raise ValueError(f"unknown label space {space!r}; known: {list(LABEL_SPACES)}")


@dataclass
class LabelMap:
    """raw_category -> :class:`LabelEntry` (from ``scannetv2-labels.combined.tsv``)."""

    entries: dict[str, LabelEntry]
    path: Path | None = None

    def find(self, raw: str) -> LabelEntry | None:
        return self.entries.get(raw)

    def get(self, raw: str, *, where: str = "") -> LabelEntry:
        entry = self.entries.get(raw)
        if entry is None:
            raise FormatError(f"{where}label {raw!r} is not a raw_category of the label map "
                              f"{self.path or '(in memory)'} ({len(self.entries)} categories)")
        return entry

    def __contains__(self, raw: object) -> bool:
        return raw in self.entries

    def __len__(self) -> int:
        return len(self.entries)


def _int_or_none(text: str | None) -> int | None:
    text = (text or "").strip()
    if not text:
        return None
    try:
        return int(float(text))
    except ValueError:
        return None


def load_label_map(path: str | Path) -> LabelMap:
    """Read ``scannetv2-labels.combined.tsv`` (tab-separated, header row)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ScanNet label map not found: {path}")
    with path.open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh, delimiter="\t")
        header = reader.fieldnames or []
        missing = [c for c in ("raw_category", "nyu40id", "nyu40class") if c not in header]
        if missing:
            raise FormatError(f"label map header lacks column(s) {missing} (has {header})", path=path, line=1)
        entries: dict[str, LabelEntry] = {}
        for lineno, row in enumerate(reader, start=2):
            raw = (row.get("raw_category") or "").strip()
            if not raw:
                raise FormatError("empty raw_category", path=path, line=lineno)
            nid = _int_or_none(row.get("nyu40id"))
            ncls = (row.get("nyu40class") or "").strip() or None
            s20 = SCANNET20_NYU40_IDS.index(nid) if nid in SCANNET20_NYU40_IDS else None
            entries[raw] = LabelEntry(raw, (row.get("category") or raw).strip(), nid, ncls, s20,
                                      ncls if s20 is not None else None)
    return LabelMap(entries, path)


def find_label_map(start: str | Path, levels: int = 3) -> Path | None:
    """``scannetv2-labels.combined.tsv`` in ``start`` or up to ``levels`` parents, or None."""
    p = Path(start).resolve()
    for d in [p, *list(p.parents)[:levels]]:
        cand = d / LABELS_TSV
        if cand.is_file():
            return cand
    return None


# --------------------------------------------------------------------------------------------
# scenes
# --------------------------------------------------------------------------------------------
@dataclass
class ScanNetObject:
    """A ground-truth object: aggregation ``objectId``, labels, its mesh vertices and box."""

    object_id: int
    raw_label: str
    entry: LabelEntry
    vertex_indices: np.ndarray
    points: np.ndarray
    bbox: tuple[tuple[float, float, float], tuple[float, float, float]]
    centroid: tuple[float, float, float]

    @property
    def nyu40_label(self) -> str | None:
        return self.entry.nyu40_class

    @property
    def scannet20_label(self) -> str | None:
        return self.entry.scannet20_class

    def label(self, space: str = "nyu40") -> str | None:
        return self.entry.label(space)


@dataclass
class ScanNetScene:
    """One loaded scene: mesh vertices, per-vertex object ids and the ground-truth objects."""

    scene_id: str
    path: Path
    vertices: np.ndarray
    vertex_object: np.ndarray  # object id per vertex, -1 when unannotated
    objects: dict[int, ScanNetObject]
    label_map: LabelMap
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (objectId, reason)

    def node_id(self, object_id: int) -> str:
        """Graph node id of an object: ``<sceneId>/<objectId>``."""
        return f"{self.scene_id}/{object_id}"

    @property
    def floor_z(self) -> float:
        """Floor height: median z of vertices labelled floor, else the 2nd percentile of all z."""
        zs = [o.points[:, 2] for o in self.objects.values() if o.nyu40_label == "floor"]
        if zs:
            return float(np.median(np.concatenate(zs)))
        return float(np.percentile(self.vertices[:, 2], 2.0)) if len(self.vertices) else 0.0

    def vertex_labels(self, space: str = "nyu40") -> list[str | None]:
        """Label of every vertex in ``space`` (None when unannotated)."""
        lookup = {oid: o.label(space) for oid, o in self.objects.items()}
        return [lookup.get(int(o)) if o >= 0 else None for o in self.vertex_object]

    def add_to_graph(self, graph: Any, *, label_space: str = "nyu40") -> list[str]:
        """Add every object as node ``<sceneId>/<objectId>`` with attributes ``centroid``,
        ``bbox``, ``label`` (in ``label_space``), ``raw_label``, ``nyu40_id``, ``nyu40_label``,
        ``scannet20_label``, ``scene``, ``object_id``, ``n_vertices``, ``floor_z``. Returns the ids."""
        fz = self.floor_z
        ids = []
        for oid in sorted(self.objects):
            o = self.objects[oid]
            nid = self.node_id(oid)
            graph.add_node(nid, centroid=o.centroid, bbox=o.bbox, label=o.label(label_space),
                           raw_label=o.raw_label, nyu40_id=o.entry.nyu40_id, nyu40_label=o.nyu40_label,
                           scannet20_label=o.scannet20_label, scene=self.scene_id, object_id=oid,
                           n_vertices=int(len(o.vertex_indices)), floor_z=fz)
            ids.append(nid)
        return ids

    def channel(self, **kw: Any) -> ScanNetChannel:
        return ScanNetChannel([self], **kw)


def scene_files(scene_dir: str | Path, scene_id: str | None = None) -> dict[str, Path]:
    """The scene's file paths ('mesh', 'segs', 'aggregation'); raises FileNotFoundError naming
    the expected file when one is missing."""
    d = Path(scene_dir)
    if not d.is_dir():
        raise FileNotFoundError(f"ScanNet scene folder not found: {d}")
    sid = scene_id or d.name
    mesh = d / f"{sid}_vh_clean_2.ply"
    if not mesh.is_file():
        plys = sorted(d.glob("*_vh_clean_2.ply"))
        if scene_id is None and len(plys) == 1:
            sid = plys[0].name[: -len("_vh_clean_2.ply")]
            mesh = plys[0]
        else:
            raise FileNotFoundError(f"ScanNet scene {d}: missing mesh {mesh.name}")
    segs = d / f"{sid}_vh_clean_2.0.010000.segs.json"
    if not segs.is_file():
        raise FileNotFoundError(f"ScanNet scene {d}: missing over-segmentation {segs.name}")
    agg = d / f"{sid}.aggregation.json"
    if not agg.is_file():
        alt = d / f"{sid}_vh_clean.aggregation.json"
        if not alt.is_file():
            raise FileNotFoundError(f"ScanNet scene {d}: missing aggregation {agg.name} (or {alt.name})")
        agg = alt
    return {"mesh": mesh, "segs": segs, "aggregation": agg, "scene_id": Path(sid)}


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise FormatError(f"invalid JSON: {exc.msg}", path=path, line=exc.lineno) from None


def read_axis_alignment(path: str | Path) -> np.ndarray | None:
    """The 4x4 ``axisAlignment`` matrix of a scene's ``<sceneId>.txt`` metadata (row-major), or None."""
    p = Path(path)
    if not p.is_file():
        return None
    for lineno, line in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), start=1):
        key, sep, value = line.partition("=")
        if sep and key.strip() == "axisAlignment":
            try:
                vals = [float(x) for x in value.split()]
            except ValueError:
                raise FormatError("field 'axisAlignment': expected 16 numbers", path=p, line=lineno) from None
            if len(vals) != 16 or not np.all(np.isfinite(vals)):
                raise FormatError(f"field 'axisAlignment': expected 16 finite numbers, got {len(vals)}", path=p, line=lineno)
            return np.asarray(vals, dtype=float).reshape(4, 4)
    return None


def load_scene(scene_dir: str | Path, labels: LabelMap | str | Path | None = None, *,
               scene_id: str | None = None, on_unknown_label: str = "error", axis_align: bool = True) -> ScanNetScene:
    """Load a ScanNet v2 scene folder into ground-truth objects.

    ``labels``: a :class:`LabelMap` or the tsv path (default: found next to / above the folder).
    ``on_unknown_label``: 'error' (default) raises when an aggregation label is not a
    raw_category of the tsv; 'skip' drops such objects (listed in ``scene.skipped``).
    ``axis_align``: apply the ``axisAlignment`` matrix of ``<sceneId>.txt`` when the folder has
    one, so that boxes are axis-aligned in the gravity-aligned room frame (as ScanNet's own tools do).
    Raises FileNotFoundError for missing files and FormatError for malformed or inconsistent
    ones (e.g. segIndices length != mesh vertex count).
    """
    import open3d as o3d

    if on_unknown_label not in ("error", "skip"):
        raise ValueError("on_unknown_label must be 'error' or 'skip'")
    files = scene_files(scene_dir, scene_id)
    sid = str(files["scene_id"])
    if not isinstance(labels, LabelMap):
        tsv = Path(labels) if labels is not None else find_label_map(scene_dir)
        if tsv is None:
            raise FileNotFoundError(f"{LABELS_TSV} not found in {scene_dir} or its parents; pass labels=PATH")
        labels = load_label_map(tsv)

    # a ScanNet _vh_clean_2.ply read as a mesh makes open3d warn "TriangleMesh appears to be a
    # PointCloud" once per scene; only its errors reach the console
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh = o3d.io.read_triangle_mesh(str(files["mesh"]))
    vertices = np.asarray(mesh.vertices, dtype=float)
    if vertices.ndim != 2 or len(vertices) == 0:
        raise FormatError("mesh has no vertices (unreadable or empty PLY)", path=files["mesh"])
    if axis_align:
        align = read_axis_alignment(Path(scene_dir) / f"{sid}.txt")
        if align is not None:
            vertices = vertices @ align[:3, :3].T + align[:3, 3]

    segs_doc = _read_json(files["segs"])
    if not isinstance(segs_doc, Mapping) or not isinstance(segs_doc.get("segIndices"), list):
        raise FormatError("field 'segIndices': missing or not a list", path=files["segs"])
    seg = np.asarray(segs_doc["segIndices"], dtype=np.int64)
    if len(seg) != len(vertices):
        raise FormatError(f"field 'segIndices' has {len(seg)} entries but the mesh {files['mesh'].name} "
                          f"has {len(vertices)} vertices", path=files["segs"])

    agg = _read_json(files["aggregation"])
    groups = agg.get("segGroups") if isinstance(agg, Mapping) else None
    if not isinstance(groups, list):
        raise FormatError("field 'segGroups': missing or not a list", path=files["aggregation"])

    vertex_object = np.full(len(vertices), -1, dtype=np.int64)
    objects: dict[int, ScanNetObject] = {}
    skipped: list[tuple[int, str]] = []
    for k, g in enumerate(groups):
        where = f"segGroups[{k}]"
        if not isinstance(g, Mapping):
            raise FormatError(f"{where}: expected an object", path=files["aggregation"])
        for key in ("label", "segments"):
            if key not in g:
                raise FormatError(f"{where}: missing field '{key}'", path=files["aggregation"])
        oid = g.get("objectId", g.get("id"))
        if not isinstance(oid, int) or isinstance(oid, bool):
            raise FormatError(f"{where}: field 'objectId' must be an integer, got {oid!r}", path=files["aggregation"])
        if oid in objects or any(s[0] == oid for s in skipped):
            raise FormatError(f"{where}: duplicate objectId {oid}", path=files["aggregation"])
        raw = str(g["label"])
        entry = labels.find(raw)
        if entry is None:
            if on_unknown_label == "error":
                raise FormatError(f"{where} (objectId {oid}): label {raw!r} is not a raw_category of "
                                  f"{labels.path or 'the label map'}", path=files["aggregation"])
            skipped.append((oid, f"label {raw!r} not in the label map"))
            continue
        segments = np.asarray(list(g["segments"]), dtype=np.int64)
        vidx = np.flatnonzero(np.isin(seg, segments))
        if vidx.size == 0:
            skipped.append((oid, "no mesh vertex belongs to its segments"))
            warnings.warn(f"{files['aggregation']}: objectId {oid} ({raw!r}) has no vertices; skipped",
                          stacklevel=2)
            continue
        pts = vertices[vidx]
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        box = pcd.get_axis_aligned_bounding_box()
        lo = tuple(float(x) for x in box.min_bound)
        hi = tuple(float(x) for x in box.max_bound)
        c = tuple(float(x) for x in pcd.get_center())
        vertex_object[vidx] = oid
        objects[oid] = ScanNetObject(oid, raw, entry, vidx, pts, (lo, hi), c)  # type: ignore[arg-type]
    return ScanNetScene(sid, Path(scene_dir), vertices, vertex_object, objects, labels, skipped)


def load_scenes(root: str | Path, labels: LabelMap | str | Path | None = None, *,
                scene_ids: Iterable[str] | None = None, **kw: Any) -> list[ScanNetScene]:
    """Load every scene folder under ``root`` (folders holding ``*_vh_clean_2.ply``), sorted by id;
    ``root`` itself may be a scene folder."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"ScanNet scenes folder not found: {root}")
    if any(root.glob("*_vh_clean_2.ply")):
        dirs = [root]
    else:
        dirs = sorted(d for d in root.iterdir() if d.is_dir() and any(d.glob("*_vh_clean_2.ply")))
    if scene_ids is not None:
        wanted = set(scene_ids)
        dirs = [d for d in dirs if d.name in wanted]
    if not dirs:
        raise FileNotFoundError(f"no ScanNet scene folders (with *_vh_clean_2.ply) under {root}")
    if labels is None:
        tsv = find_label_map(root) or find_label_map(dirs[0])
        if tsv is None:
            raise FileNotFoundError(f"{LABELS_TSV} not found in {root} or its parents; pass labels=PATH")
        labels = tsv
    if not isinstance(labels, LabelMap):
        labels = load_label_map(labels)
    return [load_scene(d, labels, **kw) for d in dirs]


# --------------------------------------------------------------------------------------------
# geometric channel
# --------------------------------------------------------------------------------------------
class ScanNetChannel:
    """Mesh-aggregation class labels as a geometric channel.

    ``label_points(points)``: for every query point, the ``k`` nearest mesh vertices (open3d
    KDTreeFlann) within ``max_distance`` metres vote; if fewer than ``min_annotated`` (fraction) of
    the votes are annotated vertices, or no vertex is within range, the answer is None; otherwise
    the majority annotated label (in ``label_space``, default NYU40 names as used by
    ``sgbelief/configs/vocab/scannet.yaml``). Ties break alphabetically. At most ``max_points`` query points
    are used (an evenly strided subsample).

    ``label(node, t)``: the points registered with :meth:`set_points` for the node, else the
    ground-truth object's own vertices when ``node`` is ``<sceneId>/<objectId>``; None otherwise.
    The scenes are static, so ``t`` is ignored.
    """

    def __init__(self, scenes: ScanNetScene | Sequence[ScanNetScene], *, max_distance: float = 0.05, k: int = 1,
                 min_annotated: float = 0.5, label_space: str = "nyu40", max_points: int = 2000) -> None:
        if isinstance(scenes, ScanNetScene):
            scenes = [scenes]
        if label_space not in LABEL_SPACES:
            raise ValueError(f"unknown label space {label_space!r}; known: {list(LABEL_SPACES)}")
        self.scenes = {s.scene_id: s for s in scenes}
        self.max_distance = float(max_distance)
        self.k = int(k)
        self.min_annotated = float(min_annotated)
        self.label_space = label_space
        self.max_points = int(max_points)
        self._trees: dict[str, Any] = {}
        self._vlabels: dict[str, list[str | None]] = {}
        self._points: dict[Any, tuple[str | None, np.ndarray]] = {}

    def set_points(self, node: Any, points: np.ndarray, scene_id: str | None = None) -> None:
        """Register a detection's 3D points for ``node`` (scene from the id prefix if omitted)."""
        self._points[node] = (scene_id, np.asarray(points, dtype=float).reshape(-1, 3))

    def _scene_of(self, node: Any, scene_id: str | None) -> ScanNetScene | None:
        if scene_id is not None:
            return self.scenes.get(scene_id)
        if isinstance(node, str) and "/" in node:
            return self.scenes.get(node.rsplit("/", 1)[0])
        return next(iter(self.scenes.values())) if len(self.scenes) == 1 else None

    def _tree(self, scene: ScanNetScene) -> Any:
        tree = self._trees.get(scene.scene_id)
        if tree is None:
            import open3d as o3d

            pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scene.vertices))
            tree = o3d.geometry.KDTreeFlann(pcd)
            self._trees[scene.scene_id] = tree
            self._vlabels[scene.scene_id] = scene.vertex_labels(self.label_space)
        return tree

    def label_points(self, points: np.ndarray, scene: str | ScanNetScene | None = None) -> str | None:
        """Majority annotated label near ``points`` (N x 3), or None (see the class docstring)."""
        if isinstance(scene, ScanNetScene):
            sc: ScanNetScene | None = scene
        elif scene is not None:
            sc = self.scenes.get(scene)
            if sc is None:
                raise KeyError(f"unknown ScanNet scene {scene!r}; loaded: {sorted(self.scenes)}")
        elif len(self.scenes) == 1:
            sc = next(iter(self.scenes.values()))
        else:
            raise ValueError("several scenes loaded: pass scene=")
        assert sc is not None
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(pts) == 0:
            return None
        if len(pts) > self.max_points:
            pts = pts[np.linspace(0, len(pts) - 1, self.max_points).astype(int)]
        tree = self._tree(sc)
        vlabels = self._vlabels[sc.scene_id]
        r2 = self.max_distance ** 2
        votes: Counter[str] = Counter()
        unannotated = 0
        for p in pts:
            cnt, idx, d2 = tree.search_knn_vector_3d(p, self.k)
            for j, dd in zip(list(idx)[:cnt], list(d2)[:cnt]):
                if dd > r2:
                    continue
                lab = vlabels[j]
                if lab is None:
                    unannotated += 1
                else:
                    votes[lab] += 1
        total = sum(votes.values()) + unannotated
        if total == 0 or not votes or sum(votes.values()) < self.min_annotated * total:
            return None
        best = max(votes.values())
        return min(lab for lab, c in votes.items() if c == best)

    def label(self, node: Any, t: int) -> str | None:
        reg = self._points.get(node)
        if reg is not None:
            sc = self._scene_of(node, reg[0])
            return None if sc is None else self.label_points(reg[1], sc)
        sc = self._scene_of(node, None)
        if sc is None or not isinstance(node, str) or "/" not in node:
            return None
        try:
            oid = int(node.rsplit("/", 1)[1])
        except ValueError:
            return None
        obj = sc.objects.get(oid)
        return None if obj is None else self.label_points(obj.points, sc)


# --------------------------------------------------------------------------------------------
# writing scenes in the ScanNet formats (tests, demos; real scenes need none of this)
# --------------------------------------------------------------------------------------------
#: Header of the real ``scannetv2-labels.combined.tsv``.
TSV_HEADER: tuple[str, ...] = ("id", "raw_category", "category", "count", "nyu40id", "eigen13id", "nyuClass",
                               "nyu40class", "eigen13class", "ModelNet40", "ModelNet10", "ShapeNetCore55",
                               "synsetoffset", "wnsynsetid", "wnsynsetkey", "mpcat40", "mpcat40index")

#: A small subset of label-map rows: (raw_category, category, nyu40id, nyu40class).
SAMPLE_LABEL_ROWS: tuple[tuple[str, str, int, str], ...] = (
    ("wall", "wall", 1, "wall"), ("floor", "floor", 2, "floor"), ("cabinet", "cabinet", 3, "cabinet"),
    ("bed", "bed", 4, "bed"), ("chair", "chair", 5, "chair"), ("office chair", "chair", 5, "chair"),
    ("armchair", "chair", 5, "chair"), ("sofa", "sofa", 6, "sofa"), ("couch", "sofa", 6, "sofa"),
    ("table", "table", 7, "table"), ("coffee table", "table", 7, "table"), ("door", "door", 8, "door"),
    ("window", "window", 9, "window"), ("bookshelf", "bookshelf", 10, "bookshelf"),
    ("picture", "picture", 11, "picture"), ("kitchen counter", "counter", 12, "counter"),
    ("desk", "desk", 14, "desk"), ("curtain", "curtain", 16, "curtain"), ("monitor", "monitor", 40, "otherprop"),
    ("lamp", "lamp", 35, "lamp"), ("book", "book", 23, "books"), ("box", "box", 29, "box"),
    ("ceiling", "ceiling", 22, "ceiling"), ("toilet", "toilet", 33, "toilet"), ("sink", "sink", 34, "sink"),
)


def write_label_map(path: str | Path, rows: Iterable[tuple[str, str, int, str]] = SAMPLE_LABEL_ROWS) -> Path:
    """Write a label map with the real tsv header (unused columns left empty)."""
    path = Path(path)
    lines = ["\t".join(TSV_HEADER)]
    for i, (raw, cat, nid, ncls) in enumerate(rows, start=1):
        cols = {"id": str(i), "raw_category": raw, "category": cat, "count": "1", "nyu40id": str(nid),
                "nyuClass": ncls, "nyu40class": ncls}
        lines.append("\t".join(cols.get(h, "") for h in TSV_HEADER))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def write_scene_files(scene_dir: str | Path, scene_id: str,
                      objects: Sequence[tuple[str, Sequence[float], Sequence[float]]], *,
                      unannotated: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
                      aggregation_name: str | None = None) -> Path:
    """Write a scene made of boxes in the exact ScanNet v2 formats.

    ``objects``: (raw label, box min xyz, box max xyz); object ``i`` gets objectId ``i`` and two
    segments (its 8 corner vertices split 4 + 4). ``unannotated``: boxes whose segments no
    segGroup references. Writes ``<id>_vh_clean_2.ply`` (binary PLY via open3d),
    ``<id>_vh_clean_2.0.010000.segs.json`` and ``<id>.aggregation.json`` (or ``aggregation_name``).
    """
    import open3d as o3d

    d = Path(scene_dir)
    d.mkdir(parents=True, exist_ok=True)
    mesh = o3d.geometry.TriangleMesh()
    seg_indices: list[int] = []
    groups = []
    next_seg = 0
    boxes = [(lab, lo, hi, True) for lab, lo, hi in objects] + [(None, lo, hi, False) for lo, hi in unannotated]
    for i, (lab, lo, hi, annotated) in enumerate(boxes):
        lo_a, hi_a = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        size = np.maximum(hi_a - lo_a, 1e-4)
        box = o3d.geometry.TriangleMesh.create_box(width=float(size[0]), height=float(size[1]), depth=float(size[2]))
        box.translate(lo_a)
        box.paint_uniform_color([(37 * i % 255) / 255.0, (91 * i % 255) / 255.0, (53 * i % 255) / 255.0])
        nv = len(box.vertices)
        segs = [next_seg, next_seg + 1]
        next_seg += 2
        seg_indices += [segs[0]] * (nv // 2) + [segs[1]] * (nv - nv // 2)
        mesh += box
        if annotated:
            groups.append({"id": i, "objectId": i, "segments": segs, "label": lab})
    o3d.io.write_triangle_mesh(str(d / f"{scene_id}_vh_clean_2.ply"), mesh, write_ascii=False)
    segs_doc = {"params": {"kThresh": "0.0001", "segMinVerts": "20", "minPoints": "750", "maxPoints": "30000",
                           "thinThresh": "0.05", "flatThresh": "0.001", "minLength": "0.02", "maxLength": "1"},
                "sceneId": scene_id, "segIndices": seg_indices}
    (d / f"{scene_id}_vh_clean_2.0.010000.segs.json").write_text(json.dumps(segs_doc), encoding="utf-8")
    agg = {"sceneId": f"scannet.{scene_id}", "appId": "Aggregator.v2", "segGroups": groups,
           "segmentsFile": f"scannet.{scene_id}_vh_clean_2.0.010000.segs.json"}
    (d / (aggregation_name or f"{scene_id}.aggregation.json")).write_text(json.dumps(agg), encoding="utf-8")
    return d

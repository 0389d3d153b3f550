"""End-to-end harness: ConceptGraphs' own per-frame mapping code, with and without the sgbelief backend.

The ``conceptgraph`` package is imported from ``$SGBELIEF_CONCEPTGRAPH_PATH`` (a checkout of
concept-graphs/concept-graphs, branch ``main`` or ``ali-dev``); nothing of it is shipped here. The
harness runs the real ``gobs_to_detection_list`` (main) / ``detections_to_obj_pcd_and_bbox`` +
``make_detection_list_from_pcd_and_gobs`` (ali-dev), the real similarities, merges, ``denoise`` /
``filter`` / ``merge_objects``, in the order of ``cfslam_pipeline_batch.py`` (main) and
``rerun_realtime_mapping.py`` (ali-dev), on a synthetic RGB-D room rendered with open3d raycasting:

* 15 box-shaped objects (3 chairs), walls, floor, ceiling; a camera turning twice round the room;
* a noisy detector: per object error rates 0.15-0.75 (mean 0.45), a wrong label is the object's
  confuser 70 % of the time (a sofa keeps being called ``tv``), confidence U(0.55, 0.97) whether
  right or wrong; CLIP-like features per object, text features per claimed class;
* channels: ``oracle`` (the ground-truth class under the mask), ``segmenter`` (the oracle label,
  wrong 15 % of the time, missing 15 %), ``none``.

Label accuracy: the fraction of final map objects whose label is their ground-truth class (the
object's majority ground-truth object over its detections). Per-class IoU over the map's points
(a point's truth: the ground-truth object of the detections that made its object).

Used by ``benchmarks/bench_cg_harness.py`` and ``tests/test_conceptgraphs_harness.py``.
"""

from __future__ import annotations

import copy
import os
import sys
import time
import types
import uuid
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

ENV = "SGBELIEF_CONCEPTGRAPH_PATH"
BG = ["wall", "floor", "ceiling"]
# class, centre (x, y, z-bottom), size; room 6 x 5 x 2.6 m centred on the origin
WORLD = [
    ("sofa", (-2.0, 1.6, 0.0), (1.8, 0.8, 0.8)), ("tv", (-2.7, -0.8, 0.7), (0.15, 1.1, 0.65)),
    ("chair", (1.0, 1.5, 0.0), (0.5, 0.5, 0.9)), ("chair", (1.8, 1.5, 0.0), (0.5, 0.5, 0.9)),
    ("chair", (1.4, 0.2, 0.0), (0.5, 0.5, 0.9)), ("table", (1.4, 0.9, 0.0), (1.4, 0.7, 0.72)),
    ("lamp", (-2.6, 2.1, 0.0), (0.3, 0.3, 1.6)), ("stool", (0.2, -1.9, 0.0), (0.4, 0.4, 0.6)),
    ("bed", (2.0, -1.3, 0.0), (1.6, 2.0, 0.55)), ("cabinet", (-0.6, 2.2, 0.0), (1.0, 0.5, 1.2)),
    ("bookshelf", (2.7, 0.9, 0.0), (0.4, 1.2, 1.9)), ("plant", (-1.2, -2.0, 0.0), (0.45, 0.45, 1.0)),
    ("trash can", (0.8, -2.1, 0.0), (0.35, 0.35, 0.5)), ("refrigerator", (-2.6, 0.6, 0.0), (0.7, 0.7, 1.8)),
    ("box", (-0.9, -0.5, 0.0), (0.5, 0.5, 0.4)),
]
CONFUSER = {"sofa": "tv", "tv": "monitor", "chair": "stool", "table": "cabinet", "lamp": "plant",
            "stool": "chair", "bed": "sofa", "cabinet": "refrigerator", "bookshelf": "cabinet",
            "plant": "lamp", "trash can": "box", "refrigerator": "cabinet", "box": "trash can"}
CLASSES = sorted({c for c, _, _ in WORLD} | set(CONFUSER.values())) + BG


@dataclass
class Frame:
    rgb: np.ndarray  # H x W x 3 uint8
    depth: np.ndarray  # H x W float32 metres (z-depth)
    ids: np.ndarray  # H x W int: object index, -1 background / nothing
    pose: np.ndarray  # 4 x 4 camera-to-world


@dataclass
class World:
    frames: list[Frame]
    K: np.ndarray
    classes: list[str]
    objects: list[tuple[str, tuple, tuple]]
    error_rates: np.ndarray


#: classes of the small clutter objects ``render_world(clutter=N)`` scatters (more detections per frame)
CLUTTER_CLASSES = ["box", "stool", "plant", "trash can", "lamp", "chair"]


def clutter_objects(n: int, seed: int = 0) -> list[tuple[str, tuple, tuple]]:
    """``n`` small objects (0.2-0.35 m) on the floor, kept off the middle where the camera stands."""
    rng = np.random.default_rng(seed + 7919)
    out: list[tuple[str, tuple, tuple]] = []
    while len(out) < n:
        x, y = rng.uniform(-2.8, 2.8), rng.uniform(-2.3, 2.3)
        if abs(x) < 1.0 and abs(y) < 0.8:
            continue
        side = float(rng.uniform(0.2, 0.35))
        out.append((CLUTTER_CLASSES[len(out) % len(CLUTTER_CLASSES)], (float(x), float(y), 0.0),
                    (side, side, float(rng.uniform(0.2, 0.5)))))
    return out


def render_world(n_frames: int = 60, width: int = 128, height: int = 96, seed: int = 0, clutter: int = 0) -> World:
    """The room (``WORLD``) rendered along the camera path; ``clutter`` adds that many small objects
    (more detections per frame, medians: about 5 with none, 10 with 25, 19 with 150 at 128 x 96; 29
    with 200 at 192 x 144)."""
    import open3d as o3d

    objects = list(WORLD) + clutter_objects(clutter, seed)
    scene = o3d.t.geometry.RaycastingScene()
    gid_to_obj: dict[int, int] = {}

    def add_box(lo: tuple, size: tuple, obj: int) -> None:
        m = o3d.geometry.TriangleMesh.create_box(*size)
        m.translate(lo)
        gid = scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m))
        gid_to_obj[int(gid)] = obj

    for i, (_c, (x, y, z), (sx, sy, sz)) in enumerate(objects):
        add_box((x - sx / 2, y - sy / 2, z), (sx, sy, sz), i)
    for lo, size in [((-3.1, -2.6, -0.1), (6.2, 5.2, 0.1)), ((-3.1, -2.6, 2.6), (6.2, 5.2, 0.1)),
                     ((-3.1, -2.6, 0), (0.1, 5.2, 2.6)), ((3.0, -2.6, 0), (0.1, 5.2, 2.6)),
                     ((-3.1, -2.6, 0), (6.2, 0.1, 2.6)), ((-3.1, 2.5, 0), (6.2, 0.1, 2.6))]:
        add_box(lo, size, -1)
    f = width / 2.0  # 90 degrees horizontal field of view
    K = np.array([[f, 0, width / 2.0], [0, f, height / 2.0], [0, 0, 1.0]])
    rng = np.random.default_rng(seed)
    colours = rng.integers(40, 255, size=(len(WORLD) + 1, 3)).astype(np.uint8)
    if clutter:  # the room's colours as without clutter; the clutter's from their own generator
        extra = np.random.default_rng(seed + 104729).integers(40, 255, size=(clutter, 3)).astype(np.uint8)
        colours = np.concatenate([colours[:-1], extra, colours[-1:]])
    frames = []
    for k in range(n_frames):
        a = 4 * np.pi * k / n_frames
        eye = np.array([0.6 * np.cos(a * 0.5), 0.4 * np.sin(a * 0.5), 1.3])
        fwd = np.array([np.cos(a), np.sin(a), -0.25])
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0, 0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        R = np.stack([right, down, fwd], axis=1)  # camera axes (x right, y down, z forward) in world
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = R, eye
        extrinsic = np.linalg.inv(pose)
        rays = scene.create_rays_pinhole(o3d.core.Tensor(K), o3d.core.Tensor(extrinsic), width, height)
        hit = scene.cast_rays(rays)
        t = hit["t_hit"].numpy()
        r = rays.numpy()
        pts = r[..., :3] + r[..., 3:] * t[..., None]
        cam = (pts - eye) @ R
        depth = np.where(np.isfinite(t), cam[..., 2], 0).astype(np.float32)
        gids = hit["geometry_ids"].numpy().astype(np.int64)
        ids = np.vectorize(lambda g: gid_to_obj.get(int(g), -1))(gids) if gids.size else gids
        rgb = colours[np.where(ids >= 0, ids, len(objects))]
        frames.append(Frame(rgb=rgb, depth=depth, ids=ids.astype(np.int32), pose=pose))
    errs = np.linspace(0.15, 0.75, len(WORLD))
    rng.shuffle(errs)
    if clutter:
        errs = np.concatenate([errs, np.random.default_rng(seed + 15485863).uniform(0.15, 0.75, clutter)])
    return World(frames, K, list(CLASSES), objects, errs)


@dataclass
class Detections:
    """One frame's detector output (ConceptGraphs' ``gobs``) and the truth behind each mask."""

    gobs: dict
    truth: list[int]  # ground-truth object index per mask


#: where the detector's confidences come from: "uniform" (U(0.55, 0.97) whether the class is right or
#: not: confidences that carry no information), or a shipped detector's records ("rfcn", "ssd"): a
#: right class draws a score of that detector's matched records, a wrong one of its unmatched ones;
#: or scores that are not probabilities, as open-vocabulary detectors report them: "low" (U(0.15,
#: 0.55) whether right or not) and "low_informative" (U(0.3, 0.6) when right, U(0.1, 0.45) when not);
#: or "straddle" (U(0.3, 0.9) whether right or not: no information, a third of the claims below 0.5)
CONFIDENCES = ["uniform"]
CONFIDENCE_CHOICES = ["uniform", "rfcn", "ssd", "low", "low_informative", "straddle"]
_SCORE_POOLS: dict[str, tuple[np.ndarray, np.ndarray]] = {}


def _score_pools(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(scores of matched records, scores of unmatched records) of a shipped detector."""
    if name not in _SCORE_POOLS:
        from sgbelief.eval.detector_records import available_records, load_detector_records

        rec = load_detector_records(next(r for r in available_records() if r.startswith(name)))
        _SCORE_POOLS[name] = (rec.score[rec.matched == 1].astype(float), rec.score[rec.matched == 0].astype(float))
    return _SCORE_POOLS[name]


def _confidence(rng: np.random.Generator, right: bool) -> float:
    mode = CONFIDENCES[0]
    if mode == "uniform":
        return float(rng.uniform(0.55, 0.97))
    if mode == "straddle":
        return float(rng.uniform(0.3, 0.9))
    if mode == "low":
        return float(rng.uniform(0.15, 0.55))
    if mode == "low_informative":
        return float(rng.uniform(0.3, 0.6)) if right else float(rng.uniform(0.1, 0.45))
    matched, unmatched = _score_pools(CONFIDENCES[0])
    pool = matched if right else unmatched
    return float(pool[rng.integers(len(pool))])


def detect(world: World, k: int, rng: np.random.Generator, *, min_pixels: int = 60, feat_dim: int = 64,
           feats: dict | None = None) -> Detections:
    """The noisy, overconfident detector on frame ``k`` (its confidences: :data:`CONFIDENCES`)."""
    fr = world.frames[k]
    classes = world.classes
    masks, xyxy, conf, cls, img_f, txt_f, truth = [], [], [], [], [], [], []
    for i, (c, _, _) in enumerate(world.objects):
        m = fr.ids == i
        if m.sum() < min_pixels:
            continue
        ys, xs = np.nonzero(m)
        if rng.random() < world.error_rates[i]:
            wrong = CONFUSER[c] if rng.random() < 0.7 else rng.choice([x for x in classes[:-3] if x != c])
            name = str(wrong)
        else:
            name = c
        masks.append(m)
        xyxy.append([xs.min(), ys.min(), xs.max(), ys.max()])
        conf.append(_confidence(rng, name == c))
        cls.append(classes.index(name))
        v = feats["obj"][i] + 0.25 * rng.normal(size=feat_dim)
        img_f.append(v / np.linalg.norm(v))
        txt_f.append(feats["cls"][classes.index(name)])
        truth.append(i)
    h, w = fr.depth.shape
    gobs = {"xyxy": np.asarray(xyxy, dtype=float).reshape(-1, 4), "confidence": np.asarray(conf, dtype=float),
            "class_id": np.asarray(cls, dtype=int), "mask": np.asarray(masks, dtype=bool).reshape(-1, h, w),
            "classes": classes, "image_feats": np.asarray(img_f, dtype=np.float32).reshape(-1, feat_dim),
            "text_feats": np.asarray(txt_f, dtype=np.float32).reshape(-1, feat_dim),
            # ali-dev's filter_gobs pairs captions with "name id" labels
            "captions": [{"id": str(k), "name": classes[c], "caption": ""} for k, c in enumerate(cls)],
            "detection_class_labels": [f"{classes[c]} {k}" for k, c in enumerate(cls)]}
    return Detections(gobs, truth)


def features(world: World, dim: int = 64, seed: int = 1) -> dict:
    rng = np.random.default_rng(seed)
    obj = rng.normal(size=(len(world.objects), dim))
    cls = rng.normal(size=(len(world.classes), dim))
    return {"obj": obj / np.linalg.norm(obj, axis=1, keepdims=True),
            "cls": cls / np.linalg.norm(cls, axis=1, keepdims=True)}


# ------------------------------------------------------------------------------------- channels
class TruthChannel:
    """Oracle / segmenter-like label under a detection's mask (a DetectionChannel)."""

    def __init__(self, world: World, *, flip: float = 0.0, drop: float = 0.0, seed: int = 5) -> None:
        from sgbelief.fusion.channel import LabelImageChannel

        self.world = world
        self.flip, self.drop = flip, drop
        self.rng = np.random.default_rng(seed)
        names = {i: c for i, (c, _, _) in enumerate(world.objects)}
        self.inner = LabelImageChannel(lambda t: world.frames[t].ids if 0 <= t < len(world.frames) else None,
                                       classes=names, ignore_ids=[-1], min_purity=0.6, min_pixels=20)
        self.calls = 0
        #: CLOCK seconds spent in label_detection: the channel's own cost (the mask look-up)
        self.seconds = 0.0

    def label_detection(self, det: dict, index: int, t: int) -> str | None:
        t0 = CLOCK[0]()
        try:
            return self._label_detection(det, index, t)
        finally:
            self.seconds += CLOCK[0]() - t0

    def _label_detection(self, det: dict, index: int, t: int) -> str | None:
        self.calls += 1
        lab = self.inner.label_detection(det, index, t)
        if lab is None or self.drop == 0 and self.flip == 0:
            return lab
        u = self.rng.random()
        if u < self.drop:
            return None
        if u < self.drop + self.flip:
            return str(self.rng.choice([c for c in self.world.classes[:-3] if c != lab]))
        return lab

    def label(self, node: Any, t: int) -> str | None:
        return None


def make_channel(world: World, kind: str) -> Any:
    if kind == "none":
        return None
    if kind == "oracle":
        return TruthChannel(world)
    if kind == "segmenter":
        return TruthChannel(world, flip=0.15, drop=0.15)
    raise ValueError(f"unknown channel {kind!r}: oracle, segmenter, none")


# ------------------------------------------------------------------------------------- conceptgraph
def _stub(name: str, **attrs: Any) -> None:
    if name in sys.modules:
        return
    mod = types.ModuleType(name)
    mod.__dict__.update(attrs)
    sys.modules[name] = mod


BOX3D_S = [0.0]  # seconds spent in the box3d_overlap stand-in (harness code, not ConceptGraphs')
#: the clock of the per-frame timings: wall time by default; ``bench_cg_harness.py --cpu-time`` sets
#: ``time.process_time`` (this process's CPU time, steadier when other jobs share the cores)
CLOCK = [time.perf_counter]


def box3d_overlap(boxes1: Any, boxes2: Any, eps: float = 1e-4) -> tuple[Any, Any]:
    """pytorch3d.ops.box3d_overlap stand-in (no wheel for this platform): (N, M) intersection volumes
    and IoUs of boxes given as 8 corners in pytorch3d's order, by a 12^3 grid in each box of ``boxes1``."""
    import torch

    t_start = CLOCK[0]()
    b1 = boxes1.detach().double().cpu().numpy()
    b2 = boxes2.detach().double().cpu().numpy()
    # exact rejection: boxes whose corners' axis-aligned bounds are disjoint cannot intersect
    lo1, hi1 = b1.min(axis=1), b1.max(axis=1)
    lo2, hi2 = b2.min(axis=1), b2.max(axis=1)
    near = np.all((lo1[:, None] <= hi2[None] + eps) & (lo2[None] <= hi1[:, None] + eps), axis=2)
    g = (np.arange(12) + 0.5) / 12
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)

    def frame(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        o = b[0]
        axes = np.stack([b[1] - o, b[3] - o, b[4] - o])  # pytorch3d corner order: 0-1, 0-3, 0-4 edges
        return o, axes

    def volume(b: np.ndarray) -> float:
        _, ax = frame(b)
        return float(abs(np.linalg.det(ax)))

    inter = np.zeros((len(b1), len(b2)))
    for i, bi in enumerate(b1):
        if not near[i].any():
            continue
        o, ax = frame(bi)
        pts = o + grid @ ax
        for j in np.flatnonzero(near[i]):
            oj, axj = frame(b2[j])
            try:
                local = np.linalg.solve(axj.T, (pts - oj).T).T
            except np.linalg.LinAlgError:
                continue
            inside = np.all((local >= -eps) & (local <= 1 + eps), axis=1).mean()
            inter[i, j] = inside * volume(bi)
    v1 = np.array([volume(b) for b in b1])[:, None]
    v2 = np.array([volume(b) for b in b2])[None, :]
    iou = inter / np.maximum(v1 + v2 - inter, 1e-12)
    BOX3D_S[0] += CLOCK[0]() - t_start
    return torch.from_numpy(inter).float(), torch.from_numpy(iou).float()


def import_conceptgraph(path: str | None = None) -> tuple[Any, Any, Any, str]:
    """Import conceptgraph.slam.{utils,mapping,slam_classes} from ``path`` (default ``$SGBELIEF_CONCEPTGRAPH_PATH``)."""
    path = path or os.environ.get(ENV)
    if not path:
        raise ImportError(f"set {ENV} to a concept-graphs checkout")
    if path not in sys.path:
        sys.path.insert(0, path)
    # optional heavy dependencies the mapping code never calls: stand-ins so the modules import
    _stub("pytorch3d")
    _stub("pytorch3d.ops", box3d_overlap=box3d_overlap)
    sys.modules["pytorch3d"].ops = sys.modules["pytorch3d.ops"]
    for name in ("gradslam", "gradslam.datasets", "gradslam.geometry", "gradslam.slam", "gradslam.structures"):
        _stub(name)
    _stub("gradslam.datasets.datautils")
    _stub("gradslam.geometry.geometryutils", relative_transformation=None)
    _stub("gradslam.slam.pointfusion", PointFusion=object)
    _stub("gradslam.structures.rgbdimages", RGBDImages=object)
    sys.modules["gradslam.datasets"].datautils = sys.modules["gradslam.datasets.datautils"]
    import importlib

    utils = importlib.import_module("conceptgraph.slam.utils")
    mapping = importlib.import_module("conceptgraph.slam.mapping")
    classes = importlib.import_module("conceptgraph.slam.slam_classes")
    import inspect

    gen = "main" if list(inspect.signature(utils.merge_obj2_into_obj1).parameters)[0] == "cfg" else "ali-dev"
    return utils, mapping, classes, gen


def cg_config(path: str, gen: str, **over: Any) -> Any:
    """ConceptGraphs' own mapping defaults (read from the checkout), CPU, with ``over`` applied."""
    from omegaconf import OmegaConf

    if gen == "main":
        cfg = OmegaConf.load(os.path.join(path, "conceptgraph/configs/slam_pipeline/base.yaml"))
    else:
        cfg = OmegaConf.load(os.path.join(path, "conceptgraph/hydra_configs/base_mapping.yaml"))
    base = dict(device="cpu", spatial_sim_type="overlap", match_method="sim_sum", phys_bias=0.0,
                sim_threshold=1.2, denoise_interval=20, filter_interval=-1, merge_interval=20,
                obj_min_detections=3, skip_bg=True, use_contain_number=False, mask_area_threshold=25,
                max_bbox_area_ratio=1.0, mask_conf_threshold=0.2, obj_pcd_max_points=5000,
                run_denoise_final_frame=True, run_filter_final_frame=True, run_merge_final_frame=True,
                make_edges=False)
    base.update(over)
    cfg = OmegaConf.merge(OmegaConf.create({k: v for k, v in OmegaConf.to_container(cfg).items()
                                            if not isinstance(v, str) or "${" not in v}), base)
    return cfg


class _ObjClasses:
    def __init__(self, classes: list[str]) -> None:
        self.classes = classes

    def get_classes_arr(self) -> list[str]:
        return self.classes

    def get_bg_classes_arr(self) -> list[str]:
        return BG


@dataclass
class RunResult:
    labels: list[str]
    truth: list[int]
    accuracy: float
    miou: float
    n_objects: int
    fusion_ms: list[float] = field(default_factory=list)  # per frame: ConceptGraphs' fusion step
    summary: Any = None
    n_dets: list[int] = field(default_factory=list)  # per timed frame: detections fused
    n_map: list[int] = field(default_factory=list)  # per timed frame: map objects before the fusion step
    box3d_ms: list[float] = field(default_factory=list)  # per timed frame: of fusion_ms, the box3d stand-in
    # per timed frame: of fusion_ms, the merge (main: merge_detections_to_objects; ali-dev: match +
    # merge_obj_matches + the relabel loop), where the backend, when installed, does its work
    merge_ms: list[float] = field(default_factory=list)
    #: ConceptGraphs' vote with its ties broken at random, as an expected accuracy: an object whose
    #: detections name k classes equally often counts 1/k when its class is one of them (the vote
    #: itself breaks ties by the lowest class id on main, by the first seen on ali-dev)
    vote_ties_at_random: float = float("nan")


def run(world: World, cg: tuple, path: str, *, backend: Any = None, seed: int = 3, frames: int | None = None,
        fusion_hook: Any = None, prepopulate: int = 0) -> RunResult:
    """ConceptGraphs' per-frame loop on ``world`` (backend installed around it when given).

    ``prepopulate``: after the first frame's detections seed the map, append this many copies of them
    moved onto a grid outside the room (x >= 10 m), so the map holds ``prepopulate`` objects more
    while the frames' detections stay those of the room; ConceptGraphs' similarities and merges run
    over the whole map. The copies are left out of the accuracy."""
    utils, mapping, slam_classes, gen = cg
    cfg = cg_config(path, gen)
    rng = np.random.default_rng(seed)
    # ConceptGraphs draws from numpy's global generator (the point jitter of its depth back-projection,
    # instance colours): seeded per run, every run of a seed sees the same points, in any process
    np.random.seed(seed)
    feats = features(world)
    truth_of: dict[tuple[int, int], int] = {}
    ctx = backend.patch() if backend is not None else _null()
    with ctx:
        MapObjectList = slam_classes.MapObjectList  # noqa: N806  (rebound by the patch on Python >= 3.11)
        objects = MapObjectList(device="cpu") if backend is not None else slam_classes.MapObjectList()
        n = len(world.frames) if frames is None else frames
        fusion_ms: list[float] = []
        n_dets: list[int] = []
        n_map: list[int] = []
        box3d_ms: list[float] = []
        merge_ms: list[float] = []
        for idx in range(n):
            fr = world.frames[idx]
            dets = detect(world, idx, rng, feats=feats)
            if len(dets.truth) == 0:
                continue
            pose = fr.pose
            if gen == "main":
                fg, _bg = utils.gobs_to_detection_list(cfg=cfg, image=fr.rgb, depth_array=fr.depth, cam_K=world.K,
                                                       idx=idx, gobs=dets.gobs, trans_pose=pose,
                                                       class_names=world.classes, BG_CLASSES=BG,
                                                       color_path=f"frame{idx}.png")
                detection_list = fg
            else:
                gobs = utils.resize_gobs(dets.gobs, fr.rgb)
                gobs = utils.filter_gobs(gobs, fr.rgb, skip_bg=cfg.skip_bg, BG_CLASSES=BG,
                                         mask_area_threshold=cfg.mask_area_threshold,
                                         max_bbox_area_ratio=cfg.max_bbox_area_ratio,
                                         mask_conf_threshold=cfg.mask_conf_threshold)
                if len(gobs["mask"]) == 0:
                    continue
                from conceptgraph.utils.ious import mask_subtract_contained

                gobs["mask"] = mask_subtract_contained(gobs["xyxy"], gobs["mask"])
                pcds = utils.detections_to_obj_pcd_and_bbox(
                    depth_array=fr.depth, masks=gobs["mask"], cam_K=world.K, image_rgb=fr.rgb, trans_pose=pose,
                    min_points_threshold=cfg.min_points_threshold, spatial_sim_type=cfg.spatial_sim_type,
                    obj_pcd_max_points=cfg.obj_pcd_max_points, device="cpu")
                for o in pcds:
                    if o:
                        o["pcd"] = utils.init_process_pcd(pcd=o["pcd"], downsample_voxel_size=cfg.downsample_voxel_size,
                                                          dbscan_remove_noise=cfg.dbscan_remove_noise,
                                                          dbscan_eps=cfg.dbscan_eps, dbscan_min_points=cfg.dbscan_min_points)
                        o["bbox"] = utils.get_bounding_box(spatial_sim_type=cfg.spatial_sim_type, pcd=o["pcd"])
                detection_list = utils.make_detection_list_from_pcd_and_gobs(
                    pcds, gobs, f"frame{idx}.png", _ObjClasses(world.classes), idx)
            for d in detection_list:
                truth_of[(idx, int(d["mask_idx"][0]))] = _truth_under(d["mask"][0], fr.ids)
            if len(detection_list) == 0:
                continue
            if len(objects) == 0:
                if gen == "main":
                    for d in detection_list:
                        objects.append(d)
                else:
                    objects.extend(detection_list)
                for k in range(prepopulate):
                    objects.append(_far_copy(detection_list[k % len(detection_list)], k))
                continue
            n_dets.append(len(detection_list))
            n_map.append(len(objects))
            box0 = BOX3D_S[0]
            t0 = CLOCK[0]()
            if gen == "main":
                spatial = mapping.compute_spatial_similarities(cfg, detection_list, objects)
                visual = mapping.compute_visual_similarities(cfg, detection_list, objects)
                agg = mapping.aggregate_similarities(cfg, spatial, visual)
                agg[agg < cfg.sim_threshold] = float("-inf")
                t1 = CLOCK[0]()
                objects = mapping.merge_detections_to_objects(cfg, detection_list, objects, agg)
            else:
                spatial = mapping.compute_spatial_similarities(spatial_sim_type=cfg.spatial_sim_type,
                                                               detection_list=detection_list, objects=objects,
                                                               downsample_voxel_size=cfg.downsample_voxel_size)
                visual = mapping.compute_visual_similarities(detection_list, objects)
                agg = mapping.aggregate_similarities(match_method=cfg.match_method, phys_bias=cfg.phys_bias,
                                                     spatial_sim=spatial, visual_sim=visual)
                t1 = CLOCK[0]()
                match = mapping.match_detections_to_objects(agg_sim=agg, detection_threshold=cfg.sim_threshold)
                objects = mapping.merge_obj_matches(detection_list=detection_list, objects=objects,
                                                    match_indices=match,
                                                    downsample_voxel_size=cfg.downsample_voxel_size,
                                                    dbscan_remove_noise=cfg.dbscan_remove_noise,
                                                    dbscan_eps=cfg.dbscan_eps, dbscan_min_points=cfg.dbscan_min_points,
                                                    spatial_sim_type=cfg.spatial_sim_type, device="cpu")
                for obj in objects:  # the script's inline relabel loop (majority of class ids)
                    cid = Counter(obj["class_id"]).most_common(1)[0][0]
                    name = world.classes[cid]
                    if obj["class_name"] != name:
                        obj["class_name"] = name
            t2 = CLOCK[0]()
            fusion_ms.append(1000 * (t2 - t0))
            merge_ms.append(1000 * (t2 - t1))
            box3d_ms.append(1000 * (BOX3D_S[0] - box0))
            if fusion_hook is not None:
                fusion_hook(idx, objects)
            if idx < n - 1:
                objects = _post(cfg, utils, gen, objects, idx)
        objects = _post(cfg, utils, gen, objects, n - 1, final=True)  # the scripts' end-of-run pass
        labels = _labels(objects, gen, world.classes)
        summary = backend.summary(objects) if backend is not None else None
    if prepopulate:
        keep = [k for k, o in enumerate(objects) if not str(o["color_path"][0]).startswith("prepopulated")]
        labels, objects = [labels[k] for k in keep], [objects[k] for k in keep]
    truth = []
    for obj in objects:
        votes = Counter(truth_of.get((int(i), int(m)), -1) for i, m in zip(obj["image_idx"], obj["mask_idx"]))
        truth.append(votes.most_common(1)[0][0])
    acc = float(np.mean([lab == (world.objects[t][0] if t >= 0 else None) for lab, t in zip(labels, truth)]))
    return RunResult(labels, truth, acc, _miou(objects, labels, truth, world), len(objects), fusion_ms, summary,
                     n_dets, n_map, box3d_ms, merge_ms, _vote_ties_at_random(objects, truth, world))


def _vote_ties_at_random(objects: Any, truth: list[int], world: World) -> float:
    """The vote's expected accuracy with its ties broken at random (see RunResult)."""
    score = 0.0
    for obj, t in zip(objects, truth):
        counts = Counter(world.classes[int(c)] for c in obj["class_id"])
        top = max(counts.values())
        tied = [c for c, n in counts.items() if n == top]
        score += (t >= 0 and world.objects[t][0] in tied) / len(tied)
    return score / max(len(truth), 1)


def _far_copy(det: Any, k: int) -> dict:
    """A copy of detection ``det`` moved to grid cell ``k`` outside the room (2 m pitch from x = 10 m)."""
    c = copy.deepcopy(dict(det))
    shift = np.array([10.0 + 2.0 * (k % 32), 2.0 * (k // 32) - 32.0, 0.0])
    c["pcd"].translate(shift)
    c["bbox"].translate(shift)
    # still "seen" at the source's frame (the backend needs a time step >= 0); a mask index no frame
    # has and a path of their own keep the copies' fingerprints distinct and out of the accuracy
    c["mask_idx"] = [10_000 + k]
    c["color_path"] = [f"prepopulated-{k}"]
    if "id" in c:  # ali-dev: a fresh uuid per object
        c["id"] = uuid.uuid4()
    return c


class _null:  # noqa: N801
    def __enter__(self) -> None:
        return None

    def __exit__(self, *a: Any) -> None:
        return None


def _truth_under(mask: np.ndarray, ids: np.ndarray) -> int:
    v = ids[np.asarray(mask, dtype=bool)]
    v = v[v >= 0]
    return int(np.bincount(v).argmax()) if v.size else -1


def _post(cfg: Any, utils: Any, gen: str, objects: Any, idx: int, final: bool = False) -> Any:
    def due(interval: int, run_final: bool) -> bool:
        return (final and run_final) or (not final and interval > 0 and (idx + 1) % interval == 0)

    if gen == "main":
        if due(cfg.denoise_interval, True):
            objects = utils.denoise_objects(cfg, objects)
        if due(cfg.filter_interval, True):
            objects = utils.filter_objects(cfg, objects)
        if due(cfg.merge_interval, True):
            objects = utils.merge_objects(cfg, objects)
        return objects
    kw = dict(downsample_voxel_size=cfg.downsample_voxel_size, dbscan_remove_noise=cfg.dbscan_remove_noise,
              dbscan_eps=cfg.dbscan_eps, dbscan_min_points=cfg.dbscan_min_points,
              spatial_sim_type=cfg.spatial_sim_type, device="cpu")
    if due(cfg.denoise_interval, cfg.run_denoise_final_frame):
        objects = utils.denoise_objects(objects=objects, **kw)
    if due(cfg.filter_interval, cfg.run_filter_final_frame):
        objects = utils.filter_objects(obj_min_points=cfg.obj_min_points, obj_min_detections=cfg.obj_min_detections,
                                       objects=objects, map_edges=None)
    if due(cfg.merge_interval, cfg.run_merge_final_frame):
        objects = utils.merge_objects(merge_overlap_thresh=cfg.merge_overlap_thresh,
                                      merge_visual_sim_thresh=cfg.merge_visual_sim_thresh,
                                      merge_text_sim_thresh=cfg.merge_text_sim_thresh, objects=objects,
                                      do_edges=False, map_edges=None, **kw)
    return objects


def _labels(objects: Any, gen: str, classes: list[str]) -> list[str]:
    if gen == "main":
        return [classes[int(c)] if int(c) >= 0 else "unknown" for c in objects.get_most_common_class()]
    return [str(o["class_name"]) for o in objects]


def _miou(objects: Any, labels: list[str], truth: list[int], world: World) -> float:
    """Mean over ground-truth classes of point IoU on the map (a point's truth: its object's)."""
    tp: Counter[str] = Counter()
    fp: Counter[str] = Counter()
    fn: Counter[str] = Counter()
    for obj, lab, t in zip(objects, labels, truth):
        n = len(obj["pcd"].points)
        gt = world.objects[t][0] if t >= 0 else None
        if gt == lab:
            tp[lab] += n
        else:
            fp[lab] += n
            if gt is not None:
                fn[gt] += n
    gts = sorted({c for c, _, _ in world.objects})
    return float(np.mean([tp[c] / max(tp[c] + fp[c] + fn[c], 1) for c in gts]))


def annotated_detections(world: World, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` detections of the harness's detector with their correctness, as a user would annotate
    a few frames to fit ``ScoreCalibration`` (drawn from frames cycled in order, with their own
    generator: not the run's detections)."""
    rng = np.random.default_rng(seed + 7919)
    feats = features(world)
    scores: list[float] = []
    right: list[bool] = []
    k = 0
    while len(scores) < n:
        d = detect(world, k % len(world.frames), rng, feats=feats)
        for cid, conf, obj in zip(d.gobs["class_id"], d.gobs["confidence"], d.truth):
            scores.append(float(conf))
            right.append(world.classes[int(cid)] == world.objects[obj][0])
        k += 1
    return np.asarray(scores[:n]), np.asarray(right[:n])


def make_backend(operator: str, channel: Any, *, operator_config: Any = None, confidence_map: Any = None) -> Any:
    """The backend built exactly as the README shows: an operator name, a context, a channel (and an
    operator config only when an experiment names one). No vocabulary and no class list: the
    backend learns the class list from ConceptGraphs (the ``class_names`` the run hands
    ``gobs_to_detection_list`` on main, the class holder given to
    ``make_detection_list_from_pcd_and_gobs`` on ali-dev)."""
    from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend

    extra = {} if operator_config is None else {"operator_config": operator_config}
    if confidence_map is not None:
        extra["confidence_map"] = confidence_map
    return ConceptGraphsBackend(operator, context="harness-detector", channel=channel, **extra)

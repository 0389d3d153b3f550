"""The realistic suite: real COCO detector records laid over ScanNet-like rooms (docs/simulation.md).

One seed gives one world (rooms, camera views, the channels' labels per key frame) and, per
detector, one claim stream; a *cell* is a view of it: (detector, channel, confidence transform).

- **Matched claims.** A visible object that a COCO detector finds as class k (its NYU40 label may
  disagree: ScanNet files monitors, which COCO calls tv, under otherprop) is detected in a key frame
  with probability recall_k = matched records of k / COCO val2017 instances of k, and gets the
  score of a resampled *matched* record of k.
- **Unmatched claims.** Their number per class is Poisson(FP_k / TP_k x the stream's matched claims
  of k), the detector's own false-positive ratio in the records; each lands on another object in
  view (next to a detected object of k, on an object of a class k is mistaken for, or anywhere in
  the frame by image area) and gets the score of a resampled *unmatched* record of k.
- Scores are resampled, never invented: the quantile of a Gaussian copula (half its variance fixed
  per object and class, so an object's scores are correlated over time) picks a record of the
  stream half of a by-image split; the other half is :func:`calibration_records`.
- **Channels.** ``mesh``: the object's NYU40 label in about half of the claims (never for
  unannotated objects); ``segmenter``: a label-image classifier with confusions and persistent
  errors, about as often; ``none``.

``realistic_cell(seed, detector, channel, transform)`` returns a cell's events, truth and
vocabulary, ready for ``replay`` or ``op.update_many(graph, cell.pairs())``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from sgbelief.eval.detector_records import COCO_TO_PREDICATE, DetectorRecords, load_detector_records, split_half
from sgbelief.eval.formats import EventRecord
from sgbelief.eval.realistic_config import CHANNELS, RealisticConfig, load_realistic_config
from sgbelief.eval.realistic_world import FrameView, Room, build_room, room_types, room_views
from sgbelief.eval.sim_config import load_vocabulary
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.events import EvidenceEvent

__all__ = ["RealisticWorld", "RealisticCell", "ClaimColumns", "generate_world", "realistic_cell",
           "calibration_records", "stream_records", "detector_rates", "KINDS", "CHANNELS"]

#: what put a claim on its object: a matched detection, or an unmatched one of three origins
KINDS = ("matched", "localisation", "similar", "background")
_NONE = -1


@lru_cache(maxsize=8)
def _halves(name: str, split_seed: int) -> tuple[DetectorRecords, DetectorRecords, DetectorRecords]:
    rec = load_detector_records(name)
    cal, stream = split_half(rec, split_seed)
    return rec, cal, stream


def calibration_records(detector: str, config: RealisticConfig | None = None) -> DetectorRecords:
    """The half of a detector's records the suite never streams (for offline calibration)."""
    cfg = config or load_realistic_config()
    return _halves(cfg.detection.records[detector], cfg.detection.record_split_seed)[1]


def stream_records(detector: str, config: RealisticConfig | None = None) -> DetectorRecords:
    """The half of a detector's records whose scores the suite resamples."""
    cfg = config or load_realistic_config()
    return _halves(cfg.detection.records[detector], cfg.detection.record_split_seed)[2]


def detector_rates(detector: str, config: RealisticConfig | None = None) -> dict[str, tuple[float, float]]:
    """Per COCO class: (recall = matched records / val2017 instances, unmatched / matched records),
    from all of the detector's records."""
    cfg = config or load_realistic_config()
    rec = _halves(cfg.detection.records[detector], cfg.detection.record_split_seed)[0]
    out = {}
    for coco, cid in cfg.detection.coco_ids.items():
        m = rec.matched[rec.class_id == cid]
        tp, fp = int(m.sum()), int(m.size - m.sum())
        if tp == 0:
            raise ValueError(f"detector records {rec.name!r} have no matched record of COCO class {coco!r}")
        out[coco] = (min(1.0, tp / cfg.detection.instances_val2017[coco]), fp / tp)
    return out


@dataclass(frozen=True)
class ClaimColumns:
    """One detector's claim stream, one entry per claim, in stream order."""

    t: NDArray[np.int64]
    room: NDArray[np.intp]
    frame: NDArray[np.intp]
    obj: NDArray[np.intp]
    coco: NDArray[np.intp]  # index into config.detection.coco_ids
    kind: NDArray[np.intp]  # index into KINDS
    score: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass
class RealisticWorld:
    """One seed's rooms, views and channel labels; claim streams are built per detector on demand."""

    config: RealisticConfig
    seed: int
    rooms: list[Room]
    views: list[list[FrameView]]
    t0: list[int]
    label_names: list[str]
    mesh: list[NDArray[np.intp]]  # per room (frames, objects): label index or -1
    segmenter: list[NDArray[np.intp]]
    _claims: dict[str, ClaimColumns] = field(default_factory=dict)
    _seeds: dict[str, np.random.SeedSequence] = field(default_factory=dict)

    def claims(self, detector: str) -> ClaimColumns:
        if detector not in self.config.detection.records:
            raise ValueError(f"unknown detector {detector!r}; known: {sorted(self.config.detection.records)}")
        if detector not in self._claims:
            rng = np.random.default_rng(self._seeds[detector])
            self._claims[detector] = _claim_stream(self, detector, rng)
        return self._claims[detector]

    def nodes(self) -> list[tuple[str, Room, int]]:
        return [(room.node(i), room, i) for room in self.rooms for i in range(room.n)]

    def cell(self, detector: str = "rfcn", channel: str = "mesh", transform: str = "c") -> RealisticCell:
        return _make_cell(self, detector, channel, transform)


@dataclass(frozen=True)
class RealisticCell:
    """A cell's evidence stream, the truth it is scored against and the vocabulary."""

    seed: int
    detector: str
    channel: str
    transform: str
    events: list[EventRecord]
    truth: dict[str, dict[str, int]]
    table: SubsumptionTable
    predicates: tuple[str, ...]
    kinds: tuple[str, ...]  # per event: KINDS
    labels: dict[str, str | None]  # node -> NYU40 label (None: unannotated)
    categories: dict[str, str]  # node -> raw category

    def pairs(self) -> list[tuple[EvidenceEvent, FrameLabels]]:
        """(event, channel) pairs for ``op.update_many(graph, cell.pairs())``."""
        return [(EvidenceEvent.trusted(r.targets, r.predicate, r.confidence, r.context, r.t, r.id or f"e{i}"),
                 FrameLabels(r.geometric)) for i, r in enumerate(self.events)]


# ------------------------------------------------------------------------------------- world
def generate_world(seed: int, config: RealisticConfig | str | None = None) -> RealisticWorld:
    """Rooms, views and channel labels of one seed (claims are drawn per detector, lazily)."""
    cfg = config if isinstance(config, RealisticConfig) else load_realistic_config(config or "realistic")
    ss = np.random.SeedSequence(seed)
    s_world, s_channels, *s_det = ss.spawn(2 + len(cfg.detection.records))
    r_world, r_chan = np.random.default_rng(s_world), np.random.default_rng(s_channels)
    n_rooms = max(1, int(round(cfg.scenes * cfg.scale)))
    rooms, views, t0 = [], [], []
    t = 0
    for k, rtype in enumerate(room_types(cfg, n_rooms, r_world)):
        room = build_room(cfg, f"room{k:03d}", rtype, r_world)
        lo, hi = cfg.frames_per_scene
        n_frames = int(r_world.integers(lo, hi + 1))
        rooms.append(room)
        views.append(room_views(cfg, room, n_frames, r_world))
        t0.append(t)
        t += n_frames + cfg.time_gap
    names = sorted(cfg.labels())
    index = {name: i for i, name in enumerate(names)}
    mesh, seg = [], []
    ch = cfg.channels
    for room, vs in zip(rooms, views):
        nf = len(vs)
        m = np.full((nf, room.n), _NONE, dtype=np.intp)
        s = np.full((nf, room.n), _NONE, dtype=np.intp)
        for i, lab in enumerate(room.labels):
            seen = r_chan.random(nf) < ch.coverage
            if lab is not None:
                m[seen, i] = index[lab]
            row = ch.row(lab if lab is not None else "unlabelled")
            conf = list(row.confusions)
            w = np.asarray([row.confusions[c] for c in conf], dtype=float)
            correct = (r_chan.random(nf) < row.accuracy) if lab is not None else np.zeros(nf, dtype=bool)
            wrong = (np.asarray([index[c] for c in conf], dtype=np.intp)[r_chan.choice(len(conf), nf, p=w / w.sum())]
                     if conf else np.full(nf, _NONE, dtype=np.intp))
            out = np.where(correct, index[lab] if lab is not None else _NONE, wrong)
            if conf and r_chan.random() < ch.persistent_error:
                fixed = index[conf[int(r_chan.choice(len(conf), p=w / w.sum()))]]
                out = np.where(r_chan.random(nf) < ch.persistent_strength, fixed, out)
            s[seen, i] = out[seen]
        mesh.append(m)
        seg.append(s)
    return RealisticWorld(cfg, seed, rooms, views, t0, names, mesh, seg,
                          _seeds=dict(zip(cfg.detection.records, s_det)))


# ------------------------------------------------------------------------------------ claims
def _pools(cfg: RealisticConfig, detector: str) -> dict[tuple[int, int], NDArray[np.float64]]:
    rec = stream_records(detector, cfg)
    out = {}
    for k, cid in enumerate(cfg.detection.coco_ids.values()):
        for y in (0, 1):
            pool = np.sort(rec.score[(rec.class_id == cid) & (rec.matched == y)].astype(np.float64))
            if pool.size == 0:
                raise ValueError(f"detector {detector!r}: no {'matched' if y else 'unmatched'} record of COCO "
                                 f"class {cid} in the stream half")
            out[(k, y)] = pool
    return out


def _claim_stream(world: RealisticWorld, detector: str, rng: np.random.Generator) -> ClaimColumns:
    cfg = world.config
    coco_names = list(cfg.detection.coco_ids)
    cidx = {c: i for i, c in enumerate(coco_names)}
    rates = detector_rates(detector, cfg)
    recall = np.asarray([rates[c][0] for c in coco_names])
    fp_ratio = np.asarray([rates[c][1] for c in coco_names])
    fps = cfg.false_positives
    shape = fps.attraction_shape
    attraction = [rng.gamma(shape, 1.0 / shape, room.n) for room in world.rooms]
    u = [rng.standard_normal((room.n, len(coco_names))) for room in world.rooms]
    coco_of = [np.asarray([cidx[c] if c is not None else _NONE for c in room.coco], dtype=np.intp)
               for room in world.rooms]
    rows: list[tuple[int, int, int, int, int]] = []  # room, frame, obj, coco, kind
    # matched detections, frame by frame
    for r, vs in enumerate(world.views):
        for f, v in enumerate(vs):
            k = coco_of[r][v.visible]
            det = (k >= 0) & (rng.random(k.size) < recall[np.maximum(k, 0)])
            rows += [(r, f, int(o), int(kk), 0) for o, kk in zip(v.visible[det], k[det])]
    tp = np.asarray(rows, dtype=np.intp).reshape(-1, 5)
    # frames with something in view (background false positives)
    framelist = [(r, f) for r, vs in enumerate(world.views) for f, v in enumerate(vs) if v.visible.size]
    cat_of = [np.asarray(room.categories, dtype=object) for room in world.rooms]
    shares = [fps.shares.get(k, 0.0) for k in ("localisation", "similar", "background")]

    def background(k: int, r: int, f: int) -> tuple[int, int, int, int, int] | None:
        v = world.views[r][f]
        ok = coco_of[r][v.visible] != k
        if not ok.any():
            return None
        w = (v.area * attraction[r][v.visible])[ok]
        o = v.visible[ok][int(rng.choice(int(ok.sum()), p=w / w.sum()))] if w.sum() > 0 else v.visible[ok][0]
        return (r, f, int(o), k, 3)

    for k, name in enumerate(coco_names):
        n_tp = int((tp[:, 3] == k).sum())
        n_fp = int(rng.poisson(fp_ratio[k] * n_tp)) if n_tp else 0
        if n_fp == 0:
            continue
        mine = tp[tp[:, 3] == k]
        sim_cats = set(fps.similar.get(name, []))
        cand = [(r, f, int(o)) for r, vs in enumerate(world.views) for f, v in enumerate(vs)
                for o in v.visible if cat_of[r][o] in sim_cats and coco_of[r][o] != k] if sim_cats else []
        cand_w = np.asarray([attraction[r][o] for r, _, o in cand], dtype=float)
        kinds = rng.choice(3, n_fp, p=np.asarray(shares) / sum(shares))
        for kind in kinds:
            row: tuple[int, int, int, int, int] | None = None
            if kind == 0:  # a poorly localised box next to a detected object of k
                r, f, o = (int(x) for x in mine[int(rng.integers(len(mine)))][:3])
                v = world.views[r][f]
                j = int(np.flatnonzero(v.visible == o)[0])
                iou = _overlap(v.boxes[j], v.boxes) * attraction[r][v.visible]
                iou[coco_of[r][v.visible] == k] = 0.0
                if iou.sum() > 0:
                    row = (r, f, int(v.visible[int(rng.choice(iou.size, p=iou / iou.sum()))]), k, 1)
                else:
                    row = background(k, r, f)
            elif kind == 1 and cand:  # an object of a class k is mistaken for
                r, f, o = cand[int(rng.choice(len(cand), p=cand_w / cand_w.sum()))]
                row = (r, f, o, k, 2)
            if row is None:
                for _ in range(20):
                    r, f = framelist[int(rng.integers(len(framelist)))]
                    row = background(k, r, f)
                    if row is not None:
                        break
            if row is not None:
                rows.append(row)
    arr = np.asarray(rows, dtype=np.intp).reshape(-1, 5)
    t = np.asarray([world.t0[r] + f for r, f in arr[:, :2]], dtype=np.int64)
    order = np.lexsort((rng.random(len(arr)), t))
    arr, t = arr[order], t[order]
    # scores: the copula quantile picks a record of the stream half
    pools = _pools(cfg, detector)
    rho = cfg.detection.score_persistence
    z = (math.sqrt(rho) * np.asarray([u[r][o, k] for r, _, o, k, _ in arr])
         + math.sqrt(1 - rho) * rng.standard_normal(len(arr)))
    q = 0.5 * np.vectorize(math.erfc)(-z / math.sqrt(2.0)) if len(arr) else np.zeros(0)
    score = np.empty(len(arr))
    for i, ((_, _, _, k, kind), qi) in enumerate(zip(arr, q)):
        pool = pools[(int(k), int(kind == 0))]
        score[i] = pool[min(int(qi * pool.size), pool.size - 1)]
    return ClaimColumns(t=t, room=arr[:, 0], frame=arr[:, 1], obj=arr[:, 2], coco=arr[:, 3], kind=arr[:, 4],
                        score=score)


def _overlap(box: NDArray[np.float64], boxes: NDArray[np.float64]) -> NDArray[np.float64]:
    """IoU of one image box with many (zero for the box itself is the caller's business)."""
    iw = np.clip(np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0]), 0, None)
    ih = np.clip(np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1]), 0, None)
    inter = iw * ih
    union = (box[2] - box[0]) * (box[3] - box[1]) + (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]) - inter
    out = np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)
    out[np.all(boxes == box, axis=1)] = 0.0
    return out


# -------------------------------------------------------------------------------------- cells
def _make_cell(world: RealisticWorld, detector: str, channel: str, transform: str) -> RealisticCell:
    cfg = world.config
    if channel not in CHANNELS:
        raise ValueError(f"unknown channel {channel!r}; known: {list(CHANNELS)}")
    if transform not in cfg.transforms:
        raise ValueError(f"unknown confidence transform {transform!r}; known: {sorted(cfg.transforms)}")
    power = cfg.transforms[transform]
    cl = world.claims(detector)
    coco_ids = list(cfg.detection.coco_ids.values())
    pred_of = [COCO_TO_PREDICATE[cid][0] for cid in coco_ids]
    names = world.label_names
    grid: list[NDArray[np.intp]] | None = {"mesh": world.mesh, "segmenter": world.segmenter}.get(channel)
    events = []
    for i in range(len(cl)):
        r, f, o = int(cl.room[i]), int(cl.frame[i]), int(cl.obj[i])
        node = world.rooms[r].node(o)
        lab = None
        if grid is not None:
            li = int(grid[r][f, o])
            lab = names[li] if li >= 0 else None
        c = float(cl.score[i]) ** power
        events.append(EventRecord(int(cl.t[i]), {node: 1.0}, pred_of[int(cl.coco[i])], c, detector, {node: lab},
                                  f"e{i:07d}"))
    vocab = load_vocabulary(cfg.vocabulary)
    positives = {p: set(spec.get("positive", [])) for p, spec in vocab["predicates"].items()}
    truth = {node: {p: int(room.labels[i] in pos) for p, pos in positives.items()} for node, room, i in world.nodes()}
    return RealisticCell(
        seed=world.seed, detector=detector, channel=channel, transform=transform, events=events, truth=truth,
        table=_table(cfg.vocabulary), predicates=tuple(cfg.evaluated_predicates),
        kinds=tuple(KINDS[int(k)] for k in cl.kind),
        labels={node: room.labels[i] for node, room, i in world.nodes()},
        categories={node: room.categories[i] for node, room, i in world.nodes()},
    )


@lru_cache(maxsize=4)
def _table(name: str) -> SubsumptionTable:
    return SubsumptionTable.resolve(name)


def realistic_cell(seed: int, detector: str = "rfcn", channel: Literal["mesh", "segmenter", "none"] | str = "mesh",
                   transform: str = "c", config: RealisticConfig | str | None = None) -> RealisticCell:
    """One cell of the realistic suite: its events (with the channel's labels), truth and vocabulary.

    Several cells of one seed share the world; to build many, call :func:`generate_world` once and
    ``world.cell(detector, channel, transform)``.
    """
    return generate_world(seed, config).cell(detector, channel, transform)

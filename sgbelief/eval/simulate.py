"""Seeded generator of simulated evidence logs (outdoor KITTI-360-like, indoor ScanNet-like).

``simulate(config, seed)`` lays out scenes (:mod:`sgbelief.eval.sim_world`), moves a camera through
them, and emits for every frame: the two geometric channels' labels (``oracle`` and ``segmenter``)
for every visible element, box proposals verified by a foundation model (a latent score ``z`` per
claim, turned into a confidence by the profile's strictly increasing per-class distortion
``c = sigmoid(gain * z + bias)``), hallucinated boxes, and targeting distributions from
projected-box IoU.  The generative model is documented in docs/simulation.md.

The generator knows nothing about update operators: it uses the vocabulary only to decide the
ground truth of (element, predicate) pairs (label in the predicate's positive set).
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sgbelief.errors import ConfigError
from sgbelief.eval.formats import (
    EventRecord,
    NodeInfo,
    NodesFile,
    SceneInfo,
    write_events,
    write_nodes,
    write_truth,
)
from sgbelief.eval.metrics import segmentation_iou
from sgbelief.eval.sim_config import SimConfig, load_sim_config, load_vocabulary
from sgbelief.eval.sim_world import (
    SceneWorld,
    box_iou,
    build_indoor_scene,
    build_outdoor_scene,
    occlusion_ioa,
    project_boxes,
)

__all__ = ["SimulatedSuite", "Claim", "View", "simulate", "load_sim_config", "suite_statistics", "most_contradicted",
           "CHANNELS"]

CHANNELS = ("oracle", "segmenter")
_MASS_DECIMALS = 4
_CONF_DECIMALS = 6


@dataclass(frozen=True)
class Claim:
    """One foundation-model claim, independent of the profile and of the geometric channel."""

    t: int
    targets: dict[str, float]
    predicate: str
    z: float  # latent evidence score (logit); confidence = sigmoid(gain * z + bias)
    y: int  # truth of the predicate on the grounding element (0 for hallucinated boxes)
    primary: str | None  # grounding element (None for a box on nothing)
    hallucinated: bool
    geometric: dict[str, dict[str, str | None]]  # channel -> {node: label or None}


@dataclass(frozen=True)
class View:
    """An element's largest unoccluded in-view frame: the crop a whole-image prompt reads."""

    t: int
    area_px: float
    labels: dict[str, str | None]  # geometric channel -> label of the element at t


@dataclass
class SimulatedSuite:
    """The output of :func:`simulate`: claims (any profile / channel view), truth and node geometry."""

    config: SimConfig
    seed: int
    profile: str
    channel: str
    claims: list[Claim]
    truth: dict[str, dict[str, int]]
    nodes: NodesFile
    stats: dict[str, Any] = field(default_factory=dict)
    #: node -> its largest unoccluded view (elements never seen unoccluded are absent)
    views: dict[str, View] = field(default_factory=dict)
    #: the persistent latent offset u_{v,phi} of every (node, predicate) the VLM was asked about
    offsets: dict[tuple[str, str], float] = field(default_factory=dict)
    _cache: dict[tuple[str, str], list[EventRecord]] = field(default_factory=dict, repr=False)

    @property
    def events(self) -> list[EventRecord]:
        """Events of the suite's default profile and channel."""
        return self.events_for(self.profile, self.channel)

    def iter_events(self, profile: str | None = None, channel: str | None = None) -> Iterator[EventRecord]:
        """Events for a profile (confidences, context tag) and a geometric channel, in time order."""
        prof_name = profile or self.profile
        ch = channel or self.channel
        if ch not in CHANNELS:
            raise ConfigError(f"channel: unknown geometric channel {ch!r}; known: {list(CHANNELS)}")
        try:
            prof = self.config.vlm.profiles[prof_name]
        except KeyError:
            raise ConfigError(f"profile: unknown profile {prof_name!r}; known: {sorted(self.config.vlm.profiles)}") \
                from None
        params = {}
        for k, cl in enumerate(self.claims):
            d = params.get(cl.predicate)
            if d is None:
                d = params[cl.predicate] = prof.distortion(cl.predicate)
            c = round(_sigmoid(d.gain * cl.z + d.bias), _CONF_DECIMALS)
            yield EventRecord(t=cl.t, targets=cl.targets, predicate=cl.predicate, confidence=c,
                              context=prof.context, geometric=cl.geometric[ch], id=f"e{k:07d}")

    def events_for(self, profile: str | None = None, channel: str | None = None) -> list[EventRecord]:
        """List version of :meth:`iter_events` (cached)."""
        key = (profile or self.profile, channel or self.channel)
        if key not in self._cache:
            self._cache[key] = list(self.iter_events(*key))
        return self._cache[key]

    def write(self, out_dir: str | os.PathLike[str], *, profile: str | None = None,
              channel: str | None = None) -> dict[str, Path]:
        """Write ``events.jsonl``, ``truth.json`` and ``nodes.json`` into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"events": out / "events.jsonl", "truth": out / "truth.json", "nodes": out / "nodes.json"}
        write_events(paths["events"], self.iter_events(profile, channel))
        write_truth(paths["truth"], self.truth)
        write_nodes(paths["nodes"], self.nodes)
        return paths


def _sigmoid(x: float) -> float:
    if x >= 0:
        return 1.0 / (1.0 + math.exp(-x))
    e = math.exp(x)
    return e / (1.0 + e)


# ----------------------------------------------------------------------------------- generator


class _LatentSource:
    """Draws latent scores z: parametric Gaussians, or quantiles of real detector records."""

    def __init__(self, cfg: SimConfig) -> None:
        self.cfg = cfg
        self.pools: dict[tuple[str, int], np.ndarray] = {}
        if cfg.fm_source == "detector_records":
            from sgbelief.eval.detector_records import load_detector_records, predicate_pool

            rec = load_detector_records(cfg.detector_records)
            preds = set(cfg.vlm.latent) | set(cfg.evaluated_predicates)
            preds |= {p for row in cfg.detector.proposals.values() for p in row}
            preds |= set(cfg.detector.hallucination_predicates)
            for p in sorted(preds):
                s, m = predicate_pool(rec, p)
                for y in (0, 1):
                    pool = np.sort(s[m == y].astype(np.float64))
                    if pool.size >= 10:
                        self.pools[(p, y)] = pool

    def z(self, predicate: str, y_eff: int, noise: float) -> float:
        """Latent score for outcome ``y_eff`` given a standard-normal correlated noise draw."""
        spec = self.cfg.vlm.spec(predicate)
        pool = self.pools.get((predicate, y_eff))
        if pool is None:
            return (spec.mu_pos if y_eff else spec.mu_neg) + spec.sigma * noise
        q = 0.5 * math.erfc(-noise / math.sqrt(2.0))  # Phi(noise)
        s = float(pool[min(int(q * pool.size), pool.size - 1)])
        s = min(max(s, 1e-4), 1 - 1e-4)
        return math.log(s / (1 - s))


def _truth_table(vocab: dict[str, Any]) -> dict[str, set[str]]:
    return {p: set(spec.get("positive", [])) for p, spec in vocab["predicates"].items()}


def simulate(
    suite_config: SimConfig | str | os.PathLike[str],
    seed: int = 0,
    out_dir: str | os.PathLike[str] | None = None,
    *,
    profile: str | None = None,
    channel: str | None = None,
    fm_source: str | None = None,
    scale: float | None = None,
) -> SimulatedSuite:
    """Generate a suite deterministically from ``seed`` (and write it to ``out_dir`` if given).

    ``profile`` / ``channel`` pick the default view (both views are always generated, so
    :meth:`SimulatedSuite.events_for` can swap them without regenerating); ``fm_source`` and
    ``scale`` override the config.
    """
    started = time.perf_counter()
    if isinstance(suite_config, SimConfig):
        upd = {k: v for k, v in {"fm_source": fm_source, "scale": scale}.items() if v is not None}
        cfg = SimConfig.model_validate({**suite_config.model_dump(), **upd}) if upd else suite_config
    else:
        cfg = load_sim_config(suite_config, fm_source=fm_source, scale=scale)
    prof = profile or cfg.profile
    ch = channel or cfg.channel
    if prof not in cfg.vlm.profiles:
        raise ConfigError(f"profile: unknown profile {prof!r}; known: {sorted(cfg.vlm.profiles)}")
    if ch not in CHANNELS:
        raise ConfigError(f"channel: unknown geometric channel {ch!r}; known: {list(CHANNELS)}")
    vocab = load_vocabulary(cfg.vocabulary)
    positives = _truth_table(vocab)
    predicates = list(vocab["predicates"])

    ss = np.random.SeedSequence(seed)
    r_world, r_occ, r_seg, r_det, r_vlm = (np.random.default_rng(s) for s in ss.spawn(5))
    latent = _LatentSource(cfg)
    det = cfg.detector
    seg = cfg.segmenter
    unlabeled = set(cfg.oracle.unlabeled)
    filt = {p: set(v) for p, v in (det.candidate_filter or {}).items()}
    hall_preds = list(det.hallucination_predicates)
    hall_p = np.asarray([det.hallucination_predicates[p] for p in hall_preds], dtype=float)
    hall_p /= hall_p.sum()

    claims: list[Claim] = []
    views: dict[str, View] = {}
    element_offsets: dict[tuple[str, str], float] = {}
    truth: dict[str, dict[str, int]] = {}
    node_infos: dict[str, NodeInfo] = {}
    scene_infos: dict[str, SceneInfo] = {}
    seg_true: list[str | None] = []
    seg_pred: list[str | None] = []
    counters: Counter[str] = Counter()
    t0 = 0

    for scene in cfg.scenes:
        world = (build_outdoor_scene if cfg.kind == "outdoor" else build_indoor_scene)(cfg, scene, r_world)
        n = world.n
        ids = [f"{scene}/{i:04d}" for i in range(n)]
        # per-element persistent traits
        detect_mult = r_det.gamma(det.detectability_shape, 1.0 / det.detectability_shape, n)
        confuse_mult = r_det.gamma(det.confusability_shape, 1.0 / det.confusability_shape, n)
        persistent = r_seg.random(n) < seg.persistent_error
        persistent_label: list[str | None] = []
        for i in range(n):
            spec = seg.spec(world.labels[i])
            conf = spec.confusions
            if persistent[i] and conf:
                keys = sorted(conf)
                pr = np.asarray([conf[k] for k in keys], dtype=float)
                persistent_label.append(keys[int(r_seg.choice(len(keys), p=pr / pr.sum()))])
            else:
                persistent_label.append(None)
        flat = (world.hi[:, 2] - world.lo[:, 2]) <= 0.3
        offsets: dict[tuple[int, str], float] = {}
        ar_state: dict[tuple[int, str], tuple[int, float]] = {}
        seen_first = np.full(n, -1)
        seen_last = np.full(n, -1)
        depths: list[list[float]] = [[] for _ in range(n)]
        drive_dir = np.zeros(n, dtype=bool)
        tracks: list[list[tuple[int, float, float, float]]] = [[] for _ in range(n)]
        half_angle = math.radians(cfg.outdoor.drive_direction_half_angle_deg) if cfg.outdoor else 0.0
        ego_track: list[tuple[int, float, float, float, float]] = []

        for f in range(world.n_frames):
            t = t0 + f
            pos, yaw = world.cam_pos[f], float(world.cam_yaw[f])
            ego_track.append((t, *(round(float(x), 3) for x in pos), round(yaw, 4)))
            lo = world.lo + world.vel * f
            hi = world.hi + world.vel * f
            boxes, depth, vis = project_boxes(lo, hi, pos, yaw, cfg.camera)
            idx = np.flatnonzero(vis)
            m = idx.size
            if m == 0:
                continue
            vb, vd = boxes[idx], depth[idx]
            occ = (occlusion_ioa(vb, vd, world.occluder[idx]) > cfg.occlusion.ioa_threshold) | (
                r_occ.random(m) < cfg.occlusion.random_rate)
            # bookkeeping for node geometry
            cen = (lo[idx] + hi[idx]) / 2
            for j, i in enumerate(idx.tolist()):
                if seen_first[i] < 0:
                    seen_first[i] = t
                seen_last[i] = t
                depths[i].append(float(vd[j]))
                if world.kind == "outdoor":
                    rel = cen[j] - pos
                    if 5.0 <= rel[0] <= 40.0 and abs(math.atan2(rel[1], rel[0])) <= half_angle:
                        drive_dir[i] = True
                    if np.any(world.vel[i]) and (not tracks[i] or t - tracks[i][-1][0] >= 2):
                        tracks[i].append((t, *(round(float(x), 3) for x in cen[j])))
            # geometric channels at (v, t)
            oracle_lab: dict[int, str | None] = {}
            seg_lab: dict[int, str | None] = {}
            u_seg = r_seg.random((m, 3))
            for j, i in enumerate(idx.tolist()):
                lab = world.labels[i]
                if occ[j]:
                    oracle_lab[i] = None
                    seg_lab[i] = None
                    continue
                oracle_lab[i] = None if lab in unlabeled else lab
                spec = seg.spec(lab)
                if persistent_label[i] is not None and u_seg[j, 0] < seg.persistent_strength:
                    s_lab: str | None = persistent_label[i]
                elif u_seg[j, 1] < spec.miss:
                    s_lab = None
                elif u_seg[j, 2] < spec.accuracy or not spec.confusions:
                    s_lab = lab
                else:
                    keys = sorted(spec.confusions)
                    pr = np.asarray([spec.confusions[k] for k in keys], dtype=float)
                    cum = np.cumsum(pr / pr.sum())
                    r = (u_seg[j, 2] - spec.accuracy) / max(1.0 - spec.accuracy, 1e-12)
                    s_lab = keys[min(int(np.searchsorted(cum, r, side="right")), len(keys) - 1)]
                seg_lab[i] = s_lab
                area = float((vb[j, 2] - vb[j, 0]) * (vb[j, 3] - vb[j, 1]))
                if ids[i] not in views or area > views[ids[i]].area_px:
                    views[ids[i]] = View(t, area, {"oracle": oracle_lab[i], "segmenter": s_lab})
                if lab not in unlabeled:
                    seg_true.append(lab)
                    seg_pred.append(s_lab)

            # box proposals (fixed detector) and hallucinated boxes
            proposals: list[tuple[int | None, str, np.ndarray]] = []
            for j, i in enumerate(idx.tolist()):
                row = det.proposals.get(world.labels[i])
                if not row:
                    continue
                for pred in sorted(row):
                    correct = world.labels[i] in positives.get(pred, ())
                    rate = row[pred] * (detect_mult[i] if correct else confuse_mult[i])
                    if occ[j]:
                        rate *= det.occluded_factor
                    if r_det.random() < min(rate, 1.0):
                        box = vb[j].copy()
                        w, h = box[2] - box[0], box[3] - box[1]
                        jit = r_det.normal(0.0, det.box_jitter, 4)
                        cu, cv = (box[0] + box[2]) / 2 + jit[0] * w, (box[1] + box[3]) / 2 + jit[1] * h
                        w2, h2 = w * math.exp(jit[2]), h * math.exp(jit[3])
                        proposals.append((i, pred, np.array([cu - w2 / 2, cv - h2 / 2, cu + w2 / 2, cv + h2 / 2])))
            for _ in range(int(r_det.poisson(det.hallucinations_per_frame))):
                j = int(r_det.integers(m))
                box = vb[j].copy()
                w, h = box[2] - box[0], box[3] - box[1]
                shift = r_det.uniform(*det.hallucination_offset) * w * (1 if r_det.random() < 0.5 else -1)
                vshift = r_det.normal(0.0, 0.3) * h
                pred = hall_preds[int(r_det.choice(len(hall_preds), p=hall_p))]
                proposals.append((None, pred, box + np.array([shift, vshift, shift, vshift])))

            for i_primary, pred, cbox in proposals:
                iou = box_iou(cbox, vb)
                if det.ground_overlap_factor < 1.0:
                    iou = np.where(flat[idx] & (idx != (-1 if i_primary is None else i_primary)),
                                   iou * det.ground_overlap_factor, iou)
                total = float(iou.sum())
                mass = iou / max(1.0, total)
                keep = np.flatnonzero(mass >= det.min_logged_mass)
                cand = filt.get(pred)
                if cand is not None:
                    if i_primary is not None and world.labels[i_primary] not in cand:
                        counters["filtered_at_intake"] += 1
                        continue
                    keep = np.asarray([k for k in keep if world.labels[int(idx[k])] in cand], dtype=int)
                if keep.size == 0:
                    counters["dropped_no_target"] += 1
                    continue
                targets: dict[str, float] = {}
                geo_o: dict[str, str | None] = {}
                geo_s: dict[str, str | None] = {}
                scale_ = 10 ** _MASS_DECIMALS
                for k in keep.tolist():
                    i = int(idx[k])
                    mk = math.floor(float(mass[k]) * scale_) / scale_
                    if mk <= 0:
                        continue
                    targets[ids[i]] = mk
                    geo_o[ids[i]] = oracle_lab[i]
                    geo_s[ids[i]] = seg_lab[i]
                if not targets:
                    counters["dropped_no_target"] += 1
                    continue
                # latent evidence score of the VLM's answer about the box
                if i_primary is None:
                    y = 0
                    key = (-1 - int(r_vlm.integers(1 << 30)), pred)
                else:
                    y = int(world.labels[i_primary] in positives.get(pred, ()))
                    key = (i_primary, pred)
                spec = cfg.vlm.spec(pred)
                flip = r_vlm.random() < spec.confident_wrong
                if key not in offsets:
                    offsets[key] = float(r_vlm.normal(0.0, cfg.vlm.element_sigma))
                last = ar_state.get(key)
                eps = float(r_vlm.normal())
                if last is None:
                    e = eps
                else:
                    rho = cfg.vlm.ar_rho_per_step ** max(t - last[0], 0)
                    e = rho * last[1] + math.sqrt(max(1.0 - rho * rho, 0.0)) * eps
                ar_state[key] = (t, e)
                tot_sd = math.sqrt(cfg.vlm.element_sigma ** 2 + spec.sigma ** 2)
                if latent.pools:
                    noise = (offsets[key] + spec.sigma * e) / tot_sd
                    z = latent.z(pred, int(y != flip), noise)
                else:
                    z = (spec.mu_pos if (y != flip) else spec.mu_neg) + offsets[key] + spec.sigma * e
                claims.append(Claim(t=t, targets=targets, predicate=pred, z=round(z, 6), y=y,
                                    primary=None if i_primary is None else ids[i_primary],
                                    hallucinated=i_primary is None,
                                    geometric={"oracle": geo_o, "segmenter": geo_s}))
                counters["flip"] += int(flip)

        element_offsets.update({(ids[i], p): u for (i, p), u in offsets.items() if i >= 0})
        # nodes, truth
        _scene_nodes(cfg, world, t0, ids, seen_first, seen_last, depths, drive_dir, tracks, node_infos)
        for i in range(n):
            truth[ids[i]] = {p: int(world.labels[i] in positives[p]) for p in predicates}
        scene_infos[scene] = SceneInfo(kind=world.kind, t_start=t0, t_end=t0 + world.n_frames - 1,
                                       ego_track=ego_track, **{k: v for k, v in world.info.items()})
        t0 += world.n_frames + cfg.time_gap

    thresholds: dict[str, float] = {}
    if cfg.outdoor:
        thresholds = {"near_road_px": cfg.outdoor.near_road_px, "intersection_radius_m": cfg.outdoor.intersection_radius_m,
                      "near_pedestrian_m": cfg.outdoor.near_pedestrian_m,
                      "drive_direction_half_angle_deg": cfg.outdoor.drive_direction_half_angle_deg,
                      "stationary_max_displacement_m": 1.0}
    elif cfg.indoor:
        ind = cfg.indoor
        thresholds = {"near_window_m": ind.near_window_m, "workspace_height_min_m": ind.workspace_height_m[0],
                      "workspace_height_max_m": ind.workspace_height_m[1], "access_depth_m": ind.access_depth_m,
                      "facing_distance_m": ind.facing_distance_m, "facing_half_angle_deg": ind.facing_half_angle_deg}
    nodes = NodesFile(suite=cfg.name, scenes=scene_infos, nodes=node_infos, geometric_thresholds=thresholds)
    miou, per_class = segmentation_iou(seg_true, seg_pred)
    suite = SimulatedSuite(config=cfg, seed=seed, profile=prof, channel=ch, claims=claims, truth=truth, nodes=nodes,
                           views=views, offsets=element_offsets)
    suite.stats = {
        "suite": cfg.name, "seed": seed, "fm_source": cfg.fm_source,
        "events": len(claims), "nodes": len(truth), "scenes": len(cfg.scenes),
        "time_steps": t0 - cfg.time_gap,
        "segmenter_miou": miou, "segmenter_iou_per_class": per_class,
        "hallucinated_claims": sum(c.hallucinated for c in claims),
        "confident_wrong_draws": counters["flip"],
        "filtered_at_intake": counters["filtered_at_intake"],
        "dropped_no_target": counters["dropped_no_target"],
        "generation_s": time.perf_counter() - started,
    }
    if out_dir is not None:
        suite.write(out_dir)
    return suite


# ----------------------------------------------------------------------------------- node geometry


def _scene_nodes(cfg: SimConfig, world: SceneWorld, t0: int, ids: list[str], first: np.ndarray, last: np.ndarray,
                 depths: list[list[float]], drive_dir: np.ndarray,
                 tracks: list[list[tuple[int, float, float, float]]], out: dict[str, NodeInfo]) -> None:
    """Per-node geometry, raw attributes and the derived geometric-channel context predicates."""
    n = world.n
    lo, hi = world.lo, world.hi
    cen = (lo + hi) / 2
    if world.kind == "outdoor":
        o = cfg.outdoor
        assert o is not None
        inter = np.asarray(world.info["intersections_x"], dtype=float)
        hw = o.road_half_width_m
        peds = [i for i in range(n) if world.labels[i] == "person"]
        for i in range(n):
            moving = bool(np.any(world.vel[i]))
            # centroid at mid-visibility for movers
            f_mid = int((first[i] + last[i]) // 2 - t0) if first[i] >= 0 else 0
            shift = world.vel[i] * f_mid
            c = cen[i] + shift
            track = tracks[i] if moving and tracks[i] else (
                [(int(first[i]), *map(float, np.round(c, 3))), (int(last[i]), *map(float, np.round(c, 3)))]
                if first[i] >= 0 else None)
            speed = float(np.linalg.norm(world.vel[i]) / o.step_s)
            gap = max(0.0, min(abs(lo[i, 1] + shift[1]), abs(hi[i, 1] + shift[1])) - hw) \
                if (lo[i, 1] + shift[1]) * (hi[i, 1] + shift[1]) > 0 else 0.0
            d_med = float(np.median(depths[i])) if depths[i] else 20.0
            road_px = cfg.camera.focal_px * gap / max(d_med, 1.0)
            inter_d = float(np.min(np.abs(inter - c[0]))) if inter.size else math.inf
            lateral = world.extra[i].get("lateral")
            near_ped = any(j != i and np.linalg.norm(cen[j][:2] - c[:2]) <= o.near_pedestrian_m for j in peds)
            attrs = {"speed": round(speed, 3), "road_distance_px": round(road_px, 2),
                     "on_sidewalk": lateral == "sidewalk", "intersection_distance": round(inter_d, 2),
                     "at_intersection": inter_d <= o.intersection_radius_m,
                     "visible_in_drive_direction": bool(drive_dir[i]), "lateral": str(lateral),
                     "views": len(depths[i])}
            geo = {"is_stationary": speed <= 0.3, "is_near_road_px": road_px <= o.near_road_px,
                   "is_on_sidewalk": lateral == "sidewalk", "is_at_intersection": inter_d <= o.intersection_radius_m,
                   "is_visible_in_drive_direction": bool(drive_dir[i]), "is_near_pedestrian": near_ped}
            out[ids[i]] = NodeInfo(
                scene=world.scene, label=world.labels[i], centroid=tuple(np.round(c, 3)),
                bbox_min=tuple(np.round(lo[i] + shift, 3)), bbox_max=tuple(np.round(hi[i] + shift, 3)),
                first_seen=int(first[i]) if first[i] >= 0 else None, last_seen=int(last[i]) if last[i] >= 0 else None,
                track=track, attributes=attrs, geometric_predicates=geo)
        return
    ind = cfg.indoor
    assert ind is not None
    windows = [i for i in range(n) if world.labels[i] == "window"]
    seats = [i for i in range(n) if world.labels[i] in ("chair", "sofa")]
    room = world.info["room_m"]
    for i in range(n):
        def gap(a: int, b: int) -> float:
            g = np.maximum(0.0, np.maximum(lo[a, :2] - hi[b, :2], lo[b, :2] - hi[a, :2]))
            return float(np.sqrt(g @ g))

        win_d = min((gap(i, w) for w in windows if w != i), default=math.inf)
        top = float(hi[i, 2])
        loaded = any(world.extra[j].get("support") == i for j in range(n))
        front = world.front[i]
        has_front = not np.any(np.isnan(front))
        accessible: bool | None = None
        facing_seat: bool | None = None
        if has_front:
            # free strip of depth access_depth in front of the element
            half = (hi[i, :2] - lo[i, :2]) / 2
            fc = cen[i, :2] + front[:2] * (np.abs(front[:2]) @ half + ind.access_depth_m / 2)
            ext = np.where(np.abs(front[:2]) > 0.5, ind.access_depth_m / 2, half)
            slo, shi = fc - ext, fc + ext
            inside = bool(np.all(slo >= -1e-6) and shi[0] <= room[0] + 1e-6 and shi[1] <= room[1] + 1e-6)
            blocked = any(j != i and world.extra[j].get("placement") not in ("window",) and lo[j, 2] < 0.3 and
                          np.all(lo[j, :2] < shi) and np.all(hi[j, :2] > slo) for j in range(n))
            accessible = inside and not blocked
            facing_seat = False
            for s in seats:
                if s == i:
                    continue
                d = cen[s, :2] - cen[i, :2]
                dist = float(np.linalg.norm(d))
                if 0 < dist <= ind.facing_distance_m and float(d @ front[:2]) / dist >= math.cos(
                        math.radians(ind.facing_half_angle_deg)):
                    facing_seat = True
                    break
        attrs = {"floor_z": 0.0, "window_distance": None if math.isinf(win_d) else round(win_d, 3),
                 "top_height": round(top, 3), "has_load_on_top": loaded, "placement": str(world.extra[i]["placement"]),
                 "views": len(depths[i])}
        geo: dict[str, bool] = {"is_near_window": win_d <= ind.near_window_m,
                                "is_workspace_height": ind.workspace_height_m[0] <= top <= ind.workspace_height_m[1],
                                "is_unobstructed": not loaded}
        if accessible is not None:
            geo["is_accessible"] = accessible
        if facing_seat is not None:
            geo["is_facing_seating"] = facing_seat
        out[ids[i]] = NodeInfo(
            scene=world.scene, label=world.labels[i], centroid=tuple(np.round(cen[i], 3)),
            bbox_min=tuple(np.round(lo[i], 3)), bbox_max=tuple(np.round(hi[i], 3)),
            first_seen=int(first[i]) if first[i] >= 0 else None, last_seen=int(last[i]) if last[i] >= 0 else None,
            front=tuple(np.round(front, 4)) if has_front else None, attributes=attrs, geometric_predicates=geo)

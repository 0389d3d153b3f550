"""Synthetic scene geometry for the simulator: element layout, camera trajectory, projection.

Outdoor (KITTI-360-like): a straight road along +x with cross streets; the ego camera drives along
it at 2 Hz and waits at some intersections.  Indoor (ScanNet-like): a rectangular room furnished by
placement rules; a hand-held camera circles the room.  All randomness comes from the Generator
passed in.  Units: metres, time steps (frames), pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sgbelief.eval.sim_config import Camera, ClassSpec, SimConfig

__all__ = ["SceneWorld", "build_outdoor_scene", "build_indoor_scene", "project_boxes", "box_iou"]

F = NDArray[np.float64]


@dataclass
class SceneWorld:
    """Elements of one scene and the camera trajectory through it."""

    scene: str
    kind: str
    labels: list[str]
    lo: F  # (N, 3) box min at local frame 0
    hi: F  # (N, 3) box max at local frame 0
    vel: F  # (N, 3) displacement per frame (outdoor movers)
    front: F  # (N, 3) unit front direction, nan if none
    occluder: NDArray[np.bool_]  # can hide elements behind it
    cam_pos: F  # (n_frames, 3)
    cam_yaw: F  # (n_frames,)
    extra: list[dict[str, object]] = field(default_factory=list)  # per-element placement facts
    info: dict[str, object] = field(default_factory=dict)  # scene-level facts (intersections, room)

    @property
    def n(self) -> int:
        return len(self.labels)

    @property
    def n_frames(self) -> int:
        return int(self.cam_pos.shape[0])


def _size(rng: np.random.Generator, spec: ClassSpec) -> F:
    s = np.asarray(spec.size, dtype=float)
    if spec.size_jitter > 0:
        s = s * np.exp(rng.normal(0.0, spec.size_jitter, 3))
    return s


# ----------------------------------------------------------------------------------- outdoor


def build_outdoor_scene(cfg: SimConfig, scene: str, rng: np.random.Generator) -> SceneWorld:
    """Lay out one KITTI-360-like sequence and drive the ego camera through it."""
    o = cfg.outdoor
    assert o is not None
    length = float(rng.uniform(*o.road_length_m))
    hw, sw = o.road_half_width_m, o.sidewalk_width_m
    # cross streets: gaps ~ spacing * U(0.5, 1.5)
    xs: list[float] = []
    x = float(rng.uniform(0.3, 0.8) * o.intersection_spacing_m)
    while x < length - 30:
        xs.append(x)
        x += float(o.intersection_spacing_m * rng.uniform(0.5, 1.5))
    inter = np.asarray(xs, dtype=float)

    labels: list[str] = []
    los: list[F] = []
    his: list[F] = []
    vels: list[F] = []
    extra: list[dict[str, object]] = []
    occl: list[bool] = []

    def add(label: str, centre: F, size: F, vel: F, facts: dict[str, object], occluder: bool = True) -> None:
        labels.append(label)
        los.append(centre - size / 2)
        his.append(centre + size / 2)
        vels.append(vel)
        extra.append(facts)
        occl.append(occluder)

    for label, spec in cfg.classes.items():
        if spec.placement in ("segment_road", "segment_sidewalk"):
            seg = spec.size[0]
            for k in range(int(math.ceil(length / seg)) + 1):
                cx = (k + 0.5) * seg
                if spec.placement == "segment_road":
                    add(label, np.array([cx, 0.0, -spec.size[2] / 2]), np.array([seg, 2 * hw, spec.size[2]]),
                        np.zeros(3), {"lateral": "road"}, occluder=False)
                else:
                    for s in (-1.0, 1.0):
                        add(label, np.array([cx, s * (hw + sw / 2), spec.size[2] / 2]),
                            np.array([seg, sw, spec.size[2]]), np.zeros(3), {"lateral": "sidewalk"}, occluder=False)
            continue
        count = int(rng.poisson(spec.density * cfg.scale * length / 100.0))
        for _ in range(count):
            size = _size(rng, spec)
            side = 1.0 if rng.random() < 0.5 else -1.0
            moving = rng.random() < spec.moving_fraction
            speed = float(rng.uniform(*spec.speed)) * o.step_s if moving else 0.0
            at_inter = inter.size > 0 and rng.random() < spec.near_intersection
            cx = float(rng.choice(inter) + rng.uniform(-12, 12)) if at_inter else float(rng.uniform(0, length))
            vel = np.zeros(3)
            lateral = "roadside"
            p = spec.placement
            if p == "parking":
                if moving:  # driving in a lane; right-hand traffic: y < 0 drives +x
                    cy = side * float(rng.uniform(0.8, 2.8))
                    vel[0] = -side * speed
                    lateral = "lane"
                else:
                    cy = side * float(rng.uniform(3.6, hw - size[1] / 2))
                    lateral = "parking"
            elif p == "sidewalk":
                cy = side * float(rng.uniform(hw + 0.4, hw + sw - 0.4))
                lateral = "sidewalk"
                if moving:
                    if label == "person" and rng.random() < 0.08:  # crossing the road
                        cy = side * float(rng.uniform(0.5, hw))
                        vel[1] = -side * speed
                        lateral = "road"
                    else:
                        vel[0] = speed if rng.random() < 0.5 else -speed
            elif p == "roadside":
                cy = side * float(rng.uniform(hw + 0.2, hw + 0.8))
                lateral = "sidewalk"
            elif p == "building":
                cy = side * (hw + sw + 1.0 + float(rng.uniform(0, 4)) + size[1] / 2)
                lateral = "offroad"
            elif p == "vegetation":
                cy = side * float(rng.uniform(hw + 1.0, hw + sw + 6.0))
                lateral = "sidewalk" if abs(cy) < hw + sw else "offroad"
            else:
                raise ValueError(f"classes.{label}.placement: unknown outdoor placement {p!r}")
            add(label, np.array([cx, cy, size[2] / 2]), size, vel, {"lateral": lateral, "side": side})

    # ego trajectory
    xs_ego: list[float] = []
    x = 0.0
    speed = float(rng.uniform(*o.cruise_speed_mps))
    stops = {float(xi): int(rng.integers(o.stop_steps[0], o.stop_steps[1] + 1))
             for xi in inter if rng.random() < o.stop_probability}
    pending = sorted(stops)
    while x < length:
        xs_ego.append(x)
        if pending and x >= pending[0] - 12.0:
            xs_ego.extend([x] * stops[pending.pop(0)])
        speed = float(np.clip(speed + rng.normal(0, 0.4), *o.cruise_speed_mps))
        x += speed * o.step_s
    ex = np.asarray(xs_ego)
    cam = np.stack([ex, np.full_like(ex, -2.0), np.full_like(ex, cfg.camera.height_m)], axis=1)
    n = len(labels)
    return SceneWorld(
        scene=scene, kind="outdoor", labels=labels,
        lo=np.asarray(los).reshape(n, 3), hi=np.asarray(his).reshape(n, 3), vel=np.asarray(vels).reshape(n, 3),
        front=np.full((n, 3), np.nan), occluder=np.asarray(occl, dtype=bool),
        cam_pos=cam, cam_yaw=np.zeros(len(ex)), extra=extra,
        info={"length_m": length, "intersections_x": inter.tolist(), "road_half_width_m": hw, "sidewalk_width_m": sw},
    )


# ----------------------------------------------------------------------------------- indoor


def build_indoor_scene(cfg: SimConfig, scene: str, rng: np.random.Generator) -> SceneWorld:
    """Furnish one ScanNet-like room and move a hand-held camera around it."""
    ind = cfg.indoor
    assert ind is not None
    wx = float(rng.uniform(*ind.room_size_m[0]))
    wy = float(rng.uniform(*ind.room_size_m[1]))
    types = list(ind.scene_types)
    probs = np.asarray([ind.scene_types[k] for k in types], dtype=float)
    stype = types[int(rng.choice(len(types), p=probs / probs.sum()))]

    labels: list[str] = []
    los: list[F] = []
    his: list[F] = []
    fronts: list[F] = []
    extra: list[dict[str, object]] = []

    def add(label: str, lo: F, hi: F, front: F | None, facts: dict[str, object]) -> int:
        labels.append(label)
        los.append(lo)
        his.append(hi)
        fronts.append(np.full(3, np.nan) if front is None else front)
        extra.append(facts)
        return len(labels) - 1

    def on_wall(size: F, z0: float) -> tuple[F, F, F]:
        wall = int(rng.integers(4))
        length, depth, h = size
        if wall in (0, 1):  # walls y = 0 / y = wy, run along x
            cx = float(rng.uniform(length / 2 + 0.1, max(length / 2 + 0.1, wx - length / 2 - 0.1)))
            y0 = 0.0 if wall == 0 else wy - depth
            lo = np.array([cx - length / 2, y0, z0])
            hi = np.array([cx + length / 2, y0 + depth, z0 + h])
            front = np.array([0.0, 1.0 if wall == 0 else -1.0, 0.0])
        else:
            cy = float(rng.uniform(length / 2 + 0.1, max(length / 2 + 0.1, wy - length / 2 - 0.1)))
            x0 = 0.0 if wall == 2 else wx - depth
            lo = np.array([x0, cy - length / 2, z0])
            hi = np.array([x0 + depth, cy + length / 2, z0 + h])
            front = np.array([1.0 if wall == 2 else -1.0, 0.0, 0.0])
        return lo, hi, front

    order = ["center", "wall", "door", "window", "free", "around_table", "on_top"]
    supports: list[int] = []
    tables: list[int] = []
    for placement in order:
        for label, spec in cfg.classes.items():
            if spec.placement != placement:
                continue
            mean = (spec.scene_types or {}).get(stype, spec.density)
            for _ in range(int(rng.poisson(mean))):
                size = _size(rng, spec)
                if placement == "center":
                    c = np.array([rng.uniform(0.3, 0.7) * wx, rng.uniform(0.3, 0.7) * wy, size[2] / 2])
                    if rng.random() < 0.5:
                        size = size[[1, 0, 2]]
                    i = add(label, c - size / 2, c + size / 2, None, {"placement": placement})
                    tables.append(i)
                    supports.append(i)
                elif placement in ("wall", "door", "window"):
                    z0 = float(rng.uniform(0.8, 1.0)) if placement == "window" else 0.0
                    lo, hi, front = on_wall(size, z0)
                    i = add(label, lo, hi, front, {"placement": placement})
                    if label in ("desk", "cabinet", "counter"):
                        supports.append(i)
                        if label == "desk":
                            tables.append(i)
                elif placement == "free" or (placement == "around_table" and not tables) or (
                        placement == "on_top" and not supports):
                    c = np.array([rng.uniform(0.5, wx - 0.5), rng.uniform(0.5, wy - 0.5), size[2] / 2])
                    ang = rng.uniform(0, 2 * np.pi)
                    add(label, c - size / 2, c + size / 2, np.array([np.cos(ang), np.sin(ang), 0.0]),
                        {"placement": "free"})
                elif placement == "around_table":
                    ti = tables[int(rng.integers(len(tables)))]
                    tlo, thi = los[ti], his[ti]
                    tc = (tlo + thi) / 2
                    side = int(rng.integers(4))
                    half = size / 2
                    if side < 2:
                        sgn = -1 if side == 0 else 1
                        cx = float(rng.uniform(tlo[0] + half[0], max(tlo[0] + half[0], thi[0] - half[0])))
                        cy = (tlo[1] - half[1] - 0.15) if sgn < 0 else (thi[1] + half[1] + 0.15)
                        front = np.array([0.0, -float(sgn), 0.0])
                    else:
                        sgn = -1 if side == 2 else 1
                        cy = float(rng.uniform(tlo[1] + half[1], max(tlo[1] + half[1], thi[1] - half[1])))
                        cx = (tlo[0] - half[0] - 0.15) if sgn < 0 else (thi[0] + half[0] + 0.15)
                        front = np.array([-float(sgn), 0.0, 0.0])
                    c = np.array([np.clip(cx, 0.3, wx - 0.3), np.clip(cy, 0.3, wy - 0.3), half[2]])
                    add(label, c - half, c + half, front, {"placement": placement, "table": int(ti)})
                    _ = tc
                else:  # on_top
                    si = supports[int(rng.integers(len(supports)))]
                    lo, hi = on_top_of(rng, los[si], his[si], size)
                    add(label, lo, hi, None, {"placement": placement, "support": int(si)})

    n_frames = int(round(rng.integers(ind.frames_per_scene[0], ind.frames_per_scene[1] + 1) * cfg.scale))
    phase = float(rng.uniform(0, 2 * np.pi))
    theta = phase + 2 * np.pi * np.arange(n_frames) / max(n_frames, 1)
    cx, cy = wx / 2, wy / 2
    pos = np.stack([cx + 0.3 * wx * np.cos(theta), cy + 0.3 * wy * np.sin(theta),
                    np.full(n_frames, cfg.camera.height_m) + 0.1 * np.sin(3 * theta)], axis=1)
    yaw = theta + np.pi / 2 + 0.8 * np.sin(2.3 * theta + phase)
    n = len(labels)
    return SceneWorld(
        scene=scene, kind="indoor", labels=labels,
        lo=np.asarray(los).reshape(n, 3), hi=np.asarray(his).reshape(n, 3), vel=np.zeros((n, 3)),
        front=np.asarray(fronts).reshape(n, 3), occluder=np.ones(n, dtype=bool),
        cam_pos=pos, cam_yaw=yaw, extra=extra,
        info={"room_m": [wx, wy, ind.room_height_m], "scene_type": stype},
    )


# ----------------------------------------------------------------------------------- camera

_CORNER_SEL = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=bool)


def on_top_of(rng: np.random.Generator, support_lo: F, support_hi: F, size: F) -> tuple[F, F]:
    """A box of ``size`` resting on the top face of the support box, at a uniform spot that keeps it
    within the support's footprint (clamped to the support's size): its (min, max) corners."""
    half = np.minimum(size / 2, (support_hi - support_lo) / 2)
    cx = float(rng.uniform(support_lo[0] + half[0], support_hi[0] - half[0] + 1e-9))
    cy = float(rng.uniform(support_lo[1] + half[1], support_hi[1] - half[1] + 1e-9))
    z0 = float(support_hi[2])
    return (np.array([cx - half[0], cy - half[1], z0]),
            np.array([cx + half[0], cy + half[1], z0 + size[2]]))


def project_boxes(lo: F, hi: F, pos: F, yaw: float, cam: Camera) -> tuple[F, F, NDArray[np.bool_]]:
    """Pinhole projection of axis-aligned 3D boxes (z up) into the image.

    Returns ``boxes`` (N, 4) = (u0, v0, u1, v1) clipped to the image, the centroid depth (N,)
    and a visibility mask (in front, within range, projected sides >= min_box_px).
    """
    corners = np.where(_CORNER_SEL[None, :, :], hi[:, None, :], lo[:, None, :]) - pos[None, None, :]
    c, s = math.cos(yaw), math.sin(yaw)
    fwd = c * corners[..., 0] + s * corners[..., 1]
    left = -s * corners[..., 0] + c * corners[..., 1]
    up = corners[..., 2]
    near = 0.3
    in_front = fwd.max(axis=1) > near
    fz = np.maximum(fwd, near)
    u = cam.width / 2 - cam.focal_px * left / fz
    v = cam.height / 2 - cam.focal_px * up / fz
    boxes = np.stack([u.min(1), v.min(1), u.max(1), v.max(1)], axis=1)
    boxes[:, [0, 2]] = np.clip(boxes[:, [0, 2]], 0, cam.width)
    boxes[:, [1, 3]] = np.clip(boxes[:, [1, 3]], 0, cam.height)
    centre = (lo + hi) / 2 - pos
    depth = c * centre[:, 0] + s * centre[:, 1]
    # distance to the box (not the centroid) for long elements such as buildings / road segments
    gap = np.maximum(0.0, np.maximum(lo - pos, pos - hi))
    dist = np.sqrt((gap[:, :2] ** 2).sum(1))
    w = boxes[:, 2] - boxes[:, 0]
    h = boxes[:, 3] - boxes[:, 1]
    vis = in_front & (dist <= cam.max_range_m) & (w >= cam.min_box_px) & (h >= cam.min_box_px)
    return boxes, np.where(depth > near, depth, np.maximum(fwd.max(1), near)), vis


def box_iou(box: F, boxes: F) -> F:
    """IoU of one box (4,) against many boxes (N, 4) in (u0, v0, u1, v1) form."""
    iw = np.clip(np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0]), 0, None)
    ih = np.clip(np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1]), 0, None)
    inter = iw * ih
    a = (box[2] - box[0]) * (box[3] - box[1])
    b = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    union = a + b - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def occlusion_ioa(boxes: F, depth: F, occluder: NDArray[np.bool_]) -> F:
    """Fraction of each box covered by the most-covering nearer occluder box."""
    n = boxes.shape[0]
    if n == 0:
        return np.zeros(0)
    iw = np.clip(np.minimum(boxes[:, None, 2], boxes[None, :, 2]) - np.maximum(boxes[:, None, 0], boxes[None, :, 0]),
                 0, None)
    ih = np.clip(np.minimum(boxes[:, None, 3], boxes[None, :, 3]) - np.maximum(boxes[:, None, 1], boxes[None, :, 1]),
                 0, None)
    area = np.maximum((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]), 1e-9)
    ioa = iw * ih / area[:, None]
    nearer = (depth[None, :] < depth[:, None]) & occluder[None, :]
    ioa = np.where(nearer, ioa, 0.0)
    return ioa.max(axis=1)

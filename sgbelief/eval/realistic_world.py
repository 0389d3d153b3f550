"""Room layouts and camera views of the realistic suite (ScanNet-like rooms, see docs/simulation.md).

A room of a sampled ScanNet scene type is furnished with raw object categories (each with its
NYU40 label and the COCO class a COCO detector finds it as), by placement rules: against a wall
(optionally raised: windows, pictures, sinks), in the centre (tables), around a table (chairs),
on top of a support (monitors on desks, pillows on beds), or free on the floor. A hand-held camera
goes round the room looking across it; each key frame sees the objects whose projected box is
large enough and not mostly covered by a nearer object's box. All randomness comes from the
generator passed in. Units: metres, pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sgbelief.eval.realistic_config import RealisticConfig
from sgbelief.eval.sim_world import occlusion_ioa, on_top_of, project_boxes

__all__ = ["Room", "FrameView", "room_types", "build_room", "room_views"]

F = NDArray[np.float64]
I = NDArray[np.intp]


@dataclass(frozen=True)
class Room:
    """One furnished room: per object its raw category, NYU40 label (None: unannotated), COCO class."""

    scene: str
    room_type: str
    size: tuple[float, float]
    categories: tuple[str, ...]
    labels: tuple[str | None, ...]
    coco: tuple[str | None, ...]
    lo: F
    hi: F

    @property
    def n(self) -> int:
        return len(self.categories)

    def node(self, i: int) -> str:
        return f"{self.scene}/{i:03d}"


@dataclass(frozen=True)
class FrameView:
    """What one key frame sees: object indices, their image boxes (u0, v0, u1, v1) and areas."""

    visible: I
    boxes: F
    area: F


def _size(rng: np.random.Generator, size: tuple[float, float, float], jitter: float) -> F:
    s = np.asarray(size, dtype=float)
    return s * np.exp(rng.normal(0.0, jitter, 3)) if jitter > 0 else s


def room_types(cfg: RealisticConfig, n_rooms: int, rng: np.random.Generator) -> list[str]:
    """Stratified room types: each type's share of ``n_rooms`` by largest remainder, in random order
    (a seed always holds bathrooms and bedrooms, so its rare classes are present)."""
    types = list(cfg.room_types)
    p = np.asarray([cfg.room_types[k].probability for k in types], dtype=float)
    want = p / p.sum() * n_rooms
    count = np.floor(want).astype(int)
    for i in np.argsort(-(want - count), kind="stable")[: n_rooms - int(count.sum())]:
        count[i] += 1
    out = [t for t, c in zip(types, count) for _ in range(int(c))]
    return [out[i] for i in rng.permutation(len(out))]


def build_room(cfg: RealisticConfig, scene: str, rtype: str, rng: np.random.Generator) -> Room:
    """Furnish one room of type ``rtype`` (its size sampled) by the placement rules."""
    (ax, bx), (ay, by) = cfg.room_types[rtype].size_m
    wx, wy = float(rng.uniform(ax, bx)), float(rng.uniform(ay, by))
    cats: list[str] = []
    los: list[F] = []
    his: list[F] = []

    def add(cat: str, lo: F, hi: F) -> None:
        cats.append(cat)
        los.append(lo)
        his.append(hi)

    def on_wall(size: F, z0: float) -> tuple[F, F]:
        length, depth, h = float(size[0]), float(size[1]), float(size[2])
        wall = int(rng.integers(4))
        side = wx if wall < 2 else wy
        length = min(length, side - 0.2)
        c = float(rng.uniform(length / 2 + 0.1, max(length / 2 + 0.1, side - length / 2 - 0.1)))
        if wall < 2:
            y0 = 0.0 if wall == 0 else wy - depth
            return np.array([c - length / 2, y0, z0]), np.array([c + length / 2, y0 + depth, z0 + h])
        x0 = 0.0 if wall == 2 else wx - depth
        return np.array([x0, c - length / 2, z0]), np.array([x0 + depth, c + length / 2, z0 + h])

    def on_floor(size: F, cx: float, cy: float) -> tuple[F, F]:
        half = np.minimum(size[:2] / 2, [wx / 2 - 0.05, wy / 2 - 0.05])
        cx = float(np.clip(cx, half[0], wx - half[0]))
        cy = float(np.clip(cy, half[1], wy - half[1]))
        return np.array([cx - half[0], cy - half[1], 0.0]), np.array([cx + half[0], cy + half[1], size[2]])

    counts = {name: int(rng.poisson(spec.rooms.get(rtype, 0.0))) for name, spec in cfg.objects.items()}
    for placement in ("wall", "center", "around_table", "free", "on_top"):
        for name, spec in cfg.objects.items():
            if spec.placement != placement:
                continue
            for _ in range(counts[name]):
                size = _size(rng, spec.size, spec.size_jitter)
                if placement == "wall":
                    lo, hi = on_wall(size, spec.z0)
                elif placement == "center":
                    if rng.random() < 0.5:
                        size = size[[1, 0, 2]]
                    lo, hi = on_floor(size, rng.uniform(0.3, 0.7) * wx, rng.uniform(0.3, 0.7) * wy)
                elif placement == "around_table":
                    tables = [i for i, c in enumerate(cats) if cfg.objects[c].coco == "dining table"]
                    if tables:
                        ti = tables[int(rng.integers(len(tables)))]
                        tc, th = (los[ti] + his[ti]) / 2, (his[ti] - los[ti]) / 2
                        ang = rng.uniform(0, 2 * np.pi)
                        reach = th[:2] + size[:2] / 2 + 0.1
                        lo, hi = on_floor(size, tc[0] + reach[0] * np.cos(ang), tc[1] + reach[1] * np.sin(ang))
                    else:
                        lo, hi = on_floor(size, rng.uniform(0, wx), rng.uniform(0, wy))
                elif placement == "free":
                    lo, hi = on_floor(size, rng.uniform(0, wx), rng.uniform(0, wy))
                else:  # on_top of a support of a listed category, else on the floor
                    sup = [i for i, c in enumerate(cats) if c in spec.supports]
                    if sup:
                        si = sup[int(rng.integers(len(sup)))]
                        lo, hi = on_top_of(rng, los[si], his[si], size)
                    else:
                        lo, hi = on_floor(size, rng.uniform(0, wx), rng.uniform(0, wy))
                add(name, lo, hi)
    n = len(cats)
    return Room(scene=scene, room_type=rtype, size=(wx, wy), categories=tuple(cats),
                labels=tuple(cfg.objects[c].label for c in cats), coco=tuple(cfg.objects[c].coco for c in cats),
                lo=np.asarray(los, dtype=float).reshape(n, 3), hi=np.asarray(his, dtype=float).reshape(n, 3))


def room_views(cfg: RealisticConfig, room: Room, n_frames: int, rng: np.random.Generator) -> list[FrameView]:
    """Key frames of a hand-held scan: an ellipse round the room, looking across it with a sway."""
    wx, wy = room.size
    phase = float(rng.uniform(0, 2 * np.pi))
    theta = phase + 2 * np.pi * np.arange(n_frames) / n_frames
    r = cfg.camera_radius
    pos = np.stack([wx / 2 + r * wx * np.cos(theta), wy / 2 + r * wy * np.sin(theta),
                    np.full(n_frames, cfg.camera.height_m)], axis=1)
    yaw = theta + np.pi + 0.7 * np.sin(2.3 * theta + phase)
    views: list[FrameView] = []
    empty = FrameView(np.zeros(0, dtype=np.intp), np.zeros((0, 4)), np.zeros(0))
    if room.n == 0:
        return [empty] * n_frames
    for k in range(n_frames):
        boxes, depth, vis = project_boxes(room.lo, room.hi, pos[k], float(yaw[k]), cfg.camera)
        idx = np.flatnonzero(vis)
        if idx.size == 0:
            views.append(empty)
            continue
        b = boxes[idx]
        hidden = occlusion_ioa(b, depth[idx], np.ones(idx.size, dtype=bool)) >= cfg.occlusion_ioa
        keep = ~hidden
        b = b[keep]
        views.append(FrameView(idx[keep], b, (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])))
    return views

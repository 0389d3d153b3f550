"""Synthetic indoor rooms of labelled boxes, with each object's true front, for the referring-query
evaluation; and their graphs (plain labels, or read back through the ScanNet loader).

A room has four walls and a floor (labels ``wall`` and ``floor``) and furniture placed the way
rooms are furnished: beds, desks, couches, cabinets and shelves with their backs to a wall, seats
facing their table, nightstands beside the bed, small objects on tables, pictures and whiteboards on
walls. Labels are ScanNet raw categories ("trash can", "office chair", "kitchen cabinets"). Every
object carries its true front (the inward normal of its wall, or towards its table) so that
view-dependent references can be generated from the truth while the query sees only the
axis-aligned boxes.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Room", "SceneObject", "make_room", "make_rooms", "rooms_graph", "scannet_layout_graph"]


@dataclass(frozen=True)
class SceneObject:
    """A labelled axis-aligned box; ``front`` is its true facing direction (None: no front)."""

    id: str
    label: str
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    front: tuple[float, float] | None = None

    @property
    def lo_a(self) -> np.ndarray:
        return np.asarray(self.lo, dtype=float)

    @property
    def hi_a(self) -> np.ndarray:
        return np.asarray(self.hi, dtype=float)


@dataclass(frozen=True)
class Room:
    scene: str
    size: tuple[float, float]
    objects: tuple[SceneObject, ...]

    def by_id(self) -> dict[str, SceneObject]:
        return {o.id: o for o in self.objects}


class _Builder:
    def __init__(self, scene: str, width: float, depth: float, rng: np.random.Generator) -> None:
        self.scene, self.w, self.d, self.rng = scene, width, depth, rng
        self.objects: list[SceneObject] = []
        self.floor_boxes: list[tuple[np.ndarray, np.ndarray]] = []
        h = 2.6
        self.add("floor", (0.0, 0.0, -0.05), (width, depth, 0.0), floor=False)
        for lo, hi in (((-0.1, 0.0, 0.0), (0.0, depth, h)), ((width, 0.0, 0.0), (width + 0.1, depth, h)),
                       ((0.0, -0.1, 0.0), (width, 0.0, h)), ((0.0, depth, 0.0), (width, depth + 0.1, h))):
            self.add("wall", lo, hi, floor=False)

    def add(self, label: str, lo: Sequence[float], hi: Sequence[float], front: tuple[float, float] | None = None,
            *, floor: bool = True) -> SceneObject:
        obj = SceneObject(f"{self.scene}/{len(self.objects)}", label, tuple(map(float, lo)),  # type: ignore[arg-type]
                          tuple(map(float, hi)), front)  # type: ignore[arg-type]
        self.objects.append(obj)
        if floor:
            self.floor_boxes.append((np.asarray(lo, float), np.asarray(hi, float)))
        return obj

    def free(self, lo: np.ndarray, hi: np.ndarray, margin: float = 0.05) -> bool:
        if lo[0] < 0 or lo[1] < 0 or hi[0] > self.w or hi[1] > self.d:
            return False
        for blo, bhi in self.floor_boxes:
            if (min(hi[0], bhi[0]) - max(lo[0], blo[0]) > -margin
                    and min(hi[1], bhi[1]) - max(lo[1], blo[1]) > -margin):
                return False
        return True

    def against_wall(self, label: str, along: float, depth: float, height: float, *, tries: int = 40,
                     side: int | None = None, z0: float = 0.0, gap: float = 0.02) -> SceneObject | None:
        """Place a box with its back to a wall (front = the wall's inward normal)."""
        for _ in range(tries):
            s = int(self.rng.integers(4)) if side is None else side
            if s in (0, 1):  # walls at x = 0 (front +x) and x = w (front -x)
                if along > self.d - 0.2:
                    continue
                y = float(self.rng.uniform(0.05, self.d - along - 0.05))
                x = gap if s == 0 else self.w - depth - gap
                lo, hi = np.array([x, y, z0]), np.array([x + depth, y + along, z0 + height])
                front = (1.0, 0.0) if s == 0 else (-1.0, 0.0)
            else:
                if along > self.w - 0.2:
                    continue
                x = float(self.rng.uniform(0.05, self.w - along - 0.05))
                y = gap if s == 2 else self.d - depth - gap
                lo, hi = np.array([x, y, z0]), np.array([x + along, y + depth, z0 + height])
                front = (0.0, 1.0) if s == 2 else (0.0, -1.0)
            if self.free(lo, hi):
                return self.add(label, lo, hi, front)
        return None

    def in_front(self, anchor: SceneObject, label: str, size: tuple[float, float, float], distance: float,
                 offset: float = 0.0, facing_back: bool = True) -> SceneObject | None:
        """Place a box in front of ``anchor`` (a seat facing it when ``facing_back``)."""
        assert anchor.front is not None
        f = np.array(anchor.front)
        lat = np.array([f[1], -f[0]])
        c = (anchor.lo_a[:2] + anchor.hi_a[:2]) / 2.0
        half_depth = 0.5 * float(abs(f[0]) * (anchor.hi[0] - anchor.lo[0]) + abs(f[1]) * (anchor.hi[1] - anchor.lo[1]))
        sx, sy, sz = size  # sx across the anchor's front, sy along it
        centre = c + f * (half_depth + distance + sy / 2.0) + lat * offset
        ext = np.abs(lat) * sx + np.abs(f) * sy
        lo = np.array([centre[0] - ext[0] / 2, centre[1] - ext[1] / 2, 0.0])
        hi = np.array([centre[0] + ext[0] / 2, centre[1] + ext[1] / 2, sz])
        if not self.free(lo, hi, margin=0.0):
            return None
        front = (-float(f[0]), -float(f[1])) if facing_back else (float(f[0]), float(f[1]))
        return self.add(label, lo, hi, front)

    def beside(self, anchor: SceneObject, label: str, size: tuple[float, float, float], side: int) -> SceneObject | None:
        """Place a box against the same wall, just beside ``anchor`` (side +1: the anchor's own left... any side)."""
        assert anchor.front is not None
        f = np.array(anchor.front)
        lat = np.array([f[1], -f[0]]) * side
        c = (anchor.lo_a[:2] + anchor.hi_a[:2]) / 2.0
        half_w = 0.5 * float(abs(lat[0]) * (anchor.hi[0] - anchor.lo[0]) + abs(lat[1]) * (anchor.hi[1] - anchor.lo[1]))
        half_d = 0.5 * float(abs(f[0]) * (anchor.hi[0] - anchor.lo[0]) + abs(f[1]) * (anchor.hi[1] - anchor.lo[1]))
        sx, sy, sz = size
        back = c - f * half_d
        centre = back + f * (sy / 2.0) + lat * (half_w + 0.08 + sx / 2.0)
        ext = np.abs(lat) * sx + np.abs(f) * sy
        lo = np.array([centre[0] - ext[0] / 2, centre[1] - ext[1] / 2, 0.0])
        hi = np.array([centre[0] + ext[0] / 2, centre[1] + ext[1] / 2, sz])
        if not self.free(lo, hi, margin=0.0):
            return None
        return self.add(label, lo, hi, anchor.front)

    def on_top(self, base: SceneObject, label: str, size: tuple[float, float, float],
               front: tuple[float, float] | None = None) -> SceneObject | None:
        sx, sy, sz = size
        blo, bhi = base.lo_a, base.hi_a
        if sx > bhi[0] - blo[0] or sy > bhi[1] - blo[1]:
            return None
        x = float(self.rng.uniform(blo[0], bhi[0] - sx))
        y = float(self.rng.uniform(blo[1], bhi[1] - sy))
        z = float(bhi[2]) + float(self.rng.uniform(-0.02, 0.03))
        return self.add(label, (x, y, z), (x + sx, y + sy, z + sz), front, floor=False)

    def on_wall(self, label: str, along: float, height: float, z0: float, side: int | None = None) -> SceneObject | None:
        s = int(self.rng.integers(4)) if side is None else side
        t = 0.04
        if s in (0, 1):
            y = float(self.rng.uniform(0.1, max(0.11, self.d - along - 0.1)))
            x = 0.0 if s == 0 else self.w - t
            lo, hi = (x, y, z0), (x + t, y + along, z0 + height)
            front = (1.0, 0.0) if s == 0 else (-1.0, 0.0)
        else:
            x = float(self.rng.uniform(0.1, max(0.11, self.w - along - 0.1)))
            y = 0.0 if s == 2 else self.d - t
            lo, hi = (x, y, z0), (x + along, y + t, z0 + height)
            front = (0.0, 1.0) if s == 2 else (0.0, -1.0)
        return self.add(label, lo, hi, front, floor=False)

    def free_spot(self, label: str, size: tuple[float, float, float], tries: int = 30) -> SceneObject | None:
        sx, sy, sz = size
        for _ in range(tries):
            x = float(self.rng.uniform(0.1, self.w - sx - 0.1))
            y = float(self.rng.uniform(0.1, self.d - sy - 0.1))
            lo, hi = np.array([x, y, 0.0]), np.array([x + sx, y + sy, sz])
            if self.free(lo, hi):
                return self.add(label, lo, hi, None)
        return None


def _u(rng: np.random.Generator, a: float, b: float) -> float:
    return float(rng.uniform(a, b))


def _bedroom(b: _Builder) -> None:
    r = b.rng
    bed = b.against_wall("bed", _u(r, 1.4, 1.8), 2.0, 0.6)
    if bed is not None:
        for side in (1, -1):
            ns = b.beside(bed, "nightstand", (0.45, 0.4, 0.55), side)
            if ns is not None and r.random() < 0.7:
                b.on_top(ns, "lamp", (0.2, 0.2, 0.45))
        for _ in range(int(r.integers(1, 4))):
            b.on_top(bed, "pillow", (0.5, 0.35, 0.15))
        if r.random() < 0.6 and bed.front is not None:
            side = {(1.0, 0.0): 0, (-1.0, 0.0): 1, (0.0, 1.0): 2, (0.0, -1.0): 3}[bed.front]
            b.on_wall("picture", 0.8, 0.5, 1.3, side)
    b.against_wall("dresser", _u(r, 0.9, 1.5), 0.5, 0.9)
    _desk_set(b)
    b.against_wall("wardrobe closet", 1.2, 0.6, 2.0)


def _desk_set(b: _Builder, n: int = 1) -> None:
    r = b.rng
    for _ in range(n):
        desk = b.against_wall("desk", _u(r, 1.0, 1.6), _u(r, 0.6, 0.75), 0.75)
        if desk is None:
            continue
        b.in_front(desk, "office chair", (0.6, 0.6, 1.0), _u(r, -0.15, 0.25))
        if r.random() < 0.8:
            b.on_top(desk, "monitor", (0.55, 0.2, 0.4), desk.front)
        if r.random() < 0.6:
            b.on_top(desk, "keyboard", (0.45, 0.15, 0.04))
        if r.random() < 0.5:
            b.beside(desk, "trash can", (0.3, 0.3, 0.45), 1 if r.random() < 0.5 else -1)


def _office(b: _Builder) -> None:
    r = b.rng
    _desk_set(b, int(r.integers(2, 4)))
    b.against_wall("bookshelf", _u(r, 0.8, 1.2), 0.35, 1.8)
    b.against_wall("file cabinet", 0.45, 0.6, 0.7)
    if r.random() < 0.7:
        b.on_wall("whiteboard", _u(r, 1.2, 2.0), 1.0, 0.9)
    for _ in range(int(r.integers(1, 3))):
        b.free_spot("trash can", (0.3, 0.3, 0.45))
    b.against_wall("printer", 0.5, 0.45, 0.4)


def _living(b: _Builder) -> None:
    r = b.rng
    couch = b.against_wall("couch", _u(r, 1.8, 2.4), 0.9, 0.85)
    if couch is not None:
        table = b.in_front(couch, "coffee table", (1.0, 0.55, 0.45), _u(r, 0.35, 0.5), facing_back=False)
        if table is not None:
            table = SceneObject(table.id, table.label, table.lo, table.hi, None)
            b.objects[-1] = table
            for _ in range(int(r.integers(0, 3))):
                b.on_top(table, "book", (0.2, 0.15, 0.04))
        for _ in range(int(r.integers(1, 4))):
            b.on_top(couch, "pillow", (0.4, 0.4, 0.15))
        for side in (1, -1):
            if r.random() < 0.6:
                b.beside(couch, "end table", (0.5, 0.5, 0.55), side)
    b.against_wall("tv stand", _u(r, 1.0, 1.6), 0.45, 0.5)
    tv_stand = b.objects[-1] if b.objects[-1].label == "tv stand" else None
    if tv_stand is not None:
        b.on_top(tv_stand, "tv", (0.9, 0.1, 0.55), tv_stand.front)
    for _ in range(int(r.integers(1, 3))):
        b.against_wall("armchair", 0.8, 0.8, 0.9)
    for _ in range(int(r.integers(0, 3))):
        b.free_spot("plant", (0.35, 0.35, 0.8))


def _kitchen(b: _Builder) -> None:
    r = b.rng
    side = int(r.integers(4))
    for _ in range(int(r.integers(2, 4))):
        b.against_wall("kitchen cabinets", _u(r, 0.8, 1.4), 0.6, 0.9, side=side)
    cab = [o for o in b.objects if o.label == "kitchen cabinets"]
    if cab and r.random() < 0.7:
        b.on_top(cab[0], "microwave", (0.5, 0.35, 0.3))
    b.against_wall("refrigerator", 0.8, 0.75, 1.8)
    table = b.free_spot("dining table", (_u(r, 1.0, 1.6), _u(r, 0.8, 1.0), 0.75))
    if table is not None:
        # chairs around the table, facing it
        for f in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)):
            if r.random() < 0.75:
                fake = SceneObject(table.id, table.label, table.lo, table.hi, f)
                b.in_front(fake, "chair", (0.45, 0.45, 0.9), 0.1)
        for _ in range(int(r.integers(0, 3))):
            b.on_top(table, "cup", (0.08, 0.08, 0.1))
    for _ in range(int(r.integers(1, 3))):
        b.free_spot("trash can", (0.35, 0.35, 0.6))


_ROOM_KINDS = (_bedroom, _office, _living, _kitchen)


def make_room(scene: str, seed: int, kind: int | None = None) -> Room:
    """One furnished room (bedroom, office, living room or kitchen; ``kind`` 0-3, default by seed)."""
    rng = np.random.default_rng(seed)
    width, depth = float(rng.uniform(4.0, 7.5)), float(rng.uniform(3.5, 6.5))
    b = _Builder(scene, width, depth, rng)
    fill = _ROOM_KINDS[(seed if kind is None else kind) % len(_ROOM_KINDS)]
    fill(b)
    # doors and a window on the walls, a couple of loose boxes and bags
    b.on_wall("door", 0.9, 2.05, 0.0)
    if rng.random() < 0.7:
        b.on_wall("window", _u(rng, 0.8, 1.6), 1.2, 0.9)
    for _ in range(int(rng.integers(0, 3))):
        b.free_spot("box", (_u(rng, 0.3, 0.6), _u(rng, 0.3, 0.6), _u(rng, 0.2, 0.5)))
    if rng.random() < 0.5:
        b.free_spot("backpack", (0.35, 0.25, 0.45))
    return Room(scene, (width, depth), tuple(b.objects))


def make_rooms(n: int, seed: int = 0, prefix: str = "synth") -> list[Room]:
    """``n`` rooms, scene ids ``<prefix>{k:04d}_00``, the kinds in turn."""
    return [make_room(f"{prefix}{k:04d}_00", seed * 100_003 + k, kind=k % len(_ROOM_KINDS)) for k in range(n)]


def rooms_graph(rooms: Iterable[Room], *, labels: bool = True, graph: Any = None) -> Any:
    """A SceneGraph of the rooms' objects (``bbox``, ``scene``, and ``label`` unless ``labels`` is
    False: a belief map gets its classes from evidence instead)."""
    from sgbelief.api.scene_graph import SceneGraph

    g = graph if graph is not None else SceneGraph(create_nodes=True)
    for room in rooms:
        for o in room.objects:
            attrs: dict[str, Any] = {"scene": room.scene}
            if labels:
                attrs["label"] = o.label
            g.add_node(o.id, bbox=(o.lo, o.hi), **attrs)
    return g


def scannet_layout_graph(rooms: Sequence[Room], folder: str | Path) -> tuple[Any, dict[str, str]]:
    """Write the rooms as ScanNet v2 scene folders (boxes as meshes, raw labels in the tsv), read
    them back with :func:`sgbelief.adapters.scannet.load_scene` into a graph whose ``label`` is the
    raw category; returns (graph, {room object id: graph node id}). Needs open3d."""
    from sgbelief.adapters.scannet import load_scene, write_label_map, write_scene_files
    from sgbelief.api.scene_graph import SceneGraph

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    raw = sorted({o.label for r in rooms for o in r.objects})
    write_label_map(folder / "scannetv2-labels.combined.tsv", [(lab, lab, 40, "otherprop") for lab in raw])
    g = SceneGraph(create_nodes=True)
    ids: dict[str, str] = {}
    for room in rooms:
        objs = [o for o in room.objects]
        write_scene_files(folder / room.scene, room.scene, [(o.label, o.lo, o.hi) for o in objs])
        scene = load_scene(folder / room.scene, folder / "scannetv2-labels.combined.tsv")
        nodes = scene.add_to_graph(g, label_space="raw")
        by_object = {int(g.node_attrs(n)["object_id"]): n for n in nodes}
        for i, o in enumerate(objs):
            if i in by_object:
                ids[o.id] = by_object[i]
    return g, ids


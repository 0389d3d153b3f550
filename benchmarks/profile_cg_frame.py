"""The ConceptGraphs backend's own cost for one frame, by detections per frame and map size.

    python benchmarks/profile_cg_frame.py --detections 10,30 --objects 15,200 [--profile] [--channel oracle|none]

A map of N objects (sgbelief's stand-in detection dicts, ConceptGraphs ``main`` layout) is built,
then frames of D detections go through the patched per-frame merge (``merge_detections_to_objects``):
90 % of the detections match an object (a third of those with a second candidate, so the beliefs
spread), the rest become new objects; the detector is wrong 40 % of the time, a label-image channel
(``oracle``: the true class under each detection's mask) or none verifies it. The geometric merge
is a stand-in that only concatenates the per-detection lists, so what is timed is the backend's
own work: routing, identity, geometry summaries, the channel, the operator, the label bookkeeping.
The same frames also go through the operator alone (the events the backend made, replayed with
``update_many`` into a fresh graph): the per-event cost of the method itself.

Prints CPU time per frame and per detection (``time.process_time``, medians over frames); with
``--breakdown`` the CPU time of the timed frames by part of the backend (exclusive times of the
wrapped functions, so nothing is counted twice; CPU time, so other jobs on the machine do not
inflate it); with ``--profile`` a pyinstrument tree (wall-clock samples; ``--profile-out`` writes it
to a file); with ``--pieces`` the warm CPU time of single pieces of a frame, each repeated on
objects the backend has already seen (the same public calls on every version of the package, so two
checkouts compare side by side).
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

CLASSES = ["chair", "table", "sofa", "tv", "lamp", "bed", "cabinet", "plant", "stool", "box"]
H, W = 60, 80


def stand_in_merge(cfg: Any, obj1: dict, obj2: dict, run_dbscan: bool = True) -> dict:
    """The geometric merge without geometry: per-detection lists concatenated, counts added."""
    for key in ("image_idx", "mask_idx", "color_path", "class_id", "class_name", "mask", "conf"):
        if key in obj1 and key in obj2:
            obj1[key] = obj1[key] + list(obj2[key])
    obj1["num_detections"] = obj1.get("num_detections", 1) + obj2.get("num_detections", 1)
    return obj1


def make_object(rng: np.random.Generator, k: int, cls: int, t: int, mask: np.ndarray, conf: float, name: str) -> dict:
    from sgbelief.adapters.conceptgraphs.standins import make_detection

    pts = rng.random((200, 3)) * 0.5 + np.array([2.0 * (k % 20), 2.0 * (k // 20), 0.0])
    d = make_detection(pts, CLASSES.index(name), name, conf, t, mask_idx=k, seed=int(rng.integers(1 << 30)))
    d["mask"] = [mask]
    return d


class Scenario:
    """Frames of ``n_dets`` detections over a map of ``n_obj`` objects (deterministic in ``seed``)."""

    def __init__(self, n_obj: int, n_dets: int, frames: int, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.truth = rng.integers(0, len(CLASSES), size=n_obj + n_dets * frames)
        self.regions = [np.zeros((H, W), dtype=bool) for _ in range(n_dets)]
        cols = max(1, int(np.ceil(np.sqrt(n_dets))))
        for i, m in enumerate(self.regions):
            r, c = divmod(i, cols)
            hh, ww = H // cols, W // cols
            m[r * hh:(r + 1) * hh, c * ww:(c + 1) * ww] = True
        self.n_obj, self.n_dets, self.frames, self.seed = n_obj, n_dets, frames, seed
        self.images: dict[int, np.ndarray] = {}

    def label_image(self, t: int, who: list[int]) -> np.ndarray:
        img = np.full((H, W), -1, dtype=np.int32)
        for i, obj in enumerate(who):
            img[self.regions[i]] = int(self.truth[obj])
        return img

    def initial_map(self) -> list[dict]:
        rng = np.random.default_rng(self.seed + 1)
        full = np.ones((H, W), dtype=bool)
        self.images[0] = np.full((H, W), -1, dtype=np.int32)
        return [make_object(rng, k, int(self.truth[k]), 0, full, 0.9, CLASSES[int(self.truth[k])])
                for k in range(self.n_obj)]

    def frame(self, t: int, n_map: int) -> tuple[list[dict], Any]:
        """Frame ``t``'s detections and their association scores against a map of ``n_map`` objects."""
        import torch

        rng = np.random.default_rng(self.seed * 1000 + t)
        agg = torch.full((self.n_dets, n_map), float("-inf"))
        who: list[int] = []
        dets = []
        for i in range(self.n_dets):
            if rng.random() < 0.9:
                j = int(rng.integers(0, min(n_map, self.n_obj)))
                agg[i, j] = 1.5
                if rng.random() < 1 / 3:
                    agg[i, (j + 1) % min(n_map, self.n_obj)] = 1.3
                obj = j
            else:
                obj = self.n_obj + (t * self.n_dets + i) % (self.n_dets * self.frames)
            who.append(obj)
            cls = int(self.truth[obj])
            name = CLASSES[cls] if rng.random() > 0.4 else CLASSES[(cls + 1) % len(CLASSES)]
            dets.append(make_object(rng, obj, cls, t, self.regions[i], float(rng.uniform(0.55, 0.97)), name))
        self.images[t] = self.label_image(t, who)
        return dets, agg


#: the parts of the backend timed by ``--breakdown``: (label, class path, method)
PARTS = [
    ("operator: update_many (without the channel)", "sgbelief.adapters.conceptgraphs.map_beliefs:MapBeliefs", "_apply"),
    ("channel: label-image look-up", "sgbelief.fusion.channel:LabelImageChannel", "label_detection"),
    ("per-claim notes after the update (counts, label predicates)", "sgbelief.adapters.conceptgraphs.map_beliefs:MapBeliefs", "flush"),
    ("routing: claims -> queued events", "sgbelief.adapters.conceptgraphs.map_beliefs:MapBeliefs", "route_detection"),
    ("routing: claims -> queued events", "sgbelief.adapters.conceptgraphs.map_beliefs:MapBeliefs", "_route_own"),
    ("identity: look-up, registration, new graph nodes", "sgbelief.adapters.conceptgraphs.map_beliefs:MapBeliefs", "ensure_node"),
    ("targeting: candidates of a score row", "sgbelief.adapters.conceptgraphs.map_beliefs:MapBeliefs", "targets_for"),
    ("geometry summaries (centroid, box)", "sgbelief.adapters.conceptgraphs.geometry", "geometry_summary"),
    ("geometric merge (stand-in, not the backend's)", "__main__", "stand_in_merge"),
]


class Breakdown:
    """Exclusive CPU time per wrapped function (a call's time minus that of wrapped calls inside it)."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = {}
        self._stack: list[list[float]] = []
        self._undo: list[tuple[Any, str, Any]] = []
        self.on = False

    def wrap(self, owner: Any, name: str, label: str) -> None:
        import functools

        fn = getattr(owner, name)
        clock = time.process_time
        totals, stack = self.totals, self._stack

        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            if not self.on:
                return fn(*args, **kwargs)
            stack.append([0.0])
            t0 = clock()
            try:
                return fn(*args, **kwargs)
            finally:
                dt = clock() - t0
                inner = stack.pop()[0]
                totals[label] = totals.get(label, 0.0) + dt - inner
                if stack:
                    stack[-1][0] += dt

        self._undo.append((owner, name, fn))
        setattr(owner, name, timed)

    def restore(self) -> None:
        for owner, name, fn in reversed(self._undo):
            setattr(owner, name, fn)
        self._undo.clear()


def _install_breakdown(bd: Breakdown) -> None:
    import importlib

    for label, where, name in PARTS:
        modname, _, cls = where.partition(":")
        mod = sys.modules.get(modname) or importlib.import_module(modname)
        owner = getattr(mod, cls) if cls else mod
        bd.wrap(owner, name, label)
        if not cls and modname.endswith("geometry"):  # the module-level names the backend's modules bound
            for bound in ("map_beliefs", "new_objects"):
                bd.wrap(importlib.import_module(f"sgbelief.adapters.conceptgraphs.{bound}"), name, label)


def run(n_obj: int, n_dets: int, frames: int, channel: str, profiler: Any = None,
        breakdown: Breakdown | None = None) -> dict:
    from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend, LabelImageChannel
    from sgbelief.adapters.conceptgraphs.functions import make_functions
    from sgbelief.adapters.conceptgraphs.standins import DetectionList

    sc = Scenario(n_obj, n_dets, frames)
    seg = None
    if channel == "oracle":
        seg = LabelImageChannel(lambda t: sc.images.get(t), classes=CLASSES, ignore_ids=[-1], min_pixels=5,
                                keep_frames=2)
    backend = ConceptGraphsBackend("comod", context="profile", channel=seg, class_names=CLASSES, print_summary=False)
    backend.event_log = []  # the (event, labels) the backend routes, for the replay below
    f = make_functions(backend, "main", originals={"merge_obj2_into_obj1": stand_in_merge})
    cfg = SimpleNamespace()
    objects = DetectionList(sc.initial_map())
    dets, agg = sc.frame(1, len(objects))
    objects = f.merge_detections_to_objects(cfg, DetectionList(dets), objects, agg)  # registers the map
    backend.event_log.clear()
    per_frame: list[float] = []
    n_routed = 0
    total = 0.0
    for t in range(2, frames + 2):
        dets, agg = sc.frame(t, len(objects))
        if profiler is not None:
            profiler.start()
        if breakdown is not None:
            breakdown.on = True
        t0 = time.process_time()
        objects = f.merge_detections_to_objects(cfg, DetectionList(dets), objects, agg)
        per_frame.append(time.process_time() - t0)
        total += per_frame[-1]
        if breakdown is not None:
            breakdown.on = False
        if profiler is not None:
            profiler.stop()
        n_routed += n_dets
    # the operator alone: the same events, replayed in one update_many call into a fresh graph
    from sgbelief.api.operators import make_operator
    from sgbelief.fusion.channel import FrameLabels
    from sgbelief.api.scene_graph import SceneGraph  # the backend's graph type: the fast store

    items = [(ev, FrameLabels(labels)) for ev, labels in backend.event_log]
    make_operator("comod", backend.operator.config, backend.table).update_many(
        SceneGraph(create_nodes=True), items)  # warm-up: first-call costs out of the timing
    op = make_operator("comod", backend.operator.config, backend.table)
    g = SceneGraph(create_nodes=True)
    # a full collection owed by the frames above would otherwise land in these few hundred events
    # (measured: 545-655 us an event instead of 5-6 with the breakdown's wrappers installed)
    gc.collect()
    t0 = time.process_time()
    op.update_many(g, items)
    replay = (time.process_time() - t0) / max(len(items), 1)
    med = statistics.median(per_frame)
    if breakdown is not None:
        breakdown.totals["frame loop, label sync, the rest"] = total - sum(breakdown.totals.values())
        breakdown.totals["(all)"] = total
    return {"objects": n_obj, "map_objects_end": len(objects), "detections": n_dets, "frames": frames,
            "channel": channel, "frame_ms_median": 1000 * med, "per_detection_us": 1e6 * med / n_dets,
            "events": len(items), "replay_per_event_us": 1e6 * replay,
            "ratio": (1e6 * med / n_dets) / (1e6 * replay) if replay else float("nan")}


def pieces(repeat: int = 2000, rounds: int = 7) -> dict[str, float]:
    """Warm µs per call of single pieces of a frame (the fastest of ``rounds`` rounds of ``repeat``
    calls, as timeit advises: slower rounds are other jobs on the machine, not the piece).

    - ``read_claims``: the claims of a one-detection dict;
    - ``route_detection``: one such detection routed to one node (queued, not applied);
    - ``refresh_geometry``: a registered object's centroid / box copied into its node;
    - ``trusted event``: ``EvidenceEvent.trusted`` from checked parts;
    - ``new object``: a fresh detection registered (identity, graph node, geometry, its claim);
    - ``sync one object``: the per-frame label sync of one touched, merged object (``main``).
    """
    import copy

    from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
    from sgbelief.adapters.conceptgraphs.claims import read_claims
    from sgbelief.adapters.conceptgraphs.functions import make_functions
    from sgbelief.fusion.events import EvidenceEvent, next_event_id

    rng = np.random.default_rng(0)
    mask = np.ones((H, W), dtype=bool)
    backend = ConceptGraphsBackend("comod", context="pieces", class_names=CLASSES, print_summary=False)
    f = make_functions(backend, "main", originals={"merge_obj2_into_obj1": stand_in_merge})
    objs = [make_object(rng, k, k % len(CLASSES), 1, mask, 0.8, CLASSES[k % len(CLASSES)]) for k in range(50)]
    for o in objs:
        backend.ensure_node(o)
    backend.flush()
    det = make_object(rng, 999, 2, 2, mask, 0.7, CLASSES[2])
    node = backend.node_of(objs[0])

    def fresh_detections(r: int) -> list[dict]:
        """``repeat`` detections with distinct first detections (each is a new object)."""
        out = [copy.copy(det) for _ in range(repeat)]
        for k, d in enumerate(out):
            d.update(image_idx=[3 + r], mask_idx=[10_000 + k], color_path=[f"frame{r}-{k}.jpg"], conf=[0.7],
                     class_id=[2], class_name=[CLASSES[2]])
        return out

    clock = time.process_time
    out: dict[str, list[float]] = {}

    def timed(name: str, fn: Any, setup: Any = None) -> None:
        for _ in range(rounds):
            if setup is not None:
                setup()
            t0 = clock()
            fn()
            out.setdefault(name, []).append(1e6 * (clock() - t0) / repeat)

    def claims() -> None:
        names = backend.class_names
        for _ in range(repeat):
            read_claims(det, names)

    def route() -> None:
        targets = {node: 1.0}
        with backend.batch():
            for _ in range(repeat):
                backend.route_detection(det, targets)
            backend._pending.clear()  # the queued events are not applied (not part of the piece)
            getattr(backend, "_pending_dicts", set()).clear()  # (older versions' bookkeeping of the same)

    def refresh() -> None:
        obj = objs[0]
        for _ in range(repeat):
            backend.refresh_geometry(obj)

    def trusted() -> None:
        targets = {node: 1.0}
        for _ in range(repeat):
            EvidenceEvent.trusted(targets, "is_chair", 0.7, "pieces", 3, next_event_id())

    def new_objects() -> None:
        with backend.batch():
            for d in fresh:
                backend.ensure_node(d)
            backend._pending.clear()
            getattr(backend, "_pending_dicts", set()).clear()  # (older versions' bookkeeping of the same)

    def sync_one() -> None:
        touched = [0]
        for _ in range(repeat):
            f.merged.add(id(objs[0]))
            f.sync_labels(objs, touched)

    timed("read_claims", claims)
    timed("route_detection", route)
    timed("refresh_geometry", refresh)
    timed("trusted event", trusted)
    for r in range(rounds):  # each round registers new detections
        fresh = fresh_detections(r)
        t0 = clock()
        new_objects()
        out.setdefault("new object", []).append(1e6 * (clock() - t0) / repeat)
    timed("sync one object", sync_one)
    return {k: min(v) for k, v in out.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--detections", default="10,30")
    ap.add_argument("--objects", default="15,200")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--channel", default="oracle", choices=["oracle", "none"])
    ap.add_argument("--profile", action="store_true", help="pyinstrument tree of the timed frames")
    ap.add_argument("--breakdown", action="store_true", help="CPU time of the timed frames by part of the backend")
    ap.add_argument("--profile-out", default=None)
    ap.add_argument("--pieces", action="store_true", help="warm CPU time of single pieces of a frame, then exit")
    args = ap.parse_args(argv)
    if args.pieces:
        import gc

        gc.collect()
        gc.disable()  # a collection landing in a few-ms piece would be timed as the piece
        try:
            timings = pieces()
        finally:
            gc.enable()
        for name, us in timings.items():
            print(f"{name:<20} {us:7.2f} us")
        return 0
    for n_obj in (int(x) for x in args.objects.split(",")):
        for n_dets in (int(x) for x in args.detections.split(",")):
            prof = None
            if args.profile:
                from pyinstrument import Profiler

                prof = Profiler(interval=0.0002)
            bd = None
            if args.breakdown:
                bd = Breakdown()
                _install_breakdown(bd)
            try:
                r = run(n_obj, n_dets, args.frames, args.channel, prof, bd)
            finally:
                if bd is not None:
                    bd.restore()
            print(f"objects {r['objects']:4d} (end {r['map_objects_end']:4d})  detections/frame {n_dets:3d}  "
                  f"frame {r['frame_ms_median']:6.2f} ms  per detection {r['per_detection_us']:6.1f} us  "
                  f"replay per event {r['replay_per_event_us']:5.1f} us ({r['events']} events)  "
                  f"ratio {r['ratio']:.1f}x")
            if bd is not None:
                allt = bd.totals.pop("(all)")
                n = args.frames * n_dets
                for label, sec in sorted(bd.totals.items(), key=lambda kv: -kv[1]):
                    print(f"    {label:<62} {1e6 * sec / n:7.1f} us per detection  {100 * sec / allt:5.1f} %")
            if prof is not None:
                text = prof.output_text(unicode=False, color=False, show_all=False)
                if args.profile_out:
                    Path(args.profile_out).with_suffix(f".{n_obj}x{n_dets}.txt").write_text(text)
                else:
                    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

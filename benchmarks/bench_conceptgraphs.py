"""ConceptGraphs' per-frame majority relabel vs the sgbelief per-frame update, side by side.

ConceptGraphs keeps every detection's class id on each map object and, every frame, relabels each
object with ``Counter(obj["class_id"]).most_common(1)`` over its full list (the loop of
``rerun_realtime_mapping.py`` / ``streamlined_mapping.py``). With the sgbelief backend each
detection is folded into the beliefs once and the label is read from them.

Both sides do the same per-frame work on the same map: every object gets one new detection
(appended to its ``class_id`` / ``conf`` / ``image_idx`` lists, as ConceptGraphs' merge does with
or without the backend) and every object's label is produced:

* ConceptGraphs: ``Counter`` over each object's full ``class_id`` list;
* sgbelief: ``ConceptGraphsBackend.route_detection`` (one ``EvidenceEvent`` per detection through
  ``majority`` / ``comod``) and ``ConceptGraphsBackend.class_id_of`` per object (what the patched
  ``get_most_common_class`` returns).

The map's history (``D`` detections per object) is built untimed, frame by frame (frame ``k`` =
one detection per object at ``t = k``), exactly as a live run would have built it. Then ``--frames``
frames are timed one by one with ``time.process_time()``, the ConceptGraphs frame and the sgbelief
frame alternately (order swapped every frame), so both sides run under the same load of this shared
machine. This runs once per operator on a fresh copy of the map; ConceptGraphs' figures pool the
passes. The report gives the median
(a typical frame), the mean (all costs amortised, including cyclic-GC pauses) and the max per frame,
and the number / total time of generation-2 collections inside sgbelief's timed frames
(ConceptGraphs' frames run with the collector paused: its own map holds few container objects, and a
collection due to the sgbelief map must not be charged to it). Ratios are ConceptGraphs / sgbelief
(> 1: sgbelief is cheaper).

Compaction never runs inside the timed frames (the history is shorter than T_prov = 1000 steps);
its amortised cost is measured afterwards by folding the whole log once
(``compaction_ms_per_frame`` = that time / frames folded). In a live run it is paid in one burst
every T_prov steps.

``--gc`` (applied to both sides after the map is loaded): ``default`` (CPython's settings, what a
pipeline script gets), ``freeze`` (``gc.collect(); gc.freeze()`` once: the loaded map leaves the
collector's view), ``checkpoint`` (that, then ``gc.collect(); gc.freeze()`` at the end of every
frame, timed: ``ConceptGraphsBackend(gc_checkpoints=True)`` on the sgbelief side; see
docs/performance.md "ConceptGraphs per-frame cost").

``--ab``: only the history question, without ConceptGraphs: for each size and operator, the maps of
every ``--dets`` value are built in one process and their frames alternate (collector paused), so
the medians share the machine's load; ``max_over_min`` near 1 = no growth with history.

Usage: .venv/bin/python benchmarks/bench_conceptgraphs.py [--frames 30] [--sizes 100,1000,5000]
       [--dets 50,500] [--operators majority,comod] [--gc default|freeze|checkpoint] [--ab] [--json]
"""

from __future__ import annotations

import argparse
import gc
import json
import statistics
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import _common  # noqa: F401

CLASSES = ("chair", "table", "sofa", "bed", "cabinet")
CONF = 0.8
GC_MODES = ("default", "freeze", "checkpoint")


class _Gen2Pauses:
    """Generation-2 collections (count, CPU seconds) while ``armed``."""

    def __init__(self) -> None:
        self.armed = False
        self.count = 0
        self.seconds = 0.0
        self._t0 = 0.0

    def __call__(self, phase: str, info: dict[str, Any]) -> None:
        if not self.armed or info.get("generation") != 2:
            return
        if phase == "start":
            self._t0 = time.process_time()
        else:
            self.count += 1
            self.seconds += time.process_time() - self._t0


def _objects(hist: Any) -> list[dict[str, list[Any]]]:
    """ConceptGraphs-style map objects holding the history ``hist[k, o]`` (frame k, object o)."""
    n_det, n_obj = hist.shape
    objs: list[dict[str, list[Any]]] = []
    for o in range(n_obj):
        ids = [int(c) for c in hist[:, o]]
        objs.append({"class_id": ids, "conf": [CONF] * n_det, "image_idx": list(range(n_det)), "mask_idx": [o] * n_det})
    return objs


def _append(obj: dict[str, list[Any]], cid: int, t: int, mask: int) -> None:
    """What ConceptGraphs' merge does to an object's per-detection lists (both sides pay it)."""
    obj["class_id"].append(cid)
    obj["conf"].append(CONF)
    obj["image_idx"].append(t)
    obj["mask_idx"].append(mask)


def _checkpoint() -> None:
    gc.collect()
    gc.freeze()


def _summary(prefix: str, per: list[float], pauses: _Gen2Pauses | None = None) -> dict[str, float]:
    out = {
        f"{prefix}_ms_per_frame": round(statistics.median(per) * 1e3, 3),
        f"{prefix}_mean_ms": round(statistics.fmean(per) * 1e3, 3),
        f"{prefix}_max_ms": round(max(per) * 1e3, 3),
    }
    if pauses is not None:
        out[f"{prefix}_gen2_collections"] = pauses.count
        out[f"{prefix}_gen2_ms"] = round(pauses.seconds * 1e3, 1)
    return out


def conceptgraphs_map(hist: Any, mode: str) -> Callable[[int, Any], None]:
    """ConceptGraphs' frame: append each object's detection, relabel every object from its full list."""
    objs = _objects(hist)
    names = CLASSES

    def frame(t: int, row: Any) -> None:
        for o, obj in enumerate(objs):
            _append(obj, int(row[o]), t, o)
        labels = []
        for obj in objs:
            labels.append(names[Counter(obj["class_id"]).most_common(1)[0][0]])
        assert len(labels) == len(objs)
        if mode == "checkpoint":
            _checkpoint()

    return frame


def sgbelief_map(op_name: str, hist: Any, mode: str) -> tuple[Any, Callable[[int, Any], None]]:
    """The same map in a ConceptGraphsBackend, its history routed frame by frame (untimed); and the
    sgbelief frame: route each detection once, read every object's label."""
    from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend

    n_det, n_obj = hist.shape
    backend = ConceptGraphsBackend(op_name, context="yolo-world/bench", class_names=CLASSES,
                                   gc_checkpoints=mode == "checkpoint")
    key = backend.label_key
    objs: list[dict[str, list[Any]]] = [{"class_id": [], "conf": [], "image_idx": [], "mask_idx": []}
                                        for _ in range(n_obj)]
    nodes: list[Any] = []

    def route(t: int, row: Any) -> None:
        for o, obj in enumerate(objs):
            cid = int(row[o])
            name = CLASSES[cid]
            # the detection ConceptGraphs hands to the patched merge; the geometric label (the
            # segmenter's class) lets comod verify the claim
            det = {"class_id": [cid], "conf": [CONF], "image_idx": [t], "class_name": [name], key: name}
            backend.route_detection(det, {nodes[o]: 1.0})
            _append(obj, cid, t, o)

    for o, obj in enumerate(objs):  # frame 0: every object is new (registered, its detection replayed)
        cid = int(hist[0, o])
        _append(obj, cid, 0, o)  # (image_idx[0], mask_idx[0]) identifies the object
        obj["class_name"] = [CLASSES[cid]]
        obj[key] = CLASSES[cid]
        nodes.append(backend.ensure_node(obj))
        del obj["class_name"]
    for k in range(1, n_det):  # the rest of the history
        route(k, hist[k])

    def frame(t: int, row: Any) -> None:
        route(t, row)
        labels = [backend.class_id_of(obj) for obj in objs]
        assert len(labels) == n_obj
        backend.end_frame()  # what the patched per-frame merge calls (gc_checkpoint when enabled)

    return backend, frame


def side_by_side(op_name: str, hist: Any, new: Any, mode: str, pauses: _Gen2Pauses) -> dict[str, Any]:
    """Time ConceptGraphs' frame and the sgbelief frame alternately (same map, same detections, same
    load on the machine); their order swaps every frame. CPU seconds per frame for both sides, and
    the compaction cost measured afterwards."""
    n_det = hist.shape[0]
    cg_frame = conceptgraphs_map(hist, mode)
    backend, sg_frame = sgbelief_map(op_name, hist, mode)
    clock = time.process_time
    cg: list[float] = []
    sg: list[float] = []
    if mode != "default":
        _checkpoint()  # the maps are loaded: take them out of the collector's view (untimed)
    pauses.count, pauses.seconds = 0, 0.0
    try:
        for f in range(new.shape[0]):
            t, row = n_det + f, new[f]
            for side in ((0, 1) if f % 2 == 0 else (1, 0)):
                if side == 0:
                    # ConceptGraphs' own map holds few container objects (no full collection in any
                    # sequential run); a collection due to the sgbelief map must not be charged to it
                    gc.disable()
                    s = clock()
                    cg_frame(t, row)
                    cg.append(clock() - s)
                    gc.enable()
                else:
                    pauses.armed = True
                    s = clock()
                    sg_frame(t, row)
                    sg.append(clock() - s)
                    pauses.armed = False
    finally:
        gc.enable()
        pauses.armed = False
        if mode != "default":
            gc.unfreeze()
    n_frames = new.shape[0]
    assert len(backend.graph) == hist.shape[1] and backend.routed_detections == hist.shape[1] * (n_det + n_frames)
    prov = backend.graph.provenance
    s = clock()
    folded = prov.compact(n_det + n_frames + 1)  # compaction's amortised cost: fold the whole log once
    compact_s = clock() - s
    prefix = f"sgbelief_{op_name}"
    out: dict[str, Any] = {"_cg": cg}
    out.update(_summary(prefix, sg, pauses))
    out[f"{prefix}_compaction_ms_per_frame"] = round(compact_s * 1e3 / (n_det + n_frames), 3)
    out[f"{prefix}_entries_folded"] = folded
    out[f"ratio_cg_over_{op_name}"] = round(statistics.median(cg) / statistics.median(sg), 2)
    out[f"ratio_cg_over_{op_name}_mean"] = round(statistics.fmean(cg) / statistics.fmean(sg), 2)
    return out


def history_ab(op_name: str, n_obj: int, dets: list[int], frames: int, seed: int) -> dict[str, Any]:
    """Does sgbelief's frame cost depend on the history? The maps of every ``dets`` value live in one
    process and their frames alternate (rotating order), so they share the machine's load and the
    heap; the collector is paused (its pauses are what the side-by-side run reports)."""
    import numpy as np

    frames_of = {}
    for n_det in dets:
        hist = np.random.default_rng([seed, n_obj, n_det]).integers(0, len(CLASSES), size=(n_det, n_obj))
        frames_of[n_det] = sgbelief_map(op_name, hist, "default")[1]
    new = np.random.default_rng([seed, n_obj]).integers(0, len(CLASSES), size=(frames, n_obj))
    per: dict[int, list[float]] = {d: [] for d in dets}
    clock = time.process_time
    gc.collect()
    gc.disable()
    try:
        for f in range(frames):
            order = dets[f % len(dets):] + dets[:f % len(dets)]
            for n_det in order:
                s = clock()
                frames_of[n_det](n_det + f, new[f])
                per[n_det].append(clock() - s)
    finally:
        gc.enable()
    med = {d: round(statistics.median(v) * 1e3, 3) for d, v in per.items()}
    return {"objects": n_obj, "operator": op_name, "ms_per_frame_by_detections": med,
            "max_over_min": round(max(med.values()) / min(med.values()), 3)}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30, help="timed frames per cell (default 30)")
    ap.add_argument("--sizes", default="100,1000,5000", help="map sizes (objects)")
    ap.add_argument("--dets", default="50,500", help="detections per object already in the map")
    ap.add_argument("--operators", default="majority,comod")
    ap.add_argument("--gc", choices=GC_MODES, default="default", help="cyclic-GC handling after the map is loaded")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ab", action="store_true",
                    help="instead: sgbelief's frame cost for every --dets value, maps in one process, frames alternating")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    import numpy as np

    ops = [o.strip() for o in args.operators.split(",") if o.strip()]
    if args.ab:
        dets = [int(x) for x in args.dets.split(",")]
        ab_rows = []
        for n_obj in [int(x) for x in args.sizes.split(",")]:
            for op_name in ops:
                ab_rows.append(history_ab(op_name, n_obj, dets, args.frames, args.seed))
                gc.collect()
                if not args.json:
                    print(json.dumps(ab_rows[-1]), flush=True)
        ab_out = {"bench": "conceptgraphs_history_ab", "frames": args.frames, "rows": ab_rows,
                  "machine": _common.machine()}
        print(json.dumps(ab_out) if args.json else json.dumps(ab_out, indent=1))
        return 0
    pauses = _Gen2Pauses()
    gc.callbacks.append(pauses)
    rows = []
    for n_obj in [int(x) for x in args.sizes.split(",")]:
        for n_det in [int(x) for x in args.dets.split(",")]:
            rng = np.random.default_rng([args.seed, n_obj, n_det])
            hist = rng.integers(0, len(CLASSES), size=(n_det, n_obj))
            new = rng.integers(0, len(CLASSES), size=(args.frames, n_obj))
            res: dict[str, Any] = {"objects": n_obj, "detections_per_object": n_det}
            cg_all: list[float] = []
            parts = []
            for op_name in ops:
                part = side_by_side(op_name, hist, new, args.gc, pauses)
                cg_all += part.pop("_cg")
                parts.append(part)
                gc.collect()
            res.update(_summary("conceptgraphs", cg_all))
            for part in parts:
                res.update(part)
            rows.append(res)
            if not args.json:
                print(json.dumps(res), flush=True)
    gc.callbacks.remove(pauses)
    out = {"bench": "conceptgraphs_relabel", "frames": args.frames, "gc": args.gc, "rows": rows,
           "machine": _common.machine()}
    print(json.dumps(out) if args.json else json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""ConceptGraphs' per-frame majority relabel vs the sgbelief per-frame update, side by side.

ConceptGraphs keeps every detection's class id on each object and, every frame, relabels each
object with ``Counter(class_ids).most_common(1)`` over its full list. sgbelief folds each
detection into a Beta belief once. Per frame: each of the map's objects gets one new detection
(ConceptGraphs then relabels all objects; sgbelief applies the frame's events with ``majority``
and ``comod``). Maps of 100 / 1,000 / 5,000 objects whose histories hold 50 / 500 detections.

Usage: .venv/bin/python benchmarks/bench_conceptgraphs.py [--frames 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter

import _common  # noqa: F401


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--sizes", default="100,1000,5000")
    ap.add_argument("--dets", default="50,500")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    import numpy as np

    from sgbelief.eval.replay import make_runs
    from sgbelief.fusion.channel import FrameLabels
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.fusion.events import EvidenceEvent

    vocab = SubsumptionTable.shipped("kitti360")
    classes = ["car", "person", "building", "vegetation", "road"]
    pred_of = {"car": "is_car", "person": "is_pedestrian", "building": "is_building", "vegetation": "is_vegetation",
               "road": "is_car"}
    rows = []
    clock = time.process_time
    for n_obj in [int(x) for x in args.sizes.split(",")]:
        for n_det in [int(x) for x in args.dets.split(",")]:
            rng = np.random.default_rng(n_obj + n_det)
            hist = [list(rng.integers(0, 5, size=n_det)) for _ in range(n_obj)]
            # ConceptGraphs: append the new detection, relabel every object from its full list
            t0 = clock()
            for f in range(args.frames):
                new = rng.integers(0, 5, size=n_obj)
                for o in range(n_obj):
                    hist[o].append(int(new[o]))
                labels = [Counter(h).most_common(1)[0][0] for h in hist]
            cg = (clock() - t0) / args.frames
            assert len(labels) == n_obj
            # sgbelief: the same histories already folded into beliefs; per frame one event per object
            res = {"objects": n_obj, "detections_per_object": n_det, "conceptgraphs_ms_per_frame": round(cg * 1e3, 3)}
            for op_name in ("majority", "comod"):
                run = make_runs([op_name], vocab)[0]
                op, g = run.operator, run.graph
                t = 0
                for o in range(n_obj):  # history (untimed)
                    node = f"o{o}"
                    for cls in hist[o][:n_det]:
                        c = classes[cls]
                        op.update(g, EvidenceEvent.trusted({node: 1.0}, pred_of[c], 0.8, "vlm", t, f"h{o}_{t}"),
                                  FrameLabels({node: c}))
                    t += 1
                t0 = clock()
                for f in range(args.frames):
                    t += 1
                    new = rng.integers(0, 5, size=n_obj)
                    for o in range(n_obj):
                        c = classes[int(new[o])]
                        node = f"o{o}"
                        op.update(g, EvidenceEvent.trusted({node: 1.0}, pred_of[c], 0.8, "vlm", t, f"f{f}_{o}"),
                                  FrameLabels({node: c}))
                sg = (clock() - t0) / args.frames
                res[f"sgbelief_{op_name}_ms_per_frame"] = round(sg * 1e3, 3)
                res[f"ratio_cg_over_{op_name}"] = round(cg / sg, 2)
            rows.append(res)
    out = {"bench": "conceptgraphs_relabel", "frames": args.frames, "rows": rows}
    print(json.dumps(out) if args.json else json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

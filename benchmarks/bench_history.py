"""Cost vs history: mean per-event cost late in a long stream vs early (comod, 1 outcome/event).

Stream: 10^4 (v, phi) pairs, 10 events per time step (compaction every T_prov = 1000 steps, i.e.
every 10^4 events), every event's geometric label decisive, so the calibration buffer grows by one
outcome per event (to ~10^6: ``--buffer-size`` defaults to 2^20 so the buffer is not capped before
10^6 outcomes; ``--buffer-size default`` uses the shipped sliding window). Reports mean cost of events
[10k, 20k) and [1M, 1.01M) and writes ``benchmarks/history.png`` (events/s per 10k-event window vs
events processed). Updates run as a replay runs them (``report=False`` inside ``relaxed_gc``).

Usage: .venv/bin/python benchmarks/bench_history.py [--events 1010000] [--operator comod]
       [--buffer-size 1048576|default|none] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from _common import pair_stream


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--events", type=int, default=1_010_000)
    ap.add_argument("--pairs", type=int, default=10_000)
    ap.add_argument("--operator", default="comod")
    ap.add_argument("--window", type=int, default=10_000)
    ap.add_argument("--buffer-size", default="1048576")
    ap.add_argument("--png", default=str(Path(__file__).with_name("history.png")))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from sgbelief.eval.replay import make_runs
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief._fast.gc import relaxed_gc

    cfg = OperatorConfig()
    if args.buffer_size != "default":
        size = None if args.buffer_size == "none" else int(args.buffer_size)
        cfg = cfg.model_copy(update={"calibration": cfg.calibration.model_copy(update={"buffer_size": size})})
    run = make_runs([args.operator], SubsumptionTable.shipped("kitti360"), cfg)[0]
    op, g = run.operator, run.graph
    clock = time.process_time
    w = args.window
    costs = []  # seconds per window (update calls only)
    acc = 0.0
    i = 0
    with relaxed_gc():
        for ev, lab in pair_stream(args.events, args.pairs):
            t0 = clock()
            op.update(g, ev, lab, report=False)
            acc += clock() - t0
            i += 1
            if i % w == 0:
                costs.append(acc)
                acc = 0.0
    early = costs[1] / w  # events 10,000-20,000
    late_idx = 1_000_000 // w
    late = costs[late_idx] / w if len(costs) > late_idx else costs[-1] / w
    cal = getattr(op, "calibrator_", None)
    res = {"bench": "history", "operator": args.operator, "events": i, "pairs": args.pairs,
           "buffer_size": cfg.calibration.buffer_size,
           "early_us_per_event": round(early * 1e6, 2), "late_us_per_event": round(late * 1e6, 2),
           "late_window": [late_idx * w, (late_idx + 1) * w] if len(costs) > late_idx else [(len(costs) - 1) * w, len(costs) * w],
           "ratio_late_over_early": round(late / early, 3),
           "calibration_outcomes_global": cal.n_outcomes() if cal else None,
           "compacted_entries": g.provenance.n_compacted, "live_entries": len(g.provenance.timeline_view())}
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        xs = [(k + 1) * w for k in range(len(costs))]
        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.plot(xs, [w / c for c in costs], lw=0.8)
        ax.set_xlabel("events processed")
        ax.set_ylabel(f"events/s ({w // 1000}k-event window)")
        ax.set_title(f"{args.operator}: throughput vs history ({args.pairs} pairs, 1 outcome/event)")
        ax.set_ylim(bottom=0)
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
        res["png"] = args.png
    except ImportError:  # pragma: no cover
        res["png"] = None
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Bounded memory: N events over 10^4 (v, phi) pairs; RSS after 10^6 events vs after N, peak RSS.

Runs in its own process (run_all starts it as a subprocess). ``--decisive`` is the fraction of
events whose geometric label is decisive (each such event adds one calibration outcome, which the
method keeps by design: the isotonic fit uses the whole buffer).

Usage: .venv/bin/python benchmarks/bench_memory.py [--events 10000000] [--operator comod] [--json]
"""

from __future__ import annotations

import argparse
import gc
import json
import time

from _common import pair_stream, rss_mb


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--events", type=int, default=10_000_000)
    ap.add_argument("--pairs", type=int, default=10_000)
    ap.add_argument("--operator", default="comod")
    ap.add_argument("--decisive", type=float, default=1.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from sgbelief.eval.replay import make_runs
    from sgbelief.fusion.compatibility import SubsumptionTable

    run = make_runs([args.operator], SubsumptionTable.shipped("kitti360"))[0]
    op, g = run.operator, run.graph
    marks = {}
    t0 = time.perf_counter()
    i = 0
    for ev, lab in pair_stream(args.events, args.pairs, p_decisive=args.decisive):
        op.update(g, ev, lab, report=False)
        i += 1
        if i in (10**5, 10**6) or i % 10**6 == 0 or i == args.events:
            gc.collect()
            marks[i] = round(rss_mb()[0], 1)
    cur, peak = rss_mb()
    after_1m = marks.get(10**6)
    cal = getattr(op, "calibrator_", None)
    res = {"bench": "memory", "operator": args.operator, "events": i, "pairs": args.pairs, "decisive": args.decisive,
           "seconds": round(time.perf_counter() - t0, 1), "rss_mb_at": marks, "peak_rss_mb": round(peak, 1),
           "rss_growth_after_1M": round(cur / after_1m - 1.0, 4) if after_1m else None,
           "live_provenance_entries": len(g.provenance.timeline_view()), "pairs_in_store": len(g.provenance),
           "quarantine_len": len(g.provenance.quarantine), "disagreement_len": len(g.provenance.disagreement),
           "calibration_outcomes_global": cal.n_outcomes() if cal else 0}
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

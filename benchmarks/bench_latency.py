"""Worst-case cost of one time step (a "frame") under the default and a short compaction interval.

Live mapping cares about the slowest frame, not only the mean: with the default schedule every
T_prov steps one pass folds all the entries that crossed the horizon since the last pass (a pause
proportional to T_prov x events per step). ``t_compact`` runs the passes more often, each folding
fewer entries. Both schedules replay the same stream in this process (``--operator``, 10^5 pairs,
100 events per step by default); per step the CPU time of its ``update`` calls is recorded, and the
median / p99 / max step cost and the overall events/s are reported side by side. What is left of
the worst step with a short interval is a cyclic-GC full collection (``--gc off`` removes it) or,
for cal/comod, an isotonic refit of a large calibration slice.

Usage: .venv/bin/python benchmarks/bench_latency.py [--events 400000] [--pairs 100000]
       [--events-per-step 100] [--operator comod] [--intervals default,10] [--gc relaxed|off] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

from _common import pair_stream


def _run(operator: str, interval: int | None, args: argparse.Namespace) -> dict[str, float]:
    from sgbelief.eval.replay import make_runs
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief._fast.gc import relaxed_gc

    cfg = OperatorConfig(t_compact=interval)
    run = make_runs([operator], SubsumptionTable.shipped("kitti360"), cfg)[0]
    op, g = run.operator, run.graph
    clock = time.process_time
    steps: list[float] = []
    acc = 0.0
    step = 0
    import contextlib
    import gc

    @contextlib.contextmanager
    def gc_off():  # type: ignore[no-untyped-def]
        gc.disable()
        try:
            yield
        finally:
            gc.enable()

    with relaxed_gc() if args.gc == "relaxed" else gc_off():
        for ev, lab in pair_stream(args.events, args.pairs, events_per_step=args.events_per_step):
            if ev.t != step:
                steps.append(acc)
                acc, step = 0.0, ev.t
            t0 = clock()
            op.update(g, ev, lab, report=False)
            acc += clock() - t0
    steps.append(acc)
    steps.sort()
    n = len(steps)
    total = sum(steps)
    return {
        "t_compact": cfg.compaction_interval,
        "steps": n,
        "step_ms_median": round(steps[n // 2] * 1e3, 3),
        "step_ms_p99": round(steps[min(n - 1, int(0.99 * n))] * 1e3, 3),
        "step_ms_max": round(steps[-1] * 1e3, 2),
        "events_per_s": round(args.events / total),
        "compaction_passes": g.meta.get("compaction_epoch", 0),
        "compacted_entries": g.provenance.n_compacted,
    }


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--events", type=int, default=400_000)
    ap.add_argument("--pairs", type=int, default=100_000)
    ap.add_argument("--events-per-step", type=int, default=100)
    ap.add_argument("--operator", default="comod")
    ap.add_argument("--intervals", default="default,10", help="comma list of t_compact values ('default' = T_prov)")
    ap.add_argument("--gc", choices=("relaxed", "off"), default="relaxed",
                    help="cyclic GC during the run: as a replay runs it (relaxed) or disabled (off: the "
                    "step costs without full-collection pauses, i.e. the compaction effect alone)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = {}
    for item in args.intervals.split(","):
        interval = None if item == "default" else int(item)
        rows[item] = _run(args.operator, interval, args)
    base = rows[next(iter(rows))]
    for row in rows.values():
        row["max_step_ratio_to_first"] = round(row["step_ms_max"] / base["step_ms_max"], 3)
        row["throughput_ratio_to_first"] = round(row["events_per_s"] / base["events_per_s"], 3)
    res = {"bench": "latency", "operator": args.operator, "events": args.events, "pairs": args.pairs,
           "events_per_step": args.events_per_step, "gc": args.gc, "t_prov": 1000, "schedules": rows}
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

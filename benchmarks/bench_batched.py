"""Batched (wave) replay vs streaming replay of the same random stream (count-based baselines).

Usage: .venv/bin/python benchmarks/bench_batched.py [--events 1000000] [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import _common  # noqa: F401


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--events", type=int, default=1_000_000)
    ap.add_argument("--stream-events", type=int, default=100_000, help="events for the streaming comparison")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from sgbelief.eval.batched import BATCHED_OPERATORS, EventColumns, batched_replay, random_records
    from sgbelief.eval.replay import make_runs, replay

    t0 = time.perf_counter()
    recs = random_records(0, args.events, n_nodes=10_000)
    gen_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    cols = EventColumns.from_records(recs)
    col_s = time.perf_counter() - t0
    out = {}
    for name in BATCHED_OPERATORS:
        t0 = time.perf_counter()
        batched_replay(cols, name)
        b = time.perf_counter() - t0
        sub = recs[: args.stream_events]
        run = make_runs([name], None)[0]
        t0 = time.perf_counter()
        replay(sub, [run])
        s = time.perf_counter() - t0
        out[name] = {"batched_events_per_s": round(args.events / b), "batched_incl_columnarise_events_per_s":
                     round(args.events / (b + col_s)), "streaming_events_per_s": round(len(sub) / s),
                     "speedup": round((args.events / b) / (len(sub) / s), 1)}
    res = {"bench": "batched", "events": args.events, "entries": len(cols.pair), "columnarise_s": round(col_s, 2),
           "generate_s": round(gen_s, 1), "operators": out}
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

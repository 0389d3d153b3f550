"""Batched (wave) replay vs the streaming engine on the same random stream, in one run.

Per operator: columnarise (once per stream), batched apply (schedule + belief waves) and store
rebuild (compacted buckets in numpy, Python objects, compacted-id memory), each the best CPU
time (``time.process_time``) of ``--repeat`` runs; the streaming engine (``replay``) on the same
stream (or its first ``--stream-events`` events), timed once; the speed-ups; and whether both
engines produced identical stores (``ProvenanceStore.to_dict``) on the streamed events.

Usage: .venv/bin/python benchmarks/bench_batched.py [--events 300000] [--stream-events N] [--repeat 5]
       [--nodes 10000] [--json]
"""

from __future__ import annotations

import argparse
import gc
import json
import statistics
import time
from collections.abc import Callable
from typing import TypeVar

import _common  # noqa: F401

T = TypeVar("T")


def _cpu(fn: Callable[[], T]) -> tuple[T, float]:
    """(result, CPU seconds) of fn(), after collecting earlier garbage outside the timing."""
    gc.collect()
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--events", type=int, default=300_000)
    ap.add_argument("--stream-events", type=int, default=0,
                    help="time the streaming engine on this prefix only (default: the whole stream)")
    ap.add_argument("--nodes", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=5, help="batched runs per operator (best is reported)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from sgbelief._fast.batched import EventColumns, batched_replay
    from sgbelief.eval.replay import make_runs, replay
    from sgbelief.fusion.registry import OPERATOR_NAMES
    from sgbelief.eval.random_stream import random_records

    recs, gen_s = _cpu(lambda: random_records(0, args.events, n_nodes=args.nodes))
    col_times = []
    for _ in range(args.repeat):
        cols, s = _cpu(lambda: EventColumns.from_records(recs))
        col_times.append(s)
    col_s = min(col_times)
    n_stream = min(args.stream_events or args.events, args.events)
    sub = recs[:n_stream]
    sub_cols = cols if n_stream == args.events else EventColumns.from_records(sub)
    out = {}
    for name in [n for n in OPERATOR_NAMES if make_runs([n], None)[0].operator.pair_rule is not None]:
        phases: dict[str, list[float]] = {}
        total = []
        for _ in range(args.repeat):
            laps: dict[str, float] = {}
            _, s = _cpu(lambda: batched_replay(cols, name, timings=laps))
            for k, v in laps.items():
                phases.setdefault(k, []).append(v)
            phases.setdefault("rebuild", []).append(laps["fold"] + laps["objects"] + laps["memory"])
            total.append(s)
        streamed = make_runs([name], None)[0]
        _, stream_s = _cpu(lambda: replay(sub, [streamed]))
        batched_graph, _ = batched_replay(sub_cols, name)
        identical = batched_graph.provenance.to_dict() == streamed.graph.provenance.to_dict()
        b = min(total)
        stream_rate = n_stream / stream_s
        out[name] = {
            "apply_s": round(min(phases["apply"]), 3),
            "rebuild_s": round(min(phases["rebuild"]), 3),
            "rebuild_parts_s": {k: round(min(phases[k]), 3) for k in ("fold", "objects", "memory")},
            "batched_s": round(b, 3),
            "batched_median_s": round(statistics.median(total), 3),
            "batched_events_per_s": round(args.events / b),
            "batched_incl_columnarise_events_per_s": round(args.events / (b + col_s)),
            "streaming_s": round(stream_s, 2),
            "streaming_events_per_s": round(stream_rate),
            "speedup": round(args.events / b / stream_rate, 1),
            "speedup_incl_columnarise": round(args.events / (b + col_s) / stream_rate, 1),
            "identical_to_streaming": identical,
        }
    res = {"bench": "batched", "events": args.events, "entries": len(cols.pair), "pairs": len(cols.pairs),
           "streaming_events": n_stream, "repeat": args.repeat, "clock": "process_time",
           "generate_s": round(gen_s, 1), "columnarise_s": round(col_s, 3),
           "columnarise_events_per_s": round(args.events / col_s), "operators": out}
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

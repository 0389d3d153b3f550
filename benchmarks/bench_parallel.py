"""run_scenes: wall time of S independent scenes serially vs over a process pool (and Ray if installed).

Usage: .venv/bin/python benchmarks/bench_parallel.py [--scenes 8] [--workers 2] [--json]
"""

from __future__ import annotations

import argparse
import functools
import json
import time

import _common  # noqa: F401


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--events", type=int, default=3000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from sgbelief.eval.parallel import random_scene_summary, run_scenes

    fn = functools.partial(random_scene_summary, n_events=args.events)
    seeds = list(range(args.scenes))
    res = {"bench": "parallel", "scenes": args.scenes, "events_per_scene": args.events, "workers": args.workers}
    t0 = time.perf_counter()
    serial = run_scenes(fn, seeds, workers=1)
    res["serial_s"] = round(time.perf_counter() - t0, 2)
    t0 = time.perf_counter()
    pooled = run_scenes(fn, seeds, workers=args.workers)
    res["pool_s"] = round(time.perf_counter() - t0, 2)
    res["pool_identical"] = pooled == serial
    try:
        import ray

        t0 = time.perf_counter()
        out = run_scenes(fn, seeds, workers=args.workers, executor="ray")
        res["ray_local_s"] = round(time.perf_counter() - t0, 2)
        res["ray_identical"] = out == serial
        ray.shutdown()
    except ImportError:
        res["ray_local_s"] = None
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

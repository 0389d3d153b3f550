"""Run every benchmark, one at a time, each in its own process; write benchmarks/RESULTS.md.

Usage: .venv/bin/python benchmarks/run_all.py [--quick] [--only throughput,history,...]
Sizes are flags of the individual scripts; ``--quick`` uses small ones (smoke run). With ``--only``
the other entries of the last full run (benchmarks/results.json) are kept, each with its own command.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from _common import machine

HERE = Path(__file__).resolve().parent
FULL = {
    "throughput": ["bench_throughput.py", "--repeat", "2"],
    "history": ["bench_history.py", "--events", "1010000"],
    "memory_comod": ["bench_memory.py", "--events", "10000000", "--operator", "comod"],
    "memory_majority": ["bench_memory.py", "--events", "3000000", "--operator", "majority"],
    "large_map": ["bench_large_map.py", "--nodes", "1000000"],
    "conceptgraphs": ["bench_conceptgraphs.py", "--frames", "30"],
    "batched": ["bench_batched.py", "--events", "300000"],
    "parallel": ["bench_parallel.py", "--scenes", "8", "--workers", "2"],
    "queries": ["bench_queries.py", "--nodes", "10000"],
    "refer": ["bench_refer.py", "--nodes", "10000", "--queries", "300", "--rooms", "40"],
    "latency_comod": ["bench_latency.py", "--operator", "comod", "--intervals", "default,10"],
    "latency_majority_gc_off": ["bench_latency.py", "--operator", "majority", "--intervals", "default,10", "--gc", "off"],
}
QUICK = {
    "throughput": ["bench_throughput.py", "--repeat", "1"],
    "history": ["bench_history.py", "--events", "40000"],
    "memory_comod": ["bench_memory.py", "--events", "200000"],
    "large_map": ["bench_large_map.py", "--nodes", "10000"],
    "conceptgraphs": ["bench_conceptgraphs.py", "--frames", "2", "--sizes", "100,1000"],
    "batched": ["bench_batched.py", "--events", "50000", "--stream-events", "10000"],
    "parallel": ["bench_parallel.py", "--scenes", "4"],
    "refer": ["bench_refer.py", "--nodes", "2000", "--queries", "50", "--rooms", "8"],
    "latency_comod": ["bench_latency.py", "--events", "60000", "--pairs", "20000", "--events-per-step", "20",
                      "--intervals", "default,10"],
}


#: RESULTS.md below this line is written by hand (measurements no script here reproduces alone); kept
HAND_WRITTEN = "<!-- hand-written sections below: run_all.py keeps them -->"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", default="")
    ap.add_argument("--out", default=str(HERE / "RESULTS.md"))
    args = ap.parse_args()
    plan = QUICK if args.quick else FULL
    if args.only:
        plan = {k: v for k, v in plan.items() if k in args.only.split(",")}
    results = {}
    previous = HERE / "results.json"
    if args.only and not args.quick and previous.exists():
        results = {k: v for k, v in json.loads(previous.read_text())["results"].items() if k in FULL}
    for name, cmd in plan.items():
        full = [sys.executable, str(HERE / cmd[0]), *cmd[1:], "--json"]
        print(f"[run_all] {name}: {' '.join(cmd)}", flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run(full, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        line = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
        try:
            data = json.loads(line)
        except json.JSONDecodeError:
            data = {"error": (proc.stderr or proc.stdout)[-2000:]}
        results[name] = {"command": ".venv/bin/python benchmarks/" + " ".join(cmd), "wall_s": round(wall, 1), "result": data}
        print(f"[run_all] {name}: {wall:.1f}s", flush=True)
    m = machine()
    results = {k: results[k] for k in FULL if k in results} | {k: v for k, v in results.items() if k not in FULL}
    lines = ["# sgbelief benchmark results", "",
             f"Command: `.venv/bin/python benchmarks/run_all.py{' --quick' if args.quick else ''}`"
             + (" (entries re-run one at a time with `--only`; each entry names its command)" if args.only else ""), "",
             f"Machine: nproc={m['nproc']}, CPU: {m['cpu']}, Python {m['python']}, {m['platform']}.",
             "The machine is shared (2 cores); figures are CPU-time based where the script says so.", ""]
    for name, r in results.items():
        lines += [f"## {name}", "", f"`{r['command']}` (wall {r['wall_s']} s)", "", "```json",
                  json.dumps(r["result"], indent=1), "```", ""]
    out = Path(args.out)
    kept = out.read_text().partition(HAND_WRITTEN)[2] if out.exists() else ""
    if kept:  # the hand-written sections (ConceptGraphs harness, ...) survive a re-run
        lines += [HAND_WRITTEN + kept.rstrip("\n"), ""]
    out.write_text("\n".join(lines))
    (HERE / "results.json").write_text(json.dumps({"machine": m, "results": results}, indent=1))
    print(f"[run_all] wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

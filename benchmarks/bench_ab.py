"""Before/after streaming cost of two checkouts, interleaved (the A/B behind docs/performance.md).

Each measurement runs in its own process that imports ``sgbelief`` from one checkout, replays the
simulated outdoor stream once (warm: calibration buffer filled), then times the same stream shifted
in time with ``update(..., report=False)`` under a generation-0 GC threshold of 100,000 (the replay
setting of ``bench_throughput.py``). The cost per event is divided by the cost of a plain
dict-increment loop over the same events in the same process, so the figure ("reference units")
follows the machine's load far less than events/s do. Checkouts alternate for ``--rounds`` rounds;
the minimum and median per checkout and the speed-up (old min / new min) are reported.
``--new-mode many`` times the new checkout through one ``update_many`` call over the stream (what the
replay engine runs) instead of per-event ``update`` calls (``--old-mode`` likewise, when the old
checkout has it).

Usage: .venv/bin/python benchmarks/bench_ab.py --old /tmp/old --new . [--operators majority,comod] [--rounds 3]
       [--old-mode update|many] [--new-mode update|many]
(make the old checkout with ``git worktree add /tmp/old <rev>``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

# before any checkout is put on sys.path: _common puts this one at its front, and child() then
# puts the measured checkout in front of it
from _common import reference_pass


def child(tree: str, operator: str, repeat: int, mode: str = "update") -> float:
    """Best (cost per event / reference-loop cost per event) of ``repeat`` timed passes."""
    sys.path.insert(0, tree)
    import gc
    import time

    from sgbelief.eval.replay import make_runs, to_event
    from sgbelief.eval.simulate import simulate
    from sgbelief.fusion.compatibility import SubsumptionTable

    recs = simulate("outdoor", 0).events_for("vlm_a", "oracle")
    vocab = SubsumptionTable.shipped("kitti360")
    shift = recs[-1].t + 1
    warm = [to_event(r, f"a{i}") for i, r in enumerate(recs)]
    timed = [to_event(r._replace(t=r.t + shift), f"b{i}") for i, r in enumerate(recs)]
    clock = time.process_time

    def ref() -> float:
        return reference_pass(timed, clock)

    best = float("inf")
    for _ in range(repeat):
        run = make_runs([operator], vocab)[0]
        op, g = run.operator, run.graph
        for ev, lab in warm:
            op.update(g, ev, lab, report=False)
        upd = op.update
        gc.collect()
        old = gc.get_threshold()
        gc.set_threshold(100_000, *old[1:])
        try:
            r1 = ref()
            t0 = clock()
            if mode == "many":
                op.update_many(g, timed)
            else:
                for ev, lab in timed:
                    upd(g, ev, lab, report=False)
            dt = clock() - t0
            r2 = ref()
        finally:
            gc.set_threshold(*old)
        best = min(best, dt / max(min(r1, r2), 1e-9))
    return best


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", help="checkout of the code before")
    ap.add_argument("--new", default=str(Path(__file__).resolve().parents[1]), help="checkout after (default: this one)")
    ap.add_argument("--operators", default="overwrite,majority,naive_bayes,refined,cal,comod")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=2, help="timed passes per process (best kept)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--old-mode", choices=("update", "many"), default="update")
    ap.add_argument("--new-mode", choices=("update", "many"), default="update")
    ap.add_argument("--child", nargs=3, metavar=("TREE", "OPERATOR", "MODE"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(child(args.child[0], args.child[1], args.repeat, args.child[2]))
        return 0
    if not args.old:
        ap.error("--old is required")
    trees = {"old": str(Path(args.old).resolve()), "new": str(Path(args.new).resolve())}
    out: dict[str, dict[str, float]] = {}
    for op in args.operators.split(","):
        costs: dict[str, list[float]] = {"old": [], "new": []}
        for _ in range(args.rounds):
            for name, tree in trees.items():
                mode = args.old_mode if name == "old" else args.new_mode
                res = subprocess.run(
                    [sys.executable, __file__, "--child", tree, op, mode, "--repeat", str(args.repeat)],
                    capture_output=True, text=True, check=True,
                )
                costs[name].append(float(res.stdout.split()[-1]))
        row = {f"{k}_{stat}": round(f(v), 1) for k, v in costs.items() for stat, f in (("min", min), ("median", statistics.median))}
        row["speedup"] = round(row["old_min"] / row["new_min"], 2)
        out[op] = row
        if not args.json:
            print(f"{op:12s} old {row['old_min']:7.1f} (median {row['old_median']:7.1f})  "
                  f"new {row['new_min']:7.1f} (median {row['new_median']:7.1f})  speed-up {row['speedup']:.2f}x", flush=True)
    res = {"bench": "ab", "unit": "cost per event / reference-loop cost per event", "old": trees["old"],
           "new": trees["new"], "old_mode": args.old_mode, "new_mode": args.new_mode, "rounds": args.rounds,
           "operators": out}
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Streaming throughput per operator on the simulated outdoor stream, vs a minimal reference loop.

Each operator first replays the stream once (warm: calibration buffer filled), then the same
stream again shifted in time with new event ids, timed (process CPU time). Four settings per
operator: ``report`` (update() with its per-target report, CPython's default collector settings),
``no_report`` (report=False, default collector), ``replay`` (report=False inside
``sgbelief._fast.gc.relaxed_gc``) and ``many`` (one ``update_many`` call over the stream inside
``relaxed_gc``, as ``sgbelief replay`` / ``bench`` run it: the same per-event updates, the per-call
set-up done once). The reference loop is a plain Python loop doing one dict increment per event
over the same event objects, in the same run.

Two normalisations. ``ratio_to_ref*`` divides an operator's events/s by the fastest reference loop
of the run (timed at its start and end). ``ref_iterations_per_event`` times the reference loop
right before and right after every timed pass and divides the pass's cost per event by the faster
of the two (best pass kept, as ``bench_ab.py`` does): on a machine whose speed drifts during the
run, this one compares the operator with the reference at the same moment.

Usage: .venv/bin/python benchmarks/bench_throughput.py [--seed 0] [--repeat 3] [--operators cal,comod] [--scale 1.0] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from _common import reference_pass  # (and sys.path)


def contextlib_null():  # noqa: ANN201
    import contextlib

    return contextlib.nullcontext()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--operators", default="", help="comma-separated subset of the operators (default: all six)")
    ap.add_argument("--scale", type=float, default=None, help="scale of the simulated suite (default: the config's)")
    args = ap.parse_args()
    from sgbelief.eval.replay import make_runs, to_event
    from sgbelief.eval.simulate import simulate
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.fusion.registry import OPERATOR_NAMES

    names = [o for o in args.operators.split(",") if o] or list(OPERATOR_NAMES)
    unknown = sorted(set(names) - set(OPERATOR_NAMES))
    if unknown:
        ap.error(f"--operators: unknown operator(s) {', '.join(unknown)}; choose from {', '.join(OPERATOR_NAMES)}")
    suite = simulate("outdoor", args.seed, scale=args.scale)
    recs = suite.events_for("vlm_a", "oracle")
    vocab = SubsumptionTable.shipped("kitti360")
    shift = recs[-1].t + 1
    warm = [to_event(r, f"a{i}") for i, r in enumerate(recs)]
    timed = [to_event(r._replace(t=r.t + shift), f"b{i}") for i, r in enumerate(recs)]
    n = len(timed)
    clock = time.process_time

    def ref_pass() -> float:
        return reference_pass(timed, clock)

    def ref_loop() -> float:
        return max(n / ref_pass() for _ in range(args.repeat))

    try:
        from sgbelief._fast.gc import relaxed_gc
    except ImportError:  # an older checkout (before/after comparisons): same setting by hand
        import contextlib
        import gc

        @contextlib.contextmanager
        def relaxed_gc():  # type: ignore[no-redef]
            old = gc.get_threshold()
            gc.set_threshold(100_000, *old[1:])
            try:
                yield
            finally:
                gc.set_threshold(*old)

    ref_before = ref_loop()
    out = {}
    settings = (("events_per_s", True, False), ("events_per_s_no_report", False, False), ("events_per_s_replay", False, True),
                ("events_per_s_many", None, True))
    short = {"events_per_s": "report", "events_per_s_no_report": "no_report", "events_per_s_replay": "replay",
             "events_per_s_many": "many"}
    for name in names:
        row: dict[str, Any] = {}
        adjacent: dict[str, float] = {}
        for key, report, relaxed in settings:
            if report is None and not hasattr(make_runs([name], vocab)[0].operator, "update_many"):
                continue  # an older checkout
            best = 0.0
            best_units = float("inf")
            for _ in range(args.repeat):
                run = make_runs([name], vocab)[0]
                op, g = run.operator, run.graph
                for ev, lab in warm:
                    op.update(g, ev, lab)
                upd = op.update
                ctx = relaxed_gc() if relaxed else contextlib_null()
                with ctx:
                    r1 = ref_pass()
                    t0 = clock()
                    if report is None:
                        op.update_many(g, timed)
                    elif report:
                        for ev, lab in timed:
                            upd(g, ev, lab)
                    else:
                        for ev, lab in timed:
                            upd(g, ev, lab, report=False)
                    dt = max(clock() - t0, 1e-9)
                    r2 = ref_pass()
                best = max(best, n / dt)
                best_units = min(best_units, dt / min(r1, r2))
            row[key] = round(best)
            adjacent[short[key]] = round(best_units, 1)
        row["ref_iterations_per_event"] = adjacent
        out[name] = row
    ref = max(ref_before, ref_loop())
    for row in out.values():
        row["ratio_to_ref"] = round(row["events_per_s"] / ref, 5)
        row["ratio_to_ref_replay"] = round(row["events_per_s_replay"] / ref, 5)
        if "events_per_s_many" in row:
            row["ratio_to_ref_many"] = round(row["events_per_s_many"] / ref, 5)
    res = {"bench": "throughput", "events": n, "targets_per_event": round(sum(len(e.targets) for e, _ in timed) / n, 2),
           "reference_loop_events_per_s": round(ref), "operators": out}
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

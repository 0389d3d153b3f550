"""What the consensus calibration and the exclusive coupling cost per event, side by side in one process.

    python benchmarks/bench_consensus_cost.py [--suite outdoor] [--rounds 3] [--operator comod]
    python benchmarks/bench_consensus_cost.py --suite realistic [--detector ssd] [--channel none]

Replays one simulated stream (vlm_a, oracle channel or ``--sim-channel segmenter``; with ``--suite realistic`` a cell of the
realistic suite, by default SSD without a channel, where the consensus weighs every claim) under
the operator with the shipped default
configuration and with each mechanism of docs/method.md §8 switched off, rounds interleaved, and
prints the CPU time per event (``time.process_time``: steadier than wall time on a shared machine)
and each configuration's ratio to the one with both mechanisms off (min over rounds).
"""

from __future__ import annotations

import argparse
import time

from sgbelief.eval.benchmark import SUITES
from sgbelief.eval.replay import make_runs, replay
from sgbelief.eval.simulate import simulate
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig

CONFIGS = {
    "default (consensus + rivals)": {},
    "default, recalled verdicts forward only": {"recalled_verdicts": "unanimous"},
    "default, no recalled verdicts": {"recalled_verdicts": "none"},
    "default, posterior outcomes only": {"calibration": {"consensus": {"adjudicated_elements": "consensus"}}},
    "default, independent emission (Dawid-Skene's)": {"calibration": {"consensus": {"emission": "multinomial"}}},
    "default, silent claims weighed at arrival only": {"calibration": {"consensus": {"silent_weights": "at_arrival"}}},
    "default, contested claims refused": {"contested_labels": "refuse"},
    "consensus only": {"exclusive_evidence": "none"},
    "rivals only": {"calibration": {"consensus": {"method": "none"}}},
    "neither": {"exclusive_evidence": "none", "calibration": {"consensus": {"method": "none"}}},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--suite", default="outdoor", choices=[*sorted(SUITES), "realistic"])
    ap.add_argument("--detector", default="ssd", help="with --suite realistic: rfcn or ssd")
    ap.add_argument("--channel", default="none", help="with --suite realistic: mesh, segmenter or none")
    ap.add_argument("--sim-channel", default="oracle", choices=["oracle", "segmenter"],
                    help="with --suite indoor or outdoor: the geometric channel (default %(default)s)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--operator", default="comod")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.suite == "realistic":
        from sgbelief.eval.realistic import realistic_cell

        cell = realistic_cell(args.seed, args.detector, args.channel, "c")
        events, table = cell.events, cell.table
        label = f"realistic suite ({args.detector}, channel {args.channel})"
    else:
        events = simulate(args.suite, args.seed).events_for("vlm_a", args.sim_channel)
        table = SubsumptionTable.shipped(SUITES[args.suite].vocab)
        label = f"{args.suite} suite ({args.sim_channel} channel)"
    cost: dict[str, list[float]] = {k: [] for k in CONFIGS}
    for _ in range(args.rounds):
        for name, cfg in CONFIGS.items():
            runs = make_runs([args.operator], table, OperatorConfig.from_mapping(cfg))
            t0 = time.process_time()
            replay(events, runs)
            cost[name].append((time.process_time() - t0) / len(events) * 1e6)
    base = min(cost["neither"])
    print(f"{label}, seed {args.seed}, {len(events)} events, {args.operator}, {args.rounds} rounds "
          "(replay CPU time per event; ratio: min over rounds / min of 'neither')")
    for name, xs in cost.items():
        print(f"  {name:30s} min {min(xs):6.1f} µs  median {sorted(xs)[len(xs) // 2]:6.1f} µs  ratio {min(xs) / base:4.2f}")


if __name__ == "__main__":
    main()

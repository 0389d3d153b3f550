"""Referring queries: time per utterance on a 10,000-node map, and accuracy by relation.

Builds synthetic furnished rooms (sgbelief.eval.refer_scenes) until the map holds ``--nodes``
nodes, generates their Sr3D-style utterances (sgbelief.eval.refer_gen) and times
``refer(graph, utterance, scene=...)`` over ``--queries`` of them, three ways:

* cold: each call reads the graph into a new node table (what a plain ``refer(graph, utt)`` pays);
* warm: a node table built once (``index=NodeTable.from_graph(graph)``) serves every call;
* search: warm, without ``scene=`` (the scene is found among all rooms that hold the classes).

Then the accuracy by relation on ``--rooms`` rooms with ground-truth labels and with a comod belief
map of noisy claims (sgbelief.eval.refer_eval).

Usage:  .venv/bin/python benchmarks/bench_refer.py [--nodes 10000] [--queries 300] [--rooms 40] [--json]
Prints one result line: ``bench_refer: nodes=... cold_ms=... warm_ms=...``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=10_000)
    ap.add_argument("--queries", type=int, default=300)
    ap.add_argument("--rooms", type=int, default=40, help="rooms of the accuracy evaluation (0: skip it)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    import numpy as np

    from sgbelief.eval.refer_eval import ClaimNoise, run_referring_eval
    from sgbelief.eval.refer_gen import generate_references
    from sgbelief.eval.refer_scenes import make_room, rooms_graph
    from sgbelief.query.referring import NodeTable, refer

    rooms = []
    n = 0
    k = 0
    while n < args.nodes:
        room = make_room(f"bench{k:05d}_00", args.seed * 7919 + k, kind=k % 4)
        if n + len(room.objects) > args.nodes:
            break
        rooms.append(room)
        n += len(room.objects)
        k += 1
    graph = rooms_graph(rooms)
    for i in range(args.nodes - len(graph)):  # top up to exactly --nodes with loose boxes in the last room
        graph.add_node(f"pad{i}", bbox=((0.1 * i, 0.0, 0.0), (0.1 * i + 0.05, 0.05, 0.05)), label="box",
                       scene=rooms[-1].scene)
    refs = generate_references(rooms[:200], seed=args.seed)
    rng = np.random.default_rng(args.seed)
    pick = [refs[int(i)] for i in rng.choice(len(refs), size=min(args.queries, len(refs)), replace=False)]

    def timed(fn) -> list[float]:
        out = []
        for r in pick:
            t = time.perf_counter()
            fn(r)
            out.append(time.perf_counter() - t)
        return out

    cold = timed(lambda r: refer(graph, r.utterance, scene=r.scene))
    t = time.perf_counter()
    index = NodeTable.from_graph(graph)
    index_s = time.perf_counter() - t
    warm = timed(lambda r: refer(graph, r.utterance, scene=r.scene, index=index))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # several rooms hold the classes: the warning is expected here
        search = timed(lambda r: refer(graph, r.utterance, index=index))
    correct = sum(refer(graph, r.utterance, scene=r.scene, index=index).best == r.target for r in pick)

    def ms(xs: list[float], q: float) -> float:
        return round(1000 * float(np.quantile(xs, q)), 2)

    result = {"bench": "bench_refer", "nodes": len(graph), "scenes": len(rooms), "queries": len(pick),
              "cold_ms_median": ms(cold, 0.5), "cold_ms_p95": ms(cold, 0.95), "cold_ms_max": ms(cold, 1.0),
              "warm_ms_median": ms(warm, 0.5), "warm_ms_p95": ms(warm, 0.95), "warm_ms_max": ms(warm, 1.0),
              "search_ms_median": ms(search, 0.5), "search_ms_p95": ms(search, 0.95),
              "index_build_ms": round(1000 * index_s, 2), "cold_mean_ms": round(1000 * statistics.fmean(cold), 2),
              "timed_queries_correct": correct}
    if args.rooms > 0:
        ev = run_referring_eval(args.rooms, seed=args.seed, noise=ClaimNoise(seed=args.seed))
        result["accuracy_rooms"] = args.rooms
        result["accuracy_references"] = ev["references"]
        result["accuracy"] = {k: {kk: (round(vv, 4) if isinstance(vv, float) else vv) for kk, vv in v.items()}
                              for k, v in ev["accuracy"].items()}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"bench_refer: nodes={result['nodes']} scenes={len(rooms)} queries={len(pick)} "
              f"cold_ms={result['cold_ms_median']} (p95 {result['cold_ms_p95']}) "
              f"warm_ms={result['warm_ms_median']} (p95 {result['warm_ms_p95']}) "
              f"search_ms={result['search_ms_median']} (p95 {result['search_ms_p95']}) "
              f"correct={correct}/{len(pick)}")
        if args.rooms > 0:
            acc = result["accuracy"]
            print("accuracy (GT / belief): " + ", ".join(
                f"{k} {v['gt']:.3f}/{v['belief']:.3f} (n={v['n']})" for k, v in acc.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

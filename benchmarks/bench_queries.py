"""Queries per second for all 15 named compounds over a 10,000-node map.

Builds a synthetic map (half indoor rooms of 20 objects, half outdoor drive segments), gives every
node evidence on one or two VLM-typed predicates, then times:

* cold batch: a fresh QueryEngine answering the 15 compounds (every belief and geometric value read
  once and cached -- per-component reuse);
* warm batch: the same 15 again on the same engine (all components cached).

Usage:  .venv/bin/python benchmarks/bench_queries.py [--nodes 10000] [--repeat 3] [--json]
Prints one result line: ``bench_queries: nodes=... cold_qps=... warm_qps=...``.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def build_map(n_nodes: int, seed: int = 0):
    from sgbelief.graph.scene_graph import SceneGraphModel

    rng = random.Random(seed)
    g = SceneGraphModel()
    indoor = ["chair", "chair", "chair", "table", "desk", "bookshelf", "sofa", "window", "cabinet", "lamp"]
    outdoor = ["car", "car", "car", "person", "traffic sign", "building", "vegetation"]
    pred_of = {"chair": "is_chair", "table": "is_table_or_desk", "desk": "is_table_or_desk",
               "bookshelf": "is_bookshelf", "sofa": "is_sofa", "car": "is_car", "person": "is_pedestrian",
               "traffic sign": "is_traffic_sign"}
    decoys = ["is_chair", "is_bookshelf", "is_table_or_desk", "is_car", "is_pedestrian", "is_traffic_sign"]
    ev = 0
    for i in range(n_nodes):
        node = f"n{i:05d}"
        if i < n_nodes // 2:
            scene = f"room{i // 20:04d}"
            lab = rng.choice(indoor)
            x, y = rng.uniform(0, 6), rng.uniform(0, 6)
            w, d, h = rng.uniform(0.3, 1.5), rng.uniform(0.3, 1.0), rng.uniform(0.4, 2.0)
            z0 = 0.0 if rng.random() > 0.15 else 0.75
            g.add_node(node, bbox=((x, y, z0), (x + w, y + d, z0 + h)), label=lab, scene=scene, floor_z=0.0)
        else:
            scene = f"drive{(i - n_nodes // 2) // 50:04d}"
            lab = rng.choice(outdoor)
            x, y = rng.uniform(0, 200), rng.uniform(-10, 10)
            moving = rng.random() < 0.3
            track = [[t, x + (2.0 * t if moving else rng.gauss(0, 0.1)), y, 0.0] for t in range(5)]
            g.add_node(node, bbox=((x, y, 0), (x + 4, y + 2, 1.5)), label=lab, scene=scene, track=track,
                       road_distance_px=rng.uniform(0, 200), on_sidewalk=rng.random() < 0.4,
                       at_intersection=rng.random() < 0.3, visible_in_drive_direction=rng.random() < 0.5)
        # (distinct, in draw order: a set's order would follow the per-process string hashes)
        for pred in dict.fromkeys((pred_of.get(lab, rng.choice(decoys)), rng.choice(decoys))):
            a = rng.uniform(0, 8)
            g.provenance.record(node, pred, f"e{ev}", 0, a, 8 - a)
            ev += 1
    return g


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    from sgbelief.query import QueryEngine, named_queries

    t0 = time.perf_counter()
    g = build_map(args.nodes)
    build_s = time.perf_counter() - t0
    queries = named_queries()
    assert len(queries) == 15
    # each dataset's thresholds: group the compounds by their RelationConfig
    groups: dict[int, tuple[object, dict]] = {}
    for name, q in queries.items():
        groups.setdefault(id(q.config), (q.config, {}))[1][name] = q.compound

    cold, warm = [], []
    retrieved = {}
    reads = 0
    for _ in range(args.repeat):
        t = time.perf_counter()
        engines = []
        for cfg, comp in groups.values():
            eng = QueryEngine(g, config=cfg)
            res = eng.evaluate_many(comp)
            retrieved.update({k: len(v) for k, v in res.items()})
            engines.append((eng, comp))
        cold.append(time.perf_counter() - t)
        reads = sum(e.belief_reads for e, _ in engines)
        t = time.perf_counter()
        for eng, comp in engines:
            eng.evaluate_many(comp)
        warm.append(time.perf_counter() - t)
    best_cold, best_warm = min(cold), min(warm)
    result = {"bench": "bench_queries", "nodes": args.nodes, "compounds": 15,
              "cold_batch_s": round(best_cold, 4), "cold_qps": round(15 / best_cold, 1),
              "warm_batch_s": round(best_warm, 4), "warm_qps": round(15 / best_warm, 1),
              "belief_reads_per_batch": reads, "map_build_s": round(build_s, 2), "retrieved": retrieved}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"bench_queries: nodes={args.nodes} compounds=15 cold_batch={best_cold:.3f}s "
              f"cold_qps={15 / best_cold:.1f} warm_batch={best_warm:.3f}s warm_qps={15 / best_warm:.1f} "
              f"belief_reads={reads}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

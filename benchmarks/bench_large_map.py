"""Large maps: build an N-node graph with 3 predicates, apply N events, save, load, run the named queries.

Each step timed; save/load throughput in MB/s of the JSON file. Events use the batched majority
engine (identical result to streaming) and, for comparison, the streaming engine on 10^5 events.

Usage: .venv/bin/python benchmarks/bench_large_map.py [--nodes 1000000] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

import _common  # noqa: F401


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--nodes", type=int, default=1_000_000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    import numpy as np

    from sgbelief.eval.batched import EventColumns, batched_replay
    from sgbelief.graph.scene_graph import SceneGraph
    from sgbelief.query import QueryEngine, named_queries

    n = args.nodes
    rng = np.random.default_rng(0)
    steps = {}
    preds = ["is_car", "is_pedestrian", "is_building"]
    t0 = time.perf_counter()
    # events: one per (node, predicate) pair on average, 100 per time step
    k = rng.integers(0, 3 * n, size=n)
    conf = np.round(rng.random(n), 4)
    pair_keys = [(f"n{i:07d}", p) for i in range(n) for p in preds]
    ev_pair = k.astype(np.int64)
    cols = EventColumns(
        event_ids=[f"e{i}" for i in range(n)], event_t=(np.arange(n) // 100).astype(np.int64), predicates=preds,
        pairs=pair_keys, pair=ev_pair, event=np.arange(n, dtype=np.int64), mass=np.ones(n), conf=conf)
    steps["columns_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    g, _stats = batched_replay(cols, "majority")
    steps["events_batched_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    for i in range(n):  # geometry for the queries (nodes without evidence get bare attributes)
        node = f"n{i:07d}"
        x, y = float(i % 1000) * 0.5, float(i // 1000) * 0.5
        if node in g.nx:
            g.nx.nodes[node].update(bbox=((x, y, 0.0), (x + 0.4, y + 0.4, 1.0)), scene=f"s{i // 1000:04d}", floor_z=0.0)
        else:
            g.add_node(node, bbox=((x, y, 0.0), (x + 0.4, y + 0.4, 1.0)), scene=f"s{i // 1000:04d}", floor_z=0.0)
    steps["build_nodes_s"] = time.perf_counter() - t0
    from sgbelief.fusion.compatibility import SubsumptionTable

    # the named compounds span both shipped vocabularies: declare them (unseen pairs read as the prior)
    g.vocabulary = frozenset(SubsumptionTable.shipped("kitti360").predicates) | frozenset(
        SubsumptionTable.shipped("scannet").predicates)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "big.json")
        t0 = time.perf_counter()
        g.save(path)
        steps["save_s"] = time.perf_counter() - t0
        mb = os.path.getsize(path) / 1e6
        t0 = time.perf_counter()
        g2 = SceneGraph.load(path)
        steps["load_s"] = time.perf_counter() - t0
    assert len(g2) == len(g)
    queries = named_queries()
    groups: dict[int, tuple[object, dict]] = {}
    for name, q in queries.items():
        groups.setdefault(id(q.config), (q.config, {}))[1][name] = q.compound
    t0 = time.perf_counter()
    hits = {}
    for cfg, comp in groups.values():
        hits.update({k2: len(v) for k2, v in QueryEngine(g2, config=cfg).evaluate_many(comp).items()})
    steps["queries_s"] = time.perf_counter() - t0
    res = {"bench": "large_map", "nodes": n, "predicates": 3, "events": n, "pairs_with_evidence": len(g.provenance),
           "json_mb": round(mb, 1), "save_mb_per_s": round(mb / steps["save_s"], 1),
           "load_mb_per_s": round(mb / steps["load_s"], 1), "named_queries": len(queries),
           **{k2: round(v, 2) for k2, v in steps.items()}}
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

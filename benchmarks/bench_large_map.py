"""Large maps: an N-node graph with 3 predicates, N events, JSON and binary save/load, every named query.

Steps, each timed separately (wall seconds from ``perf_counter``; ``*_cpu_s`` is this process's
CPU time from ``process_time``, the fairer figure on a shared machine):

1. ``columns``: the event stream as columns (N events, one target each, 100 events per step);
2. ``events_batched``: the N events applied with the *batched* (numpy wave) majority engine,
   which gives the same graph and provenance as the streaming engine, compaction included;
3. ``build_nodes``: geometry (bbox, scene, floor_z) on all N nodes;
4. ``npz_save`` / ``npz_load``: the binary layout (:mod:`sgbelief.graph.binary`), its file size
   and its JSON-equivalent throughput = JSON file size / binary time (run first, on the heap the
   graph was built in). The load (the fast loader, ``sgbelief._fast.loading.FAST_LOADING``) defers
   the settled provenance entries to the first read of a log; ``npz_materialize`` (after the queries, which read beliefs only) is that first read, and
   ``npz_load_materialized_*`` counts both;
   ``objects_floor``: building the loaded graph's Python objects alone (networkx's node and
   adjacency dicts, the attribute dicts and ``bbox`` tuples, the (node, predicate) -> belief dict)
   from ready lists - no file, no decoding, no checks: what any loader that returns this
   networkx graph pays at least; ``save_floor`` (right after the save, on the same graph):
   reading every value the layout stores out of those objects into flat lists (node ids, the
   attribute values and ``bbox`` numbers, pair keys and beliefs, each entry's eight fields) - no
   arrays, no checks, no file: what any saver of this graph pays at least;
5. ``json_save`` / ``json_load``: the JSON format, MB/s of its own file;
6. every named compound query (``sgbelief.query.named``) on the binary-loaded graph, one timing
   each (queries sharing a relation config share one engine, so the first of a group also pays
   for the shared geometric relations).

Usage: .venv/bin/python benchmarks/bench_large_map.py [--nodes 1000000] [--no-json] [--verify] [--json]
(``--json`` prints one JSON line, last on stdout, for run_all.py.)
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

from _common import rss_mb


class _Steps:
    """Wall and CPU time of each step, printed as it finishes (to stderr)."""

    def __init__(self) -> None:
        self.out: dict[str, float] = {}

    def run(self, name: str, fn: Callable[[], Any]) -> Any:
        w0, c0 = time.perf_counter(), time.process_time()
        result = fn()
        self.out[f"{name}_s"] = time.perf_counter() - w0
        self.out[f"{name}_cpu_s"] = time.process_time() - c0
        print(f"  {name:<24} {self.out[f'{name}_s']:8.2f} s wall {self.out[f'{name}_cpu_s']:8.2f} s cpu   "
              f"peak RSS {rss_mb()[1]:8.0f} MB", file=sys.stderr, flush=True)
        return result


def _floor_lists(g: Any) -> tuple[list[Any], ...]:
    """The loaded graph's contents as the flat lists ``_objects_floor`` builds from, untimed (the
    beliefs read pair by pair: the deferred log entries stay unbuilt)."""
    from itertools import chain
    from operator import itemgetter

    attrs = list(map(itemgetter(1), g.nx.nodes(data=True)))
    ids = list(g.nx.nodes)
    numbers = list(chain.from_iterable(chain.from_iterable(map(itemgetter("bbox"), attrs))))
    cols = [numbers[j::6] for j in range(6)]  # bbox lo x, y, z, hi x, y, z
    keys = list(g.provenance.pairs())
    beliefs = [g.provenance.alpha_beta(*k) for k in keys]
    return (ids, cols, list(map(itemgetter("scene"), attrs)), list(map(itemgetter("floor_z"), attrs)), keys,
            [a for a, _ in beliefs], [b for _, b in beliefs])


def _save_floor(g: Any) -> tuple[list[Any], ...]:
    """Every value the binary layout stores, read out of the graph's Python objects into flat
    lists (this benchmark's node schema): the least any saver of this graph does."""
    from itertools import chain
    from operator import attrgetter, itemgetter

    nd = g.nx._node
    ids = list(nd)
    attrs = list(nd.values())
    bbox = list(map(itemgetter("bbox"), attrs))
    numbers = list(chain.from_iterable(chain.from_iterable(bbox)))
    scenes = list(map(itemgetter("scene"), attrs))
    floor_z = list(map(itemgetter("floor_z"), attrs))
    prov = g.provenance
    keys = list(prov.logs())
    logs = list(prov.logs().values())
    pair_nodes, pair_preds = list(map(itemgetter(0), keys)), list(map(itemgetter(1), keys))
    alpha, beta = list(map(attrgetter("alpha"), logs)), list(map(attrgetter("beta"), logs))
    per_pair = list(map(attrgetter("entries"), logs))
    lengths = list(map(len, per_pair))
    flat = list(chain.from_iterable(per_pair))
    fields = [list(map(attrgetter(f), flat)) for f in ("event_id", "t", "d_alpha", "d_beta", "status", "stance",
                                                       "n_folded", "corroborated_by")]
    return (ids, numbers, scenes, floor_z, pair_nodes, pair_preds, alpha, beta, lengths, *fields)


def _objects_floor(ids: list[Any], cols: list[list[float]], scenes: list[str], floor_z: list[float],
                   keys: list[tuple[Any, str]], alpha: list[float], beta: list[float]) -> Any:
    """Build the Python objects of the loaded graph from the lists, as cheaply as Python allows."""
    import networkx as nx

    from sgbelief.graph.npz_archive import young_collections_only
    from sgbelief.graph.provenance import PairLog

    n = len(ids)
    with young_collections_only():
        bbox = list(zip(zip(cols[0], cols[1], cols[2]), zip(cols[3], cols[4], cols[5])))
        attrs = [{"bbox": b, "scene": s, "floor_z": z} for b, s, z in zip(bbox, scenes, floor_z)]
        g = nx.MultiDiGraph()
        g._node.update(zip(ids, attrs))
        g._succ.update(zip(ids, [{} for _ in range(n)]))
        g._pred.update(zip(ids, [{} for _ in range(n)]))
        pairs = dict(zip(keys, map(PairLog, alpha, beta)))
    return g, pairs


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--nodes", type=int, default=1_000_000)
    ap.add_argument("--no-json", action="store_true",
                    help="skip the JSON save/load (then no JSON-equivalent MB/s is reported)")
    ap.add_argument("--verify", action="store_true", help="check graph_to_dict(loaded) == graph_to_dict(original)")
    ap.add_argument("--json", action="store_true", help="print one JSON line")
    args = ap.parse_args()
    import numpy as np

    from sgbelief._fast.batched import EventColumns, batched_replay
    from sgbelief._fast.loading import FAST_LOADING
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.graph.persistence import load_graph, save_graph
    from sgbelief.query import QueryEngine, named_queries

    wall0 = time.perf_counter()
    n = args.nodes
    steps = _Steps()
    preds = ["is_car", "is_pedestrian", "is_building"]

    def columns() -> EventColumns:
        rng = np.random.default_rng(0)
        k = rng.integers(0, 3 * n, size=n)  # one event per (node, predicate) pair on average
        conf = np.round(rng.random(n), 4)
        pair_keys = [(f"n{i:07d}", p) for i in range(n) for p in preds]
        return EventColumns(
            event_ids=[f"e{i}" for i in range(n)], event_t=(np.arange(n) // 100).astype(np.int64), predicates=preds,
            pairs=pair_keys, pair=k.astype(np.int64), event=np.arange(n, dtype=np.int64), mass=np.ones(n), conf=conf)

    cols = steps.run("columns", columns)
    g, _stats = steps.run("events_batched", lambda: batched_replay(cols, "majority"))
    cols = None  # free the stream

    def build_nodes() -> None:  # geometry for the queries (nodes without evidence get bare attributes)
        for i in range(n):
            node = f"n{i:07d}"
            x, y = float(i % 1000) * 0.5, float(i // 1000) * 0.5
            if node in g.nx:
                g.nx.nodes[node].update(bbox=((x, y, 0.0), (x + 0.4, y + 0.4, 1.0)), scene=f"s{i // 1000:04d}",
                                        floor_z=0.0)
            else:
                g.add_node(node, bbox=((x, y, 0.0), (x + 0.4, y + 0.4, 1.0)), scene=f"s{i // 1000:04d}", floor_z=0.0)

    steps.run("build_nodes", build_nodes)
    # the named compounds span both shipped vocabularies: declare them (unseen pairs read as the prior)
    g.vocabulary = frozenset(SubsumptionTable.shipped("kitti360").predicates) | frozenset(
        SubsumptionTable.shipped("scannet").predicates)
    prov = g.provenance
    res: dict[str, Any] = {
        "bench": "large_map", "nodes": n, "predicates": 3, "events": n, "engine": "batched majority",
        "pairs_with_evidence": len(prov), "log_entries": sum(len(log.entries) for log in prov.logs().values()),
        "compacted_entries": prov.n_compacted,
    }
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_TMP")) as d:
        # binary first, on the heap the graph was built in (as after a mapping run); then JSON
        bpath = os.path.join(d, "big.npz")
        steps.run("npz_save", lambda: save_graph(g, bpath))
        npz_mb = os.path.getsize(bpath) / 1e6
        prov.materialize()  # the save did (its journal is empty after the batched engine)
        steps.run("save_floor", lambda: _save_floor(g))
        g2 = steps.run("npz_load", lambda: load_graph(bpath, loading=FAST_LOADING))
        # the floor on the same heap (original and loaded graph alive: both take fresh memory)
        floor_lists = _floor_lists(g2)
        floor = steps.run("objects_floor", lambda: _objects_floor(*floor_lists))
        floor_lists = floor = None
        gc.collect()
        json_mb = None
        if not args.no_json:
            jpath = os.path.join(d, "big.json")
            steps.run("json_save", lambda: save_graph(g, jpath))
            json_mb = os.path.getsize(jpath) / 1e6
            g_json = steps.run("json_load", lambda: load_graph(jpath, loading=FAST_LOADING))
            assert len(g_json) == len(g)
            g_json = None
            gc.collect()
            res.update(json_mb=round(json_mb, 1), save_mb_per_s=round(json_mb / steps.out["json_save_s"], 1),
                       load_mb_per_s=round(json_mb / steps.out["json_load_s"], 1))
    res["npz_mb"] = round(npz_mb, 1)
    if json_mb is not None:
        for op in ("save", "load"):
            res[f"npz_{op}_json_equiv_mb_per_s"] = round(json_mb / steps.out[f"npz_{op}_s"], 1)
            res[f"npz_{op}_json_equiv_mb_per_s_cpu"] = round(json_mb / steps.out[f"npz_{op}_cpu_s"], 1)
    assert len(g2) == len(g) and len(g2.provenance) == len(prov)
    res["npz_load_deferred"] = g2.provenance.deferred
    if args.verify:
        from sgbelief.graph.persistence import graph_to_dict

        res["verified_equal"] = steps.run("verify", lambda: graph_to_dict(g2) == graph_to_dict(g))
        assert res["verified_equal"]
    g = None  # free the original before the queries
    gc.collect()
    queries = named_queries()
    engines: dict[int, Any] = {}
    query_s: dict[str, float] = {}
    hits: dict[str, int] = {}
    for name, q in queries.items():
        engine = engines.get(id(q.config))
        if engine is None:
            engine = engines[id(q.config)] = QueryEngine(g2, config=q.config)
        result = steps.run(f"query:{name}", lambda e=engine, q=q, name=name: e.evaluate(q.compound, name=name))
        query_s[name] = round(steps.out[f"query:{name}_s"], 3)
        hits[name] = len(result)
    res["named_queries"] = len(queries)
    res["queries_s"] = round(sum(steps.out[f"query:{k}_s"] for k in queries), 2)
    res["query_s"] = query_s
    res["query_hits"] = hits
    steps.run("npz_materialize", g2.provenance.materialize)
    if json_mb is not None:
        load_all = steps.out["npz_load_s"] + steps.out["npz_materialize_s"]
        res["npz_load_materialized_json_equiv_mb_per_s"] = round(json_mb / load_all, 1)
        res["objects_floor_json_equiv_mb_per_s"] = round(json_mb / steps.out["objects_floor_s"], 1)
        res["save_floor_json_equiv_mb_per_s"] = round(json_mb / steps.out["save_floor_s"], 1)
    res.update({k: round(v, 2) for k, v in steps.out.items() if not k.startswith("query:")})
    res["peak_rss_mb"] = round(rss_mb()[1])
    res["wall_s"] = round(time.perf_counter() - wall0, 1)
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

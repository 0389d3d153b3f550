"""``sgbelief inspect MAP_DIR [NODE]``: beliefs and provenance of a saved graph (JSON or binary .npz)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("map_dir", type=Path,
                   help="saved graph: a directory holding graph.json or graph.npz, or the .json / .npz file")
    p.add_argument("node", nargs="?", default=None, help="show one node's beliefs and full provenance")
    p.add_argument("--predicate", default=None, help="only this predicate (default: all)")
    p.add_argument("--json", action="store_true", help="machine-readable output (default: a text summary)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.errors import UnknownNodeError
    from sgbelief.api.scene_graph import SceneGraph

    g = SceneGraph.load(args.map_dir)
    if args.node is None:
        preds = [args.predicate] if args.predicate else g.predicates()
        summary = {
            "nodes": len(g),
            "edges": g.nx.number_of_edges(),
            "beliefs": len(g.provenance),
            "evidence_entries": g.evidence_count(),
            "pending_quarantine": sum(1 for e in g.provenance.quarantine if e.alive and e.status.value == "quarantined"),
            "pending_disagreements": sum(1 for e in g.provenance.disagreement if e.alive and e.status.value == "refused"),
            "committed": {p: len(g.committed(p)) for p in preds},
        }
        if args.json:
            print(json.dumps(summary, indent=2))
        else:
            for k, v in summary.items():
                print(f"{k:>22}: {v}")
        return 0
    node: object = args.node
    if node not in g and args.node.lstrip("-").isdigit():
        node = int(args.node)
    if node not in g:
        raise UnknownNodeError(args.node)
    out = {}
    for pred, bel in g.beliefs(node).items():
        if args.predicate and pred != args.predicate:
            continue
        lo, hi = bel.interval(0.9)
        out[pred] = {
            "alpha": bel.alpha, "beta": bel.beta, "mean": bel.mean, "interval90": [lo, hi],
            "provenance": [list(e.as_tuple()) + [e.n_folded] for e in g.provenance.entries(node, pred)],
        }
    if args.json:
        print(json.dumps({"node": node, "attributes": {k: v for k, v in g.node_attrs(node).items()}, "beliefs": out}, indent=2, default=str))
        return 0
    print(f"node {node!r}: {g.node_attrs(node)}")
    for pred, d in out.items():
        print(f"  {pred}: Beta({d['alpha']:.3f}, {d['beta']:.3f}) mean {d['mean']:.3f} 90% [{d['interval90'][0]:.3f}, {d['interval90'][1]:.3f}]")
        for eid, t, da, db, status, n in d["provenance"]:
            extra = f" (folds {n})" if n > 1 else ""
            print(f"      t={t:<6} {str(eid):<14} dα={da:+.4f} dβ={db:+.4f} {status}{extra}")
    return 0

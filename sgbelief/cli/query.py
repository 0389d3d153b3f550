"""``sgbelief query MAP_DIR "EXPR or NAME"``: ask a compound query of a saved scene graph."""

from __future__ import annotations

import argparse
import json
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", metavar="MAP_DIR",
                        help="saved graph: a directory holding graph.json or graph.npz, or a .json / .npz file")
    parser.add_argument("query", metavar="EXPR_OR_NAME",
                        help='e.g. "is_chair & is_near_window & !is_on_top_of", or a named query '
                             '("chair near window", chair_near_window; see sgbelief/configs/queries/)')
    parser.add_argument("--tau", type=float, default=0.5, help="retrieval threshold: a node is retrieved when P > tau, strictly (the commit rule of "
                             "inspect and committed()); default: %(default)s")
    parser.add_argument("--json", action="store_true", help="print the result as JSON (default: a table)")
    parser.add_argument("--top", type=int, default=None, metavar="K",
                        help="list only the K best results (the header and n_retrieved still count all; default: all)")
    parser.add_argument("--all", action="store_true",
                        help="also list candidates at or below tau (fully scored, no pruning; they are listed, not "
                             "counted as retrieved; default: only the retrieved)")
    parser.add_argument("--explain", action="store_true", help="print the per-component breakdown of each result (default: off)")
    parser.add_argument("--no-require-evidence", action="store_true",
                        help="also score nodes with no evidence on the query's belief predicates (prior 0.5; "
                             "default: only nodes with evidence)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.api.scene_graph import SceneGraph
    from sgbelief.query import run_query

    if not 0.0 <= args.tau <= 1.0:
        print(f"sgbelief query: error: --tau must be in [0, 1], got {args.tau}", file=sys.stderr)
        return 2
    graph = SceneGraph.load(args.map)
    result = run_query(graph, args.query, tau=args.tau, include_all=args.all, limit=args.top,
                       require_evidence=not args.no_require_evidence)
    if args.json:
        json.dump(result.to_dict(), sys.stdout, indent=2, default=str)
        sys.stdout.write("\n")
        return 0
    print(result.table())
    if args.explain:
        for m in result:
            print(m.explain())
    if not len(result):
        print("(no node reaches tau)")
    return 0

"""``sgbelief refer MAP_DIR "UTTERANCE"``: the one object a referring utterance names."""

from __future__ import annotations

import argparse
import json
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", metavar="MAP_DIR",
                        help="saved graph: a directory holding graph.json or graph.npz, or a .json / .npz file")
    parser.add_argument("utterance", metavar="UTTERANCE",
                        help='e.g. "select the trash can that is closest to the doors", '
                             '"facing the front of the bed, the lamp on its left" (grammar: docs/queries.md)')
    parser.add_argument("--scene", default=None, help="search this scene only (a node 'scene' value; default: the "
                        "scene that holds the utterance's classes and explains it best)")
    parser.add_argument("--json", action="store_true", help="print the answer as JSON (default: the explanation)")
    parser.add_argument("--top", type=int, default=10, metavar="K", help="candidates and anchors to list (default: %(default)s)")
    parser.add_argument("--labels-only", action="store_true",
                        help="match classes by node labels only, not by committed is_<class> beliefs (default: both)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.api.scene_graph import SceneGraph
    from sgbelief.query.referring import refer

    if args.top < 1:
        print(f"sgbelief refer: error: --top must be at least 1, got {args.top}", file=sys.stderr)
        return 2
    graph = SceneGraph.load(args.map)
    kwargs = {} if args.scene is None else {"scene": args.scene}
    answer = refer(graph, args.utterance, use_beliefs=not args.labels_only, **kwargs)
    if args.json:
        json.dump(answer.to_dict(), sys.stdout, indent=2, default=str)
        sys.stdout.write("\n")
        return 0
    print(answer.explain(top=args.top))
    return 0 if answer.best is not None else 1

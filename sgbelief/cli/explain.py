"""``sgbelief explain MAP_DIR NODE [PREDICATE]``: a belief's story, from its provenance log.

Every entry of the pair in time order (t, event id, verdict, confidence, calibrated Lambda-hat,
weight, increments, stance, status), what compaction folded (count per status and verdict, mean
Lambda-hat, time range, summed increments, first and last event id), and one sentence saying why
the pair is or is not committed (P > tau, strictly). ``--json`` prints the same data.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from sgbelief.graph.story import STORY_KEY, render_story


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("map_dir", type=Path,
                   help="saved graph: a directory holding graph.json or graph.npz, or the .json / .npz file")
    p.add_argument("node", help="the node id")
    p.add_argument("predicate", nargs="?", default=None,
                   help="the predicate (default: every predicate with evidence on the node)")
    p.add_argument("--tau", type=float, default=0.5,
                   help="commit threshold: committed iff P > tau, strictly (default 0.5)")
    p.add_argument("--limit", type=int, default=40,
                   help="show at most this many live events per predicate in the text output, the "
                        "first and last halves (default 40; 0 = all); --json always lists all")
    p.add_argument("--json", action="store_true", help="machine-readable output, the same data (default: a text story)")


def _node_id(graph: Any, raw: str) -> Any:
    from sgbelief.errors import UnknownNodeError

    if raw in graph:
        return raw
    if raw.lstrip("-").isdigit() and int(raw) in graph:
        return int(raw)
    raise UnknownNodeError(raw)


#: the key under the tables (kept here for callers of the command module)
LEGEND = STORY_KEY


def render(story: Any, limit: int) -> list[str]:
    """The text lines of one story (:func:`sgbelief.graph.story.render_story`)."""
    return render_story(story, limit)


def _notes(stories: list[Any]) -> str:
    return max((s.not_recorded for s in stories), key=len)


def run(args: argparse.Namespace) -> int:
    from sgbelief.api.scene_graph import SceneGraph

    if not 0.0 <= args.tau <= 1.0:
        print(f"sgbelief explain: error: --tau must be in [0, 1], got {args.tau}", file=sys.stderr)
        return 2
    graph = SceneGraph.load(args.map_dir)
    node = _node_id(graph, args.node)
    if args.predicate is not None:
        graph.check_predicate(args.predicate)
        predicates = [args.predicate]
    else:
        predicates = sorted(graph.provenance.predicates_of(node))
    stories = [graph.explain(node, p, tau=args.tau) for p in predicates]
    if args.json:
        print(json.dumps({"node": node, "stories": [s.to_dict() for s in stories]}, indent=2, ensure_ascii=False))
        return 0
    if not stories:
        print(f"node {node!r} has no evidence on any predicate (every belief is the prior)")
        return 0
    for story in stories:
        print("\n".join(render(story, args.limit)))
    print(f"key: {LEGEND}.")
    print(f"note: {stories[-1].not_recorded if len(stories) == 1 else _notes(stories)}.")
    return 0

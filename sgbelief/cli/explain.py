"""``sgbelief explain MAP_DIR NODE [PREDICATE]``: a belief's story, from its provenance log.

Every entry of the pair in time order (event id, t, status, increments), what compaction folded
(count per status, time range, summed increments, first and last event id), and one sentence
saying why the pair is or is not committed (P > tau, strictly). ``--json`` prints the same data.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any


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


def _fmt_event(e: Any) -> str:
    verdict = e.verdict or "·"
    counted = "" if e.counted else "  (not counted)"
    corr = f"  corroborated by {', '.join(e.corroborated_by)}" if e.corroborated_by else ""
    return (f"    t={e.t:<7} {str(e.event_id):<16} {e.status:<11} {verdict}  dα={e.d_alpha:+.4f} "
            f"dβ={e.d_beta:+.4f}  {e.stance}{counted}{corr}")


def render(story: Any, limit: int) -> list[str]:
    """The text lines of one story."""
    from sgbelief.graph.story import count_phrase

    lines = [f"{story.node!r} {story.predicate}: Beta({story.alpha:.3f}, {story.beta:.3f}), "
             f"P = {story.probability:.3f}; {count_phrase(story.counts)}"]
    f = story.folded
    if f is not None:
        span = f"t={f.t_first}..{f.t_last}" if f.t_first is not None else f"up to t={f.t_last}"
        ids = (f"first {f.first_event_id}, last {f.last_event_id}" if f.first_event_id is not None
               else "event ids not recorded")
        lines.append(f"  compacted ({span}): {count_phrase(f.counts)}")
        lines.append(f"    counted sum dα={f.d_alpha:+.4f} dβ={f.d_beta:+.4f}; {ids}")
    events = story.events
    if events:
        lines.append(f"  live events ({len(events)}, time order; verdict ⊥ or · = not recorded):")
        if limit and len(events) > limit:
            head, tail = events[: limit // 2], events[-(limit - limit // 2):]
            lines += [_fmt_event(e) for e in head]
            lines.append(f"    ... {len(events) - len(head) - len(tail)} more (--limit 0 or --json for all)")
            lines += [_fmt_event(e) for e in tail]
        else:
            lines += [_fmt_event(e) for e in events]
    lines.append(f"  {story.sentence}")
    return lines


def run(args: argparse.Namespace) -> int:
    from sgbelief.api.scene_graph import SceneGraph
    from sgbelief.graph.story import NOT_RECORDED

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
    print(f"note: {NOT_RECORDED}.")
    return 0

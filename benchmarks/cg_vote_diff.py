"""Where the backend's labels differ from ConceptGraphs' vote in ConceptGraphs' own loop, and why.

    SGBELIEF_CONCEPTGRAPH_PATH=<concept-graphs, main or ali-dev> PYTHONPATH=$PWD \\
        python benchmarks/cg_vote_diff.py --seeds 0-9 [--confidences uniform|rfcn|ssd|low|low_informative|straddle] \\
        [--score-map N] [--channel none] [--vote-run] --out runs.jsonl
    python benchmarks/cg_vote_diff.py --summarise runs.jsonl [more.jsonl ...]

Per seed, one run of the harness (``cg_harness.run``) with the backend as the README builds it;
every final map object is written with its own detections' classes (``class_id``, ConceptGraphs'
vote), the classes of the claims routed to it, its beliefs and its provenance entries (mass,
confidence, frame), so that label rules can be compared on the same runs afterwards.

ConceptGraphs' vote is recomputed from each object's ``class_id`` list with the branch's own tie
rule: ``main``'s ``get_most_common_class`` (``np.unique`` + ``argmax``: ties to the lowest class
id), ``ali-dev``'s ``Counter(...).most_common(1)`` (ties to the first seen). ``--vote-run`` also
runs the loop without the backend and checks that the map (each object's ground truth) and the
vote are the same as recomputed.

``--summarise`` prints, per file, the mean label accuracy of the vote, of the vote with its ties
broken at random (expected value: a tied object counts 1/k when its class is among the k tied), of
the vote with its ties broken the other way (the highest class id on main, the last seen on
ali-dev), and of the backend; then the objects whose labels differ, by the reason the backend's
summary gives (``unknown``, ``tie``, ``split``, ``ranking``; ``LabelReader.summary``), with how
many of them each side labels right; then, for records that carry the rooms' score readings, the
rooms whose rank test read the scores (seed, p-value, backend minus vote) and the mean difference
to the vote over the rooms counted.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

WHY = ("unknown", "tie", "split", "ranking")


def parse_seeds(text: str) -> list[int]:
    seeds: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        seeds += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return seeds


def vote(class_names: list[str], branch: str, classes: list[str], reverse: bool = False) -> str:
    """ConceptGraphs' vote over an object's detections, with the branch's tie rule (or the other way)."""
    counts = Counter(class_names)
    top_n = max(counts.values())
    tied = [c for c in counts if counts[c] == top_n]  # first-seen order
    if branch == "main":
        return (max if reverse else min)(tied, key=classes.index)
    return tied[-1] if reverse else tied[0]


def run(args: argparse.Namespace) -> None:
    import numpy as np

    import cg_harness as H

    H.CONFIDENCES[0] = args.confidences
    world = H.render_world(n_frames=args.frames)
    cg = H.import_conceptgraph(args.cg)
    branch = cg[3]
    captured: dict[str, list] = {}
    labels_of = H._labels

    def capture(objects, gen, classes):  # the final map objects, as the harness labels them
        captured["objects"] = list(objects)
        return labels_of(objects, gen, classes)

    H._labels = capture
    with open(args.out, "a") as out:
        for seed in parse_seeds(args.seeds):
            t0 = time.perf_counter()
            rec: dict = {"seed": seed, "branch": branch, "confidences": args.confidences, "channel": args.channel,
                         "frames": args.frames, "classes": world.classes}
            cmap = None
            if args.score_map:
                from sgbelief.calibration.scores import ScoreCalibration

                cmap = ScoreCalibration.fit(*H.annotated_detections(world, args.score_map, seed))
            rec["score_map"] = args.score_map
            backend = H.make_backend("comod", H.make_channel(world, args.channel), confidence_map=cmap)
            backend.print_summary = False
            r = H.run(world, cg, args.cg, backend=backend, seed=seed)
            objects = captured["objects"]
            rec["acc"], rec["labels"] = r.accuracy, r.labels
            rec["truth"] = [world.objects[t][0] if t >= 0 else None for t in r.truth]
            # how the room read its scores: the rank test's p-value and whether the scores are read
            rec["readings"] = {ctx: {"p": r.p_value, "reads_scores": r.reads_scores, "claims": r.claims}
                               for ctx, r in backend.operator.score_readings(backend.graph).items()}
            rec["why"] = {d["node"]: d["why"] for d in r.summary.differing}
            rec["vote_labels"] = [vote([world.classes[int(c)] for c in o["class_id"]], branch, world.classes)
                                  for o in objects]
            if args.vote_run:
                v = H.run(world, cg, args.cg, seed=seed)
                if v.truth != r.truth or v.labels != rec["vote_labels"]:
                    raise SystemExit(f"seed {seed}: the run without the backend made another map or vote")
                rec["vote_run_checked"] = True
            prov = backend.graph.provenance
            rec["objects"] = []
            for o in objects:
                node = backend.node_of(o)
                item: dict = {"class_ids": [world.classes[int(c)] for c in o["class_id"]], "node": str(node)}
                if node is not None and node in backend.graph:
                    item["routed"] = {n: k for (_, n), k in backend._names_per_node.get(node, Counter()).items()}
                    item["beliefs"] = {p: (b.alpha, b.beta) for p, b in backend.graph.beliefs(node).items()}
                    item["entries"] = {p: [(e.d_alpha, e.d_beta, e.status.value, e.confidence, e.t, int(e.verdict))
                                           for e in prov.entries(node, p)] for p in backend._predicates_of(node)}
                rec["objects"].append(item)
            acc_v = float(np.mean([a == b for a, b in zip(rec["vote_labels"], rec["truth"])]))
            out.write(json.dumps(rec) + "\n")
            out.flush()
            print(f"[{branch}] seed {seed} {args.confidences}/{args.channel}: vote {acc_v:.3f} comod {r.accuracy:.3f} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)


def why_differs(obj: dict, written: str) -> str:
    """The reason the backend's summary gives (``LabelReader.summary``), from a written record."""
    if written == "unknown":
        return "unknown"
    counts = Counter(obj["class_ids"])
    if counts.get(written, 0) == max(counts.values()):
        return "tie"
    if dict(counts) != obj.get("routed", {}):
        return "split"
    return "ranking"


def summarise(paths: list[str]) -> None:
    import cg_harness as H

    for path in paths:
        recs = [json.loads(line) for line in open(path)]
        for rec in recs:
            rec.setdefault("classes", H.CLASSES)
            rec.setdefault("vote_labels", [vote(o["class_ids"], rec["branch"], rec["classes"]) for o in rec["objects"]])
        acc: dict[str, list[float]] = defaultdict(list)
        why: dict[str, Counter] = defaultdict(Counter)
        for rec in recs:
            truth, n = rec["truth"], len(rec["truth"])
            fair = other = 0.0
            for k, o in enumerate(rec["objects"]):
                counts = Counter(o["class_ids"])
                top_n = max(counts.values())
                tied = [c for c in counts if counts[c] == top_n]
                fair += (truth[k] in tied) / len(tied)
                other += vote(o["class_ids"], rec["branch"], rec["classes"], reverse=True) == truth[k]
            acc["vote"].append(sum(a == b for a, b in zip(rec["vote_labels"], truth)) / n)
            acc["vote, ties at random"].append(fair / n)
            acc["vote, ties the other way"].append(other / n)
            acc["comod"].append(rec["acc"])
            for k, o in enumerate(rec["objects"]):
                if rec["labels"][k] == rec["vote_labels"][k]:
                    continue
                reason = why_differs(o, rec["labels"][k])
                why[reason]["objects"] += 1
                why[reason]["vote right"] += rec["vote_labels"][k] == truth[k]
                why[reason]["comod right"] += rec["labels"][k] == truth[k]
        first = recs[0]
        seeds = sorted(r["seed"] for r in recs)
        print(f"{path}: {first['branch']}, confidences {first['confidences']}, channel {first['channel']}, "
              f"{len(recs)} seeds ({seeds[0]}-{seeds[-1]})")
        base = sum(acc["vote"]) / len(recs)
        for name, xs in acc.items():
            m = sum(xs) / len(xs)
            print(f"  {name:<26} {m:.3f}  ({m - base:+.3f})")
        for reason in WHY:
            c = why.get(reason)
            if c:
                print(f"  differ, {reason:<8} {c['objects']:4d} objects: vote right {c['vote right']}, "
                      f"comod right {c['comod right']}")
        read = [k for k, r in enumerate(recs) if any(v["reads_scores"] for v in r.get("readings", {}).values())]
        if any("readings" in r for r in recs):
            print(f"  scores read in {len(read)} of {len(recs)} rooms" + (
                " (seed, rank test p, comod - vote: " + ", ".join(
                    f"{recs[k]['seed']} {min(v['p'] for v in recs[k]['readings'].values()):.3f} "
                    f"{acc['comod'][k] - acc['vote'][k]:+.3f}" for k in read) + ")" if read else ""))
            counted = [k for k in range(len(recs)) if k not in read]
            if counted:
                gap = sum(acc["comod"][k] - acc["vote"][k] for k in counted) / len(counted)
                fair = sum(acc["comod"][k] - acc["vote, ties at random"][k] for k in counted) / len(counted)
                print(f"  counted rooms: comod - vote {gap:+.3f}, comod - vote with ties at random {fair:+.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cg", default=os.environ.get("SGBELIEF_CONCEPTGRAPH_PATH"))
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--frames", type=int, default=60)
    from cg_harness import CONFIDENCE_CHOICES

    ap.add_argument("--confidences", default="uniform", choices=CONFIDENCE_CHOICES)
    ap.add_argument("--score-map", type=int, default=0, metavar="N",
                    help="confidence_map=ScoreCalibration on N annotated detections (bench_cg_harness.py --score-map)")
    ap.add_argument("--channel", default="none", choices=["none", "oracle", "segmenter"])
    ap.add_argument("--vote-run", action="store_true", help="also run without the backend and check the vote")
    ap.add_argument("--out", default=None, help="append one JSON line per seed here")
    ap.add_argument("--summarise", nargs="+", default=None, metavar="JSONL")
    args = ap.parse_args(argv)
    if args.summarise:
        summarise(args.summarise)
        return 0
    if not args.cg or not args.out:
        ap.error("pass --cg (or set SGBELIEF_CONCEPTGRAPH_PATH) and --out, or --summarise")
    run(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

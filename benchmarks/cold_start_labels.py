"""Labels without a geometric channel: comod's cold start against the majority vote.

With no geometric channel the calibrator never sees an outcome, so ``comod`` fuses each claim at
the cold-start rule (``calibration.cold_start: raw``, Lambda = c / (1 - c), at weight kappa_min)
and the label is the committed predicate with the highest belief. That weighs a claim by its
confidence; the vote counts claims. Which is better depends on whether the confidence carries
information, so both kinds of stream are drawn here:

* ``real``: each claim is a record of the real detector confidences shipped in
  ``sgbelief/data/detector_confidences`` (COCO val, netcal records): a matched record claims the
  object's class at its score, an unmatched one a wrong class (one of ``--wrong`` others) at its score;
* ``uninformative``: the ConceptGraphs harness's detector: wrong with probability U(0.15, 0.75) per
  object (70 % of wrong claims name one confuser), confidence U(0.55, 0.97) whether right or wrong.

Per object, n claims (``--claims``), each one EvidenceEvent on its own node, operator ``comod``
(shipped default, fast engine, no channel). The vote breaks ties uniformly (counted fractionally).

    python benchmarks/cold_start_labels.py [--objects 3000] [--claims 3,6,12] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sgbelief.api.operators import make_operator  # noqa: E402
from sgbelief.fusion.events import EvidenceEvent  # noqa: E402
from sgbelief.graph.scene_graph import SceneGraphModel  # noqa: E402
from sgbelief.resources import data_path  # noqa: E402


def real_claims(rng: np.random.Generator, scores: np.ndarray, matched: np.ndarray, n: int, wrong: int) -> list:
    idx = rng.integers(0, len(scores), n)
    return [(0 if matched[i] else int(rng.integers(1, wrong + 1)), float(scores[i])) for i in idx]


def uninformative_claims(rng: np.random.Generator, n: int, wrong: int) -> list:
    err = rng.uniform(0.15, 0.75)
    out = []
    for _ in range(n):
        if rng.random() < err:
            k = 1 if rng.random() < 0.7 else int(rng.integers(2, wrong + 1))
        else:
            k = 0
        out.append((k, float(rng.uniform(0.55, 0.97))))
    return out


def accuracies(streams: list[list[tuple[int, float]]]) -> tuple[float, float]:
    """(vote accuracy, comod accuracy) over objects whose truth is class 0."""
    op = make_operator("comod")
    g = SceneGraphModel(create_nodes=True)
    t = 0
    for j, claims in enumerate(streams):
        for k, c in claims:
            op.update(g, EvidenceEvent({f"o{j}": 1.0}, f"is_c{k}", c, "detector", t, f"e{t}"), report=False)
            t += 1
    vote = comod = 0.0
    for j, claims in enumerate(streams):
        counts: dict[int, int] = {}
        for k, _ in claims:
            counts[k] = counts.get(k, 0) + 1
        top = max(counts.values())
        tied = [k for k, v in counts.items() if v == top]
        vote += (0 in tied) / len(tied)
        beliefs = {p: b.mean for p, b in g.beliefs(f"o{j}").items() if b.mean > 0.5}
        if beliefs:
            best = max(beliefs.values())
            winners = [p for p, m in beliefs.items() if m == best]
            comod += ("is_c0" in winners) / len(winners)
    return vote / len(streams), comod / len(streams)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", type=int, default=3000)
    ap.add_argument("--claims", default="3,6,12")
    ap.add_argument("--wrong", type=int, default=3, help="wrong classes an unmatched real record may name")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    print("| stream | claims per object | majority vote | comod (no channel) |")
    print("|---|---|---|---|")
    for name in ("rfcn-resnet-101-iou-0.60", "ssd-resnet-50-v1-iou-0.60", "uninformative"):
        if name != "uninformative":
            with np.load(data_path("detector_confidences", f"{name}.npz")) as d:
                scores, matched = d["score"].astype(float), d["matched"].astype(bool)
        for n in (int(x) for x in args.claims.split(",")):
            if name == "uninformative":
                streams = [uninformative_claims(rng, n, 13) for _ in range(args.objects)]
            else:
                streams = [real_claims(rng, scores, matched, n, args.wrong) for _ in range(args.objects)]
            v, c = accuracies(streams)
            print(f"| {name} | {n} | {v:.3f} | {c:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Referring-query accuracy by relation: ground-truth labels, and labels from a ``comod`` replay of
noisy detector claims.

``evaluate_referring(rooms, references)`` answers every generated utterance with
:func:`sgbelief.query.refer` twice: on the rooms' graph with ground-truth labels, and on a belief
map with no labels at all, whose classes come from claims replayed through a fusion operator
(``comod`` by default). The claims (:func:`noisy_claims`): each object gets ``claims_per_object``
claims ``is_<class>``; each names the true class with probability ``p_correct``, else another
class of the same room; confidences are drawn higher for correct claims than for wrong ones; a
geometric channel reports the true label with probability ``channel_rate`` (else nothing).
An answer is correct when ``best`` is the generated target.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sgbelief.eval.refer_gen import Reference, generate_references
from sgbelief.eval.refer_scenes import Room, make_rooms, rooms_graph

__all__ = ["ClaimNoise", "ReferAccuracy", "evaluate_referring", "noisy_belief_map", "render_accuracy", "run_referring_eval"]


@dataclass(frozen=True)
class ClaimNoise:
    """The noisy detector and channel of the belief-map evaluation."""

    claims_per_object: int = 4
    p_correct: float = 0.75
    channel_rate: float = 0.8
    operator: str = "comod"
    seed: int = 0


@dataclass
class ReferAccuracy:
    """Correct / total per relation, for ground-truth labels and for the belief map."""

    total: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    correct_gt: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    correct_belief: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    with_distractors: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    correct_gt_distractors: dict[str, int] = field(default_factory=lambda: defaultdict(int))

    def add(self, ref: Reference, gt_ok: bool, belief_ok: bool | None) -> None:
        for key in (ref.relation.value, "view-dependent" if ref.view_dependent else "view-independent", "all"):
            self.total[key] += 1
            self.correct_gt[key] += int(gt_ok)
            if belief_ok is not None:
                self.correct_belief[key] += int(belief_ok)
            if ref.n_distractors > 0:
                self.with_distractors[key] += 1
                self.correct_gt_distractors[key] += int(gt_ok)

    def rate(self, key: str, which: str = "gt") -> float:
        n = self.total.get(key, 0)
        if which == "gt_distractors":
            n = self.with_distractors.get(key, 0)
            return self.correct_gt_distractors.get(key, 0) / n if n else float("nan")
        hits = self.correct_gt if which == "gt" else self.correct_belief
        return hits.get(key, 0) / n if n else float("nan")

    def as_dict(self) -> dict[str, Any]:
        keys = sorted(self.total, key=_order)
        return {k: {"n": self.total[k], "gt": self.rate(k, "gt"), "belief": self.rate(k, "belief"),
                    "n_with_distractors": self.with_distractors.get(k, 0),
                    "gt_with_distractors": self.rate(k, "gt_distractors")} for k in keys}


_ORDER = ["closest", "farthest", "between", "on", "supporting", "above", "below", "left", "right", "front", "back",
          "view-independent", "view-dependent", "all"]


def _order(k: str) -> int:
    return _ORDER.index(k) if k in _ORDER else len(_ORDER)


def noisy_belief_map(rooms: Sequence[Room], noise: ClaimNoise) -> Any:
    """A belief map of the rooms: boxes and scenes, no labels; class beliefs from noisy claims
    replayed through ``noise.operator``."""
    from sgbelief.api.operators import make_operator
    from sgbelief.fusion.channel import DictChannel
    from sgbelief.fusion.compatibility import normalise_class_name
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.fusion.open_vocab import derive_table

    rng = np.random.default_rng(noise.seed)
    classes = sorted({o.label for r in rooms for o in r.objects})
    table = derive_table(classes, taxonomy=None)
    graph = rooms_graph(rooms, labels=False)
    op = make_operator(noise.operator, vocabulary=table)
    t = 0
    k = 0
    for room in rooms:
        labels = sorted({o.label for o in room.objects})
        truth = {o.id: o.label for o in room.objects}
        channel = DictChannel({n: (lab if rng.random() < noise.channel_rate else None) for n, lab in truth.items()})
        for _ in range(noise.claims_per_object):
            for o in room.objects:
                correct = rng.random() < noise.p_correct
                cls = o.label if correct else labels[int(rng.integers(len(labels)))]
                conf = float(rng.uniform(0.55, 0.95) if cls == o.label else rng.uniform(0.35, 0.8))
                event = EvidenceEvent(targets={o.id: 1.0}, predicate=f"is_{normalise_class_name(cls)}",
                                      confidence=conf, context="detector", t=t, id=f"c{k}")
                op.update(graph, event, channel, report=False)
                k += 1
            t += 1
    return graph


def evaluate_referring(rooms: Sequence[Room], references: Sequence[Reference], *,
                       noise: ClaimNoise | None = ClaimNoise()) -> tuple[ReferAccuracy, list[dict[str, Any]]]:
    """Accuracy by relation; also the failures (utterance, truth, answers) for inspection."""
    from sgbelief.query.referring import NodeTable, refer

    gt_graph = rooms_graph(rooms)
    gt_index = NodeTable.from_graph(gt_graph)
    belief_index = None
    if noise is not None:
        belief_graph = noisy_belief_map(rooms, noise)
        belief_index = NodeTable.from_graph(belief_graph)
    acc = ReferAccuracy()
    failures = []
    for ref in references:
        gt = refer(gt_graph, ref.utterance, scene=ref.scene, index=gt_index)
        b_ok = None
        b_best = None
        if belief_index is not None:
            b_best = refer(belief_index.graph, ref.utterance, scene=ref.scene, index=belief_index).best
            b_ok = b_best == ref.target
        acc.add(ref, gt.best == ref.target, b_ok)
        if gt.best != ref.target or b_ok is False:
            failures.append({"scene": ref.scene, "utterance": ref.utterance, "relation": ref.relation.value,
                             "target": ref.target, "gt_answer": gt.best, "belief_answer": b_best})
    return acc, failures


def render_accuracy(acc: ReferAccuracy, title: str = "Referring queries (synthetic rooms)") -> str:
    """A Markdown table: relation, n, accuracy with ground-truth labels (also over references with
    same-class distractors), accuracy on the belief map, and their ratio."""
    lines = [f"### {title}", "",
             "| relation | n | GT labels | GT, with distractors (n) | belief map (comod) | belief / GT |",
             "|---|---:|---:|---:|---:|---:|"]
    for key, row in acc.as_dict().items():
        ratio = row["belief"] / row["gt"] if row["gt"] and row["gt"] == row["gt"] else float("nan")
        lines.append(f"| {key} | {row['n']} | {row['gt']:.3f} | {row['gt_with_distractors']:.3f} "
                     f"({row['n_with_distractors']}) | {row['belief']:.3f} | {ratio:.3f} |")
    return "\n".join(lines)


def run_referring_eval(n_rooms: int = 40, seed: int = 0, noise: ClaimNoise | None = None) -> dict[str, Any]:
    """Generate ``n_rooms`` rooms and their references, evaluate, and return the table and numbers."""
    rooms = make_rooms(n_rooms, seed=seed)
    refs = generate_references(rooms, seed=seed)
    acc, failures = evaluate_referring(rooms, refs, noise=noise if noise is not None else ClaimNoise(seed=seed))
    return {"rooms": n_rooms, "seed": seed, "references": len(refs), "accuracy": acc.as_dict(),
            "table": render_accuracy(acc), "failures": failures}

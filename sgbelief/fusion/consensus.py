"""The map-wide consensus behind the calibration of claims the geometric channel cannot adjudicate.

A :class:`MapConsensus` belongs to one map (one provenance store) and holds

* the claim table: every claim of an exclusive class the operator applied (element, predicate,
  context, confidence, its calibration cell, whether the channel adjudicated it, event id);
* the labels the geometric channel gave, once per (element, time);
* per element, the claims each exclusive class received so far (a claim's standing,
  :func:`~sgbelief.fusion.rules.standing`).

Every so often (at least ``every`` new claims and ``growth`` times the claims held, so O(log n)
refits over a stream) it refits, in one batch over the whole table:

1. a Dawid–Skene model (:class:`~sgbelief.calibration.dawid_skene.DawidSkene`): the latent class
   of each element among the exclusive classes plus "none of these", a confusion per worker,
   where a worker is a claim's context and its confidence bin (by rank within the context, so the
   model is invariant under a monotone transform of the confidences), the element's support (how
   many claims it received, bucketed: stray detections on clutter are rarely repeated) or the
   geometric channel, whose every label (``otherprop`` included) is an observation with a learned
   confusion;
2. the consensus outcome of each silent claim, q_v(phi), and from those the per-cell isotonic
   calibration (:class:`~sgbelief.calibration.consensus.ConsensusCalibration`).

The operator asks :meth:`MapConsensus.likelihood_ratio` for a silent claim's (Lambda_hat,
kappa_hat); until the first refit it answers None and the operator uses §4.1's calibrator as before.
Per-event work is O(1): appending a row and two dictionary updates.
"""

from __future__ import annotations

from array import array
from collections.abc import Hashable, Mapping
from typing import Any

import numpy as np

from sgbelief.calibration.config import CalibrationConfig
from sgbelief.calibration.consensus import ConsensusCalibration
from sgbelief.calibration.dawid_skene import DawidSkene

__all__ = ["MapConsensus", "GEOMETRIC_WORKER", "SUPPORT_WORKER", "support_bucket"]

#: the Dawid–Skene worker name of the geometric channel
GEOMETRIC_WORKER = "<geometric>"
#: the Dawid–Skene worker whose label is how many claims an element received (its support)
SUPPORT_WORKER = "<support>"
#: support buckets: 1, 2, 3, 4-5, 6-9, 10+ claims
_SUPPORT_EDGES = (1, 2, 3, 4, 6, 10)


def support_bucket(n: int) -> int:
    """The support observation of an element with ``n`` claims: the index of its bucket 1, 2, 3, 4-5, 6-9, 10+."""
    b = 0
    for i, edge in enumerate(_SUPPORT_EDGES):
        if n >= edge:
            b = i
    return b


class MapConsensus:
    """Claim table, channel labels and the consensus calibration of one map (see the module docstring)."""

    def __init__(self, config: CalibrationConfig, exclusive: frozenset[str],
                 asserted: Mapping[str, tuple[str, ...]] | None = None) -> None:
        cc = config.consensus
        self.every, self.growth, self.bins = cc.every, cc.growth, cc.bins
        self.exclusive = exclusive
        #: label -> the predicates it asserts (the vocabulary's positive sets): a label's initial vote
        self.asserted = asserted or {}
        self._ds = DawidSkene(n_iter=cc.n_iter, smoothing=cc.smoothing, none_class=True)
        self.calibration = ConsensusCalibration(config.target_size, config.kappa_min, config.lr_max, config.cold_start)
        # the claim table, as parallel lists (appended per claim)
        # (strings interned, floats and flags in typed arrays: about 60 bytes a claim)
        self.node: list[Any] = []
        self.pred: list[str] = []
        self.ctx: list[str] = []
        self.conf = array("d")
        self.cell: list[Hashable] = []
        self.decisive = bytearray()
        self.event: list[str] = []
        self.mass = array("d")
        self._interned: dict[Hashable, Hashable] = {}
        #: the channel's labels: (element, label) per (element, time) seen
        self.labels: dict[tuple[Any, int], str] = {}
        #: element -> {exclusive predicate: claims so far}
        self.counts: dict[Any, dict[str, int]] = {}
        self.n_at_fit = 0
        self.n_fits = 0

    # ------------------------------------------------------------------ per claim
    def standing_counts(self, node: Any, predicate: str, rivals: frozenset[str]) -> tuple[int, int, int]:
        """(claims of ``predicate`` at ``node``, claims of its rivals there, the most any rival has)."""
        held = self.counts.get(node)
        if not held:
            return 0, 0, 0
        n_others = max_other = 0
        for p, n in held.items():
            if p in rivals:
                n_others += n
                if n > max_other:
                    max_other = n
        return held.get(predicate, 0), n_others, max_other

    def add_claim(self, node: Any, predicate: str, context: str, confidence: float, cell: Hashable,
                  decisive: bool, event_id: str, mass: float = 1.0) -> None:
        """Append one applied claim of an exclusive class (``mass``: its targeting mass T(v))."""
        intern = self._interned.setdefault
        self.mass.append(mass)
        self.node.append(node)
        self.pred.append(intern(predicate, predicate))  # type: ignore[arg-type]
        self.ctx.append(intern(context, context))  # type: ignore[arg-type]
        self.conf.append(confidence)
        self.cell.append(intern(cell, cell))
        self.decisive.append(1 if decisive else 0)
        self.event.append(event_id)
        held = self.counts.get(node)
        if held is None:
            held = self.counts[node] = {}
        held[predicate] = held.get(predicate, 0) + 1

    def add_label(self, node: Any, t: int, label: str) -> None:
        """The channel labelled ``node`` ``label`` at time ``t`` (kept once per (node, t))."""
        self.labels[(node, t)] = label

    def drop_events(self, event_ids: set[str]) -> None:
        """Forget the claims of retracted events (the next refit no longer sees them)."""
        keep = [i for i, e in enumerate(self.event) if e not in event_ids]
        if len(keep) == len(self.event):
            return
        for name in ("node", "pred", "ctx", "cell", "event"):
            col = getattr(self, name)
            setattr(self, name, [col[i] for i in keep])
        self.conf = array("d", [self.conf[i] for i in keep])
        self.mass = array("d", [self.mass[i] for i in keep])
        self.decisive = bytearray(self.decisive[i] for i in keep)
        self.counts = {}
        for node, pred in zip(self.node, self.pred):
            held = self.counts.setdefault(node, {})
            held[pred] = held.get(pred, 0) + 1

    # ------------------------------------------------------------------ batches
    def due(self) -> bool:
        """Whether enough claims arrived since the last refit: max(every, growth * held) new ones."""
        n = len(self.node)
        return n - self.n_at_fit >= max(self.every, self.growth * self.n_at_fit)

    @staticmethod
    def levels(cell: Hashable, predicate: str, context: str) -> tuple[Hashable, ...]:
        """A silent claim's calibration levels, finest first: its cell per predicate, its cell, its context."""
        return ((cell, predicate), (cell, "*"), (context, "*", "*"))

    def likelihood_ratio(self, confidence: float, cell: Hashable, predicate: str,
                         context: str) -> tuple[float, float] | None:
        """(Lambda_hat, kappa_hat) of a silent claim from the consensus calibration, or None before the first refit."""
        if not self.calibration.fitted:
            return None
        return self.calibration.likelihood_ratio(confidence, self.levels(cell, predicate, context))

    def refit(self) -> None:
        """Refit the Dawid–Skene model and the per-cell calibration on the whole table."""
        n = len(self.node)
        self.n_at_fit = n
        self.n_fits += 1
        if n == 0:
            return
        probas, class_of, task_of = self.fit_consensus()
        silent = [i for i in range(n) if not self.decisive[i]]
        if not silent:
            return
        q = np.array([probas[task_of[self.node[i]], class_of[self.pred[i]]] for i in silent])
        c = np.array([self.conf[i] for i in silent])
        self.calibration.fit([self.levels(self.cell[i], self.pred[i], self.ctx[i]) for i in silent], c, q)

    def fit_consensus(self) -> tuple[np.ndarray, dict[str, int], dict[Any, int]]:
        """The Dawid–Skene posterior over classes (+ none) per element: (probas, class index, task index)."""
        task_of: dict[Any, int] = {}
        for node in self.node:
            if node not in task_of:
                task_of[node] = len(task_of)
        classes = sorted(set(self.pred))
        class_set = set(classes)
        tasks = [task_of[v] for v in self.node]
        # a claim is an observation (class, confidence bin) of its context: clutter draws weak claims
        bins, ranks = self._bins()
        workers = list(self.ctx)
        labels = [f"{p}|b{b}" for p, b in zip(self.pred, bins)]
        # initial vote: a claim votes for its class by its confidence rank and for "none" by the rest
        votes = [r * m for r, m in zip(ranks, self.mass)]
        none_votes = [(1.0 - r) * m for r, m in zip(ranks, self.mass)]
        weights = list(self.mass)  # a claim is about v with probability T(v)
        vote_classes: list[str | None] = list(self.pred)
        # the support of each element is an observation: clutter receives few claims, and without
        # it "none of these" is not identifiable (one label is always best explained by its class)
        n_claims = np.bincount(np.asarray(tasks, dtype=np.intp), minlength=len(task_of))
        for task, n in enumerate(n_claims.tolist()):
            tasks.append(task)
            workers.append(SUPPORT_WORKER)
            labels.append(f"n{support_bucket(n)}")
            votes.append(0.0)
            none_votes.append(0.0)
            vote_classes.append(None)
            weights.append(1.0)
        # the channel's labels: a label that asserts a class votes for it at initialisation, any
        # other (otherprop, a class outside the vocabulary) for "none of these"; EM then learns the
        # channel's confusion, so a vocabulary's ambiguous label ends where the claims put it
        for (node, _t), label in self.labels.items():
            task = task_of.get(node)
            if task is None:  # labelled, never claimed: says nothing about a claim
                continue
            classes_of_label = [p for p in self.asserted.get(label, ()) if p in class_set]
            tasks.append(task)
            workers.append(GEOMETRIC_WORKER)
            labels.append("geo:" + label)
            weights.append(1.0)
            if classes_of_label:
                votes.append(1.0)
                none_votes.append(0.0)
                vote_classes.append(classes_of_label[0])
            else:
                votes.append(0.0)
                none_votes.append(1.0)
                vote_classes.append(None)
        ds = self._ds.fit(tasks, workers, labels, classes=classes, n_tasks=len(task_of), weights=weights,
                          votes=votes, vote_classes=vote_classes, none_votes=none_votes)
        self.ds_ = ds
        return ds.probas_, {p: i for i, p in enumerate(classes)}, task_of  # type: ignore[return-value]

    def _bins(self) -> tuple[list[int], list[float]]:
        """Each claim's confidence bin and rank quantile within its context: ``bins`` equal-count
        bins of the rank, and (rank + 1) / n in (0, 1]. Ranks (ties share the lowest) make both
        invariant under a strictly increasing transform of the confidences."""
        bins = [0] * len(self.conf)
        quant = [1.0] * len(self.conf)
        by_ctx: dict[str, list[int]] = {}
        for i, ctx in enumerate(self.ctx):
            by_ctx.setdefault(ctx, []).append(i)
        for idx in by_ctx.values():
            c = np.array([self.conf[i] for i in idx])
            ranks = np.searchsorted(np.sort(c), c, side="left")
            b = np.minimum(ranks * self.bins // len(idx), self.bins - 1)
            qt = (ranks + 1) / len(idx)
            for i, bi, qi in zip(idx, b.tolist(), qt.tolist()):
                bins[i] = bi
                quant[i] = qi
        return bins, quant

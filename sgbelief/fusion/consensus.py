"""The map-wide consensus behind the calibration of claims the geometric channel cannot adjudicate.

A :class:`MapConsensus` belongs to one map (one provenance store) and holds

* the claim table: every claim of an exclusive class the operator applied (element, predicate,
  context, confidence, its calibration cell, whether the channel adjudicated it, event id);
* the labels the geometric channel gave, once per (element, time);
* per element, the claims each exclusive class received so far (a claim's standing,
  :func:`~sgbelief.fusion.rules.standing`).

When two elements of the map are merged (a ConceptGraphs merge of two map objects,
``FusionOperator.merge_nodes``), the absorbed element's claims and labels become the kept
element's (:meth:`MapConsensus.merge_elements`): a claim is about the object, whatever id it
arrived under. Without that, every detection a mapper registers as a new object and merges a frame
later stays a task of its own with one claim, and the model explains the map as mostly "none".

Every so often (at least ``every`` new claims and ``growth`` times the claims held, so O(log n)
refits over a stream) it refits, in one batch over the whole table:

1. a Dawid–Skene model (:class:`~sgbelief.calibration.dawid_skene.DawidSkene`): the latent class
   of each element among the exclusive classes plus "none of these", a confusion per worker,
   where a worker is a claim's context and its confidence bin (by rank within the context, so the
   model is invariant under a monotone transform of the confidences), the element's support (how
   many claims it received, bucketed: stray detections on clutter are rarely repeated) or the
   geometric channel, whose every label (``otherprop`` included) is an observation with a learned
   confusion;
2. the consensus outcome of each silent claim, q_v(phi) (:func:`silent_claim_outcome`: the
   channel's own verdict where it labelled the element decisively at other times and always the
   same way, else the Dawid–Skene posterior), and from those the per-cell isotonic calibration
   (:class:`~sgbelief.calibration.consensus.ConsensusCalibration`).

The operator asks :meth:`MapConsensus.likelihood_ratio` for a silent claim's (Lambda_hat,
kappa_hat); until the first refit it answers None and the operator uses §4.1's calibrator as before.
Per-event work is O(1): appending a row and two dictionary updates.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import numpy as np

from sgbelief.calibration.agreement_shift import ContextReading, ShiftCalibration
from sgbelief.calibration.config import CalibrationConfig
from sgbelief.calibration.consensus import ConsensusCalibration
from sgbelief.calibration.dawid_skene import NONE_CLASS, DawidSkene

__all__ = ["MapConsensus", "GEOMETRIC_WORKER", "SUPPORT_WORKER", "label_reliability", "silent_claim_outcome",
           "support_bucket"]

#: the Dawid–Skene worker name of the geometric channel
GEOMETRIC_WORKER = "<geometric>"
#: the Dawid–Skene worker whose label is how many claims an element received (its support)
SUPPORT_WORKER = "<support>"
#: the most classes a map's table codes (cell and class share one integer key in the calibration)
_MAX_CLASSES = 1 << 20
#: support buckets: 1, 2, 3, 4-5, 6-9, 10+ claims
_SUPPORT_EDGES = (1, 2, 3, 4, 6, 10)


def support_bucket(n: int) -> int:
    """The support observation of an element with ``n`` claims: the index of its bucket 1, 2, 3, 4-5, 6-9, 10+."""
    b = 0
    for i, edge in enumerate(_SUPPORT_EDGES):
        if n >= edge:
            b = i
    return b


def silent_claim_outcome(posterior: np.ndarray, n_positive: np.ndarray, n_decisive: np.ndarray) -> np.ndarray:
    """The consensus outcome q_v(phi) of claims the channel did not adjudicate when they arrived (docs/method.md §8).

    q = n_pos / n_dec  where the channel's decisive labels of v for phi are unanimous
                       (n_dec > 0 and n_pos in {0, n_dec}): the channel's verdict, given at another time;
    q = P(z_v = phi | everything)  otherwise: the Dawid–Skene posterior.

    The channel is the one source whose errors the calibration does not have to learn from the map;
    where it spoke about v decisively and never changed its mind, a claim that arrived while it was
    looking elsewhere (or at a silent label) has the same truth as the claims it adjudicated.
    Where its labels disagree (a monitor labelled otherprop, once television) the posterior decides.
    All arguments are arrays of one shape, one entry per silent claim.
    """
    unanimous = (n_decisive > 0) & ((n_positive == 0) | (n_positive == n_decisive))
    return np.where(unanimous, n_positive / np.maximum(n_decisive, 1), posterior)


def label_reliability(theta: np.ndarray, priors: np.ndarray) -> np.ndarray:
    """How far a label of the channel asserts each exclusive class: r[phi, l] (docs/method.md §8).

    ``theta``: the channel's confusion learned by the consensus, P(label l | z) (rows: the latent
    classes, *none* last; columns: the labels); ``priors``: pi_z. Against phi's rivals weighed by
    their priors, and with a uniform prior on phi itself (Eq. 2's uniform reference)::

        LR(phi, l) = theta[phi, l] / (sum_{z != phi} pi_z theta[z, l] / sum_{z != phi} pi_z)
        r(phi, l)  = LR / (1 + LR)

    With ``label_weights: reliability`` a decisive label's observation of y
    (:func:`~sgbelief.fusion.rules.verification_increments`) counts r of a pseudo-count when the
    label asserts phi and 1 - r when it denies it. A channel that is never wrong has r near 1 for
    its asserting labels and near 0 for its denying ones, so each observation stays about whole.
    Returns an array (exclusive classes, labels), without the *none* row.
    """
    theta = np.asarray(theta, dtype=np.float64)
    pi = np.asarray(priors, dtype=np.float64)
    k = theta.shape[0] - 1
    mixed = pi @ theta  # sum_z pi_z theta[z, l], per label
    own = pi[:k, None] * theta[:k]  # pi_phi theta[phi, l]
    rivals = np.maximum(1.0 - pi[:k], 1e-300)[:, None]  # sum_{z != phi} pi_z
    p_rival = np.maximum(mixed[None, :] - own, 0.0) / rivals
    lr = theta[:k] / np.maximum(p_rival, 1e-300)
    return lr / (1.0 + lr)


class _Codes:
    """Names <-> small integer codes, in order of first appearance."""

    __slots__ = ("index", "names")

    def __init__(self) -> None:
        self.index: dict[Hashable, int] = {}
        self.names: list[Any] = []

    def code(self, name: Hashable) -> int:
        i = self.index.get(name)
        if i is None:
            i = self.index[name] = len(self.names)
            self.names.append(name)
        return i


class MapConsensus:
    """Claim table, channel labels and the consensus calibration of one map (see the module docstring)."""

    def __init__(self, config: CalibrationConfig, exclusive: frozenset[str],
                 asserted: Mapping[str, tuple[str, ...]] | None = None,
                 outcomes: Mapping[str, Mapping[str, int]] | None = None) -> None:
        cc = config.consensus
        self.every, self.growth, self.bins = cc.every, cc.growth, cc.bins
        self.exclusive = exclusive
        #: label -> the predicates it asserts (the vocabulary's positive sets): a label's initial vote
        self.asserted = asserted or {}
        #: predicate -> {label: y}: the channel's verdicts (the vocabulary's outcome tables); with
        #: ``adjudicated_elements: channel`` a unanimous verdict is a silent claim's outcome
        self.outcomes = outcomes if cc.adjudicated_elements == "channel" else None
        self._ds = DawidSkene(n_iter=cc.n_iter, smoothing=cc.smoothing, none_class=True, emission=cc.emission)
        #: ``method: agreement_shift``: no Dawid-Skene posterior, one shift per context of the
        #: confidences' reading (:mod:`sgbelief.calibration.agreement_shift`)
        self.shift_only = cc.method == "agreement_shift"
        self.calibration: ConsensusCalibration | ShiftCalibration = (
            ShiftCalibration(config.kappa_min, config.lr_max, cc.score_test_level) if self.shift_only
            else ConsensusCalibration(config.target_size, config.kappa_min, config.lr_max, config.cold_start))
        # codes of elements (the Dawid-Skene tasks), classes, contexts, cells and channel labels
        self._tasks, self._classes, self._contexts, self._cells, self._labels = (_Codes() for _ in range(5))
        # the claim table: one row per claim, integer codes and floats in typed arrays (~50 bytes a claim)
        self.task, self.cls, self.ctx_code, self.cell_code = array("l"), array("l"), array("l"), array("l")
        self.conf = array("d")
        self.mass = array("d")
        self.time = array("q")
        self.decisive = bytearray()
        self.event: list[str] = []
        #: the channel's labels: label code per (element, time) seen
        self.labels: dict[tuple[Any, int], int] = {}
        #: element -> {exclusive predicate: claims so far}
        self.counts: dict[Any, dict[str, int]] = {}
        #: element code -> the code it was merged into (itself when never merged); resolved at fit time
        self._merged_into = array("l")
        #: row of each element code in the last fit's posterior (-1: no claim)
        self._row_of_code = np.zeros(0, dtype=np.intp)
        #: (posterior row, label code) of every channel label the last fit saw
        self._geo_rows = np.zeros((0, 2), dtype=np.intp)
        #: :func:`label_reliability` of the last fit, by (predicate, label) (empty before a fit)
        self._label_r: dict[tuple[str, Hashable], float] = {}
        self.n_at_fit = 0
        #: claims whose element was merged into another since the last fit (they agree or
        #: disagree with other claims now): they count toward the next refit as new claims do
        self.moved_since_fit = 0
        self.n_fits = 0
        #: no more refits (the operator's calibration is frozen): the last fit stays
        self.frozen = False

    # decoded columns (diagnostics, tests)
    @property
    def node(self) -> list[Any]:
        rep, names = self._representatives(), self._tasks.names
        return [names[rep[i]] for i in self.task]

    @property
    def pred(self) -> list[str]:
        return [self._classes.names[i] for i in self.cls]

    @property
    def ctx(self) -> list[str]:
        return [self._contexts.names[i] for i in self.ctx_code]

    @property
    def cell(self) -> list[Hashable]:
        return [self._cells.names[i] for i in self.cell_code]

    # ------------------------------------------------------------------ per claim
    def standing_counts(self, node: Any, predicate: str, rivals: tuple[str, ...] | frozenset[str]) -> tuple[int, int, int]:
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

    def _task_code(self, node: Any) -> int:
        """The element's code (a new one, merged into itself, for an element not seen yet)."""
        i = self._tasks.code(node)
        if i == len(self._merged_into):
            self._merged_into.append(i)
        return i

    def _representatives(self) -> np.ndarray:
        """Per element code, the code of the element it ended up merged into (follows chains)."""
        rep = np.frombuffer(self._merged_into, dtype=np.int_).astype(np.intp) if len(self._merged_into) else \
            np.zeros(0, dtype=np.intp)
        while len(rep) and np.any(rep[rep] != rep):
            rep = rep[rep]
        return rep

    def add_claim(self, node: Any, predicate: str, context: str, confidence: float, cell: Hashable,
                  decisive: bool, event_id: str, mass: float = 1.0, t: int = 0) -> None:
        """Append one applied claim of an exclusive class (``mass``: its targeting mass T(v); ``t``:
        its event's time)."""
        self.task.append(self._task_code(node))
        self.cls.append(self._classes.code(predicate))
        self.ctx_code.append(self._contexts.code(context))
        self.cell_code.append(self._cells.code(cell))
        self.conf.append(confidence)
        self.mass.append(mass)
        self.time.append(t)
        self.decisive.append(1 if decisive else 0)
        self.event.append(event_id)
        held = self.counts.get(node)
        if held is None:
            held = self.counts[node] = {}
        held[predicate] = held.get(predicate, 0) + 1

    def add_label(self, node: Any, t: int, label: str) -> None:
        """The channel labelled ``node`` ``label`` at time ``t`` (kept once per (node, t))."""
        self.labels[(node, t)] = self._labels.code(label)

    def merge_elements(self, keep: Any, absorb: Any) -> None:
        """Element ``absorb`` was merged into ``keep``: from now on its claims and labels are
        ``keep``'s (O(1) here plus the two elements' class counts; the table is re-coded at the
        next fit)."""
        if absorb == keep or absorb not in self._tasks.index:
            return
        a, k = self._tasks.index[absorb], self._task_code(keep)
        self._merged_into[a] = k
        self._tasks.index[absorb] = k  # a late claim under the absorbed id counts for keep
        moved = self.counts.pop(absorb, None)
        if moved:
            self.moved_since_fit += sum(moved.values())
            held = self.counts.setdefault(keep, {})
            for p, n in moved.items():
                held[p] = held.get(p, 0) + n

    def silent_claims(self, since: float = -math.inf) -> list[tuple[str, Any, str, int]]:
        """(event id, element, predicate, row) of every claim in the table that the channel did
        not adjudicate and whose event time is at least ``since``, in arrival order; the element is
        the one it ended up merged into."""
        if not self.event:
            return []
        silent = np.frombuffer(bytes(self.decisive), dtype=np.uint8) == 0
        if since > -math.inf:
            silent &= np.frombuffer(self.time, dtype=np.int64) >= since
        rep = self._representatives()
        names, classes, task, cls, event = self._tasks.names, self._classes.names, self.task, self.cls, self.event
        return [(event[i], names[rep[task[i]]], classes[cls[i]], i) for i in np.flatnonzero(silent).tolist()]

    def row_likelihood_ratio(self, row: int) -> tuple[float, float]:
        """(Lambda_hat, kappa_hat) of the table's claim ``row`` under the current calibration (its
        cell for its predicate, its cell, its context: the levels of :meth:`likelihood_ratio`)."""
        cell = self.cell_code[row]
        return self.calibration.likelihood_ratio(self.conf[row], (cell * _MAX_CLASSES + self.cls[row], cell,
                                                                  self.ctx_code[row]))

    def rows_likelihood_ratios(self, rows: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`row_likelihood_ratio` of many rows at once (``ConsensusCalibration.likelihood_ratios``)."""
        r = np.asarray(rows, dtype=np.intp)
        cell = np.frombuffer(self.cell_code, dtype=np.int_).astype(np.int64)[r]
        cls = np.frombuffer(self.cls, dtype=np.int_).astype(np.int64)[r]
        ctx = np.frombuffer(self.ctx_code, dtype=np.int_).astype(np.int64)[r]
        return self.calibration.likelihood_ratios(np.frombuffer(self.conf, dtype=np.float64)[r],
                                                  (cell * _MAX_CLASSES + cls, cell, ctx))

    def row_mass(self, row: int) -> float:
        """The targeting mass T(v) of the table's claim ``row``."""
        return self.mass[row]

    def drop_events(self, event_ids: set[str]) -> None:
        """Forget the claims of retracted events (the next refit no longer sees them)."""
        keep = [i for i, e in enumerate(self.event) if e not in event_ids]
        if len(keep) == len(self.event):
            return
        for name in ("task", "cls", "ctx_code", "cell_code", "conf", "mass", "time"):
            col = getattr(self, name)
            setattr(self, name, array(col.typecode, [col[i] for i in keep]))
        self.decisive = bytearray(self.decisive[i] for i in keep)
        self.event = [self.event[i] for i in keep]
        self.counts = {}
        for node, pred in zip(self.node, self.pred):
            held = self.counts.setdefault(node, {})
            held[pred] = held.get(pred, 0) + 1

    # ------------------------------------------------------------------ batches
    def due(self) -> bool:
        """Whether enough changed since the last refit: max(every, growth * held) claims that are
        new or whose element was merged into another (:meth:`merge_elements`)."""
        if self.frozen:
            return False
        n = len(self.event)
        return n - self.n_at_fit + self.moved_since_fit >= max(self.every, self.growth * self.n_at_fit)

    def changed_since_fit(self) -> bool:
        """Whether any claim arrived or any element was merged since the last refit."""
        return not self.frozen and (len(self.event) > self.n_at_fit or self.moved_since_fit > 0)

    def likelihood_ratio(self, confidence: float, cell: Hashable, predicate: str,
                         context: str) -> tuple[float, float] | None:
        """(Lambda_hat, kappa_hat) of a silent claim from the consensus calibration, or None before the first refit.

        The levels, finest first: the claim's cell for its predicate, its cell, its context."""
        cal = self.calibration
        if not cal.fitted:
            return None
        cell_i = self._cells.index.get(cell, -1)
        cls_i = self._classes.index.get(predicate, -1)
        return cal.likelihood_ratio(confidence, (cell_i * _MAX_CLASSES + cls_i if cell_i >= 0 and cls_i >= 0 else -1,
                                                 cell_i, self._contexts.index.get(context, -1)))

    def score_readings(self) -> dict[str, ContextReading]:
        """{context: how its confidences are read} under ``method: agreement_shift``; empty otherwise."""
        if not isinstance(self.calibration, ShiftCalibration):
            return {}
        names = self._contexts.names
        return {str(names[w]): reading for w, reading in self.calibration.readings_.items()}

    def refit(self) -> None:
        """Refit the Dawid–Skene model and the per-cell calibration on the whole table."""
        n = len(self.event)
        self.n_at_fit = n
        self.moved_since_fit = 0
        self.n_fits += 1
        if n == 0:
            return
        if self.shift_only:
            # every claim is evidence of agreement, adjudicated or not; merged elements are one task
            task = self._representatives()[np.asarray(self.task, dtype=np.intp)]
            self.calibration.fit(task, np.asarray(self.cls, dtype=np.intp), np.asarray(self.conf),
                                 np.asarray(self.ctx_code, dtype=np.intp), np.asarray(self.mass))
            return
        probas = self.fit_consensus()
        silent = np.flatnonzero(np.frombuffer(bytes(self.decisive), dtype=np.uint8) == 0)
        if silent.size == 0:
            return
        cls = np.asarray(self.cls, dtype=np.int64)[silent]
        cell = np.asarray(self.cell_code, dtype=np.int64)[silent]
        rows = self._row_of_code[np.asarray(self.task, dtype=np.intp)[silent]]
        q = probas[rows, cls]
        if self.outcomes is not None:
            n_pos, n_dec = self._element_outcomes(probas.shape[0])
            q = silent_claim_outcome(q, n_pos[rows, cls], n_dec[rows, cls])
        c = np.asarray(self.conf)[silent]
        levels = [cell * _MAX_CLASSES + cls, cell, np.asarray(self.ctx_code, dtype=np.int64)[silent]]
        self.calibration.fit(levels, c, q)

    def _element_outcomes(self, n_rows: int) -> tuple[np.ndarray, np.ndarray]:
        """Per (posterior row, class): how many of the channel's labels of the element decide the
        class (n_dec) and how many of those corroborate it (n_pos); rows and labels as in the last
        :meth:`fit_consensus`."""
        k = len(self._classes.names)
        n_pos, n_dec = np.zeros((n_rows, k)), np.zeros((n_rows, k))
        if not self.labels or self.outcomes is None:
            return n_pos, n_dec
        # y of each label code for each class: 1, 0, or -1 (decides nothing)
        y = np.full((len(self._labels.names), k), -1, dtype=np.int8)
        for j, pred in enumerate(self._classes.names):
            table = self.outcomes.get(pred, {})
            for i, label in enumerate(self._labels.names):
                v = table.get(label)
                if v is not None:
                    y[i, j] = v
        pairs = self._geo_rows  # (posterior row, label code) of each (element, time) label, from the last fit
        if len(pairs):
            ys = y[pairs[:, 1]]  # (labels, classes)
            np.add.at(n_dec, pairs[:, 0], (ys >= 0).astype(float))
            np.add.at(n_pos, pairs[:, 0], (ys == 1).astype(float))
        return n_pos, n_dec

    def fit_consensus(self) -> np.ndarray:
        """The Dawid–Skene posterior over classes (+ none) per element (rows: task codes, columns:
        class codes, the last one *none*); the fitted model is ``self.ds_``."""
        k, b = len(self._classes.names), self.bins
        n_ctx, n_geo = len(self._contexts.names), len(self._labels.names)
        # tasks: the elements that received claims, merged elements counted as one
        rep = self._representatives()
        codes, task = np.unique(rep[np.asarray(self.task, dtype=np.intp)], return_inverse=True)
        task = task.astype(np.intp)
        n_t = len(codes)
        row_of_rep = np.full(len(rep), -1, dtype=np.intp)
        row_of_rep[codes] = np.arange(n_t)
        self._row_of_code = row_of_rep[rep]
        cls = np.asarray(self.cls, dtype=np.intp)
        ctx = np.asarray(self.ctx_code, dtype=np.intp)
        mass = np.asarray(self.mass)
        bins, ranks = self._bins(ctx, np.asarray(self.conf))
        # label space: (class, bin) of a claim | support bucket | channel label
        support_base, geo_base = k * b, k * b + len(_SUPPORT_EDGES)
        n_claims = np.bincount(task, minlength=n_t)
        support = np.array([support_bucket(int(x)) for x in n_claims], dtype=np.intp)
        row = self._row_of_code
        geo = [(row[i] if (i := self._tasks.index.get(node, -1)) >= 0 else -1, code)
               for (node, _t), code in self.labels.items()]
        geo_arr = self._geo_rows = np.array([g for g in geo if g[0] >= 0], dtype=np.intp).reshape(-1, 2)
        tasks = np.concatenate([task, np.arange(n_t), geo_arr[:, 0]])
        workers = np.concatenate([ctx, np.full(n_t, n_ctx), np.full(len(geo_arr), n_ctx + 1)])
        labels = np.concatenate([cls * b + bins, support_base + support, geo_base + geo_arr[:, 1]])
        # a claim is about v with probability T(v); support and labels count once
        weights = np.concatenate([mass, np.ones(n_t + len(geo_arr))])
        # initial vote: a claim votes for its class by its confidence rank and for "none" by the rest;
        # a label for the class it asserts, any other label (otherprop, ...) for "none"
        q = np.zeros((n_t, k + 1))
        np.add.at(q, (task, cls), ranks * mass)
        q[:, k] += self._ds.none_prior_votes + np.bincount(task, weights=(1.0 - ranks) * mass, minlength=n_t)
        label_class = np.array([self._label_class(name) for name in self._labels.names] or [0], dtype=np.intp)
        if len(geo_arr):
            vote = label_class[geo_arr[:, 1]]
            np.add.at(q, (geo_arr[:, 0], np.where(vote >= 0, vote, k)), 1.0)
        q /= q.sum(axis=1, keepdims=True)
        # the overdispersed emission (docs/method.md §8) is the detector contexts': the support is one
        # observation per element, and the channel's labels stay independent (measured there)
        independent = np.arange(n_ctx + 2) >= n_ctx
        ds = self._ds.fit_coded(tasks, workers, labels, n_ctx + 2, geo_base + n_geo, q, weights, independent=independent)
        ds.classes_ = [*self._classes.names, NONE_CLASS]
        ds.workers_ = [*self._contexts.names, SUPPORT_WORKER, GEOMETRIC_WORKER]
        ds.labels_ = ([f"{c}|b{i}" for c in self._classes.names for i in range(b)]
                      + [f"n{i}" for i in range(len(_SUPPORT_EDGES))] + ["geo:" + g for g in self._labels.names])
        self.ds_ = ds
        r = label_reliability(ds.errors_[n_ctx + 1][:, geo_base:], ds.priors_).tolist()  # type: ignore[index]
        labels = self._labels.names
        self._label_r = {(pred, labels[i]): x for pred, row in zip(self._classes.names, r) for i, x in enumerate(row)}
        return ds.probas_  # type: ignore[return-value]

    def verdict_reliability(self, predicate: str, label: str, outcome: int) -> float:
        """How much of a pseudo-count a decisive label's verdict ``outcome`` on ``predicate`` counts
        (``label_weights: reliability``): :func:`label_reliability` of the last fit, r for a label
        that asserts the predicate and 1 - r for one that denies it; 1 before the first fit, without
        a Dawid–Skene fit (``method: agreement_shift``) and for a class or a label the last fit
        did not hold."""
        r = self._label_r.get((predicate, label))  # one look-up per decisive label (docs/performance.md)
        if r is None:
            return 1.0
        return r if outcome == 1 else 1.0 - r

    def class_of(self, predicate: str) -> int:
        """The column of ``predicate`` in :meth:`fit_consensus`'s posterior (-1 if never claimed)."""
        return self._classes.index.get(predicate, -1)

    def task_of(self, node: Any) -> int:
        """The row of ``node`` in the last :meth:`fit_consensus`'s posterior (-1 if it had no
        claim then; a merged element gives the row of the element it was merged into)."""
        i = self._tasks.index.get(node, -1)
        return int(self._row_of_code[i]) if 0 <= i < len(self._row_of_code) else -1

    def posterior(self, node: Any, predicate: str) -> float | None:
        """q_v(phi) of the last fit (the Dawid–Skene posterior of ``predicate`` at ``node``), or
        None when there was no fit yet or the element or the class was not in it."""
        ds = getattr(self, "ds_", None)
        if ds is None:
            return None
        row, col = self.task_of(node), self.class_of(predicate)
        probas = ds.probas_
        if row < 0 or not 0 <= col < probas.shape[1] - 1:  # (the last column is "none")
            return None
        return float(probas[row, col])

    def _label_class(self, label: str) -> int:
        for p in self.asserted.get(label, ()):
            i = self._classes.index.get(p)
            if i is not None:
                return i
        return -1

    def _bins(self, ctx: np.ndarray, conf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each claim's confidence bin and rank quantile within its context: ``bins`` equal-count
        bins of the rank, and (rank + 1) / n in (0, 1]. Ranks (ties share the lowest) make both
        invariant under a strictly increasing transform of the confidences."""
        bins = np.zeros(len(conf), dtype=np.intp)
        quant = np.ones(len(conf))
        for j in np.unique(ctx).tolist():
            idx = np.flatnonzero(ctx == j)
            c = conf[idx]
            ranks = np.searchsorted(np.sort(c), c, side="left")
            if self.bins > 1:
                bins[idx] = np.minimum(ranks * self.bins // len(idx), self.bins - 1)
            quant[idx] = (ranks + 1) / len(idx)
        return bins, quant

"""Labels out of the beliefs of a ConceptGraphs map: the committed predicate of an object, the class
written for it, and the summary of what the backend did.

:class:`LabelReader` is the reading half of :class:`~.map_beliefs.MapBeliefs` (which inherits it):
it reads the per-node bookkeeping the routing half keeps (the class names claimed at a node, the
predicates routed there, the labels the channel gave there) and the operator's probabilities.
Every read first applies the evidence still queued (``flush``), so it sees every routed claim.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from sgbelief.adapters.conceptgraphs.summary import (BackendSummary, ClassSummary, low_confidence_note,
                                                      score_reading_note)
from sgbelief.adapters.conceptgraphs.vocab import normalise_class_name
from sgbelief.fusion.operators.calibrated import CalibratedOperator
from sgbelief.fusion.rules import exclusive_marginal

__all__ = ["LabelReader"]


class LabelReader:
    """Committed predicates, written classes and the summary (see the module doc). The attributes
    it reads are set by :class:`~.map_beliefs.MapBeliefs`."""

    # attributes MapBeliefs provides
    graph: Any
    operator: Any
    tau: float
    table: Any
    vocabulary: Any
    class_names: dict[int, str]
    label_rule: Any
    unknown_label: str
    unknown_class_id: int
    abstain: bool
    labels: Any
    _names_per_node: dict[Any, Counter[tuple[int | None, str]]]
    _preds_per_node: dict[Any, set[str]]
    _pending: list[Any]
    _external_graph: bool
    _label_preds_per_node: dict[Any, set[str]]
    _labels_per_node: dict[Any, Counter[str]]
    _claim_counts: dict[str, Any]
    _claims_below_half: int
    _claims_counted: int
    _has_channel: bool
    _reads_scores_shifted: bool
    _routed_detections: int

    def flush(self) -> None:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def node_of(self, obj: Mapping[str, Any]) -> Any | None:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def _predicate(self, class_name: str) -> str | None:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def _predicates_of(self, node: Any) -> set[str]:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def evidence_count(self) -> int:  # pragma: no cover - MapBeliefs defines it
        raise NotImplementedError

    def beliefs(self, obj: Mapping[str, Any]) -> dict[str, Any]:
        """{predicate: BetaBelief} of a map object (empty for an object the backend never saw)."""
        self.flush()
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return {}
        return dict(self.graph.beliefs(node))

    def probability(self, obj: Mapping[str, Any], predicate: str) -> float:
        self.flush()
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return 0.5
        return float(self.operator.probability(self.graph, node, predicate))

    def committed_predicate(self, node: Any) -> str | None:
        """The predicate with the highest committed probability (> tau), or None.

        The candidates are the predicates the node's detections claimed. Only when none of them
        commits are the predicates that the geometric labels alone asserted considered (comod,
        ``geometric_evidence: label``): a sofa the detector always calls ``tv`` is labelled
        ``sofa``, while one stray label of a segmenter does not outrank a class the detector
        keeps naming and the geometry keeps confirming. Under independent Beta(1, 1) beliefs, a
        single observation (mean 2/3) would otherwise outrank a well-supported class with a few
        contradictions. The probability is the operator's (``FusionOperator.probability``), for
        every operator.

        Among several committed predicates, exclusive classes are ranked by
        :func:`~sgbelief.fusion.rules.exclusive_marginal` (each class's evidence against its
        rivals' evidence, whatever the order the claims came in), for the method's operators (cal,
        comod) unless they couple the classes themselves (``exclusive_evidence: rivals``); any
        other operator ranks by its own probability. Under independent Betas the mean of a class is the average calibrated
        reliability of its claims, whatever their number: an object claimed four times as stool
        and twice as chair would come out chair when the two chair claims were the more confident.

        When nothing commits and ``abstain`` is off, the object still gets the claimed class of
        highest probability (ranked the same way: the Bayes choice when every object must carry
        one label), unless two classes tie."""
        self.flush()
        claimed = sorted(self._predicates_of(node))
        best = self._best_committed(claimed, node)
        if best is None:
            extra = self._label_preds_per_node.get(node)
            if extra:
                best = self._best_committed(sorted(extra), node)
        if best is None and not self.abstain:
            best = self._most_probable(claimed, node)
        return best

    def _most_probable(self, preds: Iterable[str], node: Any) -> str | None:
        """The predicate ranked strictly first among ``preds`` (None on a tie or none)."""
        rank = self._ranking(node)
        ranked = sorted(((rank(p), p) for p in preds), reverse=True)
        if not ranked or (len(ranked) > 1 and ranked[0][0] == ranked[1][0]):
            return None
        return ranked[0][1]

    def _best_committed(self, preds: Iterable[str], node: Any) -> str | None:
        """The committed predicate (probability > tau) ranked first (see committed_predicate)."""
        probability = self.operator.probability
        graph, tau = self.graph, self.tau
        committed = [pred for pred in preds if float(probability(graph, node, pred)) > tau]
        if len(committed) < 2:
            return committed[0] if committed else None
        rank = self._ranking(node)
        best, best_r = None, -1.0
        for pred in committed:  # ties keep the first in order
            r = rank(pred)
            if r > best_r:
                best, best_r = pred, r
        return best

    def _ranking(self, node: Any) -> Any:
        """The key that ranks ``node``'s predicates: the mean of
        :func:`~sgbelief.fusion.rules.exclusive_marginal` over the predicates ``node`` holds, or
        the operator's probability (see committed_predicate)."""
        probability, graph = self.operator.probability, self.graph
        table, op = self.table, self.operator
        # the method's operators (cal, comod) read the coupling unless they write it; the baselines
        # and operators written against the protocol keep their own probability
        if table is None or not isinstance(op, CalibratedOperator) or op.config.exclusive_evidence == "rivals":
            return lambda pred: float(probability(graph, node, pred))
        held = {p: (b.alpha, b.beta) for p, b in graph.beliefs(node).items()}
        prior = graph.provenance.prior_alpha
        exclusive_with = table.exclusive_with

        def coupled_mean(pred: str) -> float:
            a, b = held.get(pred, (prior, graph.provenance.prior_beta))
            a, b = exclusive_marginal(a, b, (held[q][0] for q in exclusive_with(pred) if q in held), prior)
            return a / (a + b)

        return coupled_mean

    def _class_for(self, node: Any, pred: str | None) -> tuple[int | None, str] | None:
        if pred is None:
            return None
        counts = self._names_per_node.get(node)
        if not counts:
            return None
        predicate = self._predicate
        rule = self.label_rule
        if rule == "first":
            for key in counts:  # Counter keeps first-seen order
                if predicate(key[1]) == pred:
                    return key
            return self._class_named_by(pred)
        if not isinstance(rule, str) and pred in rule:
            name = rule[pred]
            for key in counts:
                if key[1] == name:
                    return key
            cid = next((i for i, n in self.class_names.items() if n == name), None)
            return (cid, name)
        if self._covers_several(pred):  # a merged predicate: the channel's own name, when it has one
            own = self._channel_class(node, pred, counts)
            if own is not None:
                return own
        best, best_n = None, 0
        for key, n in counts.items():  # most frequent; ties keep first-seen order
            if n > best_n and predicate(key[1]) == pred:
                best, best_n = key, n
        return best if best is not None else self._class_named_by(pred)

    def _covers_several(self, pred: str) -> bool:
        """Whether ``pred`` stands for several class names (a merged group: table, desk, ...)."""
        table = self.table
        spec = table.specs.get(pred) if table is not None else None
        return spec is not None and len(spec.aliases) > 1

    def _channel_class(self, node: Any, pred: str, counts: Counter[tuple[int | None, str]]) -> tuple[int | None, str] | None:
        """(class id, name) of the label the channel gave most often at ``node`` among those naming
        ``pred``'s classes (the detector's spelling and id when a claim used that name), or None."""
        seen = self._labels_per_node.get(node)
        vocab = self.vocabulary
        if not seen or vocab is None:
            return None
        for label, _n in seen.most_common():
            if vocab.predicate(label) != pred:
                continue
            key = normalise_class_name(label)
            for cid, name in counts:
                if normalise_class_name(name) == key:
                    return (cid, name)
            cid = next((i for i, n in sorted(self.class_names.items()) if normalise_class_name(n) == key), None)
            return (cid, self.class_names[cid] if cid is not None else label)
        return None

    def _class_named_by(self, pred: str) -> tuple[int | None, str] | None:
        """(class id, name) for a predicate no detection of the node named (the geometric labels
        committed it): the first class of the class list whose predicate it is."""
        predicate = self._predicate
        for cid, name in sorted(self.class_names.items()):
            if predicate(name) == pred:
                return (cid, name)
        return None

    def committed_class(self, node: Any) -> tuple[int | None, str] | None:
        """(class id, class name) of the node's committed predicate under ``label_rule``, or None
        when nothing commits."""
        return self._class_for(node, self.committed_predicate(node))

    def node_label(self, node: Any) -> str:
        """The class name the beliefs give graph node ``node`` (``unknown_label`` when nothing commits)."""
        label = self._one_class_label(node)  # a node claimed as one class only: most new objects
        if label is not None:
            return label
        hit = self.committed_class(node)
        return self.unknown_label if hit is None else hit[1]

    def _one_class_label(self, node: Any) -> str | None:
        """:meth:`node_label` of a node whose claims all named one class and that no geometric
        label reached (each new object's first label on ``ali-dev``), or None for any other node.

        Then the candidates are that class's predicate alone: it is the label when it commits
        (always, without ``abstain``), else ``unknown_label``; under a ``label_rule`` mapping that
        names the predicate, the mapped name. No ranking and no scan of the claimed names."""
        counts = self._names_per_node.get(node)
        preds = self._preds_per_node.get(node)
        if (counts is None or len(counts) != 1 or preds is None or len(preds) != 1 or self._pending
                or self._external_graph or self._label_preds_per_node.get(node) or self._labels_per_node.get(node)):
            return None
        ((key, n),) = counts.items()
        (pred,) = preds
        # read in committed_class's order: the probability, then (when it commits) the class
        committed = float(self.operator.probability(self.graph, node, pred)) > self.tau
        if not committed and self.abstain:
            return self.unknown_label
        if n <= 0 or self._predicate(key[1]) != pred:
            return None
        rule = self.label_rule
        if not isinstance(rule, str) and pred in rule:
            return rule[pred]
        return key[1]

    def label_of(self, obj: Mapping[str, Any]) -> str | None:
        """Class name from the beliefs (``unknown_label`` when nothing commits; None if unseen)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return None
        return self.node_label(node)

    def class_id_of(self, obj: Mapping[str, Any]) -> int | None:
        """Class id from the beliefs (``unknown_class_id`` when nothing commits; None if unseen)."""
        node = self.node_of(obj)
        if node is None or node not in self.graph:
            return None
        hit = self.committed_class(node)
        if hit is None or hit[0] is None:
            return self.unknown_class_id
        return hit[0]

    def summary(self, objects: Sequence[Mapping[str, Any]] | None = None) -> BackendSummary:
        """What the backend did, over ``objects`` (a map object list) or every live node it tracks:
        objects labelled and left ``unknown``, and per detector class the claims (verified, refused,
        unverifiable by the channel) and the objects whose vote is that class (committed, unknown,
        written label differing from the vote). See :class:`~.summary.BackendSummary`.

        The vote is ConceptGraphs' majority over the object's own detections (its ``class_id``
        list) when ``objects`` are given, else over the claims routed to the node. Each object
        whose label differs says why (``"why"``): ``unknown`` (nothing commits), ``tie`` (the
        vote's top count is shared and the label is one of the tied classes: the vote's pick is
        its tie rule), ``split`` (the claims routed to the object are not its own detections'
        classes: a detection split between candidates, T(v) < 1, or merged elsewhere) or
        ``ranking`` (the same counts, another class ranked first by the beliefs)."""
        self.flush()
        own: dict[Any, Counter[str]] = {}
        if objects is not None:
            nodes = []
            for obj in objects:
                n = self.node_of(obj)
                if n is not None and n in self.graph:
                    nodes.append(n)
                    names = self._own_class_names(obj)
                    if names:
                        own[n] = names
        else:
            nodes = [n for n in self.graph.nodes() if n in self._names_per_node]
        attrs = self.graph.nx.nodes
        filtered = sum(1 for n in nodes if attrs[n].get("cg_filtered"))
        live = [n for n in nodes if not attrs[n].get("cg_filtered")]
        per_class: dict[str, dict[str, int]] = {
            name: {"claims": c.claims, "verified": c.verified, "refused": c.refused, "unverifiable": c.unverifiable}
            for name, c in self._claim_counts.items()}
        differing: list[dict[str, Any]] = []
        labelled = 0
        for n in live:
            hit = self.committed_class(n)
            labelled += hit is not None
            routed = Counter[str]()
            for (_cid, name), k in self._names_per_node.get(n, Counter()).items():
                routed[name] += k
            counts = own.get(n, routed)
            vote = _vote(counts) if counts else None
            if vote is None:
                continue
            row = per_class.setdefault(vote, {})
            key = "committed" if hit is not None else "unknown"
            row[key] = row.get(key, 0) + 1
            written = self.unknown_label if hit is None else hit[1]
            if written != vote:
                row["differ"] = row.get("differ", 0) + 1
                differing.append({"node": str(n), "vote": vote, "label": written,
                                  "why": _why(hit is None, written, counts, routed)})
        vocab = self.vocabulary
        readings = self.operator.score_readings(self.graph) if isinstance(self.operator, CalibratedOperator) else {}
        notes = score_reading_note(readings) if not self._has_channel else []
        note = None if self._reads_scores_shifted else low_confidence_note(self._claims_counted,
                                                                           self._claims_below_half, self._has_channel)
        return BackendSummary(objects=len(live), labelled=labelled, unknown=len(live) - labelled,
                              below_half=self._claims_below_half, notes=notes if note is None else [note, *notes],
                              filtered=filtered, detections=self._routed_detections,
                              events=self.evidence_count(),
                              classes={k: ClassSummary(**v) for k, v in sorted(per_class.items())},
                              differing=differing, channel=self.labels.report() if self._has_channel else {},
                              vocabulary=getattr(vocab, "name", "") if vocab is not None else "",
                              operator=self._operator_settings())

    def _own_class_names(self, obj: Mapping[str, Any]) -> Counter[str]:
        """Class names of the object's own detections (its ``class_id`` list), as ConceptGraphs
        counts them for its vote; empty when the object has no such list or an id is unknown."""
        names = Counter[str]()
        try:
            ids = list(obj.get("class_id", ()))
        except TypeError:
            return names
        for cid in ids:
            name = self.class_names.get(int(cid))
            if name is None:
                return Counter()
            names[name] += 1
        return names

    def _operator_settings(self) -> dict[str, str]:
        """The operator's name and its settings for claims the channel does not decide."""
        op = self.operator
        out = {"name": str(getattr(op, "name", type(op).__name__))}
        cfg = getattr(op, "config", None)
        if cfg is not None:
            out["geometric_evidence"] = str(cfg.geometric_evidence)
            out["consensus"] = str(cfg.calibration.consensus.method)
            out["exclusive_evidence"] = str(cfg.exclusive_evidence)
            if getattr(op, "check_compatibility", False):  # refusing operators: the channel's earlier labels
                out["recalled_verdicts"] = str(cfg.recalled_verdicts)
                out["contested_labels"] = str(cfg.contested_labels)
        return out


def _vote(names: Counter[str]) -> str:
    """The majority class name of an object's claims (ties to the first seen, as ali-dev's
    ``Counter`` vote; main's ``np.unique`` vote gives ties to the lowest class id)."""
    best, best_n = "", 0
    for name, n in names.items():
        if n > best_n:
            best, best_n = name, n
    return best


def _why(unknown: bool, written: str, counts: Counter[str], routed: Counter[str]) -> str:
    """Why a written label differs from the vote over ``counts`` (see LabelReader.summary)."""
    if unknown:
        return "unknown"
    top = max(counts.values())
    if counts.get(written, 0) == top:
        return "tie"
    if counts != routed:
        return "split"
    return "ranking"

"""Compound-query retrieval evaluation (the paper's Table 3, "full pool" columns).

For every operator: replay the event log into a fresh graph, then for every named compound

* **pool** (``n``): nodes targeted (mass > 0) by at least one event on each of the compound's
  positive belief predicates -- the elements the operator was asked about;
* **positives**: pool nodes for which the compound holds in ground truth: every belief literal
  from the ground-truth class (``truth(node, predicate)``, negated literals inverted) and every
  geometric literal from the ground-truth geometry (authoritative, computed once on a copy of the
  map carrying ground-truth labels; committed beliefs are *not* used there);
* **retrieved**: pool nodes with ``P(compound) > tau`` (strictly above, the commit rule; default 0.5) where belief components are
  the operator's probability (``operator.probability``, i.e. after its recalibration, if any) and
  the geometric components are the same ground-truth indicators;
* **F1** of retrieved vs. positives (``sgbelief.eval.metrics.retrieval_f1``).

Operators are independent once the pools and positives are fixed, so :func:`evaluate_sources` runs
one task per (source, operator) over processes or Ray (``sgbelief retrieval --workers N``) with the
same scores, in the same order, as :func:`evaluate_retrieval`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from sgbelief.adapters.scannet import ScanNetChannel, load_scenes
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.eval.formats import node_attributes, read_events, read_nodes, read_truth
from sgbelief.eval.metrics import retrieval_f1
from sgbelief.eval.parallel import run_scenes
from sgbelief.fusion.channel import RecordedChannel
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.api.operators import make_operator
from sgbelief.query.engine import BELIEF, GEOMETRIC, QueryEngine
from sgbelief.query.named import NamedQuery, load_query_set, named_queries
from sgbelief.query.relations import DEFAULT_REGISTRY, RelationConfig, RelationRegistry

__all__ = ["RetrievalData", "CompoundScore", "evaluate_retrieval", "scannet_retrieval_data",
           "suite_retrieval_data", "format_scores", "RetrievalSource", "RetrievalJob", "run_retrieval_job",
           "evaluate_sources", "retrieval_plans", "retrieved_sets", "replay_operator",
           "recorded_channel_factory"]


@dataclass
class RetrievalData:
    """Everything a retrieval evaluation needs.

    ``nodes``: node id -> attributes (geometry + ground-truth ``label``); ``truth(node, predicate)``
    -> bool: ground truth of a belief predicate; ``events``: validated event records
    (``sgbelief.eval.formats.EventRecord``); ``channel_factory()``: a fresh geometric channel per
    operator; ``vocabulary``: the SubsumptionTable; ``queries``: named compounds to score."""

    name: str
    nodes: dict[Any, dict[str, Any]]
    truth: Callable[[Any, str], bool]
    events: Sequence[Any]
    channel_factory: Callable[[], Any]
    vocabulary: Any
    queries: dict[str, NamedQuery]
    config: RelationConfig = field(default_factory=RelationConfig)


@dataclass(frozen=True)
class CompoundScore:
    """One (compound, operator) cell: pool size, positive rate, F1 at P > tau."""

    query: str
    title: str
    group: str
    operator: str
    n: int
    positives: int
    pos_rate: float
    retrieved: int
    tp: int
    fp: int
    fn: int
    precision: float
    recall: float
    f1: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _build_graph(nodes: Mapping[Any, Mapping[str, Any]], vocabulary: Any = None) -> SceneGraph:
    g = SceneGraph(vocabulary=vocabulary, create_nodes=True)
    for node, attrs in nodes.items():
        g.add_node(node, **dict(attrs))
    return g


def _event_obj(rec: Any, i: int) -> EvidenceEvent:
    if isinstance(rec, EvidenceEvent):
        return rec
    return EvidenceEvent.trusted(dict(rec.targets), rec.predicate, float(rec.confidence), rec.context, int(rec.t),
                                 rec.id or f"ev{i:08d}")


_Plans = tuple[dict[str, dict[Any, "bool | None"]], dict[str, tuple[NamedQuery, list[Any], set[Any]]]]


def _ground_truth_plans(data: RetrievalData, registry: RelationRegistry, gt_config: RelationConfig) -> _Plans:
    """Per compound: its pool and positives, plus the ground-truth geometric values (shared by all operators)."""
    gt_graph = _build_graph(data.nodes)
    gt_engine = QueryEngine(gt_graph, registry=registry, config=gt_config, require_evidence=False)

    # pools: nodes targeted with mass > 0 per predicate
    targeted: dict[str, set[Any]] = {}
    for rec in data.events:
        s = targeted.setdefault(rec.predicate, set())
        s.update(n for n, m in rec.targets.items() if m > 0)

    # ground truth of every compound over its pool, geometric values shared with the operators
    geo_values: dict[str, dict[Any, bool | None]] = {}
    plans: dict[str, tuple[NamedQuery, list[Any], set[Any]]] = {}
    for key, nq in data.queries.items():
        pos_beliefs = [lit.name for lit in nq.compound.literals if lit in nq.belief and not lit.negated]
        pool_set: set[Any] | None = None
        for p in pos_beliefs:
            pool_set = set(targeted.get(p, set())) if pool_set is None else pool_set & targeted.get(p, set())
        pool = sorted(pool_set or set(), key=str)
        positives: set[Any] = set()
        for node in pool:
            ok = True
            for lit in nq.compound.literals:
                if lit in nq.belief:
                    val: bool | None = bool(data.truth(node, lit.name))
                else:
                    vals = geo_values.setdefault(lit.name, {})
                    if node not in vals:
                        vals[node] = gt_engine.geometric(node, lit.name) if node in data.nodes else None
                    val = vals[node]
                if val is None or val == lit.negated:
                    ok = False
                    break
            if ok:
                positives.add(node)
        plans[key] = (nq, pool, positives)
    # fill the remaining geometric values of pool nodes (short-circuit above may have skipped some)
    for key, (nq, pool, _) in plans.items():
        for lit in nq.geometric:
            vals = geo_values.setdefault(lit.name, {})
            for node in pool:
                if node not in vals:
                    vals[node] = gt_engine.geometric(node, lit.name) if node in data.nodes else None
    return geo_values, plans


def retrieval_plans(data: RetrievalData, registry: RelationRegistry | None = None) -> _Plans:
    """``(geometric values, {query: (named query, pool, positives)})``: the pools and ground truth
    every operator is scored on (see the module docstring)."""
    return _ground_truth_plans(data, registry or DEFAULT_REGISTRY, replace(data.config, use_committed_labels=False))


def replay_operator(data: RetrievalData, op_name: Any, operator_config: Any = None) -> tuple[Any, SceneGraph]:
    """``(operator, graph)`` after replaying the events through one operator on a fresh graph."""
    graph = _build_graph(data.nodes, data.vocabulary)
    op = make_operator(op_name, operator_config, data.vocabulary)
    channel = data.channel_factory()
    for i, rec in enumerate(data.events):
        op.update(graph, _event_obj(rec, i), channel)
    return op, graph


def retrieved_sets(data: RetrievalData, op: Any, graph: Any, plans: _Plans, *, tau: float = 0.5,
                   registry: RelationRegistry | None = None) -> dict[str, set[Any]]:
    """Per compound, the pool nodes with ``P(compound) > tau`` under ``op``'s beliefs on ``graph``."""
    geo_values, compound_plans = plans
    gt_config = replace(data.config, use_committed_labels=False)
    engine = QueryEngine(graph, registry=registry or DEFAULT_REGISTRY, config=gt_config, tau=tau,
                         require_evidence=False, probability=lambda n, p, _op=op, _g=graph: _op.probability(_g, n, p))
    for name, vals in geo_values.items():
        engine.preload_geometric(name, vals)
    out: dict[str, set[Any]] = {}
    for key, (nq, pool, _positives) in compound_plans.items():
        compound, kinds = nq.compound, {lit.name: (BELIEF if lit in nq.belief else GEOMETRIC)
                                        for lit in nq.compound.literals}
        retrieved = set()
        for node in pool:
            m = engine.score(node, compound, kinds, prune=True, tau=tau)
            if m is not None and m.retrieved:
                retrieved.add(node)
        out[key] = retrieved
    return out


def _score_operator(data: RetrievalData, op_name: Any, plans: _Plans, *, tau: float, operator_config: Any,
                    registry: RelationRegistry, gt_config: RelationConfig) -> list[CompoundScore]:
    """Replay the events through one operator on a fresh graph and score every compound."""
    _geo_values, compound_plans = plans
    op, graph = replay_operator(data, op_name, operator_config)
    found = retrieved_sets(replace(data, config=gt_config), op, graph, plans, tau=tau, registry=registry)
    scores: list[CompoundScore] = []
    for key, (nq, pool, positives) in compound_plans.items():
        retrieved = found[key]
        s = retrieval_f1(retrieved, positives)
        n = len(pool)
        scores.append(CompoundScore(key, nq.title, nq.group, op_name if isinstance(op_name, str) else op.name,
                                    n, len(positives), (len(positives) / n if n else 0.0), len(retrieved),
                                    s.tp, s.fp, s.fn, s.precision, s.recall, s.f1))
    return scores


def evaluate_retrieval(data: RetrievalData, operators: Iterable[str], *, tau: float = 0.5,
                       operator_config: Any = None, registry: RelationRegistry | None = None,
                       progress: Any = None) -> list[CompoundScore]:
    """Scores for every (named compound, operator); see the module docstring for the definitions.

    ``progress``, if given, is called with each operator's name once it is scored."""
    registry = registry or DEFAULT_REGISTRY
    gt_config = replace(data.config, use_committed_labels=False)
    plans = _ground_truth_plans(data, registry, gt_config)
    scores: list[CompoundScore] = []
    for op_name in operators:
        scores += _score_operator(data, op_name, plans, tau=tau, operator_config=operator_config,
                                  registry=registry, gt_config=gt_config)
        if progress is not None:
            progress(op_name)
    return scores


# ---------------------------------------------------------------- many sources / operators in parallel
@dataclass(frozen=True)
class RetrievalSource:
    """A picklable description of one retrieval dataset, loaded where it is evaluated.

    ``kind="suite"``: ``path`` is a simulated suite folder; ``kind="scannet"``: ``path`` holds the
    ScanNet scene folders and ``events`` the event log (``labels``/``channel`` as in
    :func:`scannet_retrieval_data`)."""

    kind: str
    path: str
    events: str | None = None
    vocab: str | None = None
    queries: str | None = None
    labels: str | None = None
    channel: str = "scannet"

    def load(self) -> RetrievalData:
        if self.kind == "suite":
            return suite_retrieval_data(self.path, self.vocab, queries=self.queries)
        if self.kind == "scannet":
            if self.events is None:
                raise ValueError("a ScanNet retrieval source needs an event log")
            return scannet_retrieval_data(self.path, self.events, self.vocab or "scannet", labels=self.labels,
                                          queries=self.queries or "scannet", channel=self.channel)
        raise ValueError(f"unknown retrieval source kind {self.kind!r} (suite | scannet)")


@dataclass(frozen=True)
class RetrievalJob:
    """One (source, operator) cell of a retrieval run: the unit ``evaluate_sources`` fans out."""

    source: RetrievalSource
    operator: str
    tau: float = 0.5
    operator_config: str | None = None  # YAML path (None: the default configuration)


#: per process: the last loaded source with its ground-truth plans (a worker usually gets several
#: operators of the same source in a row)
_LOADED: dict[RetrievalSource, tuple[RetrievalData, _Plans, RelationConfig]] = {}


def _load_planned(source: RetrievalSource) -> tuple[RetrievalData, _Plans, RelationConfig]:
    hit = _LOADED.get(source)
    if hit is None:
        data = source.load()
        gt_config = replace(data.config, use_committed_labels=False)
        hit = (data, _ground_truth_plans(data, DEFAULT_REGISTRY, gt_config), gt_config)
        _LOADED.clear()
        _LOADED[source] = hit
    return hit


def run_retrieval_job(job: RetrievalJob) -> tuple[str, list[CompoundScore]]:
    """(source name, scores of the job's operator): module-level, so it runs in a worker or a Ray task."""
    data, plans, gt_config = _load_planned(job.source)
    scores = _score_operator(data, job.operator, plans, tau=job.tau, operator_config=job.operator_config,
                             registry=DEFAULT_REGISTRY, gt_config=gt_config)
    return data.name, scores


def evaluate_sources(sources: Sequence[RetrievalSource], operators: Sequence[str], *, tau: float = 0.5,
                     operator_config: str | None = None, workers: int = 1,
                     executor: str = "local") -> list[tuple[str, list[CompoundScore]]]:
    """``[(source name, scores)]`` per source, every (source, operator) evaluated independently over
    ``workers`` processes or Ray (:func:`sgbelief.eval.parallel.run_scenes`); same scores, in the
    same order, as :func:`evaluate_retrieval` on each source."""
    jobs = [RetrievalJob(src, op, tau, operator_config) for src in sources for op in operators]
    try:
        results = run_scenes(run_retrieval_job, jobs, workers=workers, executor=executor)
    finally:
        _LOADED.clear()  # a serial run loaded the sources in this process
    out: list[tuple[str, list[CompoundScore]]] = []
    k = 0
    for _src in sources:
        name, scores = "", []
        for _op in operators:
            name, part = results[k]
            scores += part
            k += 1
        out.append((name, scores))
    return out


def format_scores(scores: Sequence[CompoundScore], title: str = "") -> str:
    """Text table: one row per compound; n, pos %, then F1 per operator."""
    ops: list[str] = []
    for s in scores:
        if s.operator not in ops:
            ops.append(s.operator)
    by_q: dict[str, dict[str, CompoundScore]] = {}
    for s in scores:
        by_q.setdefault(s.query, {})[s.operator] = s
    w = max([len("compound")] + [len(next(iter(d.values())).title) for d in by_q.values()])
    head = f"{'compound'.ljust(w)}  {'n':>6}  {'pos %':>6}  " + "  ".join(f"{o:>11}" for o in ops)
    lines = ([title] if title else []) + [head, "-" * len(head)]
    group = None
    for d in by_q.values():
        first = next(iter(d.values()))
        if first.group != group and first.group:
            group = first.group
            lines.append(f"[{group}]")
        cells = "  ".join(f"{_f1_cell(d[o].f1):>11}" if o in d else f"{'':>11}" for o in ops)
        lines.append(f"{first.title.ljust(w)}  {first.n:>6d}  {100 * first.pos_rate:>6.1f}  {cells}")
    lines.append("(F1 at P > tau over the full pool; n = nodes targeted by the VLM-typed predicate's events; "
                 "n/a: no positives in the pool, so F1 is undefined)")
    return "\n".join(lines)


def _f1_cell(f1: float) -> str:
    """An F1 as the tables print it: n/a where it is undefined (a compound with no positives)."""
    return "n/a" if f1 != f1 else f"{f1:.3f}"


def _queries_for(spec: str | Path | Mapping[str, NamedQuery]) -> tuple[dict[str, NamedQuery], RelationConfig]:
    if isinstance(spec, Mapping):
        qs = dict(spec)
        cfg = next(iter(qs.values())).config if qs else RelationConfig()
        return qs, cfg
    p = Path(spec)
    if p.suffix in (".yaml", ".yml") or p.exists():
        qset = load_query_set(p)
        return qset.queries, qset.config
    qs = named_queries(str(spec))
    return qs, next(iter(qs.values())).config


def _load_vocab(vocab: Any) -> SubsumptionTable:
    return SubsumptionTable.resolve(vocab)


def scannet_retrieval_data(scenes: str | Path, events: str | Path, vocab: Any = "scannet", *,
                           labels: str | Path | None = None, queries: Any = "scannet",
                           channel: str = "scannet", max_distance: float = 0.05) -> RetrievalData:
    """Retrieval data from ScanNet scene folders + an event log addressing ``<sceneId>/<objectId>``.

    Ground truth: the aggregation's NYU40 labels (belief predicates: label in the vocabulary's
    positive set); geometry: the objects' boxes. ``channel``: 'scannet' (mesh-label oracle,
    :class:`~sgbelief.adapters.scannet.ScanNetChannel`) or 'recorded' (the events' ``geometric``)."""
    table = _load_vocab(vocab)
    loaded = load_scenes(scenes, labels)
    nodes: dict[Any, dict[str, Any]] = {}
    for sc in loaded:
        fz = sc.floor_z
        for oid, o in sorted(sc.objects.items()):
            nodes[sc.node_id(oid)] = {"centroid": o.centroid, "bbox": o.bbox, "label": o.nyu40_label,
                                      "raw_label": o.raw_label, "scene": sc.scene_id, "object_id": oid,
                                      "floor_z": fz}
    recs = read_events(events)
    qs, cfg = _queries_for(queries)

    def truth(node: Any, predicate: str) -> bool:
        lab = nodes.get(node, {}).get("label")
        return lab is not None and table.outcome(predicate, lab) == 1

    if channel == "scannet":
        def factory() -> Any:
            return _CachedChannel(ScanNetChannel(loaded, max_distance=max_distance))
    elif channel == "recorded":
        factory = _recorded_factory(recs)
    else:
        raise ValueError("channel must be 'scannet' or 'recorded'")
    return RetrievalData(f"scannet:{Path(scenes).name}", nodes, truth, recs, factory, table, qs, cfg)


class _CachedChannel:
    """Memoises a static channel's labels per node (mesh labels do not change over time)."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self._cache: dict[Any, str | None] = {}

    def label(self, node: Any, t: int) -> str | None:
        if node not in self._cache:
            self._cache[node] = self.inner.label(node, t)
        return self._cache[node]


def recorded_channel_factory(recs: Sequence[Any]) -> Callable[[], Any]:
    """A factory of fresh geometric channels replaying the events' recorded ``geometric`` labels."""
    return _recorded_factory(recs)


def _recorded_factory(recs: Sequence[Any]) -> Callable[[], Any]:
    def factory() -> Any:
        ch = RecordedChannel(hold=False)
        for rec in recs:
            for node, lab in (rec.geometric or {}).items():
                ch.record(node, rec.t, lab)
        return ch

    return factory


def suite_retrieval_data(suite: str | Path, vocab: Any = None, *, queries: Any = None) -> RetrievalData:
    """Retrieval data from a simulated suite folder holding ``nodes.json``, ``events.jsonl`` and
    ``truth.json`` (docs/formats.md). The channel replays the events' recorded ``geometric``
    labels; geometric predicates use the nodes' precomputed ``geometric_predicates`` when present
    and the registry otherwise. ``vocab`` defaults to scannet for all-indoor suites, else kitti360;
    ``queries`` defaults to the vocabulary's dataset name."""
    suite = Path(suite)
    for f in ("nodes.json", "events.jsonl", "truth.json"):
        if not (suite / f).is_file():
            raise FileNotFoundError(f"simulated suite {suite}: missing {f}")
    nf = read_nodes(suite / "nodes.json")
    if vocab is None:  # indoor suites use the ScanNet vocabulary, outdoor ones KITTI-360's
        kinds = {sc.kind for sc in nf.scenes.values()}
        vocab = "scannet" if kinds == {"indoor"} else "kitti360"
    table = _load_vocab(vocab)
    nodes: dict[Any, dict[str, Any]] = {}
    for nid, info in nf.nodes.items():
        nodes[nid] = node_attributes(info)
    truth_map = read_truth(suite / "truth.json")
    recs = read_events(suite / "events.jsonl")
    if queries is None:
        queries = getattr(table, "name", None) or "kitti360"
    qs, cfg = _queries_for(queries)

    def truth(node: Any, predicate: str) -> bool:
        return bool(truth_map.get(str(node), {}).get(predicate, 0))

    return RetrievalData(f"suite:{suite.name}", nodes, truth, recs, _recorded_factory(recs), table, qs, cfg)

"""Replay a logged evidence stream through several fusion operators side by side.

The stream is read once (incrementally, so logs larger than memory work) and every event is
applied to every operator's own scene graph; each operator's update time is measured on its own.
Metrics compare the end-of-stream maps with ground truth (truth is never shown to operators).
"""

from __future__ import annotations

import time
import warnings
from itertools import islice
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sgbelief._fast.gc import relaxed_gc
from sgbelief.api.operators import make_operator
from sgbelief.errors import FormatError, InputMismatchWarning, SgbeliefError, UnknownPredicateError
from sgbelief.eval.formats import EventRecord, ReadStats, iter_events
from sgbelief.eval.metrics import SetScores, brier_over_pairs, mean_iou, per_predicate_scores, without_positives
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.protocol import FusionOperator
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.fusion.registry import OPERATOR_NAMES


@dataclass
class OperatorRun:
    """One operator's end-of-stream map and its counters."""

    name: str
    operator: FusionOperator
    graph: SceneGraph
    seconds: float = 0.0
    events: int = 0

    @property
    def events_per_s(self) -> float:
        return self.events / self.seconds if self.seconds > 0 else float("nan")


@dataclass
class OperatorScores:
    """Replay metrics of one operator (the ``--json`` object of ``sgbelief replay``)."""

    per_predicate: dict[str, SetScores]
    mean_iou: float
    brier: float
    refusals: int
    quarantined: int
    released: int
    events: int
    events_per_s: float
    stats: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {
            "per_predicate": {
                p: {"iou": s.iou, "precision": s.precision, "recall": s.recall, "tp": s.tp, "fp": s.fp, "fn": s.fn}
                for p, s in self.per_predicate.items()
            },
            "mean_iou": self.mean_iou,
            "brier": self.brier,
            "refusals": self.refusals,
            "quarantined": self.quarantined,
            "released": self.released,
            "events": self.events,
            "events_per_s": self.events_per_s,
            "stats": dict(self.stats),
        }


def to_event(rec: EventRecord, fallback_id: str) -> tuple[EvidenceEvent, FrameLabels]:
    """An already-validated record as an (event, per-event geometric channel) pair."""
    ev = EvidenceEvent.trusted(rec.targets, rec.predicate, rec.confidence, rec.context, rec.t, rec.id or fallback_id)
    return ev, FrameLabels(rec.geometric)


def make_runs(
    operators: Sequence[str | FusionOperator],
    vocabulary: SubsumptionTable | None,
    config: OperatorConfig | None = None,
    *,
    strict: bool = True,
) -> list[OperatorRun]:
    runs = []
    for op in operators:
        inst = make_operator(op, config, vocabulary)
        graph = SceneGraph(vocabulary=vocabulary if (strict and vocabulary is not None) else None, create_nodes=True)
        runs.append(OperatorRun(inst.name, inst, graph))
    return runs


ENGINES = ("streaming", "batched", "auto")


def _batchable(run: OperatorRun) -> bool:
    """An operator that declares a pair rule (``pair_rule``), on a fresh graph: the batched engine
    gives its exact result."""
    g = run.graph
    return (
        run.operator.pair_rule is not None
        and run.events == 0
        and not len(g.nx) and not len(g.provenance) and g.clock == -1 and not g.meta
    )


def replay(
    records: Iterable[EventRecord],
    runs: Sequence[OperatorRun],
    *,
    line_of: ReadStats | None = None,
    source: object = None,
    progress: Any = None,
    engine: str = "streaming",
) -> list[OperatorRun]:
    """Apply every record to every run; errors name the line (from ``line_of.lines``) when known.

    ``engine``: ``streaming`` (event by event, records read incrementally), ``batched`` (the runs
    whose operator declares a pair rule, e.g. majority / naive_bayes / overwrite, go through
    :func:`sgbelief._fast.batched.batched_replay`, bit-identical and faster (README's performance table has the measured figures); the other runs stream; records are held in memory; event times
    must not decrease) or ``auto`` (batched when the stream allows it, streaming otherwise). In every engine event times must not
    decrease: a log whose t goes back is rejected, naming the line.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    waves = [r for r in runs if engine != "streaming" and _batchable(r)]
    if not waves:
        return _stream(records, runs, line_of, source, progress)
    recs: list[EventRecord] = []
    lines: list[int] = []
    for rec in records:
        recs.append(rec)
        lines.append(line_of.lines if line_of is not None else len(recs))
    back = next((i for i in range(1, len(recs)) if recs[i].t < recs[i - 1].t), None)
    if back is not None:
        raise FormatError(_time_goes_back(recs[back - 1].t, recs[back].t), path=source, line=lines[back])
    others = [r for r in runs if r not in waves]
    if others:
        _stream(recs, others, _Lines(lines), source, None)
    if waves:
        _waves(recs, lines, waves, source)
    if progress is not None:
        progress.update(len(recs))
    return runs


class _Lines:
    """Line numbers of already-read records, served in order as ``ReadStats.lines`` would be."""

    def __init__(self, lines: list[int]) -> None:
        self._it = iter(lines)
        self.lines = 0

    def advance(self) -> None:
        self.lines = next(self._it)


#: records per chunk handed to each run's ``update_many`` by the streaming engine
STREAM_CHUNK = 512


def _time_goes_back(before: int, after: int) -> str:
    """The one rule of both engines: event times in a log never decrease."""
    return f"event times must not decrease; t goes back from {before} to {after}"


def _stream(records: Iterable[EventRecord], runs: Sequence[OperatorRun], line_of: Any, source: object,
            progress: Any) -> list[OperatorRun]:
    """The streaming engine: every record to every run, in order. Records are read a chunk at a
    time; each run applies the chunk through its operator's ``update_many`` (which skips the
    per-target reports replay discards). Runs are independent, so the result is that of feeding
    each record to every run."""
    perf = time.perf_counter
    n = 0
    last_t = -1
    advance = line_of.advance if isinstance(line_of, _Lines) else None
    it = iter(records)
    with relaxed_gc():
        while True:
            chunk: list[tuple[EvidenceEvent, FrameLabels]] = []
            lines: list[int | None] = []
            for rec in islice(it, STREAM_CHUNK):
                n += 1
                if advance is not None:
                    advance()
                line = line_of.lines if line_of is not None else None
                if rec.t < last_t:
                    raise FormatError(_time_goes_back(last_t, rec.t), path=source, line=line)
                last_t = rec.t
                chunk.append(to_event(rec, f"line{line if line is not None else n}"))
                lines.append(line)
            if not chunk:
                break
            for run in runs:
                op = run.operator
                t0 = perf()
                done = op.stats["events"]
                try:
                    op.update_many(run.graph, chunk)
                except SgbeliefError as exc:
                    i = op.stats["events"] - done  # the events before the rejected one stay applied
                    raise FormatError(f"event {chunk[i][0].id!r} rejected by {run.name}: {exc}", path=source,
                                      line=lines[i]) from exc
                run.seconds += perf() - t0
                run.events += len(chunk)
            if progress is not None:
                progress.update(len(chunk))
    return runs


def _waves(recs: list[EventRecord], lines: list[int], runs: Sequence[OperatorRun], source: object) -> None:
    """The batched engine for the runs with a pair rule; each run's time includes columnarisation."""
    from sgbelief._fast.batched import EventColumns, batched_replay

    if any(r.graph.vocabulary is not None for r in runs):
        for rec, line in zip(recs, lines):
            for r in runs:
                if r.graph.vocabulary is not None and rec.predicate not in r.graph.vocabulary:
                    exc = UnknownPredicateError(rec.predicate, r.graph.vocabulary)
                    raise FormatError(f"event {rec.id or f'line{line}'!r} rejected by {r.name}: {exc}",
                                      path=source, line=line)
    t0 = time.perf_counter()
    named = [rec if rec.id is not None else rec._replace(id=f"line{line}") for rec, line in zip(recs, lines)]
    cols = EventColumns.from_records(named)
    t_cols = time.perf_counter() - t0
    for run in runs:
        t0 = time.perf_counter()
        batched_replay(cols, run.operator, graph=run.graph)  # counts into run.operator.stats
        run.seconds += t_cols + time.perf_counter() - t0
        run.events += len(recs)


def require_events(stats: ReadStats, source: object) -> None:
    """An evidence log that yielded no event is an error (nothing to score, nothing worth saving
    over an existing map): raise :class:`FormatError` naming the file."""
    if stats.events == 0:
        why = f"all {stats.skipped} event lines were malformed and skipped" if stats.skipped else "the log is empty"
        raise FormatError(f"no evidence events to replay ({why}; {stats.lines} lines read)", path=source)


def evidence_nodes(runs: Sequence[OperatorRun]) -> set[Any]:
    """The nodes some run holds evidence on (a provenance entry): the nodes the log scored."""
    return {node for r in runs for node, _ in r.graph.provenance.pairs()}


def _examples(nodes: Iterable[Any], k: int = 3) -> str:
    shown = sorted(map(str, nodes))
    return ", ".join(shown[:k]) + (", ..." if len(shown) > k else "")


def check_coverage(kind: str, covered: Collection[Any], log_nodes: Collection[Any], *, path: object,
                   log: object, missing_means: str) -> int:
    """How much of the log a second input file (a truth or a nodes file) describes.

    ``covered``: the node ids the file has; ``log_nodes``: the nodes the evidence log holds
    evidence on. No shared node is a :class:`FormatError` naming the file (a file of another
    scene or suite); a partial overlap is an :class:`InputMismatchWarning` with the counts, saying
    what happens to the uncovered nodes (``missing_means``). Returns how many log nodes it covers."""
    shared = sum(1 for n in log_nodes if n in covered)
    if log_nodes and not shared:
        raise FormatError(
            f"{kind} shares no node with the evidence log {log} ({len(covered)} nodes here, e.g. "
            f"{_examples(covered) or 'none'}; {len(log_nodes)} in the log, e.g. {_examples(log_nodes)}): "
            "is it the file of another scene or suite?", path=path)
    if shared < len(log_nodes):
        lacking = [n for n in log_nodes if n not in covered]
        warnings.warn(InputMismatchWarning(
            f"{path}: {len(lacking)} of the {len(log_nodes)} nodes with evidence in {log} are not in this {kind} "
            f"(e.g. {_examples(lacking)}); {missing_means}"), stacklevel=2)
    return shared


def replay_file(
    events: str | Path,
    operators: Sequence[str | FusionOperator] = OPERATOR_NAMES,
    vocabulary: SubsumptionTable | None = None,
    config: OperatorConfig | None = None,
    *,
    skip_bad_lines: bool = False,
    progress: Any = None,
) -> tuple[list[OperatorRun], ReadStats]:
    """Replay an ``events.jsonl`` file (streamed) through the chosen operators."""
    stats = ReadStats()
    runs = make_runs(operators, vocabulary, config)
    replay(iter_events(events, skip_bad_lines=skip_bad_lines, stats=stats), runs, line_of=stats, source=events, progress=progress)
    return runs, stats


def graph_probabilities(graph: SceneGraph, truth: Mapping[str, Mapping[str, int]]) -> dict[str, dict[str, float]]:
    """End-of-stream posterior means for the (node, predicate) pairs truth mentions."""
    prov = graph.provenance
    return {node: {p: prov.mean(node, p) for p in row} for node, row in truth.items()}


def score_run(
    run: OperatorRun,
    truth: Mapping[str, Mapping[str, int]],
    predicates: Sequence[str] | None = None,
    *,
    tau: float = 0.5,
) -> OperatorScores:
    """Per-predicate IoU/precision/recall at tau, mean IoU, Brier over pairs with evidence, queue counts."""
    preds = list(predicates) if predicates is not None else sorted({p for row in truth.values() for p in row})
    probs = graph_probabilities(run.graph, truth)
    per = per_predicate_scores(probs, truth, preds, tau=tau)
    brier = brier_over_pairs(probs, truth, [k for k in run.graph.provenance.pairs() if k[1] in preds])
    stats = dict(run.operator.stats)
    return OperatorScores(
        per_predicate=per,
        mean_iou=mean_iou(per),
        brier=brier,
        refusals=stats.get("refused", 0),
        quarantined=stats.get("quarantined", 0),
        released=stats.get("released", 0),
        events=run.events,
        events_per_s=run.events_per_s,
        stats=stats,
    )


def format_table(scores: Mapping[str, OperatorScores], predicates: Sequence[str]) -> str:
    """A fixed-width text table: one row per operator."""
    short = [p.removeprefix("is_")[:12] for p in predicates]
    head = f"{'operator':<12}" + "".join(f"{s + ' IoU/P/R':>24}" for s in short)
    head += f"{'mIoU':>7}{'Brier':>8}{'refused':>9}{'quar.':>7}{'rel.':>6}{'events/s':>11}"
    lines = [head, "-" * len(head)]
    for name, sc in scores.items():
        row = f"{name:<12}"
        for p in predicates:
            s = sc.per_predicate[p]
            row += f"{_num(s.iou):>10}/{_num(s.precision)}/{_num(s.recall)}"
        row += f"{_num(sc.mean_iou):>7}{_num(sc.brier, 4):>8}{sc.refusals:>9d}{sc.quarantined:>7d}{sc.released:>6d}{sc.events_per_s:>11.0f}"
        lines.append(row)
    note = no_positives_note(scores, predicates)
    return "\n".join(lines + ([note] if note else []))


def _num(x: float, digits: int = 3) -> str:
    """A score as the tables print it: n/a where it is undefined (nan)."""
    return "n/a" if x != x else f"{x:.{digits}f}"


def no_positives_note(scores: Mapping[str, OperatorScores], predicates: Sequence[str]) -> str:
    """The line under a score table naming the predicates with no positives in the truth (IoU and
    recall n/a, left out of mIoU); empty when every predicate has some. Positives depend on the
    truth alone, so any operator's scores tell."""
    first = next(iter(scores.values()), None)
    if first is None:
        return ""
    empty = without_positives({p: first.per_predicate[p] for p in predicates})
    if not empty:
        return ""
    verb = "has" if len(empty) == 1 else "have"
    return (f"n/a: {', '.join(empty)} {verb} no positives in the truth file (no node is one), so IoU and recall "
            f"are undefined there; left out of mIoU")


# ------------------------------------------------------------------ many scenes
@dataclass
class SceneJob:
    """One scene's replay, picklable so it can run in a worker process or a Ray task."""

    events: str
    operators: tuple[str, ...]
    vocab: str
    config: dict[str, Any] | None = None
    strict: bool = True
    skip_bad_lines: bool = False
    save_graph: str | None = None
    graph_format: str = "json"
    engine: str = "streaming"


@dataclass
class SceneResult:
    """Per-operator end-of-stream probabilities of the pairs a scene's graph holds, and counters."""

    events: str
    n_events: int
    skipped: int
    probabilities: dict[str, dict[str, dict[str, float]]]  # operator -> node -> predicate -> p
    evidence_pairs: dict[str, list[tuple[str, str]]]
    stats: dict[str, dict[str, int]]
    seconds: dict[str, float]


def replay_scene(job: SceneJob) -> SceneResult:
    """Replay one scene's ``events.jsonl`` through the job's operators (module-level: picklable)."""
    vocab = SubsumptionTable.resolve(job.vocab)
    config = OperatorConfig.from_mapping(job.config) if job.config is not None else OperatorConfig.default()
    stats = ReadStats()
    runs = make_runs(list(job.operators), vocab, config, strict=job.strict)
    replay(iter_events(job.events, skip_bad_lines=job.skip_bad_lines, stats=stats), runs, line_of=stats, source=job.events,
           engine=job.engine)
    require_events(stats, job.events)  # before any graph is saved
    probs: dict[str, dict[str, dict[str, float]]] = {}
    pairs: dict[str, list[tuple[str, str]]] = {}
    for r in runs:
        prov = r.graph.provenance
        d: dict[str, dict[str, float]] = {}
        for node, pred in prov.pairs():
            d.setdefault(node, {})[pred] = prov.mean(node, pred)
        probs[r.name] = d
        pairs[r.name] = list(prov.pairs())
        if job.save_graph:
            r.graph.save(Path(job.save_graph) / r.name / Path(job.events).parent.name, format=job.graph_format)
    return SceneResult(
        job.events, stats.events, stats.skipped, probs, pairs,
        {r.name: dict(r.operator.stats) for r in runs}, {r.name: r.seconds for r in runs},
    )


def pool_scene_scores(
    results: Sequence[SceneResult], truth: Mapping[str, Mapping[str, int]], predicates: Sequence[str], *, tau: float = 0.5,
) -> dict[str, OperatorScores]:
    """Metrics over the union of several scenes (node ids are unique across scenes)."""
    if not results:
        return {}
    out: dict[str, OperatorScores] = {}
    for name in results[0].probabilities:
        probs: dict[str, dict[str, float]] = {}
        pairs: list[tuple[str, str]] = []
        stats: dict[str, int] = {}
        seconds = 0.0
        for res in results:
            for node, row in res.probabilities[name].items():
                probs.setdefault(node, {}).update(row)
            pairs += [p for p in res.evidence_pairs[name] if p[1] in predicates]
            for k, v in res.stats[name].items():
                stats[k] = stats.get(k, 0) + v
            seconds += res.seconds[name]
        n = sum(r.n_events for r in results)
        per = per_predicate_scores(probs, truth, predicates, tau=tau)
        out[name] = OperatorScores(
            per_predicate=per, mean_iou=mean_iou(per), brier=brier_over_pairs(probs, truth, pairs),
            refusals=stats.get("refused", 0), quarantined=stats.get("quarantined", 0), released=stats.get("released", 0),
            events=n, events_per_s=n / seconds if seconds > 0 else float("nan"), stats=stats,
        )
    return out

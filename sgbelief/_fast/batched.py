"""Private: vectorised (numpy) replay of the pair-local baselines: the same final map, many times faster.

The streaming engine applies one event at a time. When an operator declares a pair-local rule
(``operator.pair_rule``, a :class:`~sgbelief.fusion.protocol.LinearRule` or
:class:`~sgbelief.fusion.protocol.ResetRule`: ``majority``, ``naive_bayes``, ``overwrite``), the
increment at (v, phi) depends only on the event and on that pair's own state, so a stream can
instead be applied in *waves*: wave j holds the j-th entry of every (v, phi) pair, so the pairs of
one wave are distinct and the wave is one numpy operation. Every pair still sees its increments in
stream order, and the rule object is the operator's own (its arithmetic runs on arrays), so the
running (alpha, beta) are bit-identical to the streaming ones.

The provenance store is rebuilt exactly as the streaming store holds it at the end of the
stream, and only what survives compaction becomes Python objects: one ``compacted`` bucket per
pair (the staged ``math.fsum`` of the store, :func:`sgbelief._fast.folds.group_fsums`), the live
entries of the last T_prov steps (logs, event index, timeline) and the bounded memory of
compacted event ids, filled in the order the streaming store fills it (:func:`_remember`).
Node order, pair order, clock, compaction epoch (the operator's
:class:`~sgbelief.fusion.operators.compaction.CompactionSchedule`) and operator stats
(:data:`~sgbelief.fusion.protocol.STAT_KEYS`) match too (tests/test_batched.py compares
everything, floats bit for bit). The store is filled in :func:`_install`, through the builder
methods of its object log (``prov.object_log()``).

``cal`` / ``comod`` declare no pair rule: their increments depend on a calibration buffer shared
by all pairs, which every outcome changes, so events cannot be reordered across pairs.

Usage::

    cols = EventColumns.from_records(records)        # columnarise once
    graph, stats = batched_replay(cols, operator)    # an operator with a pair_rule (or its name)
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from itertools import chain, repeat
from operator import attrgetter
from typing import Any, Protocol

import numpy as np

from sgbelief._fast.folds import group_fsums
from sgbelief._fast.gc import relaxed_gc
from sgbelief.errors import DuplicateEventError, UnknownNodeError, UnknownPredicateError
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.operators.compaction import CompactionSchedule
from sgbelief.fusion.protocol import FusionOperator, LinearRule, PairRule, ResetRule, increment_stance, new_stats
from sgbelief.fusion.registry import make_reference_operator
from sgbelief.graph.compaction import FoldSummary, merge_into_bucket
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance import EntryStatus, ProvenanceEntry
from sgbelief.graph.scene_graph import SceneGraphModel


class Record(Protocol):
    """What columnarisation reads of a record (an ``EventRecord``, or an ``EvidenceEvent``)."""

    t: int
    targets: Mapping[Any, float]
    predicate: str
    confidence: float
    id: str | None


class _FirstSeen(dict):  # type: ignore[type-arg]
    """key -> dense code, assigned in first-lookup order (``map(index.__getitem__, keys)`` runs in C)."""

    def __missing__(self, key: Any) -> int:
        code = self[key] = len(self)
        return code


@dataclass
class EventColumns:
    """A stream as flat arrays, one row per (event, target) entry, in stream order.

    ``pair`` indexes ``pairs`` (distinct (node, predicate) keys, in any order); ``event``
    indexes ``event_ids`` / ``event_t``. ``unique_ids`` records whether no event id repeats
    (``from_records`` checks it once per stream; None: each replay checks it).
    """

    event_ids: list[str]
    event_t: np.ndarray  # int64, per event
    predicates: list[str]  # distinct predicates
    pairs: list[tuple[Any, str]]
    pair: np.ndarray  # int64, per entry
    event: np.ndarray  # int64, per entry
    mass: np.ndarray  # float64, per entry
    conf: np.ndarray  # float64, per entry
    unique_ids: bool | None = None

    @property
    def n_events(self) -> int:
        return len(self.event_ids)

    @classmethod
    @relaxed_gc()
    def from_records(cls, records: Iterable[Record]) -> EventColumns:
        """Columnarise records; ids default to ``line<n>`` (1-based) as in the streaming replay.

        Every per-record or per-target step is a C-level ``map``/``fromiter`` pass (no Python
        loop body); pair codes come from dense (node, predicate) codes.
        """
        recs = records if isinstance(records, (list, tuple)) else list(records)
        n = len(recs)
        event_t = np.fromiter(map(attrgetter("t"), recs), dtype=np.int64, count=n)
        conf_ev = np.fromiter(map(attrgetter("confidence"), recs), dtype=np.float64, count=n)
        targets = list(map(attrgetter("targets"), recs))
        ids = list(map(attrgetter("id"), recs))
        if not all(ids):  # missing ids, named as replay() names them
            ids = [eid or f"line{i}" for i, eid in enumerate(ids, 1)]
        n_targets = np.fromiter(map(len, targets), dtype=np.int64, count=n)
        m = int(n_targets.sum())
        node_index, pred_index = _FirstSeen(), _FirstSeen()
        node = np.fromiter(map(node_index.__getitem__, chain.from_iterable(targets)), dtype=np.int64, count=m)
        pred_ev = np.fromiter(map(pred_index.__getitem__, map(attrgetter("predicate"), recs)), dtype=np.int64, count=n)
        mass = np.fromiter(chain.from_iterable(map(dict.values, targets)), dtype=np.float64, count=m)
        event = np.repeat(np.arange(n, dtype=np.int64), n_targets)
        n_pred = max(len(pred_index), 1)
        code = node * n_pred + pred_ev[event]
        space = len(node_index) * n_pred
        if space <= 4 * m + 1024:  # a dense table of the codes in use
            used = np.bincount(code, minlength=space) > 0
            pair = (np.cumsum(used) - 1)[code]
            uniq = np.flatnonzero(used)
        else:
            uniq, pair = np.unique(code, return_inverse=True)
        nodes, preds = list(node_index), list(pred_index)
        pairs = [(nodes[u // n_pred], preds[u % n_pred]) for u in uniq.tolist()]
        return cls(ids, event_t, preds, pairs, pair.astype(np.int64, copy=False), event, mass, conf_ev[event],
                   len(set(ids)) == n)


# ------------------------------------------------------------------ numpy helpers
def _stable_argsort(keys: np.ndarray, n_keys: int) -> np.ndarray:
    """Stable argsort of non-negative int keys < n_keys, by 16-bit radix passes when they fit."""
    if n_keys <= 1 << 16:
        return np.argsort(keys.astype(np.uint16), kind="stable")
    if n_keys <= 1 << 32:
        lo = np.argsort((keys & 0xFFFF).astype(np.uint16), kind="stable")
        hi = np.argsort((keys[lo] >> 16).astype(np.uint16), kind="stable")
        return lo[hi]
    return np.argsort(keys, kind="stable")


def _starts(keys: np.ndarray) -> np.ndarray:
    """Indices where a run of equal consecutive keys begins."""
    if len(keys) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])


class _Waves:
    """Elements grouped into rows (element order kept within a row), visited wave by wave.

    Rows are ranked longest first (``rows``) and ``order`` lists the elements row by row in that
    rank order, so wave j (the j-th element of every row that has one) covers the first
    ``width[j]`` rows and sits at ``order[start[:width[j]] + j]``.
    """

    def __init__(self, row: np.ndarray, n_rows: int, *, contiguous: bool = False) -> None:
        """``contiguous``: each row's elements are already adjacent (rows in any order), ``order`` is then None."""
        if contiguous:
            first = _starts(row)
            ids, size = row[first], np.diff(np.r_[first, len(row)])
        else:
            sizes = np.bincount(row, minlength=n_rows)
            ids = np.flatnonzero(sizes)
            size = sizes[ids]
        longest = int(size.max(initial=0))
        rank = _stable_argsort(longest - size, longest + 1)
        self.rows = ids[rank]
        size = size[rank]
        self.order: np.ndarray | None
        if contiguous:
            self.order, self.start = None, first[rank]
        else:
            rank_of = np.empty(n_rows, dtype=np.int64)
            rank_of[self.rows] = np.arange(len(self.rows))
            self.order = _stable_argsort(rank_of[row], len(self.rows))
            self.start = np.cumsum(size) - size
        self.width: list[int] = np.searchsorted(-size, -np.arange(longest), side="left").tolist()

    def arrange(self, values: np.ndarray) -> np.ndarray:
        """``values`` (one per element) in ``order``."""
        return values if self.order is None else values[self.order]

    def running_sums(self, columns: Sequence[np.ndarray], start: Sequence[float]) -> list[np.ndarray]:
        """Per column and row (``rows`` order): ``start`` + the row's values added one by one, left to right."""
        vals = [self.arrange(c) for c in columns]
        accs = [np.full(len(self.rows), s) for s in start]
        first = self.start
        for j, w in enumerate(self.width):
            at = first[:w] + j
            for acc, v in zip(accs, vals):
                acc[:w] += v[at]
        return accs


def _increments(rule: PairRule, mass: np.ndarray, conf: np.ndarray, waves: _Waves, a0: float,
                b0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(d_alpha, d_beta) per entry and final (alpha, beta) per row of ``waves``: the operator's own
    rule on arrays (the same floating-point expressions), in the same per-pair order."""
    if isinstance(rule, ResetRule):  # the increment depends on the pair's current belief: wave by wave
        ta, tb = rule.target(waves.arrange(conf), a0, b0)
        alpha, beta = np.full(len(waves.rows), a0), np.full(len(waves.rows), b0)
        da_w, db_w = np.empty(len(ta)), np.empty(len(ta))
        for j, w in enumerate(waves.width):
            at = waves.start[:w] + j
            d_a, d_b = ta[at] - alpha[:w], tb[at] - beta[:w]
            da_w[at], db_w[at] = d_a, d_b
            alpha[:w] += d_a
            beta[:w] += d_b
        da, db = np.empty(len(ta)), np.empty(len(ta))
        da[waves.order], db[waves.order] = da_w, db_w
        return da, db, alpha, beta
    p, q = rule.split(conf)  # LinearRule: d_alpha = T p, d_beta = T q
    da, db = mass * p, mass * q
    alpha, beta = waves.running_sums((da, db), (a0, b0))
    return da, db, alpha, beta


_Buckets = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _fold(waves: _Waves, pair: np.ndarray, n_pairs: int, fold_k: np.ndarray, t_entry: np.ndarray,
          da: np.ndarray, db: np.ndarray, n_fold: int) -> _Buckets:
    """The compacted bucket of every pair with folded entries, as ``ProvenanceStore.compact``
    leaves it: (pair, t, d_alpha, d_beta, n_folded) arrays.

    Each compaction adds the ``fsum`` of the pair's entries it folds to the bucket with another
    ``fsum`` (a stage); both are reproduced here without Python objects.
    """
    assert waves.order is not None
    folded = waves.order[waves.order < n_fold]  # row by row, (compaction, stream order) within
    fp, fk = pair[folded], fold_k[folded]
    g_start = np.flatnonzero(np.r_[True, (fp[1:] != fp[:-1]) | (fk[1:] != fk[:-1])])
    g_size = np.diff(np.r_[g_start, len(folded)])
    stages = _Waves(fp[g_start], n_pairs, contiguous=True)  # a pair's stages, compaction by compaction
    b_alpha, b_beta = stages.running_sums(
        (group_fsums(da[folded], g_start, g_size), group_fsums(db[folded], g_start, g_size)), (0.0, 0.0))
    # per pair (``stages.rows`` order): entries folded, and the t of the last one (t never decreases)
    p_first = _starts(fp)
    p_last = np.r_[p_first[1:], len(folded)] - 1
    at = np.empty(n_pairs, dtype=np.int64)
    at[fp[p_first]] = np.arange(len(p_first))
    rows = at[stages.rows]
    return (stages.rows, t_entry[folded[p_last]][rows], b_alpha, b_beta, (p_last - p_first + 1)[rows],
            folded[p_first][rows], folded[p_last][rows])


class _Laps:
    """CPU seconds (``time.process_time``) of consecutive named phases, into ``into`` unless None."""

    def __init__(self, into: dict[str, float] | None) -> None:
        self.into = into
        self.last = time.process_time()

    def __call__(self, name: str) -> None:
        if self.into is not None:
            now = time.process_time()
            self.into[name] = now - self.last
            self.last = now


# ------------------------------------------------------------------ event-id bookkeeping
@dataclass
class _IdRuns:
    """The events that recorded entries, regrouped by event id (ids may repeat), stream order
    within an id, with the life cycle of each id's list in the store's event index."""

    events: np.ndarray  # event index
    first_entry: np.ndarray  # index of the event's first entry (its entries are contiguous)
    fold: np.ndarray  # compaction that folds the event's entries (n_compactions: never)
    run: np.ndarray  # run number: the events of one id folded by one compaction share a run
    emptied: np.ndarray  # folding this event empties its id's list (the id is remembered)
    creator: np.ndarray  # event whose record created the id's list this event joined
    unique: bool  # every event id is distinct

    @classmethod
    def build(cls, cols: EventColumns, ev: np.ndarray, fold_k: np.ndarray, opens: np.ndarray) -> _IdRuns:
        first_entry = _starts(ev)
        events = ev[first_entry]
        ids = cols.event_ids
        unique = cols.unique_ids if cols.unique_ids is not None else len(set(ids)) == len(ids)
        if unique:
            code = events
        else:
            index = _FirstSeen()
            code = np.fromiter(map(index.__getitem__, ids), dtype=np.int64, count=len(ids))[events]
            order = _stable_argsort(code, len(index))
            events, first_entry, code = events[order], first_entry[order], code[order]
        fold = fold_k[first_entry]
        new_id = np.r_[True, code[1:] != code[:-1]]
        same_id_next = np.r_[~new_id[1:], False]
        next_event = np.r_[events[1:], 0]
        opened = np.r_[opens, np.iinfo(np.int64).max][fold]  # the event that ran the folding compaction
        # the list empties unless a later event of the id was recorded before that compaction
        emptied = (fold < len(opens)) & (~same_id_next | (next_event >= opened))
        creates = new_id | np.r_[False, emptied[:-1]]
        run = np.cumsum(new_id | np.r_[True, fold[1:] != fold[:-1]]) - 1
        creator = events[np.maximum.accumulate(np.where(creates, np.arange(len(events)), 0))]
        return cls(events, first_entry, fold, run, emptied, creator, unique)


def _remember(cap: int, cols: EventColumns, idr: _IdRuns, pair: np.ndarray, ev: np.ndarray,
              fold_k: np.ndarray, n_fold: int) -> list[str]:
    """The ids the bounded memory of compacted event ids (``cap`` of them) ends with, oldest
    first, exactly as the streaming store fills it.

    Compaction k visits its dirty pairs in the order their first folded entry arrived (stream
    order) and folds each pair's entries in log order; an id is released when the last live
    entry of its list is folded, and the memory keeps the last ``remember_compacted`` releases.
    Only the compactions whose ids stay in the memory need that order.
    """
    unit_fold = idr.fold[idr.emptied]  # one released id per emptied list
    n_rem = len(unit_fold)
    if cap <= 0 or n_rem == 0:
        return []
    k0 = int(np.sort(unit_fold)[n_rem - cap]) if n_rem > cap else 0
    lo = int(np.searchsorted(fold_k[:n_fold], k0, side="left"))  # entries folded from compaction k0 on
    n_sc = n_fold - lo
    sc_pair, sc_fold = pair[lo:n_fold], fold_k[lo:n_fold]
    # (pair, compaction) groups of those entries; a group's visit position is its first entry's
    # stream position (compactions fold in stream order, so this orders compaction by compaction)
    by_pair = _stable_argsort(sc_pair, len(cols.pairs))
    gp, gk = sc_pair[by_pair], sc_fold[by_pair]
    g_start = np.flatnonzero(np.r_[True, (gp[1:] != gp[:-1]) | (gk[1:] != gk[:-1])])
    group_of = np.empty(n_sc, dtype=np.int64)
    group_of[by_pair] = np.repeat(np.arange(len(g_start)), np.diff(np.r_[g_start, n_sc]))
    visit = by_pair[g_start]  # stream position of each group's first entry
    # an entry is folded at (visit position of its pair, stream position); an event with the
    # latest of its entries (they are contiguous); an id with the latest event of its run
    entry_key = visit[group_of] * n_sc + np.arange(n_sc)
    ev_start = _starts(ev[lo:n_fold])
    key_at = np.zeros(n_sc, dtype=np.int64)
    key_at[ev_start] = np.maximum.reduceat(entry_key, ev_start)
    in_scope = (idr.first_entry >= lo) & (idr.first_entry < n_fold)
    ev_key = np.where(in_scope, key_at[np.clip(idr.first_entry - lo, 0, n_sc - 1)], 0)
    unit_key = np.maximum.reduceat(ev_key, _starts(idr.run))[idr.run[idr.emptied]]
    sel = unit_fold >= k0
    unit_key, unit_fold = unit_key[sel], unit_fold[sel] - k0
    # visit positions grow with the compaction, so the key alone orders (compaction, key)
    order = np.argsort(unit_key, kind="stable")
    released_events = idr.events[idr.emptied][sel][order][-cap:]
    return list(map(cols.event_ids.__getitem__, released_events.tolist()))


def _index_live(cols: EventColumns, idr: _IdRuns, ev: np.ndarray, n_fold: int,
                live: list[ProvenanceEntry]) -> dict[str, ProvenanceEntry | list[ProvenanceEntry]]:
    """The event index of the live entries: per id, in the order the id's current list was created."""
    live_ev = ev[n_fold:]
    creator_of = np.empty(cols.n_events, dtype=np.int64)
    creator_of[idr.events] = idr.creator
    key = creator_of[live_ev]
    order = np.argsort(key, kind="stable")
    bounds = np.r_[_starts(key[order]), len(key)].tolist()
    owners = live_ev[order][bounds[:-1]].tolist()
    ordered = live if idr.unique else [live[i] for i in order.tolist()]
    by_event: dict[str, ProvenanceEntry | list[ProvenanceEntry]] = {}
    ids = cols.event_ids
    for owner, begin, end in zip(owners, bounds[:-1], bounds[1:]):
        # one entry: the entry itself (as ProvenanceStore.record builds the index)
        by_event[ids[owner]] = ordered[begin] if end - begin == 1 else ordered[begin:end]
    return by_event


def _first_live_duplicate(cols: EventColumns, ev: np.ndarray, fold_k: np.ndarray, opens: np.ndarray) -> int | None:
    """The first event whose id still has live entries when it arrives, or None: the event the
    streaming engine rejects (:func:`sgbelief.fusion.operators.base.check_admissible` runs before
    the event's own tick, so entries that its tick compacts are still live).

    Only the id's latest earlier event that recorded entries matters: compaction folds a time
    prefix, so when that one is folded every earlier one is."""
    ids = cols.event_ids
    unique = cols.unique_ids if cols.unique_ids is not None else len(set(ids)) == len(ids)
    if unique or not len(ev):
        return None
    n = cols.n_events
    index = _FirstSeen()
    code = np.fromiter(map(index.__getitem__, ids), dtype=np.int64, count=n)
    first = _starts(ev)  # each recording event's first entry (an event's entries fold together)
    folded_at = np.full(n, -1, dtype=np.int64)  # -1: recorded nothing
    folded_at[ev[first]] = np.r_[opens, n][fold_k[first]]  # the event whose tick folds them (n: never)
    order = _stable_argsort(code, len(index))  # by id, stream order within an id
    pos = np.arange(n)
    latest = np.maximum.accumulate(np.where(folded_at[order] >= 0, pos, -1))
    before = np.r_[-1, latest[:-1]]  # the latest earlier recording position (any id so far)
    group = np.maximum.accumulate(np.where(np.r_[True, code[order][1:] != code[order][:-1]], pos, 0))
    same_id = before >= group
    live = same_id & (folded_at[order][np.maximum(before, 0)] >= order)
    hits = order[live]
    return int(hits.min()) if len(hits) else None


# ------------------------------------------------------------------ the store
def _check_fresh(graph: SceneGraphModel) -> None:
    prov = graph.provenance
    if len(graph.nx) or len(prov) or prov.n_compacted or graph.clock != -1 or graph.meta:
        raise ValueError("batched replay fills an empty graph (no nodes, beliefs, clock or meta yet)")


def _install(prov: EntryLog, keys: list[tuple[Any, str]], alpha: list[float], beta: list[float],
             entries: list[list[ProvenanceEntry]], timeline: list[ProvenanceEntry],
             by_event: dict[str, ProvenanceEntry | list[ProvenanceEntry]], compacted_ids: list[str],
             n_compacted: int) -> None:
    """Write the rebuilt store into the (empty) ``prov``: per pair (in order) its (alpha, beta)
    and log entries, the timeline of live entries, the event index, the compacted-id memory and
    the compacted count, through the builder methods of the store's object log (the only place
    this engine fills the store)."""
    objects = prov.object_log()
    logs = objects.add_pairs(keys, alpha, beta)
    for log, pair_entries in zip(logs, entries):
        log.entries = pair_entries
    objects.extend_timeline(timeline)
    objects.index_events(by_event.items())
    objects.retire(compacted_ids, n_compacted)


# ------------------------------------------------------------------ replay
def _resolve(operator: FusionOperator | str, config: OperatorConfig | dict[str, Any] | None) -> FusionOperator:
    """The operator to replay: an instance as given, or a fresh one of that name with ``config``."""
    if isinstance(operator, str):
        return make_reference_operator(operator, config)
    if config is not None:
        raise ValueError("batched replay: give config= only with an operator name (an operator has its own)")
    return operator


@relaxed_gc()
def batched_replay(
    cols: EventColumns,
    operator: FusionOperator | str,
    vocabulary: SubsumptionTable | None = None,
    config: OperatorConfig | dict[str, Any] | None = None,
    *,
    strict: bool = True,
    graph: SceneGraphModel | None = None,
    timings: dict[str, float] | None = None,
) -> tuple[SceneGraphModel, dict[str, int]]:
    """Replay ``cols`` through an operator with a pair rule, in waves; returns (graph, the counters
    of this replay), the map and counters the streaming engine (``operator.update_many``) gives.

    ``operator``: a :class:`~sgbelief.fusion.protocol.FusionOperator` whose ``pair_rule`` is not
    None (its ``stats`` receive the counters, as ``update_many`` would count them), or the name of
    one (built with ``config``). ``graph``: an empty graph to fill instead (its vocabulary, prior
    and compacted-id memory bound apply; ``vocabulary``/``strict`` are then ignored). ``timings``:
    receives the CPU seconds of the phases ``apply`` (schedule, belief waves), ``fold`` (compacted
    buckets, in numpy), ``objects`` (nodes, logs, entries, event index) and ``memory`` (compacted
    ids, and writing the store). Needs non-decreasing event times (as in an events file); raises ValueError otherwise.
    """
    lap = _Laps(timings)
    op = _resolve(operator, config)
    rule = op.pair_rule
    if not isinstance(rule, (LinearRule, ResetRule)):
        raise ValueError(f"batched replay needs an operator with a pair rule; {op.name!r} has none "
                         f"(use the streaming engine)")
    cfg = op.config
    if graph is None:
        graph = SceneGraphModel(vocabulary=vocabulary if (strict and vocabulary is not None) else None, create_nodes=True)
    else:
        _check_fresh(graph)
        if not graph.create_nodes and cols.n_events and len(cols.pair):  # as check_admissible
            raise UnknownNodeError(cols.pairs[int(cols.pair[0])][0], cols.event_ids[int(cols.event[0])])
    if graph.vocabulary is not None:
        for pred in cols.predicates:
            if pred not in graph.vocabulary:
                raise UnknownPredicateError(pred, graph.vocabulary)
    t_ev = np.asarray(cols.event_t, dtype=np.int64)
    if np.any(t_ev[1:] < t_ev[:-1]):
        raise ValueError("batched replay needs non-decreasing event times t (use the streaming engine)")
    if np.any(cols.event[1:] < cols.event[:-1]):
        raise ValueError("EventColumns entries must be in stream order (event indices non-decreasing)")
    prov = graph.provenance
    a0, b0 = prov.prior_alpha, prov.prior_beta
    stats = new_stats()
    stats["events"] = cols.n_events
    stats["targets"] = len(cols.pair)
    if cols.n_events:
        _replay_waves(cols, rule, cfg.tau_t, CompactionSchedule.of(cfg), graph, a0, b0, stats, lap)
    own = op.stats
    for k, v in stats.items():
        own[k] = own.get(k, 0) + v
    return graph, stats


def _replay_waves(cols: EventColumns, rule: PairRule, tau_t: float, schedule: CompactionSchedule, graph: SceneGraphModel,
                  a0: float, b0: float, stats: dict[str, int], lap: _Laps) -> None:
    """The body of :func:`batched_replay` for a non-empty stream: fills ``graph`` and ``stats``."""
    t_ev = np.asarray(cols.event_t, dtype=np.int64)
    # ---- entries above the targeting threshold, in stream order
    keep = cols.mass > tau_t
    stats["below_tau_t"] = int(len(keep) - np.count_nonzero(keep))
    pair, ev = cols.pair[keep], cols.event[keep]
    t_entry = t_ev[ev]
    n = len(pair)
    n_pairs = len(cols.pairs)
    stats["committed"] = n

    # ---- time: clock and compaction schedule (a pass runs when an event opens a new epoch)
    epoch = schedule.epoch(t_ev)
    opens = np.flatnonzero(epoch > np.maximum.accumulate(np.r_[schedule.last_epoch(graph.meta), epoch[:-1]]))
    # entry e exists from its event on; compaction k folds it if k runs after that event and its
    # horizon exceeds e's t. Both bounds grow with the entry's position, so fold_k is
    # non-decreasing and the folded entries are a prefix of the stream.
    fold_k = np.maximum(np.searchsorted(opens, ev, side="right"),
                        np.searchsorted(schedule.horizon(t_ev[opens]), t_entry, side="right"))
    dup = _first_live_duplicate(cols, ev, fold_k, opens)
    if dup is not None:  # before any change, as the streaming engine's check_admissible
        raise DuplicateEventError(cols.event_ids[dup])
    graph.clock = max(int(t_ev[-1]), -1)
    if len(opens):
        schedule.record(graph.meta, int(epoch[opens[-1]]))
    if n == 0:
        return
    n_fold = int(np.count_nonzero(fold_k < len(opens)))
    stats["compacted"] = n_fold

    # ---- beliefs: waves of distinct pairs
    waves = _Waves(pair, n_pairs)
    da, db, alpha, beta = _increments(rule, cols.mass[keep], cols.conf[keep], waves, a0, b0)
    lap("apply")
    buckets = _fold(waves, pair, n_pairs, fold_k, t_entry, da, db, n_fold) if n_fold else None
    lap("fold")

    # ---- Python objects: nodes and logs in order of first appearance, buckets, live entries
    keys = cols.pairs
    assert waves.order is not None
    seq = np.argsort(waves.order[waves.start])  # rows by their first entry
    pair_seq = waves.rows[seq]
    seq_keys = list(map(keys.__getitem__, pair_seq.tolist()))
    new_nodes = list(dict.fromkeys(k[0] for k in seq_keys))
    for node in new_nodes:
        if isinstance(node, bool) or not isinstance(node, (str, int)):
            raise TypeError(f"node ids must be str or int (JSON-serialisable), got {type(node).__name__}")
    graph.nx.add_nodes_from(new_nodes)
    entries: list[list[ProvenanceEntry]] = [[] for _ in seq_keys]
    entries_of: dict[int, list[ProvenanceEntry]] = dict(zip(pair_seq.tolist(), entries))
    if buckets is not None:
        b_pair, b_t, b_alpha, b_beta, b_n, b_first, b_last = buckets
        # each pair's bucket as the store's fold makes it; what it folded: committed entries only
        # (pair rules commit every event)
        ids = cols.event_ids
        first_ids = list(map(ids.__getitem__, ev[b_first].tolist()))
        last_ids = list(map(ids.__getitem__, ev[b_last].tolist()))
        for p, t_max, d_alpha, d_beta, n_folded, t_first, first_id, last_id in zip(
                b_pair.tolist(), b_t.tolist(), b_alpha.tolist(), b_beta.tolist(), b_n.tolist(),
                t_entry[b_first].tolist(), first_ids, last_ids):
            node, predicate = keys[p]
            summary = FoldSummary.committed(n_folded, t_first, first_id, last_id)
            entries_of[p].append(merge_into_bucket(None, node, predicate, t_max, d_alpha, d_beta, n_folded, summary))
    # live entries (the last T_prov steps): logs, timeline, event index
    live_ev = ev[n_fold:]
    d_a, d_b = da[n_fold:], db[n_fold:]
    stance = increment_stance(d_a, d_b)
    live_pair = pair[n_fold:].tolist()
    live_keys = list(map(keys.__getitem__, live_pair))
    live = list(map(ProvenanceEntry, list(map(cols.event_ids.__getitem__, live_ev.tolist())),
                    t_entry[n_fold:].tolist(), d_a.tolist(), d_b.tolist(), repeat(EntryStatus.COMMITTED),
                    [k[0] for k in live_keys], [k[1] for k in live_keys], stance.tolist()))
    for p, entry in zip(live_pair, live):
        entries_of[p].append(entry)
    idr = _IdRuns.build(cols, ev, fold_k, opens)
    by_event = _index_live(cols, idr, ev, n_fold, live)
    lap("objects")
    prov = graph.provenance
    compacted_ids = _remember(prov.remember_compacted, cols, idr, pair, ev, fold_k, n_fold) if n_fold else []
    _install(prov, seq_keys, alpha[seq].tolist(), beta[seq].tolist(), entries, live, by_event, compacted_ids, n_fold)
    lap("memory")


__all__ = ["EventColumns", "batched_replay"]

"""Vectorised (numpy) replay of the count-based baselines: the same final map, many times faster.

The streaming engine (:mod:`sgbelief.eval.replay`) applies one event at a time. For the
baselines whose increment at (v, phi) depends only on the event and on that pair's own state
(``majority``, ``naive_bayes``, ``overwrite``), a stream can instead be applied in *waves*:
wave j holds the j-th entry of every (v, phi) pair, so the pairs of one wave are distinct and
the wave is one numpy operation. Every pair still sees its increments in stream order, so the
running (alpha, beta) are bit-identical to the streaming ones.

Provenance is rebuilt exactly as the streaming store would hold it at the end of the stream:
entries older than the last compaction horizon are folded into one ``compacted`` bucket per
pair with the same staged ``math.fsum`` (one fold per T_prov epoch), newer entries are
materialised as :class:`ProvenanceEntry` objects in arrival order, and the node order, pair
order, clock, compaction epoch and operator stats match. The only difference is the *order* in
which the bounded "recently compacted ids" memory was filled within one compaction (the
streaming store follows a set's iteration order there); its contents are the same.

``cal`` / ``comod`` are not batched: their increments depend on a calibration buffer shared by
all pairs, which every outcome changes, so events cannot be reordered across pairs.

Usage::

    cols = EventColumns.from_records(records)        # columnarise once (Python loop)
    graph, stats = batched_replay(cols, "majority", vocabulary)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sgbelief.errors import UnknownPredicateError
from sgbelief.eval.formats import EventRecord
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig, resolve_config
from sgbelief.graph.provenance import EntryStatus, ProvenanceEntry, _PairLog
from sgbelief.graph.scene_graph import SceneGraph

BATCHED_OPERATORS = ("majority", "naive_bayes", "overwrite")


@dataclass
class EventColumns:
    """A stream as flat arrays, one row per (event, target) entry, in stream order.

    ``pair`` indexes ``pairs`` ((node, predicate) in first-appearance order); ``event`` indexes
    ``event_ids`` / ``event_t``.
    """

    event_ids: list[str]
    event_t: np.ndarray  # int64, per event
    predicates: list[str]  # distinct predicates
    pairs: list[tuple[Any, str]]
    pair: np.ndarray  # int64, per entry
    event: np.ndarray  # int64, per entry
    mass: np.ndarray  # float64, per entry
    conf: np.ndarray  # float64, per entry

    @property
    def n_events(self) -> int:
        return len(self.event_ids)

    @classmethod
    def from_records(cls, records: Iterable[EventRecord]) -> EventColumns:
        """Columnarise records; ids default to ``line<n>`` (1-based) as in the streaming replay."""
        ids: list[str] = []
        ts: list[int] = []
        pair_index: dict[tuple[Any, str], int] = {}
        pairs: list[tuple[Any, str]] = []
        preds: dict[str, None] = {}
        p_col: list[int] = []
        e_col: list[int] = []
        m_col: list[float] = []
        c_col: list[float] = []
        for i, rec in enumerate(records):
            ids.append(rec.id or f"line{i + 1}")
            ts.append(rec.t)
            pred, c = rec.predicate, rec.confidence
            preds.setdefault(pred, None)
            for node, mass in rec.targets.items():
                key = (node, pred)
                k = pair_index.get(key)
                if k is None:
                    k = pair_index[key] = len(pairs)
                    pairs.append(key)
                p_col.append(k)
                e_col.append(i)
                m_col.append(mass)
                c_col.append(c)
        return cls(
            ids, np.asarray(ts, dtype=np.int64), list(preds), pairs,
            np.asarray(p_col, dtype=np.int64), np.asarray(e_col, dtype=np.int64),
            np.asarray(m_col, dtype=np.float64), np.asarray(c_col, dtype=np.float64),
        )


def _increments(op: str, cfg: OperatorConfig, mass: np.ndarray, conf: np.ndarray,
                alpha: np.ndarray, beta: np.ndarray, a0: float, b0: float) -> tuple[np.ndarray, np.ndarray]:
    """One wave's (d_alpha, d_beta), with the same floating-point expressions as the operators."""
    if op == "majority":
        return mass * conf, mass * (1.0 - conf)
    if op == "naive_bayes":
        r = cfg.baselines.naive_bayes.reliability
        p = r * conf + (1.0 - r) * (1.0 - conf)
        return mass * p, mass * (1.0 - p)
    s = cfg.baselines.overwrite.strength
    pos = conf >= 0.5
    ta = np.where(pos, a0 + s, a0)
    tb = np.where(pos, b0, b0 + s)
    return ta - alpha, tb - beta


def batched_replay(
    cols: EventColumns,
    operator: str,
    vocabulary: SubsumptionTable | None = None,
    config: OperatorConfig | dict[str, Any] | None = None,
    *,
    strict: bool = True,
) -> tuple[SceneGraph, dict[str, int]]:
    """Replay ``cols`` through a count-based baseline in waves; returns (graph, operator stats)
    equal to what ``make_runs([operator], vocabulary, config)`` + the streaming replay produce."""
    if operator not in BATCHED_OPERATORS:
        raise ValueError(f"batched replay supports {BATCHED_OPERATORS}, not {operator!r} (use the streaming engine)")
    cfg = resolve_config(config)
    graph = SceneGraph(vocabulary=vocabulary if (strict and vocabulary is not None) else None)
    if graph.vocabulary is not None:
        for pred in cols.predicates:
            if pred not in graph.vocabulary:
                raise UnknownPredicateError(pred, graph.vocabulary)
    prov = graph.provenance
    a0, b0 = prov.prior_alpha, prov.prior_beta
    stats = {k: 0 for k in ("events", "targets", "committed", "refused", "quarantined", "released",
                            "corroborated", "discarded", "resolved", "expired", "below_tau_t", "compacted")}
    stats["events"] = cols.n_events
    stats["targets"] = len(cols.pair)
    if cols.n_events == 0:
        return graph, stats

    # ---- entries above the targeting threshold, in stream order
    keep = cols.mass > cfg.tau_t
    stats["below_tau_t"] = int((~keep).sum())
    pair = cols.pair[keep]
    ev = cols.event[keep]
    mass = cols.mass[keep]
    conf = cols.conf[keep]
    t_entry = cols.event_t[ev]
    n = len(pair)
    stats["committed"] = n

    # ---- waves: rank of each entry within its pair (stable), then apply rank by rank
    order = np.argsort(pair, kind="stable")
    sorted_pairs = pair[order]
    starts = np.flatnonzero(np.r_[True, sorted_pairs[1:] != sorted_pairs[:-1]])
    counts = np.diff(np.r_[starts, n])
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n) - np.repeat(starts, counts)
    wave_order = np.lexsort((np.arange(n), rank))  # by rank, stream order within a wave
    wave_bounds = np.searchsorted(rank[wave_order], np.arange(int(rank.max()) + 2))
    n_pairs = len(cols.pairs)
    alpha = np.full(n_pairs, a0)
    beta = np.full(n_pairs, b0)
    da = np.empty(n)
    db = np.empty(n)
    for j in range(len(wave_bounds) - 1):
        sel = wave_order[wave_bounds[j]:wave_bounds[j + 1]]
        idx = pair[sel]
        d_a, d_b = _increments(operator, cfg, mass[sel], conf[sel], alpha[idx], beta[idx], a0, b0)
        da[sel] = d_a
        db[sel] = d_b
        alpha[idx] += d_a
        beta[idx] += d_b
    stance = np.where(da > db, 1, np.where(da < db, -1, 0))

    # ---- time: clock, compaction schedule (a compaction runs when an event opens a new epoch)
    t_ev = cols.event_t
    t_prov = cfg.t_prov
    epoch = t_ev // t_prov
    opens = np.flatnonzero(epoch > np.maximum.accumulate(np.r_[0, epoch[:-1]]))
    horizons = t_ev[opens] - t_prov  # compaction k folds every settled entry with t < horizons[k]
    graph.clock = int(t_ev[-1])
    if len(opens):
        graph.meta["compaction_epoch"] = int(epoch[opens[-1]])
    # entry e is recorded after the compactions of events <= its own event: it is folded by the
    # first later compaction whose horizon exceeds its t
    fold_k = np.full(n, -1, dtype=np.int64)
    if len(opens):
        first_after = np.searchsorted(opens, ev, side="right")  # compactions strictly after entry's event
        # horizons are non-decreasing, so the first compaction >= first_after with horizon > t
        hmax = np.maximum.accumulate(horizons)
        cand = np.searchsorted(hmax, t_entry, side="right")
        k = np.maximum(first_after, cand)
        fold_k = np.where(k < len(opens), k, -1)
    folded = fold_k >= 0
    stats["compacted"] = int(folded.sum())
    prov.n_compacted = stats["compacted"]

    # ---- materialise: nodes and pairs in first-appearance order
    pair_nodes = cols.pairs
    used = np.zeros(n_pairs, dtype=bool)
    used[pair] = True
    first_pos = np.full(n_pairs, n, dtype=np.int64)
    np.minimum.at(first_pos, pair, np.arange(n))
    pair_seq = np.flatnonzero(used)[np.argsort(first_pos[used], kind="stable")]
    gnx = graph.nx
    for k_pair in pair_seq.tolist():
        node = pair_nodes[k_pair][0]
        if node not in gnx:
            graph.add_node(node)
    logs: list[_PairLog | None] = [None] * n_pairs
    alpha_l, beta_l = alpha.tolist(), beta.tolist()
    for k_pair in pair_seq.tolist():
        log = _PairLog(alpha_l[k_pair], beta_l[k_pair])
        prov._pairs[pair_nodes[k_pair]] = log
        logs[k_pair] = log

    # compacted buckets: staged fsum, one stage per compaction that folded entries of the pair
    if folded.any():
        fi = np.flatnonzero(folded)
        grp = np.lexsort((fi, fold_k[fi], pair[fi]))
        fi = fi[grp]
        gp, gk = pair[fi], fold_k[fi]
        brk = np.flatnonzero(np.r_[True, (gp[1:] != gp[:-1]) | (gk[1:] != gk[:-1]), True])
        da_l, db_l, t_l = da[fi].tolist(), db[fi].tolist(), t_entry[fi].tolist()
        gp_l = gp.tolist()
        fsum = math.fsum
        bucket: ProvenanceEntry | None = None
        bucket_pair = -1
        for s, e in zip(brk[:-1].tolist(), brk[1:].tolist()):
            k_pair = gp_l[s]
            sa, sb, tm = fsum(da_l[s:e]), fsum(db_l[s:e]), max(t_l[s:e])
            if k_pair != bucket_pair:  # first compaction that folds this pair: a new bucket
                node, pred = pair_nodes[k_pair]
                bucket = ProvenanceEntry(None, tm, sa, sb, EntryStatus.COMPACTED, node, pred)
                bucket.n_folded = e - s
                logs[k_pair].entries.append(bucket)  # type: ignore[union-attr]
                bucket_pair = k_pair
            else:  # a later compaction: fold the stage into the bucket, as ProvenanceStore does
                bucket.d_alpha = fsum((bucket.d_alpha, sa))  # type: ignore[union-attr]
                bucket.d_beta = fsum((bucket.d_beta, sb))  # type: ignore[union-attr]
                bucket.n_folded += e - s  # type: ignore[union-attr]
                bucket.t = max(bucket.t, tm)  # type: ignore[union-attr]
        # event ids whose every entry was folded are remembered (bounded, most recent kept)
        live_ev = np.zeros(cols.n_events, dtype=bool)
        live_ev[ev[~folded]] = True
        gone = np.unique(ev[folded])
        gone = gone[~live_ev[gone]]
        for i in gone[-prov.remember_compacted:].tolist() if prov.remember_compacted > 0 else []:
            prov._remember_compacted(cols.event_ids[i])

    # live entries in arrival order: pair logs, event index, timeline
    ids = cols.event_ids
    by_event = prov._by_event
    timeline = prov._timeline
    committed = EntryStatus.COMMITTED
    live = np.flatnonzero(~folded)
    for i, k_pair, e_i, t_i, d_a, d_b, st in zip(
        live.tolist(), pair[live].tolist(), ev[live].tolist(), t_entry[live].tolist(),
        da[live].tolist(), db[live].tolist(), stance[live].tolist(),
    ):
        node, pred = pair_nodes[k_pair]
        eid = ids[e_i]
        entry = ProvenanceEntry(eid, t_i, d_a, d_b, committed, node, pred, st)
        logs[k_pair].entries.append(entry)  # type: ignore[union-attr]
        bucket_list = by_event.get(eid)
        if bucket_list is None:
            by_event[eid] = [entry]
        else:
            bucket_list.append(entry)
        timeline.append(entry)
    return graph, stats


def provenance_signature(graph: SceneGraph) -> dict[str, Any]:
    """Everything the equality tests compare: beliefs, logs, queues, event index, compaction."""
    prov = graph.provenance
    return {
        "nodes": list(graph.nx.nodes),
        "clock": graph.clock,
        "meta": dict(graph.meta),
        "pairs": [
            (key, log.alpha, log.beta,
             [(e.as_tuple(), e.stance, e.corroborated_by, e.n_folded, e.node, e.predicate) for e in log.entries])
            for key, log in prov._pairs.items()
        ],
        "quarantine": [e.as_tuple() for e in prov.quarantine if e.alive and e.status is EntryStatus.QUARANTINED],
        "disagreement": [e.as_tuple() for e in prov.disagreement if e.alive and e.status is EntryStatus.REFUSED],
        "by_event": {k: [e.as_tuple() for e in v] for k, v in prov._by_event.items()},
        "timeline": [e.as_tuple() for e in prov._timeline if e.alive],
        "compacted_ids": set(prov._compacted_order),
        "n_compacted": prov.n_compacted,
    }


def random_records(
    seed: int,
    n_events: int,
    *,
    n_nodes: int = 50,
    predicates: Sequence[str] = ("is_car", "is_pedestrian", "is_building"),
    max_targets: int = 4,
    events_per_step: float = 3.0,
    labels: Sequence[str | None] = ("car", "person", "building", "road", None),
    mass_decimals: int = 4,
) -> list[EventRecord]:
    """A seeded random evidence stream (non-decreasing t) for tests and benchmarks."""
    rng = np.random.default_rng(seed)
    out: list[EventRecord] = []
    t = 0
    preds = list(predicates)
    labs = list(labels)
    for i in range(n_events):
        if rng.random() < 1.0 / events_per_step:
            t += int(rng.integers(1, 4))
        k = int(rng.integers(1, max_targets + 1))
        nodes = rng.choice(n_nodes, size=min(k, n_nodes), replace=False)
        w = rng.dirichlet(np.ones(len(nodes))) * rng.uniform(0.5, 1.0)
        targets = {f"n{int(v):05d}": round(float(m), mass_decimals) for v, m in zip(nodes, w)}
        geo = {node: labs[int(rng.integers(len(labs)))] for node in targets}
        out.append(EventRecord(t=t, targets=targets, predicate=preds[int(rng.integers(len(preds)))],
                               confidence=round(float(rng.random()), 6), context="rnd", geometric=geo,
                               id=f"r{i:07d}"))
    return out


__all__ = ["BATCHED_OPERATORS", "EventColumns", "batched_replay", "provenance_signature", "random_records"]

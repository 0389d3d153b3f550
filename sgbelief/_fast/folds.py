"""Compaction of a journalled provenance store without materialising its old journal records.

The reference pass (:meth:`sgbelief.graph.provenance.ProvenanceStore.compact`) folds entry
objects. A journalled store (:mod:`sgbelief._fast.journal`) also holds committed increments as
plain tuples (journal records); when a pass may fold them as they stand (the store checks that,
``old_journal``), these functions fold them straight into the pairs' compacted buckets and give,
bit for bit and in every observable order, what materialising them first and running the
reference pass would:

- :func:`fold_with_journal`: the old timeline entries and the old journal records, pair by
  pair, in the reference's pair order, with one ``math.fsum`` per pair over both;
- :func:`fold_journal_records`: journal records alone (the timeline is empty), grouped by pair
  in numpy instead of record by record.

Both merge each pair's sum into its bucket with the reference's
:func:`~sgbelief.graph.provenance.merge_into_bucket`.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Iterable, Sequence
from itertools import chain
from operator import itemgetter
from typing import Any

import numpy as np

from sgbelief.graph.provenance import (
    COUNTED,
    EntryStatus,
    FoldSummary,
    PairKey,
    PairLog,
    ProvenanceEntry,
    merge_into_bucket,
    settled_before,
)

#: a committed entry not yet materialised as a ProvenanceEntry:
#: (pair key, event id, t, d_alpha, d_beta, stance, the pair's log). The log is the one the store
#: holds for the key: whatever removes or replaces a pair's log materialises the journal first.
JournalRecord = tuple[PairKey, str | None, int, float, float, int, PairLog | None]
record_event_id = itemgetter(1)
record_t = itemgetter(2)
record_d_alpha = itemgetter(3)
record_d_beta = itemgetter(4)
record_log = itemgetter(6)
_COMPACTED = EntryStatus.COMPACTED


def last_seen_order(ids: Iterable[str | None]) -> list[str]:
    """The distinct ids, None left out, each placed where it occurs last."""
    last_first = dict.fromkeys(reversed(list(ids)))
    last_first.pop(None, None)  # type: ignore[call-overload]  # entries without an id are never remembered
    order = list(last_first)
    order.reverse()
    return order  # type: ignore[return-value]


def old_prefix_length(timeline: deque[ProvenanceEntry], before_t: int) -> int:
    """Length of the timeline's prefix a pass at ``before_t`` takes: up to its first live entry
    with ``t >= before_t`` (as the reference pass pops it)."""
    n_old = 0
    for entry in timeline:
        if entry.t >= before_t and entry.alive:
            break
        n_old += 1
    return n_old


def retired_ids(
    entry_ids: list[str], marks: list[tuple[int, list[JournalRecord]]], raws: list[JournalRecord], all_recs_seen: bool
) -> list[str]:
    """The event ids a compaction pass that folds journal records retires, in the order it
    folds them. Per folded pair, in order: the ids its entries took out of the event index
    (``entry_ids[i:j]`` for consecutive marks), then each journal id whose last record is among
    the pair's records (``marks``: (j, records)); the journal holds no id of the index. An id
    with records in a pair the pass skipped (``all_recs_seen`` false) is not retired."""
    if all_recs_seen and not entry_ids:
        # journal records only: each id is retired at its last record, in that order
        return last_seen_order(map(record_event_id, chain.from_iterable([recs for _, recs in marks])))
    remaining: Counter[str | None] = Counter(map(record_event_id, raws))
    remaining.pop(None, None)
    gone: list[str] = []
    done = 0
    for upto, recs in marks:
        gone += entry_ids[done:upto]
        done = upto
        for rec in recs:
            eid = rec[1]
            left = remaining[eid]  # 0 for None
            if left == 1:
                gone.append(eid)  # type: ignore[arg-type]
            else:
                remaining[eid] = left - 1
    gone += entry_ids[done:]
    return gone


def _records_summary(recs: Sequence[JournalRecord], n: int | None = None) -> FoldSummary:
    """The fold summary of journal records (committed, in time order): ``recs`` holds them all,
    or, with ``n`` given, only the first and the last of the ``n``. The first event id is the
    first record's with an id, as :meth:`FoldSummary.of_entries` takes it."""
    first = next((r[1] for r in recs if r[1] is not None), None)
    last = next((r[1] for r in reversed(recs) if r[1] is not None), None)
    return FoldSummary.committed(len(recs) if n is None else n, recs[0][2], first, last)


def fold_with_journal(store: Any, before_t: int, n_old: int, raws: list[JournalRecord]) -> int:
    """One compaction pass over the timeline's first ``n_old`` entries and the old journal
    records ``raws`` (a prefix of the journal, all after the timeline in arrival order);
    returns the number of entries folded."""
    timeline: deque[ProvenanceEntry] = store._timeline
    if n_old == len(timeline):
        old = list(timeline)
        timeline.clear()
    else:
        popleft = timeline.popleft
        old = [popleft() for _ in range(n_old)]
    # the old journal records by pair, in the order each pair's first record arrived
    groups: dict[PairKey, list[JournalRecord]] = {}
    group_of = groups.get
    for rec in raws:
        grp = group_of(rec[0])
        if grp is None:
            groups[rec[0]] = [rec]
        else:
            grp.append(rec)
    # pairs in the order their oldest entry past the horizon arrived (journal records arrived
    # after every timeline entry)
    dirty = dict.fromkeys(chain([(e.node, e.predicate) for e in old if e.alive], groups))
    pairs_get = store._pairs.get
    unindex = store._unindex
    # the ids the folded entries took out of the event index, in order, and per pair with
    # journal records: how many of those ids came before its records, and the records (their
    # ids are gone with the last of their records)
    gone: list[str] = []
    marks: list[tuple[int, list[JournalRecord]]] = []
    all_recs_seen = True
    folded_total = 0
    compacted = _COMPACTED
    fsum = math.fsum
    for key in dirty:
        log = pairs_get(key)
        recs = group_of(key)  # journal records come after every entry
        if log is None:
            if recs:
                all_recs_seen = False
            continue
        entries = log.entries
        keep: list[ProvenanceEntry] | None
        if not entries:
            bucket, fold, keep = None, [], []
        elif len(entries) == 1 and entries[0].status is compacted:  # only the bucket: kept as is
            bucket, fold, keep = entries[0], [], None
        else:
            bucket, fold, keep = settled_before(entries, before_t)
        n_fold = len(fold) + len(recs) if recs else len(fold)
        if not n_fold:
            continue
        # the reference's fold_into_bucket of (fold + the records as entries), summed in one pass
        if n_fold == 1:  # the common case: fsum of one value is that value (+ 0.0 turns -0.0 into 0.0)
            if fold:
                first = fold[0]
                if first.status in COUNTED:
                    d_alpha, d_beta = first.d_alpha + 0.0, first.d_beta + 0.0
                else:
                    d_alpha = d_beta = 0.0
                n, t_max = first.n_folded, first.t
            else:
                rec = recs[0]  # type: ignore[index]
                t_max, d_alpha, d_beta, n = rec[2], rec[3] + 0.0, rec[4] + 0.0, 1
        elif not fold:  # journal records only (committed: all counted), in time order
            d_alpha = fsum(map(record_d_alpha, recs))  # type: ignore[arg-type]
            d_beta = fsum(map(record_d_beta, recs))  # type: ignore[arg-type]
            n, t_max = len(recs), recs[-1][2]  # type: ignore[arg-type, index]
        else:
            das: list[float] = []
            dbs: list[float] = []
            n = 0
            t_max = fold[0].t
            for e in fold:
                if e.status in COUNTED:
                    das.append(e.d_alpha)
                    dbs.append(e.d_beta)
                n += e.n_folded
                if e.t > t_max:
                    t_max = e.t
            if recs:
                das += map(record_d_alpha, recs)
                dbs += map(record_d_beta, recs)
                if recs[-1][2] > t_max:
                    t_max = recs[-1][2]
                n += len(recs)
            d_alpha = fsum(das)
            d_beta = fsum(dbs)
        summary = FoldSummary.of_entries(fold)
        if recs:
            summary.absorb(_records_summary(recs))
        bucket = merge_into_bucket(bucket, key[0], key[1], t_max, d_alpha, d_beta, n, summary)
        for entry in fold:
            entry.alive = False
            if unindex(entry):
                gone.append(entry.event_id)  # type: ignore[arg-type]
        if recs:
            marks.append((len(gone), recs))
        if keep is not None:
            keep.insert(0, bucket)
            log.entries = keep
        folded_total += n_fold
    gone = retired_ids(gone, marks, raws, all_recs_seen)
    store.drop_folded_records(len(raws))
    store.n_compacted += folded_total
    if gone:
        store._compacted_order.extend(gone)
    return folded_total


def fold_journal_records(store: Any, raws: list[JournalRecord]) -> int | None:
    """A compaction pass over journal records alone (the timeline is empty), grouped by pair in
    numpy instead of record by record; returns the number folded.

    The result is the loop's, bit for bit: pairs in the order of their first record; per pair
    one ``math.fsum`` of its increments (for one value that is the value + 0.0, for two their
    IEEE sum + 0.0: both correctly rounded, -0.0 turned into 0.0 as fsum does), added to the
    pair's bucket by ``merge_into_bucket``; the bucket's t is the last record's (the journal is
    in time order) and its count grows by the records folded; retired ids as
    :func:`retired_ids` orders them. Returns None, having changed nothing, when a pair's log
    holds more than its bucket, a time does not fit in 64 bits or a sum is not finite: the
    loop then takes the pass (and raises where ``math.fsum`` does).
    """
    m = len(raws)
    logs = list(map(record_log, raws))
    try:
        t = np.fromiter(map(record_t, raws), np.int64, m)
    except OverflowError:
        return None
    glogs = list(dict.fromkeys(logs))  # the pairs in the order of their first record
    k = len(glogs)
    compacted = _COMPACTED
    for log in glogs:
        entries = log.entries  # type: ignore[union-attr]
        if entries and (len(entries) > 1 or entries[0].status is not compacted):
            return None
    da = np.fromiter(map(record_d_alpha, raws), np.float64, m)
    db = np.fromiter(map(record_d_beta, raws), np.float64, m)
    if k == m:  # one record per pair: each is its own group, in journal order
        order: Any = None
        n = np.ones(m, dtype=np.int64)
        head = list(range(m))
        sa, sb, t_last = da + 0.0, db + 0.0, t
    else:
        slot = dict(zip(glogs, range(k)))
        group = np.fromiter(map(slot.__getitem__, logs), np.intp, m)
        order = np.argsort(group, kind="stable")  # records by pair, journal order within
        n = np.bincount(group, minlength=k)
        ends = np.cumsum(n)
        starts = ends - n
        head = order[starts].tolist()
        t_last = t[order[ends - 1]]
        da, db = da[order], db[order]
        sa, sb = da[starts], db[starts]
        two = np.flatnonzero(n == 2)
        if len(two):
            sa[two] += da[starts[two] + 1]
            sb[two] += db[starts[two] + 1]
        sa += 0.0
        sb += 0.0
        big = np.flatnonzero(n > 2)
        if len(big):
            da_l, db_l = da.tolist(), db.tolist()
            fsum = math.fsum
            try:
                for g, a, b in zip(big.tolist(), starts[big].tolist(), ends[big].tolist()):
                    sa[g] = fsum(da_l[a:b])
                    sb[g] = fsum(db_l[a:b])
            except (OverflowError, ValueError):
                return None
    if not (np.isfinite(sa).all() and np.isfinite(sb).all()):
        return None
    # ---- nothing has changed so far
    tail = list(range(m)) if order is None else order[ends - 1].tolist()
    for log, d_alpha, d_beta, c, t_max, i, j in zip(glogs, sa.tolist(), sb.tolist(), n.tolist(),
                                                    t_last.tolist(), head, tail):
        entries = log.entries  # type: ignore[union-attr]
        key = raws[i][0]
        if order is None:
            summary = _records_summary((raws[i],))
        elif raws[i][1] is None or raws[j][1] is None:  # rare: scan the pair's records for ids
            g = slot[log]  # type: ignore[index]
            summary = _records_summary([raws[r] for r in order[starts[g]:ends[g]].tolist()])
        else:
            summary = _records_summary((raws[i], raws[j]), c)
        bucket = merge_into_bucket(entries[0] if entries else None, key[0], key[1], t_max, d_alpha, d_beta, c,
                                   summary)
        if not entries:
            log.entries = [bucket]  # type: ignore[union-attr]
    eids = list(map(record_event_id, raws))
    gone = last_seen_order(eids if order is None else map(eids.__getitem__, order.tolist()))
    store.drop_folded_records(m)
    store.n_compacted += m
    if gone:
        store._compacted_order.extend(gone)
    return m


__all__ = ["JournalRecord", "fold_journal_records", "fold_with_journal", "old_prefix_length", "retired_ids"]

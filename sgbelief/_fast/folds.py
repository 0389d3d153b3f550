"""Private: the compaction kernel behind the reference fold of :mod:`sgbelief.graph.compaction`.

The reference pass (:func:`sgbelief.graph.compaction.fold_pass`) folds entry objects. A
journalled store (:mod:`sgbelief._fast.journal`) also holds committed increments as plain tuples
(journal records); when a pass may fold them as they stand (the store checks that,
``old_journal``), its ``fold`` calls these functions, which fold them straight into the pairs'
compacted buckets of its object log (through the same operations as the reference pass,
:class:`~sgbelief.graph.compaction.FoldTarget`) and give, bit for bit and in every observable
order, what materialising them first and running the reference pass would (the caller then
drops the folded records from its journal):

- :func:`fold_with_journal`: the old timeline entries and the old journal records, pair by
  pair, in the reference's pair order, with one ``math.fsum`` per pair over both;
- :func:`fold_journal_records`: journal records alone (the timeline is empty), grouped by pair
  in numpy instead of record by record;
- :func:`group_fsums`: the per-pair ``math.fsum`` of many pairs' increments held in one array
  (the batched engine's buckets).

Each pair's sum goes into its bucket with the reference's
:func:`~sgbelief.graph.compaction.merge_into_bucket`.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence
from itertools import chain
from operator import itemgetter
from typing import Any

import numpy as np

from sgbelief.graph.compaction import FoldSummary, FoldTarget, lambda_hat_sum, merge_into_bucket, settled_before
from sgbelief.graph.provenance import COUNTED, EntryStatus, EntryVerdict, PairKey, PairLog, ProvenanceEntry
from sgbelief.graph.provenance_log import VERDICT_SYMBOLS, claim_lambda_hat

#: a committed entry not yet materialised as a ProvenanceEntry:
#: (pair key, event id, t, d_alpha, d_beta, stance, the pair's log, verdict, confidence). The log
#: is the one the store holds for the key: whatever removes or replaces a pair's log materialises
#: the journal first.
JournalRecord = tuple[PairKey, str | None, int, float, float, int, PairLog | None, EntryVerdict | None, float | None]
record_event_id = itemgetter(1)
record_t = itemgetter(2)
record_d_alpha = itemgetter(3)
record_d_beta = itemgetter(4)
record_log = itemgetter(6)
record_verdict = itemgetter(7)
_COMPACTED = EntryStatus.COMPACTED
_GEOMETRIC = EntryVerdict.GEOMETRIC
_EXCLUSION = EntryVerdict.EXCLUSION
_SYMBOLS = list(VERDICT_SYMBOLS.values())  # by code
#: verdict (None included) -> column of the per-pair verdict counts in fold_journal_records
_VERDICT_COLUMN: dict[Any, int] = {None: 0, **{v: int(v) + 1 for v in EntryVerdict}}


def last_seen_order(ids: Iterable[str | None]) -> list[str]:
    """The distinct ids, None left out, each placed where it occurs last."""
    last_first = dict.fromkeys(reversed(list(ids)))
    last_first.pop(None, None)  # type: ignore[call-overload]  # entries without an id are never remembered
    order = list(last_first)
    order.reverse()
    return order  # type: ignore[return-value]


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


def _records_summary(recs: Sequence[JournalRecord], n: int | None = None,
                     verdicts: dict[str, int] | None = None) -> FoldSummary:
    """The fold summary of journal records (committed, in time order) without their
    Lambda-hat: ``recs`` holds them all, or, with ``n`` given, only the first and the last of
    the ``n`` (then ``verdicts`` are their counts per verdict). The first event id is the first
    record's with an id, as :meth:`FoldSummary.of_entries` takes it."""
    first = next((r[1] for r in recs if r[1] is not None), None)
    last = next((r[1] for r in reversed(recs) if r[1] is not None), None)
    return FoldSummary.committed(len(recs) if n is None else n, recs[0][2], first, last, verdicts)


def _records_lambda_hats(recs: Sequence[JournalRecord], summary: FoldSummary) -> list[float]:
    """Count the records' verdicts into ``summary`` and return the Lambda-hat of each claim
    record (:func:`~sgbelief.graph.provenance_log.entry_lambda_hat` of the entry it stands for)."""
    lams: list[float] = []
    verdicts = summary.verdicts
    for rec in recs:
        v = rec[7]
        if v is None:
            continue
        sym = _SYMBOLS[v]
        verdicts[sym] = verdicts.get(sym, 0) + 1
        if v != _GEOMETRIC and v != _EXCLUSION:
            lam = claim_lambda_hat(rec[3], rec[4])
            if lam is not None:
                lams.append(lam)
    summary.n_lambda_hat = len(lams)
    return lams


def fold_with_journal(store: FoldTarget, before_t: int, n_old: int, raws: list[JournalRecord]) -> int:
    """One compaction pass over the object log's first ``n_old`` timeline entries and the old
    journal records ``raws`` (a prefix of the journal, all after the timeline in arrival order);
    returns the number of entries folded."""
    old = store.pop_timeline(n_old)
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
    pairs_get = store.pair_index().get
    fold_pair = store.fold_pair
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
        if recs:
            later = _records_summary(recs)
            summary = FoldSummary.of_entries(fold, later, _records_lambda_hats(recs, later))
        else:
            summary = FoldSummary.of_entries(fold)
        bucket = merge_into_bucket(bucket, key[0], key[1], t_max, d_alpha, d_beta, n, summary)
        gone += fold_pair(log, bucket, fold, keep)
        if recs:
            marks.append((len(gone), recs))
        folded_total += n_fold
    store.retire(retired_ids(gone, marks, raws, all_recs_seen), folded_total)
    return folded_total


def fold_journal_records(store: FoldTarget, raws: list[JournalRecord]) -> int | None:
    """A compaction pass over journal records alone (the object log's timeline is empty),
    grouped by pair in numpy instead of record by record; returns the number folded.

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
    verdict_cols = list(map(_VERDICT_COLUMN.__getitem__, map(record_verdict, raws)))
    # per pair (in glogs order): its records' verdict counts and Lambda-hat sum (none: baselines)
    by_pair = None if verdict_cols.count(0) == m else _verdicts_by_pair(logs, glogs, verdict_cols, da, db)
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
    for g, (log, d_alpha, d_beta, c, t_max, i, j) in enumerate(zip(glogs, sa.tolist(), sb.tolist(), n.tolist(),
                                                                   t_last.tolist(), head, tail)):
        entries = log.entries  # type: ignore[union-attr]
        key = raws[i][0]
        verdicts = None if by_pair is None else by_pair[0][g]
        if order is None:
            summary = _records_summary((raws[i],), 1, verdicts)
        elif raws[i][1] is None or raws[j][1] is None:  # rare: scan the pair's records for ids
            summary = _records_summary([raws[r] for r in order[starts[g]:ends[g]].tolist()], c, verdicts)
        else:
            summary = _records_summary((raws[i], raws[j]), c, verdicts)
        if by_pair is not None:
            summary.lambda_hat_sum, summary.n_lambda_hat = by_pair[1][g], by_pair[2][g]
        bucket = merge_into_bucket(entries[0] if entries else None, key[0], key[1], t_max, d_alpha, d_beta, c,
                                   summary)
        if not entries:
            store.fold_pair(log, bucket, (), [])  # type: ignore[arg-type]  # the new bucket is the log
    eids = list(map(record_event_id, raws))
    store.retire(last_seen_order(eids if order is None else map(eids.__getitem__, order.tolist())), m)
    return m


def _verdicts_by_pair(logs: list[Any], glogs: list[Any], verdict_cols: list[int], da: np.ndarray, db: np.ndarray
                      ) -> tuple[list[dict[str, int]], list[float], list[int]]:
    """Per pair (``glogs`` order; ``logs``: each record's pair): its records' counts per verdict,
    the exactly rounded sum of their claims' Lambda-hat (:func:`lambda_hat_sum`, record order)
    and how many claims have one, as :meth:`FoldSummary.of_entries` gives them for the entries."""
    m, k = len(logs), len(glogs)
    slot = dict(zip(glogs, range(k)))
    group = np.fromiter(map(slot.__getitem__, logs), np.intp, m)
    cols = np.asarray(verdict_cols, dtype=np.intp)  # 0: None, code + 1 otherwise
    n_cols = len(_SYMBOLS) + 1  # None, then one column per verdict code
    table = np.bincount(group * n_cols + cols, minlength=n_cols * k).reshape(k, n_cols)[:, 1:].tolist()
    verdicts = [{_SYMBOLS[c]: n for c, n in enumerate(row) if n} for row in table]
    finite = np.isfinite(da) & np.isfinite(db)
    claim = (cols >= 1) & (cols <= 3) & (db > 0.0) & (da >= 0.0) & finite  # claim_lambda_hat is not None
    idx = np.flatnonzero(claim)
    n_lam = np.bincount(group[idx], minlength=k)
    order = idx[np.argsort(group[idx], kind="stable")]  # claims by pair, record order within
    lams = (da[order] / db[order]).tolist()
    bounds = np.zeros(k + 1, dtype=np.intp)
    np.cumsum(n_lam, out=bounds[1:])
    sums = [lambda_hat_sum(lams[a:b]) if b > a else 0.0 for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist())]
    return verdicts, sums, n_lam.tolist()


def group_fsums(values: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """``math.fsum`` of each group ``values[starts[g]:starts[g] + sizes[g]]``, bit for bit.

    fsum is the correctly rounded exact sum (a zero sum is +0.0). A float addition is correctly
    rounded too, so groups of one or two values are done in numpy (``+ 0.0`` turns -0.0 into
    fsum's +0.0); only groups of three or more go through ``math.fsum``.
    """
    out = values[starts] + 0.0
    two = sizes == 2
    out[two] += values[starts[two] + 1]
    big = np.flatnonzero(sizes >= 3)
    if len(big):
        vals = values[np.repeat(sizes >= 3, sizes)].tolist()
        ends = np.cumsum(sizes[big]).tolist()
        fsum = math.fsum
        out[big] = [fsum(vals[a:b]) for a, b in zip([0, *ends[:-1]], ends)]
    return out


__all__ = ["JournalRecord", "fold_journal_records", "fold_with_journal", "group_fsums", "retired_ids"]

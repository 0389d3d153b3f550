"""Saving the provenance store in the binary layout: pairs, entries, queues and timeline as columns.

The columns are described in :mod:`sgbelief.graph.npz_provenance` (which reads and checks them);
:func:`provenance_arrays` writes them from any :class:`~sgbelief.graph.entry_log.EntryLog`
through its read views (``logs()`` builds a lazy store's entries first).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from itertools import chain, repeat
from operator import attrgetter, is_, is_not, itemgetter
from typing import Any

import numpy as np

from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.npz_archive import B1, CHUNK, F8, I1, I4, I8, U1
from sgbelief.graph.npz_columns import distinct_codes, encode_strings, positions
from sgbelief.graph.provenance_log import EntryStatus, EntryVerdict, ProvenanceEntry

#: the store's entries: every status, in the order of their codes in a file written now
STATUSES = list(EntryStatus)
#: an entry's verdict -> its code in ``entry_verdict`` (-1: not recorded)
_VERDICT_CODE: dict[Any, int] = {None: -1, **{v: int(v) for v in EntryVerdict}}


def provenance_arrays(
    store: EntryLog, node_rows: Callable[[Sequence[Any]], np.ndarray]
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(arrays, header fields) of a store; ``node_rows`` gives the node-table row of each node
    (-1 for one the graph does not hold). Raises ValueError on what the layout cannot hold."""
    logs_by_key = store.logs()  # every entry an object (a lazy store builds them here)
    arrays: dict[str, np.ndarray] = {}
    keys = list(logs_by_key)
    logs = list(logs_by_key.values())
    n_pairs = len(keys)
    pair_nodes, pair_preds = tuple(map(itemgetter(0), keys)), tuple(map(itemgetter(1), keys))
    pair_node = node_rows(pair_nodes)
    if n_pairs and pair_node.min() < 0:
        bad = pair_nodes[int(np.flatnonzero(pair_node < 0)[0])]
        raise ValueError(f"provenance refers to node {bad!r} that the graph does not contain")
    arrays["pair_node"] = pair_node
    pred_code, pred_names = distinct_codes(pair_preds)
    for p in pred_names:
        if not isinstance(p, str) or not p:
            raise ValueError(f"provenance predicate {p!r} must be a non-empty string")
    arrays["pair_predicate"] = pred_code.astype(I4)
    alpha, beta, lengths = np.empty(n_pairs, F8), np.empty(n_pairs, F8), np.empty(n_pairs, I8)
    flat: list[ProvenanceEntry] = []  # every entry, grouped by pair in log order
    for a in range(0, n_pairs, CHUNK):
        chunk = logs[a:a + CHUNK]
        b = a + len(chunk)
        alpha[a:b] = np.fromiter(map(attrgetter("alpha"), chunk), F8, b - a)
        beta[a:b] = np.fromiter(map(attrgetter("beta"), chunk), F8, b - a)
        entry_lists = list(map(attrgetter("entries"), chunk))
        lengths[a:b] = np.fromiter(map(len, entry_lists), I8, b - a)
        flat += chain.from_iterable(entry_lists)
    arrays["pair_alpha"], arrays["pair_beta"], arrays["pair_length"] = alpha, beta, lengths
    bad = ~(np.isfinite(alpha) & np.isfinite(beta))
    if bad.any():
        raise ValueError(f"belief of {keys[int(np.flatnonzero(bad)[0])]!r} is not finite")
    # ---- entries, in the order of ``flat``
    m = len(flat)
    pair_of = lambda i: keys[int(np.searchsorted(np.cumsum(lengths), i, side="right"))]  # noqa: E731
    # chunk by chunk, so that the eight attribute passes over a chunk's entries hit the cache
    t_arr, stance, n_folded = np.empty(m, I8), np.empty(m, I1), np.empty(m, I8)
    da, db = np.empty(m, F8), np.empty(m, F8)
    status_c: list[Any] = []
    eid_c: list[Any] = []
    corr_c: list[Any] = []
    verdict_c: list[Any] = []
    conf_c: list[Any] = []
    get = attrgetter("t"), attrgetter("stance"), attrgetter("n_folded"), attrgetter("d_alpha"), attrgetter("d_beta")
    for a in range(0, m, CHUNK):
        chunk = flat[a:a + CHUNK]
        b, k = a + len(chunk), len(chunk)
        try:
            t_arr[a:b] = np.fromiter(map(get[0], chunk), I8, k)
            stance[a:b] = np.fromiter(map(get[1], chunk), I1, k)
            n_folded[a:b] = np.fromiter(map(get[2], chunk), I8, k)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ValueError(f"provenance entry t / n_folded must be 64-bit integers and stance in [-128, 127] "
                             f"({exc})") from None
        da[a:b] = np.fromiter(map(get[3], chunk), F8, k)
        db[a:b] = np.fromiter(map(get[4], chunk), F8, k)
        status_c += map(attrgetter("status"), chunk)
        eid_c += map(attrgetter("event_id"), chunk)
        corr_c += map(attrgetter("corroborated_by"), chunk)
        verdict_c += map(attrgetter("verdict"), chunk)
        conf_c += map(attrgetter("confidence"), chunk)
    arrays["entry_t"], arrays["entry_stance"], arrays["entry_n_folded"] = t_arr, stance, n_folded
    arrays.update(_verdict_arrays(verdict_c, conf_c, pair_of))
    arrays["entry_d_alpha"], arrays["entry_d_beta"] = da, db
    bad = ~(np.isfinite(da) & np.isfinite(db))
    if bad.any():
        raise ValueError(f"provenance entry of {pair_of(int(np.flatnonzero(bad)[0]))!r}: increments must be finite")
    status_code = {s: i for i, s in enumerate(STATUSES)}
    try:
        status = np.fromiter(map(status_code.__getitem__, status_c), U1, m)
    except (KeyError, TypeError):
        i = next(i for i, s in enumerate(status_c) if not _is_status(s, status_code))
        raise ValueError(f"provenance entry of {pair_of(i)!r}: status {status_c[i]!r} is not an EntryStatus") from None
    arrays["entry_status"] = status
    null = np.fromiter(map(is_, eid_c, repeat(None)), B1, m)
    arrays["entry_event_null"] = null
    eids = ["" if e is None else e for e in eid_c] if null.any() else eid_c
    arrays.update({f"entry_event{s}": a
                   for s, a in encode_strings(eids, lambda i: f"event id of the entry of {pair_of(i)!r}").items()})
    cidx = np.flatnonzero(np.fromiter(map(is_not, corr_c, repeat(None)), B1, m)).astype(I8)
    clists = [list(corr_c[i]) for i in cidx.tolist()]
    arrays["corroborated_entry"] = cidx
    arrays["corroborated_length"] = np.fromiter(map(len, clists), I8, len(clists))
    cids = list(chain.from_iterable(clists))
    arrays.update({f"corroborated_by{s}": a
                   for s, a in encode_strings(cids, lambda i: "corroborated_by event id").items()})
    # ---- queues and compaction timeline, as entry indices (identity lookup; dead entries drop out)
    flat_ids = np.fromiter(map(id, flat), np.uint64, m)
    order = np.argsort(flat_ids)
    sorted_ids = flat_ids[order]
    arrays["timeline"] = positions(store.compaction_timeline(), sorted_ids, order)
    q = positions(store.quarantine, sorted_ids, order)
    arrays["quarantine"] = q[status[q] == STATUSES.index(EntryStatus.QUARANTINED)]
    d = positions(store.disagreement, sorted_ids, order)
    arrays["disagreement"] = d[status[d] == STATUSES.index(EntryStatus.REFUSED)]
    # ---- what each compacted bucket folded (optional arrays: files without them load as unknown)
    summarised = [i for i, e in enumerate(flat) if e.summary is not None]
    if summarised:
        arrays["fold_summary_entry"] = np.asarray(summarised, dtype=I8)
        texts = [json.dumps(flat[i].summary.to_dict(), separators=(",", ":")) for i in summarised]  # type: ignore[union-attr]
        arrays.update({f"fold_summary{s}": a for s, a in encode_strings(texts, lambda i: "fold summary").items()})
    compacted = store.compacted_ids()
    arrays.update({f"compacted_ids{s}": a
                   for s, a in encode_strings(compacted, lambda i: "compacted event id").items()})
    header = {
        "prior": [store.prior_alpha, store.prior_beta],
        "remember_compacted": store.remember_compacted,
        "n_compacted": store.n_compacted,
        "statuses": [s.value for s in STATUSES],
        "predicates": pred_names,
        "counts": {"pairs": n_pairs, "entries": m, "corroborated": len(clists), "corroborating_ids": len(cids),
                   "timeline": len(arrays["timeline"]), "quarantine": len(arrays["quarantine"]),
                   "disagreement": len(arrays["disagreement"]), "compacted_ids": len(compacted)},
    }
    return arrays, header


def _verdict_arrays(verdicts: list[Any], confidences: list[Any], pair_of: Callable[[int], Any]
                    ) -> dict[str, np.ndarray]:
    """The optional ``entry_verdict`` (code, -1 = not recorded) and ``entry_confidence`` (NaN = not
    recorded) columns; none when no entry recorded either (files of the baselines stay as they were)."""
    m = len(verdicts)
    if verdicts.count(None) == m and confidences.count(None) == m:
        return {}
    try:
        code = np.fromiter(map(_VERDICT_CODE.__getitem__, verdicts), I1, m)
    except (KeyError, TypeError):
        i = next(i for i, v in enumerate(verdicts) if not _is_status(v, _VERDICT_CODE))
        raise ValueError(f"provenance entry of {pair_of(i)!r}: verdict {verdicts[i]!r} is not an EntryVerdict") from None
    try:
        conf = np.fromiter((math.nan if c is None else c for c in confidences), F8, m)
    except (TypeError, ValueError):
        raise ValueError("provenance entry confidence must be None or a number") from None
    bad = ~(np.isnan(conf) | ((conf >= 0.0) & (conf <= 1.0)))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"provenance entry of {pair_of(i)!r}: confidence {confidences[i]!r} is not in [0, 1]")
    return {"entry_verdict": code, "entry_confidence": conf}


def _is_status(value: Any, codes: dict[Any, int]) -> bool:
    try:
        return value in codes
    except TypeError:  # unhashable
        return False


__all__ = ["STATUSES", "provenance_arrays"]

"""The provenance store in the binary layout: pairs, entries, queues and timeline as columns, read
and checked (saving them is :mod:`sgbelief.graph.npz_provenance_save`).

Per pair (in the store's order): ``pair_node`` (row in the node table), ``pair_predicate`` (code
into the header's ``predicates``), ``pair_alpha`` / ``pair_beta`` (the running belief) and
``pair_length``. Per entry, grouped by pair in log order: ``entry_t``, ``entry_d_alpha``,
``entry_d_beta``, ``entry_status`` (code into the header's ``statuses``), ``entry_stance``,
``entry_n_folded``, ``entry_event`` (a string column) with ``entry_event_null``, and the
``corroborated_*`` lists. The compaction ``timeline`` and the queues ``quarantine`` /
``disagreement`` are entry indices in their exact order; ``compacted_ids`` the remembered ids.

Loading checks every index, code and number, and Eq. 4 on every pair (prior + sum of the
counted increments equals the stored belief, in extended precision), before any Python object is
made (:func:`read_provenance`). :func:`build_reference_store` then makes the reference store from
the checked columns; a store that builds its entries later starts from the same columns.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from typing import Any, Protocol

import numpy as np

from sgbelief.errors import FormatError
from sgbelief.graph.npz_archive import B1, F8, I1, I4, I8, U1, NpzArchive, check_index
from sgbelief.graph.npz_columns import decode_values, pylist, read_strings_later
from sgbelief.graph.provenance import (
    COUNTED,
    PENDING,
    EntryStatus,
    FoldSummary,
    PairLog,
    ProvenanceEntry,
    ProvenanceStore,
)
from sgbelief.graph.provenance_log import VERDICT_BY_CODE



# ======================================================================= loading
class ProvenanceCounts(Protocol):
    """The header's row counts of the provenance arrays."""

    pairs: int
    entries: int
    corroborated: int
    corroborating_ids: int
    timeline: int
    quarantine: int
    disagreement: int
    compacted_ids: int


class ProvenanceHeader(Protocol):
    """The header fields of the provenance arrays (validated with the rest of the header)."""

    prior: list[float]
    remember_compacted: int
    n_compacted: int
    statuses: list[str]
    predicates: list[str]

    @property
    def counts(self) -> ProvenanceCounts: ...


def segment_sums(x: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Per-segment sums in extended precision (np.longdouble: 64-bit mantissa on x86-64)."""
    out = np.zeros(len(lengths), dtype=np.longdouble)
    nonempty = lengths > 0
    if nonempty.any():
        out[nonempty] = np.add.reduceat(x.astype(np.longdouble), starts[nonempty])
    return out


class ProvenanceColumns:
    """The checked provenance columns of a file, and the entry objects they describe.

    ``pair_keys`` are the (node, predicate) keys in the file's pair order, made from the loaded
    node ids; ``error`` makes a FormatError naming the file (for what only building can find)."""

    def __init__(self, h: ProvenanceHeader, error: Callable[[str], FormatError], pair_keys: list[tuple[Any, str]],
                 pair_nodes: np.ndarray, pair_preds: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                 lengths: np.ndarray, t: np.ndarray, da: np.ndarray, db: np.ndarray, status: np.ndarray,
                 stance: np.ndarray, n_folded: np.ndarray, null: np.ndarray, eids: Callable[[], list[str]],
                 corr_entry: np.ndarray, corr_len: np.ndarray, corr_ids: list[str], timeline: np.ndarray,
                 quarantine: np.ndarray, disagreement: np.ndarray, compacted_ids: list[str]) -> None:
        self.prior = (h.prior[0], h.prior[1])
        self.remember_compacted, self.n_compacted = h.remember_compacted, h.n_compacted
        self.error = error
        self.statuses = [EntryStatus(s) for s in h.statuses]
        self.status_arr = np.empty(len(self.statuses), dtype=object)
        for i, s in enumerate(self.statuses):
            self.status_arr[i] = s
        self.pair_keys, self.pair_nodes, self.pair_preds = pair_keys, pair_nodes, pair_preds
        self.alpha, self.beta, self.lengths = alpha, beta, lengths
        self.offsets = np.zeros(len(lengths) + 1, dtype=I8)
        np.cumsum(lengths, out=self.offsets[1:])
        self.t, self.da, self.db, self.status, self.stance, self.n_folded = t, da, db, status, stance, n_folded
        self.null, self._eids, self._eid_arr = null, eids, None
        self.corr_entry, self.corr_len, self.corr_ids = corr_entry, corr_len, corr_ids
        self.timeline, self.quarantine, self.disagreement = timeline, quarantine, disagreement
        self.compacted_ids = compacted_ids
        #: entry index -> the saved fold summary (a dict) of that compacted bucket
        self.fold_summaries: dict[int, dict[str, Any]] = {}
        #: the optional per-entry verdict codes (-1: not recorded) and confidences (NaN: not recorded)
        self.verdict: np.ndarray | None = None
        self.confidence: np.ndarray | None = None

    @property
    def n_entries(self) -> int:
        return len(self.t)

    @property
    def event_ids_split(self) -> bool:
        """Whether the event-id column has been split into strings yet (it is, on first use)."""
        return self._eid_arr is not None

    def eid_array(self) -> np.ndarray:
        """Each entry's event id (None where the file says null), as an object array."""
        if self._eid_arr is None:
            arr = np.fromiter(self._eids(), object, len(self.t))
            if self.null.any():
                arr[self.null] = None
            self._eid_arr = arr
        return self._eid_arr

    def pending_rows(self) -> np.ndarray:
        """Indices of the entries waiting in a queue (refused, quarantined), in file order."""
        return np.flatnonzero(np.isin(self.status, [i for i, s in enumerate(self.statuses) if s in PENDING]))

    def entries(self, rows: np.ndarray | None = None) -> list[ProvenanceEntry]:
        """New entry objects for the given entry indices (all when None), in that order."""
        pick = (lambda a: a) if rows is None else (lambda a: a[rows])  # noqa: E731
        pair_of = np.repeat(np.arange(len(self.lengths)), self.lengths)
        pairs = pick(pair_of)
        extras: list[Iterable[Any]] = []
        if self.verdict is not None and self.confidence is not None:
            extras = [_VERDICT_OBJECTS[pick(self.verdict).astype(np.intp) + 1].tolist(),
                      _confidences(pick(self.confidence))]
        entries = list(map(ProvenanceEntry, pick(self.eid_array()).tolist(), pylist(pick(self.t)),
                           pylist(pick(self.da)), pylist(pick(self.db)), self.status_arr[pick(self.status)].tolist(),
                           self.pair_nodes[pairs].tolist(), self.pair_preds[pairs].tolist(), pick(self.stance).tolist(),
                           *extras))
        n_folded = pick(self.n_folded)
        folded = np.flatnonzero(n_folded != 1)
        at = entries.__getitem__
        set_folded = ProvenanceEntry.n_folded.__set__  # type: ignore[attr-defined]
        deque(map(set_folded, map(at, folded.tolist()), n_folded[folded].tolist()), maxlen=0)
        if len(self.corr_entry):
            bounds = np.zeros(len(self.corr_len) + 1, dtype=I8)
            np.cumsum(self.corr_len, out=bounds[1:])
            where = np.arange(len(self.t)) if rows is None else np.full(len(self.t), -1, dtype=I8)
            if rows is not None:
                where[rows] = np.arange(len(rows))
            for i, a, b in zip(where[self.corr_entry].tolist(), bounds[:-1].tolist(), bounds[1:].tolist()):
                if i >= 0:
                    entries[i].corroborated_by = self.corr_ids[a:b]
        if self.fold_summaries:
            if rows is None:
                for i, d in self.fold_summaries.items():
                    entries[i].summary = FoldSummary.from_dict(d)
            else:
                at_row = {r: j for j, r in enumerate(rows.tolist())}
                for i, d in self.fold_summaries.items():
                    j = at_row.get(i)
                    if j is not None:
                        entries[j].summary = FoldSummary.from_dict(d)
        return entries

    def split(self, entries: list[Any]) -> Iterable[list[Any]]:
        """The per-pair entry lists (consecutive runs of ``entries``, one per pair), in pair order."""
        lengths, offsets = self.lengths, self.offsets
        if len(lengths) and int(lengths.min()) == 1 and int(lengths.max()) == 1:
            return map(list, zip(entries))  # one entry per pair (zip reuses its 1-tuple)
        return map(entries.__getitem__, map(slice, offsets[:-1].tolist(), offsets[1:].tolist()))

    def duplicate_pair_error(self) -> FormatError:
        return self.error("arrays 'pair_node' / 'pair_predicate': duplicate (node, predicate) pair")


def read_provenance(arch: NpzArchive, h: ProvenanceHeader, node_ids: list[Any]) -> ProvenanceColumns:
    """Read and check the provenance arrays (every index, code, number, and Eq. 4 per pair)."""
    c = h.counts
    n, n_pairs, m = len(node_ids), c.pairs, c.entries
    statuses = [EntryStatus(s) for s in h.statuses]
    pair_node = arch.read("pair_node", I8, (n_pairs,))
    check_index(arch, "pair_node", pair_node, n)
    pair_pred = arch.read("pair_predicate", I4, (n_pairs,))
    check_index(arch, "pair_predicate", pair_pred, len(h.predicates))
    alpha = arch.read("pair_alpha", F8, (n_pairs,))
    beta = arch.read("pair_beta", F8, (n_pairs,))
    for name, arr in (("pair_alpha", alpha), ("pair_beta", beta)):
        bad = ~(np.isfinite(arr) & (arr > 0))
        if bad.any():
            raise arch.error(f"array '{name}': row {int(np.flatnonzero(bad)[0])} is not a finite number > 0")
    lengths = arch.read("pair_length", I8, (n_pairs,))
    if n_pairs and (int(lengths.min()) < 0 or int(lengths.max()) > m):
        raise arch.error(f"array 'pair_length': lengths must be in [0, {m}]")
    if int(lengths.sum()) != m:
        raise arch.error(f"array 'pair_length': lengths add up to {int(lengths.sum())}, header counts {m} entries")
    t = arch.read("entry_t", I8, (m,))
    da = arch.read("entry_d_alpha", F8, (m,))
    db = arch.read("entry_d_beta", F8, (m,))
    for name, arr in (("entry_d_alpha", da), ("entry_d_beta", db)):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise arch.error(f"array '{name}': non-finite increment at entry {int(np.flatnonzero(bad)[0])}")
    status = arch.read("entry_status", U1, (m,))
    if m and int(status.max()) >= len(statuses):
        raise arch.error(f"array 'entry_status': status code {int(status.max())} out of range [0, {len(statuses)})")
    stance = arch.read("entry_stance", I1, (m,))
    n_folded = arch.read("entry_n_folded", I8, (m,))
    if m and int(n_folded.min()) < 1:
        raise arch.error("array 'entry_n_folded': every entry stands for at least 1 original entry")
    null = arch.read("entry_event_null", B1, (m,))
    eids = read_strings_later(arch, "entry_event", m)  # split when the entries are built
    corr_entry = arch.read("corroborated_entry", I8, (c.corroborated,))
    check_index(arch, "corroborated_entry", corr_entry, m)
    if len(corr_entry) > 1 and not (np.diff(corr_entry) > 0).all():
        raise arch.error("array 'corroborated_entry': entry indices must be strictly increasing")
    corr_len = arch.read("corroborated_length", I8, (c.corroborated,))
    if c.corroborated and (int(corr_len.min()) < 0 or int(corr_len.max()) > c.corroborating_ids) \
            or int(corr_len.sum()) != c.corroborating_ids:
        raise arch.error("array 'corroborated_length': lengths must be >= 0 and add up to counts.corroborating_ids")
    corr_ids = decode_values(arch, "corroborated_by", {"kind": "str"}, c.corroborating_ids)
    timeline = arch.read("timeline", I8, (c.timeline,))
    check_index(arch, "timeline", timeline, m)
    queues = {}
    for name, want in (("quarantine", EntryStatus.QUARANTINED), ("disagreement", EntryStatus.REFUSED)):
        idx = arch.read(name, I8, (getattr(c, name),))
        check_index(arch, name, idx, m)
        if len(idx) and not all(statuses[s] is want for s in np.unique(status[idx]).tolist()):
            raise arch.error(f"array '{name}': refers to an entry whose status is not {want.value!r}")
        queues[name] = idx
    compacted = decode_values(arch, "compacted_ids", {"kind": "str"}, c.compacted_ids)
    # ---- Eq. 4 on every pair: prior + sum of counted increments must equal the stored belief
    offsets = np.zeros(n_pairs + 1, dtype=I8)
    np.cumsum(lengths, out=offsets[1:])
    starts = offsets[:-1]
    counted = np.isin(status, [i for i, s in enumerate(statuses) if s in COUNTED])
    for name, stored, prior, d in (("alpha", alpha, h.prior[0], da), ("beta", beta, h.prior[1], db)):
        ref = np.longdouble(prior) + segment_sums(np.where(counted, d, 0.0), starts, lengths)
        diff = np.abs(stored.astype(np.longdouble) - ref)
        tol = np.maximum(1e-9 * np.maximum(np.abs(stored), np.abs(ref)), 1e-9)
        bad = diff > tol
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            key = (node_ids[int(pair_node[i])], h.predicates[int(pair_pred[i])])
            raise arch.error(f"pair {i} {key!r}: stored {name}={float(stored[i])!r} does not equal prior + sum of "
                             f"logged increments ({float(ref[i])!r}); the file was edited or corrupted")
    # pair keys (node, predicate) now, before the node dicts: young collections untrack the tuples early
    node_arr = np.empty(n, dtype=object)
    node_arr[:] = node_ids
    pred_arr = np.empty(len(h.predicates), dtype=object)
    pred_arr[:] = h.predicates
    pair_nodes = node_arr[pair_node]
    pair_preds = pred_arr[pair_pred]
    pair_keys = list(zip(pair_nodes.tolist(), pair_preds.tolist()))
    cols = ProvenanceColumns(h, arch.error, pair_keys, pair_nodes, pair_preds, alpha, beta, lengths, t, da, db,
                             status, stance, n_folded, null, eids, corr_entry, corr_len, corr_ids, timeline,
                             queues["quarantine"], queues["disagreement"], compacted)
    cols.fold_summaries = _read_fold_summaries(arch, m, status, statuses)
    cols.verdict, cols.confidence = _read_verdicts(arch, m)
    return cols


def _read_verdicts(arch: NpzArchive, m: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The optional ``entry_verdict`` / ``entry_confidence`` columns (absent in older files and
    in maps of operators without verdicts: every entry's are None)."""
    has_v, has_c = arch.has("entry_verdict"), arch.has("entry_confidence")
    if not (has_v or has_c):
        return None, None
    if has_v != has_c:
        raise arch.error("arrays 'entry_verdict' and 'entry_confidence' come together")
    verdict = arch.read("entry_verdict", I1, (m,))
    if m and (int(verdict.min()) < -1 or int(verdict.max()) >= len(VERDICT_BY_CODE)):
        bad = int(np.flatnonzero((verdict < -1) | (verdict >= len(VERDICT_BY_CODE)))[0])
        raise arch.error(f"array 'entry_verdict': code {int(verdict[bad])} at entry {bad} out of range "
                         f"[-1, {len(VERDICT_BY_CODE)})")
    confidence = arch.read("entry_confidence", F8, (m,))
    bad = ~(np.isnan(confidence) | ((confidence >= 0.0) & (confidence <= 1.0)))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise arch.error(f"array 'entry_confidence': {float(confidence[i])!r} at entry {i} is not in [0, 1] (NaN: "
                         "not recorded)")
    return verdict, confidence


#: verdict code + 1 -> the entry's verdict (code -1: None)
_VERDICT_OBJECTS = np.array([None, *VERDICT_BY_CODE], dtype=object)


def _confidences(conf: np.ndarray) -> list[float | None]:
    """Confidences as Python values, NaN (not recorded) as None."""
    values = pylist(conf)
    missing = np.flatnonzero(np.isnan(conf))
    for i in missing.tolist():
        values[i] = None
    return values


def _read_fold_summaries(arch: NpzArchive, m: int, status: np.ndarray, statuses: list[EntryStatus]
                         ) -> dict[int, dict[str, Any]]:
    """The optional fold summaries of the compacted buckets (absent in older files: unknown)."""
    if not arch.has("fold_summary_entry"):
        return {}
    idx = arch.read("fold_summary_entry", I8, (None,))
    check_index(arch, "fold_summary_entry", idx, m)
    if len(idx) and not all(statuses[s] is EntryStatus.COMPACTED for s in np.unique(status[idx]).tolist()):
        raise arch.error("array 'fold_summary_entry': refers to an entry whose status is not 'compacted'")
    values = decode_values(arch, "fold_summary", {"kind": "json"}, len(idx))
    out: dict[int, dict[str, Any]] = {}
    for row, (i, d) in enumerate(zip(idx.tolist(), values)):
        try:
            FoldSummary.from_dict(d)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise arch.error(f"array 'fold_summary' row {row}: malformed fold summary ({exc})") from None
        out[i] = d
    return out


def build_reference_store(cols: ProvenanceColumns) -> ProvenanceStore:
    """The reference store of checked columns: every entry an object, now."""
    logs = dict(zip(cols.pair_keys, map(PairLog, pylist(cols.alpha), pylist(cols.beta))))
    if len(logs) != len(cols.pair_keys):
        raise cols.duplicate_pair_error()
    entries = cols.entries()
    set_entries = PairLog.entries.__set__  # type: ignore[attr-defined]
    deque(map(set_entries, logs.values(), cols.split(entries)), maxlen=0)
    pick = entries.__getitem__
    return ProvenanceStore.from_logs(
        logs,
        prior=cols.prior,
        remember_compacted=cols.remember_compacted,
        timeline=map(pick, cols.timeline.tolist()),
        quarantine=map(pick, cols.quarantine.tolist()),
        disagreement=map(pick, cols.disagreement.tolist()),
        compacted_ids=cols.compacted_ids,
        n_compacted=cols.n_compacted,
    )

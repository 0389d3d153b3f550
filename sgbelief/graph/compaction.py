"""Compaction (paper §4.3): a pair's settled old entries folded into one ``compacted`` bucket of
equal increment, so that Eq. 4 still gives the same belief.

This module is the reference fold, in one place:

- :func:`settled_before` picks what a pass folds (settled entries older than the horizon, and
  any second bucket), :func:`fold_into_bucket` folds them (one ``math.fsum`` per pair and pass)
  and :func:`merge_into_bucket` adds an already summed increment to a pair's bucket (or makes it);
  node migration merges two buckets with it too;
- :class:`FoldSummary` is what a bucket folded, in bounded memory (counts per status and
  verdict, the Lambda-hat sum of its claims, first and last event ids);
- :func:`old_prefix_length` / :func:`take_old` give the prefix of the store's arrival-order
  timeline a pass scans;
- :func:`compact` is the policy over any :class:`~sgbelief.graph.entry_log.EntryLog` (the store
  folds, ``log.fold``), and :func:`fold_pass` the reference pass an object-backed store runs, over
  the few operations of :class:`FoldTarget`.

The fast kernel behind it (private, :mod:`sgbelief._fast.folds`, run by the journalled store's
``fold``) folds journal records and numpy groups without entry objects through the same
:class:`FoldTarget` operations and merges each pair's sum with :func:`merge_into_bucket`, bit
for bit the same (``sgbelief.testing.check_store_matches_reference``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

from sgbelief.graph.entry_log import EntryLog, PairKey
from sgbelief.graph.provenance_log import (
    COUNTED,
    PENDING,
    VERDICT_SYMBOLS,
    EntryStatus,
    PairLog,
    ProvenanceEntry,
    entry_lambda_hat,
)

# a member read once (an attribute lookup on an Enum class runs Python code)
_COMPACTED = EntryStatus.COMPACTED
_SYMBOL_OF = dict(VERDICT_SYMBOLS)
_SYMBOL_ORDER = tuple(VERDICT_SYMBOLS.values())  # the order a summary lists its verdicts in


def lambda_hat_sum(values: Iterable[float]) -> float:
    """The exactly rounded sum of Lambda-hat values (``math.fsum``; +inf when it overflows), so
    that it does not depend on the order in which compaction meets them."""
    try:
        return math.fsum(values)
    except OverflowError:
        return math.inf


class FoldSummary:
    """What a compacted bucket folded, in bounded memory (at most one count per status and per
    verdict): how many original entries per status and per recorded verdict (⊤, ⊥, ∅,
    "geometric"), the sum of Lambda-hat over the folded claim entries with their number (so
    their mean stays answerable), the time of the first, and the first and last event ids (in
    log order). The last time, the summed increments and the total are the bucket's own ``t``,
    ``d_alpha``/``d_beta`` and ``n_folded``. Entries folded before summaries were kept (files
    written by older versions) count under the status ``"unknown"``; entries without a recorded
    verdict count under no verdict."""

    __slots__ = ("counts", "t_first", "first_event_id", "last_event_id", "verdicts", "lambda_hat_sum",
                 "n_lambda_hat")

    def __init__(
        self,
        counts: dict[str, int],
        t_first: int | None,
        first_event_id: str | None,
        last_event_id: str | None,
        verdicts: dict[str, int] | None = None,
        lambda_hat_sum: float = 0.0,
        n_lambda_hat: int = 0,
    ) -> None:
        self.counts = counts
        self.t_first = t_first
        self.first_event_id = first_event_id
        self.last_event_id = last_event_id
        #: folded entries per recorded verdict symbol (VERDICT_SYMBOLS)
        self.verdicts: dict[str, int] = {} if verdicts is None else verdicts
        #: sum of Lambda-hat over the folded claim entries (:func:`entry_lambda_hat`), and their number
        self.lambda_hat_sum = lambda_hat_sum
        self.n_lambda_hat = n_lambda_hat

    @property
    def mean_lambda_hat(self) -> float | None:
        """The mean Lambda-hat of the folded claims (None when none had one recorded)."""
        return self.lambda_hat_sum / self.n_lambda_hat if self.n_lambda_hat else None

    @classmethod
    def unknown(cls, n: int) -> FoldSummary:
        """The summary of ``n`` folded entries of which nothing was kept."""
        return cls({UNKNOWN_STATUS: n}, None, None, None)

    @classmethod
    def committed(cls, n: int, t_first: int, first_event_id: str | None, last_event_id: str | None,
                  verdicts: dict[str, int] | None = None) -> FoldSummary:
        """The summary of ``n`` committed entries (what the journalled fast paths fold); their
        Lambda-hat sum is the caller's to set."""
        return cls({EntryStatus.COMMITTED.value: n}, t_first, first_event_id, last_event_id, verdicts)

    @classmethod
    def of_entries(cls, folded: Sequence[ProvenanceEntry], later: FoldSummary | None = None,
                   later_lambda_hats: Sequence[float] = ()) -> FoldSummary:
        """The summary of folding these entries (a bucket among them contributes its summary),
        then, when given, the entries ``later`` summarises (folded in the same pass, after these)
        whose Lambda-hat values are ``later_lambda_hats``: the Lambda-hat sum is one exactly
        rounded sum over all of them (:func:`lambda_hat_sum`), whatever way the pass is split."""
        out = cls({}, None, None, None)
        lams: list[float] = []
        counts, verdicts = out.counts, out.verdicts
        for e in folded:
            if e.status is _COMPACTED:
                s = e.summary if e.summary is not None else cls.unknown(e.n_folded)
                lams.append(s.lambda_hat_sum)
                out.absorb(s, with_lambda_hat=False)
                continue
            status = e.status.value
            counts[status] = counts.get(status, 0) + 1
            if e.verdict is not None:
                sym = _SYMBOL_OF[e.verdict]
                verdicts[sym] = verdicts.get(sym, 0) + 1
                lam = entry_lambda_hat(e)
                if lam is not None:
                    lams.append(lam)
                    out.n_lambda_hat += 1
            if out.t_first is None or e.t < out.t_first:
                out.t_first = e.t
            if e.event_id is not None:
                if out.first_event_id is None:
                    out.first_event_id = e.event_id
                out.last_event_id = e.event_id
        if later is not None:
            out.absorb(later, with_lambda_hat=False)
            lams += later_lambda_hats
        out.lambda_hat_sum = lambda_hat_sum(lams)
        return out

    def absorb(self, later: FoldSummary, *, with_lambda_hat: bool = True) -> None:
        """Add the summary of entries folded after (or logged after) these ones (their
        Lambda-hat sum by one IEEE addition, unless ``with_lambda_hat`` is false: then only
        their count)."""
        counts = self.counts
        for status, n in later.counts.items():
            counts[status] = counts.get(status, 0) + n
        verdicts = self.verdicts
        for sym, n in later.verdicts.items():
            verdicts[sym] = verdicts.get(sym, 0) + n
        if with_lambda_hat:
            self.lambda_hat_sum += later.lambda_hat_sum
        self.n_lambda_hat += later.n_lambda_hat
        if later.t_first is not None and (self.t_first is None or later.t_first < self.t_first):
            self.t_first = later.t_first
        if self.first_event_id is None:
            self.first_event_id = later.first_event_id
        if later.last_event_id is not None:
            self.last_event_id = later.last_event_id

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (Lambda-hat's sum +inf only if it overflowed: then written as null)."""
        lam = self.lambda_hat_sum
        return {
            "counts": dict(self.counts),
            "t_first": self.t_first,
            "first_event_id": self.first_event_id,
            "last_event_id": self.last_event_id,
            "verdicts": {sym: self.verdicts[sym] for sym in _SYMBOL_ORDER if sym in self.verdicts},
            "lambda_hat_sum": lam if math.isfinite(lam) else None,
            "n_lambda_hat": self.n_lambda_hat,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FoldSummary:
        """A summary from :meth:`to_dict`'s form; summaries written before verdicts were kept
        (no ``verdicts`` / ``lambda_hat_sum``) load with none."""
        counts = {str(k): int(v) for k, v in data["counts"].items()}
        t_first = data.get("t_first")
        verdicts = {str(k): int(v) for k, v in (data.get("verdicts") or {}).items()}
        unknown = set(verdicts) - set(VERDICT_SYMBOLS.values())
        if unknown:
            raise ValueError(f"unknown verdict {sorted(unknown)[0]!r} in a fold summary")
        lam = data.get("lambda_hat_sum", 0.0)
        n_lam = int(data.get("n_lambda_hat", 0))
        if n_lam < 0 or any(v < 0 for v in (*counts.values(), *verdicts.values())):
            raise ValueError("fold summary counts must be >= 0")
        return cls(counts, None if t_first is None else int(t_first), data.get("first_event_id"),
                   data.get("last_event_id"), verdicts, math.inf if lam is None else float(lam), n_lam)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, FoldSummary) and self.to_dict() == other.to_dict()

    def __repr__(self) -> str:
        return f"FoldSummary({self.to_dict()!r})"


#: the status under which a summary counts folded entries whose statuses were not kept
UNKNOWN_STATUS = "unknown"


# ------------------------------------------------------------------ the fold
def settled_before(
    entries: Sequence[ProvenanceEntry], before_t: int
) -> tuple[ProvenanceEntry | None, list[ProvenanceEntry], list[ProvenanceEntry]]:
    """Split a pair's log for compaction: (its compacted bucket or None, the entries to fold,
    the entries kept). Folded are the settled entries (not pending in a queue) with
    ``t < before_t``, and any further compacted entry (a log holds at most one bucket)."""
    bucket: ProvenanceEntry | None = None
    fold: list[ProvenanceEntry] = []
    keep: list[ProvenanceEntry] = []
    for entry in entries:
        if entry.status is _COMPACTED and bucket is None:
            bucket = entry
        elif entry.status is _COMPACTED or (entry.t < before_t and entry.status not in PENDING):
            fold.append(entry)
        else:
            keep.append(entry)
    return bucket, fold, keep


def fold_into_bucket(
    bucket: ProvenanceEntry | None, folded: Sequence[ProvenanceEntry], node: Any, predicate: str
) -> ProvenanceEntry:
    """Compaction (§4.3): fold entries into a pair's ``compacted`` bucket (a new one when None).

    The bucket's increment grows by the exactly rounded sum of the folded entries' counted
    increments, so the pair's belief under Eq. 4 is unchanged; it stands for as many original
    entries as they did (``n_folded``) and takes the latest of their times."""
    d_alpha = math.fsum(e.d_alpha for e in folded if e.status in COUNTED)
    d_beta = math.fsum(e.d_beta for e in folded if e.status in COUNTED)
    n_folded = sum(e.n_folded for e in folded)
    t_max = max(e.t for e in folded)
    summary = FoldSummary.of_entries(folded)
    return merge_into_bucket(bucket, node, predicate, t_max, d_alpha, d_beta, n_folded, summary)


def merge_into_bucket(
    bucket: ProvenanceEntry | None,
    node: Any,
    predicate: str,
    t_max: int,
    d_alpha: float,
    d_beta: float,
    n_folded: int,
    summary: FoldSummary | None = None,
) -> ProvenanceEntry:
    """Add one folded increment (already summed) to a pair's bucket, or make the bucket.
    ``summary`` describes the folded entries (None: nothing known of them but their number).

    One IEEE addition of two floats is correctly rounded, so adding the sum to the bucket equals
    ``math.fsum`` of the two (``+ 0.0`` turns a sum of two -0.0 into fsum's +0.0)."""
    if summary is None:
        summary = FoldSummary.unknown(n_folded)
    if bucket is None:
        bucket = ProvenanceEntry(None, t_max, d_alpha, d_beta, _COMPACTED, node, predicate)
        bucket.n_folded = n_folded
        bucket.summary = summary
        return bucket
    if bucket.summary is None:
        bucket.summary = FoldSummary.unknown(bucket.n_folded)
    bucket.summary.absorb(summary)
    bucket.d_alpha = bucket.d_alpha + d_alpha + 0.0  # + 0.0: -0.0 + -0.0 gives fsum's +0.0
    bucket.d_beta = bucket.d_beta + d_beta + 0.0
    bucket.n_folded += n_folded
    if t_max > bucket.t:
        bucket.t = t_max
    return bucket


def bucket_summary(entries: Iterable[ProvenanceEntry]) -> FoldSummary | None:
    """The fold summary of a log's compacted bucket (None without a bucket or a summary)."""
    for e in entries:
        if e.status is _COMPACTED:
            return e.summary
    return None


def attach_summary(entries: list[ProvenanceEntry], summary: FoldSummary, where: str) -> None:
    """Give a loaded log's bucket its saved fold summary."""
    for e in entries:
        if e.status is _COMPACTED:
            e.summary = summary
            return
    raise ValueError(f"{where}.fold_summary: the pair has no compacted entry to summarise")


# ------------------------------------------------------------------ the pass's scan
def old_prefix_length(timeline: Iterable[ProvenanceEntry], before_t: int) -> int:
    """Length of the timeline's prefix a pass at ``before_t`` takes: up to its first live entry
    with ``t >= before_t``."""
    n_old = 0
    for entry in timeline:
        if entry.t >= before_t and entry.alive:
            break
        n_old += 1
    return n_old


def take_old(timeline: deque[ProvenanceEntry], before_t: int) -> list[ProvenanceEntry]:
    """Pop the timeline's prefix up to its first live entry with ``t >= before_t`` (the entries
    a pass at ``before_t`` scans, in arrival order)."""
    old: list[ProvenanceEntry] = []
    while timeline and (timeline[0].t < before_t or not timeline[0].alive):
        old.append(timeline.popleft())
    return old


# ------------------------------------------------------------------ the pass
class FoldTarget(Protocol):
    """What a compaction pass changes in an object-backed store
    (:class:`sgbelief.graph.provenance.ProvenanceStore` implements it)."""

    def pair_index(self) -> Mapping[PairKey, PairLog]:
        """Every pair's log (live, read-only)."""

    def timeline_view(self) -> Sequence[ProvenanceEntry]:
        """The timeline in arrival order (live, read-only)."""

    def pop_timeline(self, n: int) -> list[ProvenanceEntry]:
        """Take the timeline's first ``n`` entries (the ones a pass scans)."""

    def fold_pair(self, log: PairLog, bucket: ProvenanceEntry, folded: Iterable[ProvenanceEntry],
                  keep: list[ProvenanceEntry] | None) -> list[str]:
        """A pair's log becomes ``[bucket, *keep]`` (``keep`` None: unchanged, the bucket is in
        place); the folded entries die and leave the event index. Returns the ids that had their
        last live entry among them, in order."""

    def retire(self, event_ids: Iterable[str], n_folded: int) -> None:
        """Count ``n_folded`` folded entries and remember the retired ids (the oldest drop out)."""


def fold_pass(store: FoldTarget, before_t: int) -> int:
    """The reference pass: every settled entry with ``t < before_t`` folded into one equivalent
    increment per pair (:func:`fold_into_bucket`); returns the number of entries folded.

    Pending entries are never folded. Cost is amortised O(1) per entry: only pairs that received
    entries older than the horizon are visited, in the order their oldest such entry arrived
    (deterministic: the compacted-id memory fills in that order, each pair's folded entries in log
    order, an id when its last live entry is folded).

    The timeline is scanned in arrival order up to the first live entry not older than the horizon
    (:func:`old_prefix_length`): when times go back (replayed or merged logs), entries behind it
    wait for a later pass. Dead entries (retracted) hold nothing back, so a loaded copy, which no
    longer holds them, folds the same entries.
    """
    old = store.pop_timeline(old_prefix_length(store.timeline_view(), before_t))
    pairs_get = store.pair_index().get
    folded = 0
    retired: list[str] = []
    for key in dict.fromkeys([(e.node, e.predicate) for e in old if e.alive]):
        log = pairs_get(key)
        if log is None:
            continue
        bucket, fold, keep = settled_before(log.entries, before_t)
        if not fold:
            continue
        retired += store.fold_pair(log, fold_into_bucket(bucket, fold, key[0], key[1]), fold, keep)
        folded += len(fold)
    store.retire(retired, folded)
    return folded


def compact(log: EntryLog, before_t: int) -> int:
    """Compaction (§4.3) of any store: fold every settled entry with ``t < before_t`` into its
    pair's compacted bucket, so that Eq. 4 gives the same beliefs; returns the number folded.

    The store folds (``log.fold``): the object-backed store runs :func:`fold_pass`, the journalled
    one folds its journal records with the kernel of ``sgbelief._fast.folds`` when that gives
    exactly what :func:`fold_pass` would, and :func:`fold_pass` otherwise."""
    return log.fold(before_t)


__all__ = [
    "UNKNOWN_STATUS", "FoldSummary", "FoldTarget", "attach_summary", "bucket_summary", "compact", "fold_into_bucket",
    "fold_pass", "lambda_hat_sum", "merge_into_bucket", "old_prefix_length", "settled_before", "take_old",
]

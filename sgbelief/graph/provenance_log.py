"""A provenance log (paper §4.3): its entries, their statuses, the belief they define (Eq. 4)
and the fold that compaction applies to them.

An entry is ``(event id, t, d_alpha, d_beta, status)`` plus the stance of its evidence; a pair's
log (:class:`PairLog`) is its entries in order with the running belief. The belief is *defined*
by the log (:func:`belief_from_entries`, Eq. 4); compaction folds old entries into one
``compacted`` entry of equal increment (:func:`fold_into_bucket`). The store of all logs, with
the queues, the event index, retraction and compaction, is :mod:`sgbelief.graph.provenance`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from enum import Enum
from typing import Any


class EntryStatus(str, Enum):
    """Life-cycle status of a provenance entry."""

    COMMITTED = "committed"  #: applied to the belief (Eq. 3)
    REFUSED = "refused"  #: ⊥ verdict: refused, pending in the disagreement queue Q⊥
    RESOLVED = "resolved"  #: ⊥ later corroborated by ⊤ within T_disagree; never committed
    EXPIRED = "expired"  #: ⊥ released on timeout, unresolved; never committed
    DISMISSED = "dismissed"  #: ⊥ closed by an explicit operator decision without committing
    QUARANTINED = "quarantined"  #: revision (KL > tau_rev) pending in the quarantine Q
    RELEASED = "released"  #: revision released on timeout, committed at reduced weight w/k
    DISCARDED = "discarded"  #: revision disconfirmed within T_cor; never committed
    CONFIRMED = "confirmed"  #: committed by an explicit operator confirmation
    COMPACTED = "compacted"  #: several old entries folded into one equivalent increment


#: statuses whose increments count in the belief (Eq. 4)
COUNTED: frozenset[EntryStatus] = frozenset(
    {EntryStatus.COMMITTED, EntryStatus.RELEASED, EntryStatus.CONFIRMED, EntryStatus.COMPACTED}
)
#: statuses of entries still waiting in a queue
PENDING: frozenset[EntryStatus] = frozenset({EntryStatus.REFUSED, EntryStatus.QUARANTINED})

# a member read once (an attribute lookup on an Enum class runs Python code)
_COMPACTED = EntryStatus.COMPACTED


class ProvenanceEntry:
    """One log entry. Mutable only through :class:`ProvenanceStore` (status transitions)."""

    __slots__ = (
        "event_id",
        "t",
        "d_alpha",
        "d_beta",
        "status",
        "node",
        "predicate",
        "stance",
        "corroborated_by",
        "n_folded",
        "alive",
        "summary",
    )

    def __init__(
        self,
        event_id: str | None,
        t: int,
        d_alpha: float,
        d_beta: float,
        status: EntryStatus,
        node: Any,
        predicate: str,
        stance: int = 0,
    ) -> None:
        self.event_id = event_id
        self.t = t
        self.d_alpha = d_alpha
        self.d_beta = d_beta
        self.status = status
        self.node = node
        self.predicate = predicate
        #: +1 when the evidence supports the predicate, -1 when it denies it, 0 neutral
        self.stance = stance
        #: ids of events whose corroboration committed this (revision) entry
        self.corroborated_by: list[str] | None = None
        #: number of original entries a compacted entry stands for
        self.n_folded = 1
        #: False once retracted or folded away
        self.alive = True
        #: for a compacted bucket, what it folded (:class:`FoldSummary`); None otherwise, or unknown
        self.summary: FoldSummary | None = None

    @property
    def counted(self) -> bool:
        return self.status in COUNTED

    @property
    def pending(self) -> bool:
        return self.status in PENDING

    def as_tuple(self) -> tuple[str | None, int, float, float, str]:
        """(event id, t, d_alpha, d_beta, status) as in the paper's log."""
        return (self.event_id, self.t, self.d_alpha, self.d_beta, self.status.value)

    def __repr__(self) -> str:
        return (
            f"ProvenanceEntry(event_id={self.event_id!r}, t={self.t}, d_alpha={self.d_alpha:.6g}, "
            f"d_beta={self.d_beta:.6g}, status={self.status.value}, node={self.node!r}, "
            f"predicate={self.predicate!r})"
        )


class FoldSummary:
    """What a compacted bucket folded, in bounded memory (at most one count per status):
    how many original entries per status, the time of the first, and the first and last event
    ids (in log order). The last time, the summed increments and the total are the bucket's own
    ``t``, ``d_alpha``/``d_beta`` and ``n_folded``. Entries folded before summaries were kept
    (files written by older versions) count under the status ``"unknown"``."""

    __slots__ = ("counts", "t_first", "first_event_id", "last_event_id")

    def __init__(
        self,
        counts: dict[str, int],
        t_first: int | None,
        first_event_id: str | None,
        last_event_id: str | None,
    ) -> None:
        self.counts = counts
        self.t_first = t_first
        self.first_event_id = first_event_id
        self.last_event_id = last_event_id

    @classmethod
    def unknown(cls, n: int) -> FoldSummary:
        """The summary of ``n`` folded entries of which nothing was kept."""
        return cls({UNKNOWN_STATUS: n}, None, None, None)

    @classmethod
    def committed(cls, n: int, t_first: int, first_event_id: str | None, last_event_id: str | None) -> FoldSummary:
        """The summary of ``n`` committed entries (what the journalled fast paths fold)."""
        return cls({EntryStatus.COMMITTED.value: n}, t_first, first_event_id, last_event_id)

    @classmethod
    def of_entries(cls, folded: Sequence[ProvenanceEntry]) -> FoldSummary:
        """The summary of folding these entries (a bucket among them contributes its summary)."""
        out = cls({}, None, None, None)
        for e in folded:
            if e.status is _COMPACTED:
                out.absorb(e.summary if e.summary is not None else cls.unknown(e.n_folded))
            else:
                out.absorb(cls({e.status.value: 1}, e.t, e.event_id, e.event_id))
        return out

    def absorb(self, later: FoldSummary) -> None:
        """Add the summary of entries folded after (or logged after) these ones."""
        counts = self.counts
        for status, n in later.counts.items():
            counts[status] = counts.get(status, 0) + n
        if later.t_first is not None and (self.t_first is None or later.t_first < self.t_first):
            self.t_first = later.t_first
        if self.first_event_id is None:
            self.first_event_id = later.first_event_id
        if later.last_event_id is not None:
            self.last_event_id = later.last_event_id

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return {
            "counts": dict(self.counts),
            "t_first": self.t_first,
            "first_event_id": self.first_event_id,
            "last_event_id": self.last_event_id,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FoldSummary:
        counts = {str(k): int(v) for k, v in data["counts"].items()}
        t_first = data.get("t_first")
        return cls(counts, None if t_first is None else int(t_first), data.get("first_event_id"),
                   data.get("last_event_id"))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, FoldSummary) and self.to_dict() == other.to_dict()

    def __repr__(self) -> str:
        return f"FoldSummary({self.to_dict()!r})"


#: the status under which a summary counts folded entries whose statuses were not kept
UNKNOWN_STATUS = "unknown"


# ------------------------------------------------------------------ the equations
def belief_from_entries(prior: tuple[float, float], entries: Iterable[ProvenanceEntry]) -> tuple[float, float]:
    """Eq. 4 (``eq:provrecon``): the belief a log defines,

        (alpha, beta) = (alpha_0, beta_0) + sum over counted entries of (d_alpha, d_beta),

    each sum exactly rounded (``math.fsum``), so it does not depend on the order of the log."""
    counted = [e for e in entries if e.status in COUNTED]
    return (
        prior[0] + math.fsum(e.d_alpha for e in counted),
        prior[1] + math.fsum(e.d_beta for e in counted),
    )


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
    ``math.fsum`` of the two."""
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
    bucket.d_alpha += d_alpha
    bucket.d_beta += d_beta
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


def merged_summary(head: ProvenanceEntry, extra: ProvenanceEntry) -> FoldSummary:
    """The summary of two buckets merged into one (migration), ``head`` first."""
    merged = FoldSummary({}, None, None, None)
    for bucket, n in ((head, head.n_folded - extra.n_folded), (extra, extra.n_folded)):
        merged.absorb(bucket.summary if bucket.summary is not None else FoldSummary.unknown(n))
    return merged


# ------------------------------------------------------------------ a pair's log
def event_list(found: ProvenanceEntry | list[ProvenanceEntry] | None) -> list[ProvenanceEntry]:
    """A value of the event index as a (new) list of entries."""
    if found is None:
        return []
    if type(found) is list:
        return list(found)
    return [found]  # type: ignore[list-item]


def index_event(by_event: dict[str, Any], event_id: str, entry: ProvenanceEntry) -> None:
    """Add an entry to an event index: the entry itself for an id's first entry, a list from its
    second on (the id keeps its place in the dict; most events have one entry, and then no list
    is allocated)."""
    prev = by_event.get(event_id)
    if prev is None:
        by_event[event_id] = entry
    elif type(prev) is list:
        prev.append(entry)
    else:
        by_event[event_id] = [prev, entry]


class PairLog:
    """The log of one (node, predicate) pair: its entries in order and its running belief
    (equal to :func:`belief_from_entries` of the entries, kept so that reads are O(1))."""

    __slots__ = ("alpha", "beta", "entries")

    def __init__(self, alpha: float, beta: float) -> None:
        self.alpha = alpha
        self.beta = beta
        self.entries: list[ProvenanceEntry] = []

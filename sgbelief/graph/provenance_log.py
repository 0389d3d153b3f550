"""A provenance log (paper §4.3): its entries, their statuses, the belief they define (Eq. 4)
and the fold that compaction applies to them.

An entry is ``(event id, t, d_alpha, d_beta, status)`` plus the stance of its evidence and, for
the calibrated operators, the verdict (:class:`EntryVerdict`) and the event's raw confidence; a
claim's calibrated Lambda-hat and weight are not stored but read back from its increments
(:func:`claim_lambda_hat`, :func:`claim_weight`, the inversion of Eq. 3). A pair's log
(:class:`PairLog`) is its entries in order with the running belief. The belief is *defined*
by the log (:func:`belief_from_entries`, Eq. 4); compaction folds old entries into one
``compacted`` entry of equal increment (:func:`fold_into_bucket`). The store of all logs, with
the queues, the event index, retraction and compaction, is :mod:`sgbelief.graph.provenance`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from enum import Enum, IntEnum
from typing import Any, NamedTuple


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


class EntryVerdict(IntEnum):
    """What the geometric channel said of the event behind an entry, recorded when the operator
    writes it (a small int: one shared object per code). Entries of operators without a verdict
    (the baselines) and entries of files written before verdicts were kept hold None."""

    NO_CLAIM = 0  #: ∅: the channel makes no verifiable assertion at (v, t)
    CORROBORATES = 1  #: ⊤: the geometric label agrees with the claim's sign
    CONTRADICTS = 2  #: ⊥: the geometric label contradicts it
    GEOMETRIC = 3  #: not a claim: the decisive geometric label itself as one observation of y
    EXCLUSION = 4  #: not a claim of this predicate: a claim of an exclusive rival class, as evidence against it

    @property
    def symbol(self) -> str:
        """⊤ / ⊥ / ∅, "geometric" for a geometric observation, "exclusion" for a rival class's
        claim (the keys of the fold summaries)."""
        return VERDICT_SYMBOLS[self]

    @property
    def is_claim(self) -> bool:
        """Whether the entry holds a claim's increments (Eq. 3), from which Lambda-hat follows."""
        return self is not EntryVerdict.GEOMETRIC and self is not EntryVerdict.EXCLUSION


#: the symbol of each verdict code (the keys of :attr:`FoldSummary.verdicts`)
VERDICT_SYMBOLS: dict[EntryVerdict, str] = {
    EntryVerdict.NO_CLAIM: "∅",
    EntryVerdict.CORROBORATES: "⊤",
    EntryVerdict.CONTRADICTS: "⊥",
    EntryVerdict.GEOMETRIC: "geometric",
    EntryVerdict.EXCLUSION: "exclusion",
}
#: verdict code -> member (for loaders: ``VERDICT_BY_CODE[code]``)
VERDICT_BY_CODE: tuple[EntryVerdict, ...] = tuple(EntryVerdict)
_GEOMETRIC = EntryVerdict.GEOMETRIC
_SYMBOL_OF = {v: VERDICT_SYMBOLS[v] for v in EntryVerdict}
_SYMBOL_ORDER = tuple(VERDICT_SYMBOLS.values())  # the order a summary lists its verdicts in


def claim_lambda_hat(d_alpha: float, d_beta: float) -> float | None:
    """The calibrated Lambda-hat of a claim, read back from its increments (Eq. 3 inverted).

    Eq. 3 writes (d_alpha, d_beta) = (w Lambda / (1 + Lambda), w / (1 + Lambda)), so::

        Lambda = d_alpha / d_beta

    (exact up to rounding: a few ulps). A common scale of both increments (a revision released
    at w/k) leaves it unchanged. None when the increments cannot be a claim's (d_beta <= 0,
    d_alpha < 0, or either not finite)."""
    if d_beta > 0.0 and d_alpha >= 0.0 and d_beta < math.inf and d_alpha < math.inf:
        return d_alpha / d_beta
    return None


def claim_weight(d_alpha: float, d_beta: float) -> float:
    """The weight w T(v) of a claim, read back from its increments (Eq. 3 inverted)::

        w T(v) = d_alpha + d_beta

    (exact up to rounding); for an entry released at w/k, its released weight."""
    return d_alpha + d_beta


def entry_lambda_hat(entry: ProvenanceEntry) -> float | None:
    """Lambda-hat of an entry that records a claim (a verdict other than "geometric" and
    "exclusion"); None for an observation, an entry without a recorded verdict or impossible
    increments."""
    v = entry.verdict
    if v is None or not v.is_claim:
        return None
    return claim_lambda_hat(entry.d_alpha, entry.d_beta)


def lambda_hat_sum(values: Iterable[float]) -> float:
    """The exactly rounded sum of Lambda-hat values (``math.fsum``; +inf when it overflows), so
    that it does not depend on the order in which compaction meets them."""
    try:
        return math.fsum(values)
    except OverflowError:
        return math.inf


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
        "verdict",
        "confidence",
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
        verdict: EntryVerdict | None = None,
        confidence: float | None = None,
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
        #: the verdict when the operator wrote the entry (None: the operator has none, or not recorded)
        self.verdict = verdict
        #: the event's raw confidence c (None: not recorded)
        self.confidence = confidence

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
            f"predicate={self.predicate!r}, verdict={None if self.verdict is None else self.verdict.symbol}, "
            f"confidence={self.confidence!r})"
        )


class EntryRecord(NamedTuple):
    """The fields of one new log entry, built by keyword and handed to a store
    (``store.append(EntryRecord(node=v, predicate=phi, event_id=..., t=..., d_alpha=...,
    d_beta=..., status=..., stance=..., verdict=..., confidence=...))``); the store makes the
    :class:`ProvenanceEntry` (which then changes only through the store)."""

    node: Any
    predicate: str
    event_id: str | None
    t: int
    d_alpha: float
    d_beta: float
    #: the entry's status: counted ones change the belief, pending ones join their queue
    status: EntryStatus = EntryStatus.COMMITTED
    #: +1 when the evidence supports the predicate, -1 when it denies it, 0 neutral
    stance: int = 0
    #: what the channel said when the operator wrote the entry (None: no verdict, e.g. a baseline)
    verdict: EntryVerdict | None = None
    #: the event's raw confidence c (None: not recorded)
    confidence: float | None = None


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


# ------------------------------------------------------------------ the JSON row of an entry
def entry_row(e: ProvenanceEntry) -> list[Any]:
    """An entry as a graph.json row: ``[event_id, t, d_alpha, d_beta, status, stance,
    corroborated_by, n_folded]``, then ``verdict`` (its code) and ``confidence`` when either
    was recorded (rows without them are what older versions wrote, and still read)."""
    row = [e.event_id, e.t, e.d_alpha, e.d_beta, e.status.value, e.stance, e.corroborated_by, e.n_folded]
    if e.verdict is not None or e.confidence is not None:
        row += (None if e.verdict is None else int(e.verdict), e.confidence)
    return row


def entry_extras(row: Sequence[Any], where: str) -> tuple[EntryVerdict | None, float | None]:
    """(verdict, confidence) of a graph.json row (None, None for an 8-field row); ValueError
    naming ``where`` for a bad code or a confidence that is not a number in [0, 1]."""
    if len(row) == 8:
        return None, None
    if len(row) != 10:
        raise ValueError(f"{where}: an entry has 8 or 10 fields, got {len(row)}")
    code, confidence = row[8], row[9]
    verdict = None
    if code is not None:
        if type(code) is not int or not 0 <= code < len(VERDICT_BY_CODE):
            raise ValueError(f"{where}: verdict code must be null or an integer in [0, {len(VERDICT_BY_CODE)}), "
                             f"got {code!r}")
        verdict = VERDICT_BY_CODE[code]
    if confidence is not None:
        if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) or not 0.0 <= confidence <= 1.0:
            raise ValueError(f"{where}: confidence must be null or a number in [0, 1], got {confidence!r}")
        confidence = float(confidence)
    return verdict, confidence

"""A provenance log (paper §4.3): its entries, their statuses, the belief they define (Eq. 4)
and the fold that compaction applies to them.

An entry is ``(event id, t, d_alpha, d_beta, status)`` plus the stance of its evidence and, for
the calibrated operators, the verdict (:class:`EntryVerdict`) and the event's raw confidence; a
claim's calibrated Lambda-hat and weight are not stored but read back from its increments
(:func:`claim_lambda_hat`, :func:`claim_weight`, the inversion of Eq. 3). A pair's log
(:class:`PairLog`) is its entries in order with the running belief. The belief is *defined*
by the log (:func:`belief_from_entries`, Eq. 4). A new entry is written as an
:class:`EntryRecord` (built by keyword). Compaction, which folds old entries into one
``compacted`` entry of equal increment, is :mod:`sgbelief.graph.compaction`; the store of all
logs, with the queues, the event index and retraction, is :mod:`sgbelief.graph.provenance`.
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
    WITHDRAWN = "withdrawn"  #: committed while the channel had not adjudicated its element, then contradicted by all its labels; no longer counted


#: statuses whose increments count in the belief (Eq. 4)
COUNTED: frozenset[EntryStatus] = frozenset(
    {EntryStatus.COMMITTED, EntryStatus.RELEASED, EntryStatus.CONFIRMED, EntryStatus.COMPACTED}
)
#: statuses of entries still waiting in a queue
PENDING: frozenset[EntryStatus] = frozenset({EntryStatus.REFUSED, EntryStatus.QUARANTINED})



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


#: the symbol of each verdict code (the keys of ``FoldSummary.verdicts``)
VERDICT_SYMBOLS: dict[EntryVerdict, str] = {
    EntryVerdict.NO_CLAIM: "∅",
    EntryVerdict.CORROBORATES: "⊤",
    EntryVerdict.CONTRADICTS: "⊥",
    EntryVerdict.GEOMETRIC: "geometric",
    EntryVerdict.EXCLUSION: "exclusion",
}
#: verdict code -> member (for loaders: ``VERDICT_BY_CODE[code]``)
VERDICT_BY_CODE: tuple[EntryVerdict, ...] = tuple(EntryVerdict)


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
        #: for a compacted bucket, what it folded (a :class:`~sgbelief.graph.compaction.FoldSummary`,
        #: which compaction, one module up, writes); None otherwise, or unknown
        self.summary: Any = None
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

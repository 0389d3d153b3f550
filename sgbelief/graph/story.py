"""A belief's story: every provenance entry of one (node, predicate) pair, in time order, what
happened to it, and why the pair is or is not committed (P > tau, strictly).

The story is read from the provenance log alone (§4.3), so it is the same for a map in memory
and for one loaded from graph.json or graph.npz. Compaction (T_prov) folds old entries into one
``compacted`` bucket; its :class:`~sgbelief.graph.provenance_log.FoldSummary` keeps how many
entries of each status it folded, the time range and the first and last event ids, so the
counts of a story do not depend on compaction.

What an entry does not hold is said, not guessed: the log keeps the increments (d_alpha, d_beta)
and the stance of the evidence, not the verdict, confidence, calibrated Lambda-hat or weight that
produced them. Only the verdict of an entry of the disagreement queue is known from its status
(refused, resolved, expired, dismissed: it arrived as ⊥).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from sgbelief.graph.provenance_log import COUNTED, UNKNOWN_STATUS, EntryStatus, ProvenanceEntry
from sgbelief.graph.scene_graph import SceneGraph

__all__ = ["NOT_RECORDED", "FoldedStory", "StoryEvent", "BeliefStory", "explain"]

#: statuses of an entry that arrived with a ⊥ verdict (it went through the disagreement queue Q⊥)
REFUSAL_STATUSES = frozenset(
    {EntryStatus.REFUSED, EntryStatus.RESOLVED, EntryStatus.EXPIRED, EntryStatus.DISMISSED}
)
#: what the provenance log does not keep (said once in every story)
NOT_RECORDED = (
    "the log keeps each event's increments and stance, not its verdict, confidence, calibrated "
    "Λ̂ or weight (only ⊥ is known, from a refusal status); retracted events leave no entry"
)
_STANCE = {1: "supports", -1: "denies", 0: "neutral"}


@dataclass(frozen=True)
class StoryEvent:
    """One live (not compacted) provenance entry of the pair."""

    event_id: str | None
    t: int
    status: str
    d_alpha: float
    d_beta: float
    counted: bool  #: whether its increments are in the belief (Eq. 4)
    stance: str  #: supports / denies / neutral
    verdict: str | None  #: "⊥" for an entry of the disagreement queue; None: not recorded
    corroborated_by: tuple[str, ...] = ()


@dataclass(frozen=True)
class FoldedStory:
    """What compaction folded into the pair's bucket. ``counts`` holds ``"unknown"`` for entries
    folded by a version that kept no summary; then ``t_first`` and the ids may be None."""

    n: int
    counts: dict[str, int]
    t_first: int | None
    t_last: int
    d_alpha: float
    d_beta: float
    first_event_id: str | None
    last_event_id: str | None


@dataclass(frozen=True)
class BeliefStory:
    """The story of one (node, predicate) pair."""

    node: Any
    predicate: str
    alpha: float
    beta: float
    probability: float
    tau: float
    committed: bool
    folded: FoldedStory | None
    events: tuple[StoryEvent, ...]
    counts: dict[str, int]  #: entries per status, folded and live together
    verdicts: dict[str, int]  #: entries per known verdict ("⊥"); the rest are not recorded
    sentence: str
    not_recorded: str = NOT_RECORDED

    @property
    def n_entries(self) -> int:
        return sum(self.counts.values())

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of the whole story (what ``sgbelief explain --json`` prints)."""
        out = asdict(self)
        out["events"] = [asdict(e) | {"corroborated_by": list(e.corroborated_by)} for e in self.events]
        out["n_entries"] = self.n_entries
        return out


def _event(entry: ProvenanceEntry) -> StoryEvent:
    status = entry.status
    return StoryEvent(
        event_id=entry.event_id,
        t=entry.t,
        status=status.value,
        d_alpha=entry.d_alpha,
        d_beta=entry.d_beta,
        counted=status in COUNTED,
        stance=_STANCE.get(entry.stance, str(entry.stance)),
        verdict="⊥" if status in REFUSAL_STATUSES else None,
        corroborated_by=tuple(entry.corroborated_by or ()),
    )


def _folded(bucket: ProvenanceEntry) -> FoldedStory:
    s = bucket.summary
    counts = dict(s.counts) if s is not None else {UNKNOWN_STATUS: bucket.n_folded}
    return FoldedStory(
        n=bucket.n_folded,
        counts=counts,
        t_first=s.t_first if s is not None else None,
        t_last=bucket.t,
        d_alpha=bucket.d_alpha,
        d_beta=bucket.d_beta,
        first_event_id=s.first_event_id if s is not None else None,
        last_event_id=s.last_event_id if s is not None else None,
    )


def count_phrase(counts: dict[str, int]) -> str:
    """``"22 entries: 17 refused, 5 committed"`` (statuses by count, largest first)."""
    n = sum(counts.values())
    parts = ", ".join(f"{c} {s}" for s, c in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])) if c)
    noun = "entry" if n == 1 else "entries"
    return f"{n} {noun}: {parts}" if parts else f"{n} {noun}"


def _sentence(predicate: str, p: float, tau: float, counts: dict[str, int], pending: int,
              added: tuple[float, float]) -> str:
    if not counts:
        return (f"Not committed: no evidence on {predicate}, so the belief is the prior "
                f"(P = {p:.3f} ≤ τ = {tau:g}).")
    refused = sum(counts.get(s.value, 0) for s in REFUSAL_STATUSES)
    counted = sum(counts.get(s.value, 0) for s in COUNTED if s is not EntryStatus.COMPACTED)
    why = (f"{counted} of {sum(counts.values())} entries count in the belief, adding "
           f"dα={added[0]:+.3f} dβ={added[1]:+.3f} to the prior")
    if refused:
        why += f", {refused} arrived contradicted (⊥) and do not"
    if counts.get(UNKNOWN_STATUS):
        why += f", {counts[UNKNOWN_STATUS]} were folded without a record of their status"
    if pending:
        why += f"; {pending} still pending in a queue can change it"
    if p > tau:
        return f"Committed: P = {p:.3f} > τ = {tau:g} ({why})."
    return f"Not committed: P = {p:.3f} ≤ τ = {tau:g} ({why})."


def explain(graph: SceneGraph, node: Any, predicate: str, *, tau: float = 0.5) -> BeliefStory:
    """The story of (node, predicate) in ``graph``: its compacted bucket's summary, then every
    live entry in time order, the counts per status, and one sentence saying why the pair is or
    is not committed at ``tau`` (committed iff P > tau)."""
    belief = graph.belief(node, predicate)
    alpha, beta = belief.alpha, belief.beta
    p = graph.probability(node, predicate)
    entries = graph.provenance.entries(node, predicate)
    buckets = [e for e in entries if e.status is EntryStatus.COMPACTED]
    live = sorted((e for e in entries if e.status is not EntryStatus.COMPACTED), key=lambda e: e.t)
    folded = _folded(buckets[0]) if buckets else None
    counts: dict[str, int] = dict(folded.counts) if folded is not None else {}
    events = tuple(map(_event, live))
    for ev in events:
        counts[ev.status] = counts.get(ev.status, 0) + 1
    refused = sum(counts.get(s.value, 0) for s in REFUSAL_STATUSES)
    verdicts = {"⊥": refused} if refused else {}
    pending = sum(1 for e in live if e.pending)
    return BeliefStory(
        node=node,
        predicate=predicate,
        alpha=alpha,
        beta=beta,
        probability=p,
        tau=tau,
        committed=p > tau,
        folded=folded,
        events=events,
        counts=counts,
        verdicts=verdicts,
        sentence=_sentence(predicate, p, tau, counts, pending,
                           (alpha - graph.provenance.prior_alpha, beta - graph.provenance.prior_beta)),
    )

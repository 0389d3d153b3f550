"""A belief's story: every provenance entry of one (node, predicate) pair, in time order, what
happened to it, and why the pair is or is not committed (P > tau, strictly).

The story is read from the provenance log alone (§4.3), so it is the same for a map in memory
and for one loaded from graph.json or graph.npz. Each entry written by a calibrated operator
records its verdict (⊤ / ⊥ / ∅, or "geometric" for the geometric label observed as evidence)
and the event's raw confidence; a claim's calibrated Lambda-hat and weight are read back from its
increments (Eq. 3 inverted: :func:`~sgbelief.graph.provenance_log.claim_lambda_hat`,
:func:`~sgbelief.graph.provenance_log.claim_weight`). Compaction (T_prov) folds old entries into
one ``compacted`` bucket; its :class:`~sgbelief.graph.compaction.FoldSummary` keeps how
many entries of each status and verdict it folded, the sum of their Lambda-hat, the time range
and the first and last event ids, so the counts of a story do not depend on compaction.

What the log does not hold is said, not guessed (:data:`NOT_RECORDED`). Entries of the
baselines (no verdict) and of files written before verdicts were kept carry neither verdict nor
confidence; of those, only an entry of the disagreement queue has a known verdict, from its
status (refused, resolved, expired, dismissed: it arrived as ⊥).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from sgbelief.graph.compaction import UNKNOWN_STATUS
from sgbelief.graph.provenance_log import (
    COUNTED,
    VERDICT_SYMBOLS,
    EntryStatus,
    EntryVerdict,
    ProvenanceEntry,
    claim_lambda_hat,
    claim_weight,
)
from sgbelief.graph.scene_graph import SceneGraphModel

__all__ = ["NOT_RECORDED", "NOT_RECORDED_OLD", "STORY_KEY", "FoldedStory", "StoryEvent", "BeliefStory", "explain",
           "render_story"]

#: statuses of an entry that arrived with a ⊥ verdict (it went through the disagreement queue Q⊥)
REFUSAL_STATUSES = frozenset(
    {EntryStatus.REFUSED, EntryStatus.RESOLVED, EntryStatus.EXPIRED, EntryStatus.DISMISSED}
)
#: what the provenance log does not keep (said once in every story)
NOT_RECORDED = (
    "Λ̂ = dα/dβ and the weight w·T(v) = dα + dβ are read back from each claim's increments (Eq. 3 "
    "inverted), not stored; not kept: how the weight splits into w0·κ̂·T(v), the event's other "
    "targets, and retracted events (they leave no entry); a compacted bucket keeps only its counts "
    "per status and verdict, time range, sums and mean Λ̂"
)
#: added when some entry carries no verdict or confidence
NOT_RECORDED_OLD = (
    "entries written by an operator without verdicts (the baselines) or by an older sgbelief carry "
    "no verdict or confidence (·; ⊥ is known from a refusal status)"
)
_STANCE = {1: "supports", -1: "denies", 0: "neutral"}
_BOTTOM = VERDICT_SYMBOLS[EntryVerdict.CONTRADICTS]
_GEOMETRIC = VERDICT_SYMBOLS[EntryVerdict.GEOMETRIC]
_EXCLUSION = VERDICT_SYMBOLS[EntryVerdict.EXCLUSION]
#: the verdicts of a claim (every verdict but the geometric observation)
CLAIM_VERDICTS = tuple(sym for v, sym in VERDICT_SYMBOLS.items() if v.is_claim)


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
    #: ⊤ / ⊥ / ∅ / "geometric" as recorded; "⊥" for an unrecorded entry of the disagreement
    #: queue; None: not recorded
    verdict: str | None
    confidence: float | None = None  #: the event's raw confidence c (None: not recorded)
    lambda_hat: float | None = None  #: a claim's calibrated Lambda-hat, dα/dβ (None: not a claim, or unknown)
    weight: float | None = None  #: w·T(v) = dα + dβ (at w/k once released); None: unknown
    corroborated_by: tuple[str, ...] = ()
    recorded: bool = False  #: whether the verdict and confidence were recorded with the entry


@dataclass(frozen=True)
class FoldedStory:
    """What compaction folded into the pair's bucket. ``counts`` holds ``"unknown"`` for entries
    folded by a version that kept no summary; then ``t_first`` and the ids may be None.
    ``verdicts`` counts the folded entries per recorded verdict; ``mean_lambda_hat`` is the mean
    Lambda-hat of the ``n_lambda_hat`` folded claims that had one."""

    n: int
    counts: dict[str, int]
    t_first: int | None
    t_last: int
    d_alpha: float
    d_beta: float
    first_event_id: str | None
    last_event_id: str | None
    verdicts: dict[str, int]
    n_lambda_hat: int
    mean_lambda_hat: float | None


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
    #: entries per verdict (⊤ / ⊥ / ∅ / geometric), folded and live together; entries without a
    #: recorded verdict count only as ⊥ when their status says so
    verdicts: dict[str, int]
    n_claims: int  #: claim entries with a known Lambda-hat, folded and live
    mean_lambda_hat: float | None  #: their mean Lambda-hat (None without any)
    sentence: str
    not_recorded: str = NOT_RECORDED

    @property
    def n_entries(self) -> int:
        return sum(self.counts.values())

    def render(self, limit: int = 40, *, key: bool = True) -> str:
        """The story as text, as ``sgbelief explain`` prints it (``limit`` live events at most, 0 =
        all; ``key``: end with the key to the columns and what the log does not record)."""
        lines = render_story(self, limit)
        if key:
            lines += [f"key: {STORY_KEY}.", f"note: {self.not_recorded}."]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.render()

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of the whole story (what ``sgbelief explain --json`` prints)."""
        out = asdict(self)
        out["events"] = [asdict(e) | {"corroborated_by": list(e.corroborated_by)} for e in self.events]
        out["n_entries"] = self.n_entries
        return out


def _event(entry: ProvenanceEntry) -> StoryEvent:
    status, v = entry.status, entry.verdict
    da, db = entry.d_alpha, entry.d_beta
    if v is not None:
        symbol = VERDICT_SYMBOLS[v]
        lam = claim_lambda_hat(da, db) if v is None or v.is_claim else None
        weight: float | None = claim_weight(da, db)
    elif status in REFUSAL_STATUSES:  # a refused claim: its increments are a claim's (Eq. 3)
        symbol, lam, weight = _BOTTOM, claim_lambda_hat(da, db), claim_weight(da, db)
    else:
        symbol, lam, weight = None, None, None
    return StoryEvent(
        event_id=entry.event_id,
        t=entry.t,
        status=status.value,
        d_alpha=da,
        d_beta=db,
        counted=status in COUNTED,
        stance=_STANCE.get(entry.stance, str(entry.stance)),
        verdict=symbol,
        confidence=entry.confidence,
        lambda_hat=lam,
        weight=weight,
        corroborated_by=tuple(entry.corroborated_by or ()),
        recorded=v is not None or entry.confidence is not None,
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
        verdicts=dict(s.verdicts) if s is not None else {},
        n_lambda_hat=s.n_lambda_hat if s is not None else 0,
        mean_lambda_hat=s.mean_lambda_hat if s is not None else None,
    )


def count_phrase(counts: dict[str, int]) -> str:
    """``"22 entries: 17 refused, 5 committed"`` (statuses by count, largest first)."""
    n = sum(counts.values())
    parts = ", ".join(f"{c} {s}" for s, c in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])) if c)
    noun = "entry" if n == 1 else "entries"
    return f"{n} {noun}: {parts}" if parts else f"{n} {noun}"


def verdict_phrase(verdicts: dict[str, int]) -> str:
    """``"17 ⊥, 5 ⊤, 3 geometric"`` (verdicts by count, largest first; empty without any)."""
    return ", ".join(f"{c} {v}" for v, c in sorted(verdicts.items(), key=lambda kv: (-kv[1], kv[0])) if c)


def _sentence(predicate: str, p: float, tau: float, counts: dict[str, int], pending: int,
              added: tuple[float, float], verdicts: dict[str, int], n_claims: int,
              mean_lam: float | None) -> str:
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
    if mean_lam is not None:
        claims = sum(verdicts.get(v, 0) for v in CLAIM_VERDICTS)
        why += f"; {max(claims, n_claims)} claims, mean Λ̂ {mean_lam:.2f}"
        if verdicts.get(_GEOMETRIC):
            why += f", and {verdicts[_GEOMETRIC]} geometric observations"
        if verdicts.get(_EXCLUSION):
            why += f", and {verdicts[_EXCLUSION]} claims of exclusive classes against it"
    if pending:
        why += f"; {pending} still pending in a queue can change it"
    if p > tau:
        return f"Committed: P = {p:.3f} > τ = {tau:g} ({why})."
    return f"Not committed: P = {p:.3f} ≤ τ = {tau:g} ({why})."


def explain(graph: SceneGraphModel, node: Any, predicate: str, *, tau: float = 0.5) -> BeliefStory:
    """The story of (node, predicate) in ``graph``: its compacted bucket's summary, then every
    live entry in time order, the counts per status and per verdict, the mean Lambda-hat of the
    claims, and one sentence saying why the pair is or is not committed at ``tau`` (committed
    iff P > tau)."""
    belief = graph.belief(node, predicate)
    alpha, beta = belief.alpha, belief.beta
    p = graph.probability(node, predicate)
    entries = graph.provenance.entries(node, predicate)
    buckets = [e for e in entries if e.status is EntryStatus.COMPACTED]
    live = sorted((e for e in entries if e.status is not EntryStatus.COMPACTED), key=lambda e: e.t)
    folded = _folded(buckets[0]) if buckets else None
    counts: dict[str, int] = dict(folded.counts) if folded is not None else {}
    verdicts: dict[str, int] = {}
    lam_total, n_claims, complete = 0.0, 0, True
    if folded is not None:
        verdicts.update(folded.verdicts)
        # a bucket folded before verdicts were kept still knows its refusals from their statuses
        folded_refused = sum(folded.counts.get(s.value, 0) for s in REFUSAL_STATUSES)
        if folded_refused > verdicts.get(_BOTTOM, 0):
            verdicts[_BOTTOM] = folded_refused
        if sum(folded.verdicts.values()) < folded.n:
            complete = False
        if folded.mean_lambda_hat is not None:
            lam_total, n_claims = folded.mean_lambda_hat * folded.n_lambda_hat, folded.n_lambda_hat
    events = tuple(map(_event, live))
    for ev in events:
        counts[ev.status] = counts.get(ev.status, 0) + 1
        if ev.verdict is not None:
            verdicts[ev.verdict] = verdicts.get(ev.verdict, 0) + 1
        if ev.lambda_hat is not None:
            lam_total += ev.lambda_hat
            n_claims += 1
        complete = complete and ev.recorded
    mean_lam = lam_total / n_claims if n_claims else None
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
        verdicts={v: verdicts[v] for v in VERDICT_SYMBOLS.values() if verdicts.get(v)},
        n_claims=n_claims,
        mean_lambda_hat=mean_lam,
        sentence=_sentence(predicate, p, tau, counts, pending,
                           (alpha - graph.provenance.prior_alpha, beta - graph.provenance.prior_beta),
                           verdicts, n_claims, mean_lam),
        not_recorded=NOT_RECORDED if complete or not counts else f"{NOT_RECORDED}; {NOT_RECORDED_OLD}",
    )


# ------------------------------------------------------------------------------ text
_STANCE_MARK = {"supports": "+", "denies": "-", "neutral": "0"}
_HEADER = (f"    {'t':>7}  {'event':<16} {'v':<3} {'c':>5} {'Λ̂':>8} {'w·T(v)':>7} {'dα':>8} {'dβ':>8}  "
           "± status")


def _num(x: float | None, spec: str) -> str:
    return "·" if x is None else format(x, spec)


def _fmt_event(e: Any) -> str:
    verdict = {"geometric": "geo", "exclusion": "exc"}.get(e.verdict, e.verdict) if e.verdict is not None else "·"
    counted = "" if e.counted else " (not counted)"
    corr = f", corroborated by {', '.join(e.corroborated_by)}" if e.corroborated_by else ""
    return (f"    {e.t:>7}  {str(e.event_id):<16} {verdict:<3} {_num(e.confidence, '.3f'):>5} "
            f"{_num(e.lambda_hat, '.3f'):>7} {_num(e.weight, '.3f'):>7} {e.d_alpha:>+8.4f} {e.d_beta:>+8.4f}  "
            f"{_STANCE_MARK.get(e.stance, e.stance)} {e.status}{counted}{corr}")


def render_story(story: BeliefStory, limit: int = 40) -> list[str]:
    """The text lines of one story, as ``sgbelief explain`` prints them: the belief and counts,
    what compaction folded, the live events in time order (at most ``limit``, the first and last
    halves; 0 = all) and the sentence saying why the pair is or is not committed."""
    lines = [f"{story.node!r} {story.predicate}: Beta({story.alpha:.3f}, {story.beta:.3f}), "
             f"P = {story.probability:.3f}; {count_phrase(story.counts)}"]
    if story.verdicts:
        mean = (f"; mean Λ̂ {story.mean_lambda_hat:.3f} over {story.n_claims} claims"
                if story.mean_lambda_hat is not None else "")
        lines.append(f"  verdicts: {verdict_phrase(story.verdicts)}{mean}")
    f = story.folded
    if f is not None:
        span = f"t={f.t_first}..{f.t_last}" if f.t_first is not None else f"up to t={f.t_last}"
        ids = (f"first {f.first_event_id}, last {f.last_event_id}" if f.first_event_id is not None
               else "event ids not recorded")
        lines.append(f"  compacted ({span}): {count_phrase(f.counts)}")
        if f.verdicts or f.mean_lambda_hat is not None:
            mean = (f"; mean Λ̂ {f.mean_lambda_hat:.3f} over {f.n_lambda_hat} claims"
                    if f.mean_lambda_hat is not None else "")
            lines.append(f"    verdicts: {verdict_phrase(f.verdicts) or 'none recorded'}{mean}")
        lines.append(f"    counted sum dα={f.d_alpha:+.4f} dβ={f.d_beta:+.4f}; {ids}")
    events = story.events
    if events:
        lines.append(f"  live events ({len(events)}, time order):")
        lines.append(_HEADER)
        if limit and len(events) > limit:
            head, tail = events[: limit // 2], events[-(limit - limit // 2):]
            lines += [_fmt_event(e) for e in head]
            lines.append(f"    ... {len(events) - len(head) - len(tail)} more (--limit 0 or --json for all)")
            lines += [_fmt_event(e) for e in tail]
        else:
            lines += [_fmt_event(e) for e in events]
    lines.append(f"  {story.sentence}")
    return lines


#: the key under the tables
STORY_KEY = ("v: verdict (⊤ corroborated, ⊥ contradicted, ∅ no geometric claim, geo: the geometric label "
             "observed as evidence, exc: a claim of an exclusive rival class, counted against; a ⊥ claim that is "
             "committed was weighed, not refused: the element's labels had both asserted and denied the predicate, "
             "contested_labels); c: the event's confidence; Λ̂: calibrated likelihood ratio; w·T(v): weight; "
             "±: stance; · = not recorded")

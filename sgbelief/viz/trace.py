"""One (element, predicate) belief over time, read from its provenance (Figure 1(a) for any pair).

The belief is defined by its log (Eq. 4): the prior plus the counted increments. Replaying the
pair's entries in time order therefore gives the posterior after each event, exactly as the
store holds it: the last point of the trace is the pair's current belief. Entries an event
recorded at the pair (a verification increment and the claim's own) form one trace event; a
compacted bucket is one event standing for the entries it folded.

The verdict of an event is the one its claim entry recorded (⊤ / ⊥ / ∅); for an entry written
without one (a baseline, an older file) what its status tells: ⊥ for a refused claim (the refusal
family), otherwise ``?``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import groupby
from typing import Any

from sgbelief.graph.belief import BetaBelief
from sgbelief.graph.provenance_log import EntryVerdict
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.viz.style import REFUSED_STATUSES

#: the credible level of the trace's interval (the paper's Figure 1(a): 90 %)
TRACE_LEVEL = 0.9


@dataclass(frozen=True)
class TraceEvent:
    """One event at the pair and the belief after it."""

    event_id: str | None
    t: int
    status: str  #: what happened: the provenance status of the claim (refused, committed, ...)
    verdict: str  #: ⊤ / ⊥ / ∅ as recorded; else ⊥ (refused) or ? (the log does not say)
    d_alpha: float  #: the counted increments the event added at the pair
    d_beta: float
    folded: int  #: entries a compacted bucket stands for (1 for an ordinary event)
    mean: float  #: posterior mean after the event
    lower: float  #: the interval after the event (:data:`TRACE_LEVEL`)
    upper: float


@dataclass(frozen=True)
class BeliefTrace:
    """The pair's belief from its prior to now, one step per event."""

    node: Any
    predicate: str
    prior: tuple[float, float]
    events: tuple[TraceEvent, ...]
    level: float = TRACE_LEVEL

    @property
    def final(self) -> tuple[float, float]:
        """(alpha, beta) after the last event: the pair's belief by Eq. 4."""
        a, b = self.prior
        for e in self.events:
            a, b = a + e.d_alpha, b + e.d_beta
        return a, b

    def steps(self, until: int | None = None) -> tuple[list[int], list[float], list[float], list[float]]:
        """(t, mean, lower, upper) as step-function vertices: the prior at the first event's
        time, then the belief after each event, held until ``until`` when that is later."""
        if not self.events:
            return [], [], [], []
        prior = BetaBelief(*self.prior)
        lo, hi = prior.interval(self.level)
        ts, ms, ls, us = [self.events[0].t], [prior.mean], [lo], [hi]
        for e in self.events:
            ts.append(e.t)
            ms.append(e.mean)
            ls.append(e.lower)
            us.append(e.upper)
        if until is not None and until > ts[-1]:
            ts.append(until)
            ms.append(ms[-1])
            ls.append(ls[-1])
            us.append(us[-1])
        return ts, ms, ls, us

    def counts(self) -> dict[str, int]:
        """Events per status (a compacted bucket counts once)."""
        out: dict[str, int] = {}
        for e in self.events:
            out[e.status] = out.get(e.status, 0) + 1
        return out


def belief_trace(graph: SceneGraphModel, node: Any, predicate: str, *, level: float = TRACE_LEVEL) -> BeliefTrace:
    """The trace of ``(node, predicate)`` from ``graph``'s provenance (empty when it has no entry)."""
    prov = graph.provenance
    prior = (prov.prior_alpha, prov.prior_beta)
    entries = sorted((e for e in prov.entries(node, predicate) if e.alive), key=lambda e: e.t)  # stable: log order
    a, b = prior
    events: list[TraceEvent] = []
    # consecutive entries of one event form one step; compacted buckets (no id) stay apart
    for key, group in groupby(entries, key=lambda e: (e.event_id, e.t) if e.event_id is not None else id(e)):
        grp = list(group)
        da = sum(e.d_alpha for e in grp if e.counted)
        db = sum(e.d_beta for e in grp if e.counted)
        a, b = a + da, b + db
        statuses = [e.status.value for e in grp]
        refused = next((s for s in statuses if s in REFUSED_STATUSES), None)
        status = refused or statuses[-1]
        recorded = [e.verdict.symbol for e in grp if e.verdict is not None and e.verdict.is_claim]
        bel = BetaBelief(a, b)
        lo, hi = bel.interval(level)
        if recorded:
            verdict = recorded[-1]
        elif any(e.verdict is EntryVerdict.EXCLUSION for e in grp):  # a claim of a rival class, against this one
            verdict = EntryVerdict.EXCLUSION.symbol
        else:
            verdict = "⊥" if refused else "?"
        events.append(TraceEvent(grp[0].event_id, int(grp[0].t), status, verdict, da, db,
                                 sum(max(1, int(e.n_folded or 1)) for e in grp), bel.mean, lo, hi))
    return BeliefTrace(node, predicate, prior, tuple(events), level)

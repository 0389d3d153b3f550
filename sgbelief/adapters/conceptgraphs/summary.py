"""What the ConceptGraphs backend did: per class, the claims and how the channel judged them, the
objects committed or left ``unknown``, and the labels that differ from ConceptGraphs' vote.

:class:`BackendSummary` is what :meth:`MapBeliefs.summary` returns; the backend prints
:meth:`BackendSummary.format` at ``uninstall()`` and writes :meth:`BackendSummary.to_dict` as JSON
beside a saved map.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from collections.abc import Mapping

    from sgbelief.calibration.agreement_shift import ContextReading

__all__ = ["BackendSummary", "ClassSummary", "ClaimCounts", "LOW_CONFIDENCE_MIN_CLAIMS", "low_confidence_note",
           "score_reading_note"]

#: claims routed before :func:`low_confidence_note` judges their confidences
LOW_CONFIDENCE_MIN_CLAIMS = 100


def low_confidence_note(claims: int, below_half: int, has_channel: bool, min_claims: int = 1) -> str | None:
    """What to tell the user when at least half of ``claims`` (and at least ``min_claims``) have a
    confidence below 0.5 and no geometric channel is configured; None otherwise.

    sgbelief reads a claim's confidence c as the probability that it is right (the cold start of
    docs/method.md §4 until outcomes calibrate it), so a claim with c < 0.5 is evidence *against*
    its class. Detectors whose scores are not probabilities (open-vocabulary detectors report
    0.2-0.5 for detections that are mostly right) then leave most objects unknown, and a channel is
    the only source of outcomes the backend has to calibrate them on."""
    # every condition evaluated (no short circuit): a frame's check costs the same whatever the map
    applies = (not has_channel) & (claims >= max(1, min_claims)) & (2 * below_half >= claims)
    if not applies:
        return None
    return (f"{below_half} of {claims} claims have a confidence below 0.5 and no geometric channel can calibrate them: "
            "sgbelief reads a confidence as the probability that the claim is right, so each of those counts "
            "against its class and objects are left unknown. If this detector's scores are not probabilities, "
            "give the backend a label channel (channel=LabelImageChannel(...)), or a map from its scores to the "
            "probability of being right fitted on annotated detections: confidence_map="
            "sgbelief.calibration.scores.ScoreCalibration.fit(scores, correct) (sgbelief import-cg: --channel, "
            "--confidence-map)")


def score_reading_note(readings: Mapping[str, ContextReading]) -> list[str]:
    """What the backend learned of the detector's scores with no channel (``calibration.consensus.method:
    agreement_shift``; ``readings``: context -> :class:`~sgbelief.calibration.agreement_shift.ContextReading`):
    per detector context, whether its scores are read and how a claim at 0.35 reads."""
    notes = []
    for context, r in sorted(readings.items()):
        if not r.reads_scores:
            level = r.log_lr(0.35, math.inf)  # the same for every confidence
            notes.append(f"no channel: the scores of {context} do not show which of its claims agree with the other "
                         f"claims on their objects (rank test p = {r.p_value:.2f} over {r.claims} claims); every claim "
                         f"is read at one level, {1.0 / (1.0 + math.exp(-level)):.2f}, so the map counts them "
                         "(docs/method.md §8)")
        elif r.fitted > 0:
            read = 1.0 / (1.0 + math.exp(-r.log_lr(0.35, math.inf)))  # the reading of a claim at 0.35
            notes.append(f"no channel: the scores of {context} are read {r.fitted:+.2f} higher in log-odds, learned "
                         f"from how often {r.claims} claims on objects with several claims agree (a claim at 0.35 "
                         f"reads as {read:.2f}; docs/method.md §8)")
        else:
            notes.append(f"no channel: {r.claims} claims of {context} on objects with several claims agree less often "
                         f"than its scores say (fitted shift {r.fitted:+.2f} in log-odds); they are read as the scores "
                         "say, since lowering them would count claims against their classes (docs/method.md §8)")
    return notes


class ClaimCounts:
    """Per detector class: claims routed, and what the geometric channel said of them (by the
    claim's sign: a claim with c >= 0.5 asserts the class). Mutable counters, one per class, kept
    by the backend while it routes claims."""

    __slots__ = ("claims", "verified", "refused", "unverifiable")

    def __init__(self) -> None:
        self.claims = 0
        self.verified = 0
        self.refused = 0
        self.unverifiable = 0


@dataclass(frozen=True)
class ClassSummary:
    """One detector class in :class:`BackendSummary` (objects grouped by their vote class)."""

    claims: int = 0  #: claims routed with this class name
    verified: int = 0  #: the channel's label corroborated the claim
    refused: int = 0  #: the channel's label contradicted it (comod holds such a claim back)
    unverifiable: int = 0  #: no label, a label that decides nothing, or a class the vocabulary cannot check
    committed: int = 0  #: live objects whose vote is this class and whose beliefs commit a label
    unknown: int = 0  #: live objects whose vote is this class and where nothing commits
    differ: int = 0  #: live objects whose vote is this class and whose written label is another


@dataclass(frozen=True)
class BackendSummary:
    """Counts over the backend's live map objects and the claims it routed (see :meth:`format`)."""

    objects: int  #: live (not merged away, not filtered) objects the backend tracks
    labelled: int  #: objects whose label comes from a committed predicate
    unknown: int  #: objects left unknown: nothing commits (``unknown_label`` / ``unknown_class_id``)
    filtered: int  #: objects ConceptGraphs filtered (marked ``cg_filtered``)
    detections: int  #: per-detection claims routed
    events: int  #: evidence entries in the graph
    classes: dict[str, ClassSummary] = field(default_factory=dict)  #: per detector class
    #: objects whose written label differs from the vote: {"node", "vote", "label", "why"}, ``why``
    #: one of "unknown", "tie", "split", "ranking" (:meth:`~.labels_out.LabelReader.summary`)
    differing: list[dict[str, Any]] = field(default_factory=list)
    #: labels the channel gave: total, matched, and unmatched label -> count (empty: no channel)
    channel: dict[str, Any] = field(default_factory=dict)
    vocabulary: str = ""  #: the vocabulary's name (its class list, or the table)
    #: the operator and the settings that decide what a claim with no channel outcome does:
    #: {"name", "geometric_evidence", "consensus", "exclusive_evidence", "recalled_verdicts",
    #: "contested_labels"} (those it has)
    operator: dict[str, str] = field(default_factory=dict)
    #: claims whose confidence (after ``confidence_map``) is below 0.5: each counts against its class
    below_half: int = 0
    #: what the user should know about the run (e.g. :func:`low_confidence_note`)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (what the backend writes beside a saved map)."""
        out = asdict(self)
        out["format"] = "sgbelief.cg_summary"
        out["version"] = 1
        return out

    def format(self) -> str:
        """A plain-text report: one line per class, then the objects whose label changed."""
        lines = [f"sgbelief backend ({self.vocabulary or 'vocabulary'}): {self.detections} claims routed, "
                 f"{self.objects} objects: {self.labelled} labelled, {self.unknown} unknown"
                 + (f", {self.filtered} filtered" if self.filtered else "")]
        if self.classes:
            width = max(8, *(len(c) for c in self.classes))
            head = ("class".ljust(width) + "  claims  verified  refused  unverifiable  committed  unknown  "
                    "differ from vote")
            lines.append(head)
            for name in sorted(self.classes, key=lambda c: (-self.classes[c].claims, c)):
                s = self.classes[name]
                lines.append(f"{name.ljust(width)}  {s.claims:6d}  {s.verified:8d}  {s.refused:7d}  "
                             f"{s.unverifiable:12d}  {s.committed:9d}  {s.unknown:7d}  {s.differ:16d}")
        if self.differing:
            shown = ", ".join(f"{d['node']}: {d['vote']} -> {d['label']}" for d in self.differing[:12])
            more = f" (+{len(self.differing) - 12} more)" if len(self.differing) > 12 else ""
            why = Counter(d.get("why", "?") for d in self.differing)
            reasons = ", ".join(f"{k} {why[k]}" for k in ("unknown", "tie", "split", "ranking", "?") if why[k])
            lines.append(f"labels that differ from the vote ({reasons}): {shown}{more}")
        if self.operator:
            rest = ", ".join(f"{k}={v}" for k, v in self.operator.items() if k != "name")
            lines.append(f"operator: {self.operator.get('name', '?')}" + (f" ({rest})" if rest else ""))
        lines.extend(f"note: {n}" for n in self.notes)
        if self.channel:
            unmatched = self.channel.get("unmatched") or {}
            lines.append(f"channel: {self.channel.get('labels', 0)} labels, {self.channel.get('matched', 0)} matched"
                         + (", unmatched: " + ", ".join(f"{k!r} x{v}" for k, v in unmatched.items())
                            if unmatched else ""))
        return "\n".join(lines)

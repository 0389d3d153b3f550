"""What the geometric channel has said about each element so far: its labels, once per (element, time).

A claim is adjudicated by the label its element bears in the claim's own frame. A mesh-label or
panoptic channel sees a targeted element only part of the time, so many claims arrive while it
looks elsewhere, yet it may have labelled that element, decisively and always the same way, in
other frames. :class:`LabelMemory` keeps those labels per map (one per provenance store, like the
support counts) and :func:`~sgbelief.fusion.rules.recalled_outcome` reads the outcome they agree on.
``comod`` refuses a claim the recalled outcome contradicts (``recalled_verdicts: unanimous``,
docs/method.md §8); nothing is written for it but the refused entry, so Eq. 4 and exact retraction
hold as for any refusal. With ``recalled_verdicts: retroactive`` (the default) the memory also
holds, per element, the predicates it took unadjudicated claims for before any label judged them,
and says which of them a new label makes unanimously denied (:meth:`LabelMemory.judged`): those
claims are withdrawn (:func:`~sgbelief.fusion.queues.withdraw_unadjudicated`).

A label is an observation of the channel, not part of a claim: retracting the claim it came with
does not unsee it. Labels of claims below the targeting threshold tau_T count too (the channel
still saw the element). Per label O(1); per claim, O(distinct labels of the element).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sgbelief.fusion.rules import labels_contested, recalled_outcome

__all__ = ["LabelMemory"]


class LabelMemory:
    """Per element: how many times (distinct frames) the channel gave it each label."""

    __slots__ = ("counts", "_last_t", "min_labels", "_held", "_withdrawn")

    def __init__(self, min_labels: int = 1) -> None:
        #: element -> {label: frames it bore that label}
        self.counts: dict[Any, dict[str, int]] = {}
        self._last_t: dict[Any, int] = {}
        #: decisive labels needed before an outcome is recalled
        self.min_labels = min_labels
        #: element -> predicates it holds claims for that no decisive label has judged yet
        #: (``recalled_verdicts: retroactive``)
        self._held: dict[Any, set[str]] = {}
        #: element -> predicates whose unadjudicated claims are withdrawn while its labels deny them
        self._withdrawn: dict[Any, set[str]] = {}

    def add(self, node: Any, t: int, label: str) -> bool:
        """The channel labelled ``node`` ``label`` at time ``t`` (the first label of a frame counts);
        True when it counted."""
        if self._last_t.get(node) == t:
            return False
        self._last_t[node] = t
        held = self.counts.get(node)
        if held is None:
            held = self.counts[node] = {}
        held[label] = held.get(label, 0) + 1
        return True

    def recalled(self, node: Any, outcomes: Mapping[str, int]) -> int | None:
        """The outcome the element's labels agree on for a predicate with ``outcomes`` (label -> y), or None."""
        held = self.counts.get(node)
        return None if not held else recalled_outcome(outcomes, held, self.min_labels)

    def contested(self, node: Any, outcomes: Mapping[str, int]) -> bool:
        """Whether the element's labels both assert and deny a predicate with ``outcomes`` (label ->
        y): :func:`~sgbelief.fusion.rules.labels_contested`."""
        held = self.counts.get(node)
        return bool(held) and labels_contested(outcomes, held)  # type: ignore[arg-type]

    def hold(self, node: Any, predicate: str, outcomes: Mapping[str, int]) -> None:
        """An unadjudicated claim for phi (outcome table ``outcomes``) was applied at ``node``:
        remember the pair until the element's labels judge it, unless one of them already asserts
        phi (then they never deny it unanimously)."""
        held = self.counts.get(node)
        if held and any(outcomes.get(label) == 1 for label in held):
            return
        preds = self._held.get(node)
        if preds is None:
            preds = self._held[node] = set()
        preds.add(predicate)

    def judged(self, node: Any, tables: Mapping[str, Mapping[str, int]]) -> tuple[list[str], list[str]]:
        """After a new label of ``node``: (denied, reinstated). ``denied``: the held predicates its
        labels now unanimously deny (their unadjudicated claims are withdrawn), each returned once; a
        held predicate some label asserts is released (its claims can never be unanimously denied);
        one with no decisive label, or fewer denials than ``min_labels``, stays held.
        ``reinstated``: the withdrawn predicates a label now asserts: the labels no longer agree,
        so, as the recalled verdict lapses, the withdrawal is undone (once; they stay mixed)."""
        denied: list[str] = []
        reinstated: list[str] = []
        held = self.counts[node]
        gone = self._withdrawn.get(node)
        if gone:
            for pred in sorted(gone):  # a fixed order: the map's history must not depend on hashing
                if any(tables[pred].get(label) == 1 for label in held):
                    reinstated.append(pred)
                    gone.discard(pred)
            if not gone:
                del self._withdrawn[node]
        preds = self._held.get(node)
        if preds:
            for pred in sorted(preds):
                y = recalled_outcome(tables[pred], held, self.min_labels)
                if y == 0:
                    denied.append(pred)
                    preds.discard(pred)
                    self._withdrawn.setdefault(node, set()).add(pred)
                elif any(tables[pred].get(label) == 1 for label in held):
                    preds.discard(pred)
            if not preds:
                del self._held[node]
        return denied, reinstated

    def merge(self, keep: Any, absorb: Any) -> None:
        """``absorb`` was merged into ``keep``: its labels and held predicates are keep's."""
        for index in (self._held, self._withdrawn):
            moved_preds = index.pop(absorb, None)
            if moved_preds:
                index.setdefault(keep, set()).update(moved_preds)
        moved = self.counts.pop(absorb, None)
        t = self._last_t.pop(absorb, None)
        if moved:
            held = self.counts.setdefault(keep, {})
            for label, n in moved.items():
                held[label] = held.get(label, 0) + n
        if t is not None and t > self._last_t.get(keep, -1):
            self._last_t[keep] = t

"""A geometric channel's labels against the vocabulary: resolved forgivingly, counted, never silently off.

A channel (a segmenter, a dataset's label images, mesh labels) speaks its own spelling: ``Chairs``,
``office_chair``, ``tv-screen``. :class:`LabelResolver` maps each label it returns onto a label of
the subsumption table, case-, plural-, space-, hyphen- and underscore-insensitively, once per
distinct spelling (a dict look-up afterwards). A label that still matches nothing gives no verdict;
it is warned about once (``UnmatchedLabelWarning``) and counted, and the counts go into the
backend's summary. A channel that has matched nothing by its 20th frame raises
:class:`ChannelMismatchError` naming the labels it gave, so a channel cannot be off without anyone
noticing.
"""

from __future__ import annotations

import warnings
from collections import Counter
from typing import Any

from sgbelief.errors import ChannelMismatchError
from sgbelief.fusion.compatibility import normalise_class_name
from sgbelief.fusion.compatibility import singular_name as singular
from sgbelief.fusion.label_match import UnmatchedLabelWarning, label_index, table_labels

__all__ = ["ChannelMismatchError", "LabelResolver", "UnmatchedLabelWarning"]

#: frames a channel may go without matching one label before :class:`ChannelMismatchError`
FRAMES_TO_FIRST_MATCH = 20


class LabelResolver:
    """Resolves, counts and checks the labels one geometric channel returns (see the module doc).

    ``table``: the subsumption table (None: no table, every label passes through unchecked).
    """

    def __init__(self, table: Any, *, frames_to_first_match: int = FRAMES_TO_FIRST_MATCH) -> None:
        self.frames_to_first_match = int(frames_to_first_match)
        #: raw label -> times seen, for labels that matched nothing
        self.unmatched: Counter[str] = Counter()
        #: raw label -> times seen, for every label the channel gave
        self.seen: Counter[str] = Counter()
        self.matched = 0
        self._frames: set[int] = set()
        self._checked = False
        self.set_table(table)

    def set_table(self, table: Any) -> None:
        """Resolve against ``table`` from now on (a vocabulary learnt after construction)."""
        self.table = table
        self._cache: dict[str, str | None] = {}
        self._warned: set[str] = set()
        if table is not None:
            self._exact, self._loose = label_index(table_labels(table))

    def resolve(self, label: str) -> str | None:
        """The table's spelling of ``label`` (None: it matches nothing; counted and warned once)."""
        try:
            hit = self._cache[label]
        except KeyError:
            hit = self._cache[label] = self._lookup(label)
        self.seen[label] += 1
        if hit is None:
            self.unmatched[label] += 1
        else:
            self.matched += 1
        return hit

    def _lookup(self, label: str) -> str | None:
        """The table's spelling of ``label``; a label matching nothing is warned about once per
        folded spelling (``Car`` and ``cars`` are one warning)."""
        if self.table is None:
            return label
        key = normalise_class_name(label)
        hit = self._exact.get(key)
        if hit is None:
            hit = self._loose.get(singular(key))
        if hit is None and singular(key) not in self._warned:
            self._warned.add(singular(key))
            warnings.warn(f"geometric label {label!r} matches no label of the vocabulary ({self.table.name!r}): "
                          "claims checked against it stay unverified (counted in backend.summary())",
                          UnmatchedLabelWarning, stacklevel=4)
        return hit

    def note_frame(self, t: int) -> None:
        """A frame whose claims were routed with this channel; raises once the channel has matched
        nothing by its ``frames_to_first_match``-th frame."""
        if self._checked:
            return
        frames = self._frames
        if t not in frames:
            frames.add(t)
            if len(frames) >= self.frames_to_first_match:
                self._checked = True
                frames.clear()
                if self.matched == 0 and self.table is not None:
                    raise ChannelMismatchError(self._mismatch_message())
        if self.matched:
            self._checked = True
            frames.clear()

    def _mismatch_message(self) -> str:
        n = self.frames_to_first_match
        if not self.seen:
            return (f"the geometric channel gave no label in {n} frames: is it fed each frame "
                    "(LabelImageChannel.set_frame before the frame's detections are built), and do the "
                    "frame indices match the detections' image_idx?")
        shown = ", ".join(f"{lab!r} ({c})" for lab, c in self.seen.most_common(12))
        known = ", ".join(sorted(self._exact)[:30]) + (" ..." if len(self._exact) > 30 else "")
        return (f"the geometric channel matched no label of the vocabulary in {n} frames; it gave {shown}. "
                f"The vocabulary's labels: {known}. Give the channel the class names of the vocabulary "
                "(or a mapping into them), or build the backend with the channel's vocabulary")

    def report(self) -> dict[str, Any]:
        """What the channel gave: labels matched / unmatched (with counts)."""
        return {"labels": sum(self.seen.values()), "matched": self.matched,
                "unmatched": dict(self.unmatched.most_common())}

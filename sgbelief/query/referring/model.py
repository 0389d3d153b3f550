"""The values of a referring query: the relation, the structured query, and the answer.

A referring query names *one* object: a target class, a spatial relation and one anchor class (two
for ``between``). :class:`ReferringQuery` is the structured form an utterance parses into;
:class:`ReferAnswer` is what :func:`sgbelief.query.refer` returns (``.best``, ``.ranked``,
``.explain()``).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from sgbelief.errors import SgbeliefError

__all__ = [
    "AnchorChoice", "CandidateScore", "ReferAnswer", "ReferError", "ReferringQuery", "Relation",
    "UtteranceError",
]


class ReferError(SgbeliefError, ValueError):
    """A referring query that cannot be asked of this graph (bad relation/anchor count, no scene...)."""


class UtteranceError(ReferError):
    """An utterance the referring grammar cannot read; ``part`` is the text it could not read and
    ``position`` its 0-based offset in the (normalised) utterance."""

    def __init__(self, reason: str, utterance: str, part: str, position: int) -> None:
        self.reason = reason
        self.utterance = utterance
        self.part = part
        self.position = position
        caret = " " * position + "^" * max(1, len(part))
        super().__init__(f"cannot read the utterance: {reason}: {part!r}\n  {utterance}\n  {caret}")


class Relation(str, enum.Enum):
    """The spatial relations of a referring query (values are the canonical names)."""

    CLOSEST = "closest"
    FARTHEST = "farthest"
    NEAR = "near"
    FAR = "far"
    BETWEEN = "between"
    ON = "on"                  # the target rests on (is supported by) the anchor
    SUPPORTING = "supporting"  # the target supports the anchor
    ABOVE = "above"
    BELOW = "below"
    LEFT = "left"
    RIGHT = "right"
    FRONT = "front"
    BACK = "back"

    @property
    def n_anchors(self) -> int:
        return 2 if self is Relation.BETWEEN else 1

    @property
    def view_dependent(self) -> bool:
        """Left / right / front / back depend on a front direction (the anchor's, see docs)."""
        return self in _ALLOCENTRIC

    @property
    def family(self) -> str:
        """Sr3D's coarse reference type: horizontal, between, support, vertical or allocentric."""
        return _FAMILY[self]

    @classmethod
    def parse(cls, name: str | Relation) -> Relation:
        if isinstance(name, Relation):
            return name
        key = str(name).strip().lower().replace("-", "_").replace(" ", "_")
        key = _RELATION_ALIASES.get(key, key)
        try:
            return cls(key)
        except ValueError:
            known = ", ".join(r.value for r in cls)
            raise ReferError(f"unknown relation {name!r}; known relations: {known}") from None


_ALLOCENTRIC = frozenset({Relation.LEFT, Relation.RIGHT, Relation.FRONT, Relation.BACK})
_FAMILY = {
    Relation.CLOSEST: "horizontal", Relation.FARTHEST: "horizontal", Relation.NEAR: "horizontal",
    Relation.FAR: "horizontal", Relation.BETWEEN: "between", Relation.ON: "support",
    Relation.SUPPORTING: "support", Relation.ABOVE: "vertical", Relation.BELOW: "vertical",
    Relation.LEFT: "allocentric", Relation.RIGHT: "allocentric", Relation.FRONT: "allocentric",
    Relation.BACK: "allocentric",
}
_RELATION_ALIASES = {
    "supported_by": "on", "on_top_of": "on", "nearest": "closest", "furthest": "farthest",
    "in_front_of": "front", "behind": "back", "under": "below", "over": "above", "next_to": "closest",
    "left_of": "left", "right_of": "right", "middle": "between",
}


@dataclass(frozen=True)
class ReferringQuery:
    """"The ``target`` that is ``relation`` the ``anchors``": one target class, one relation and
    its anchor classes (two for ``between``, one otherwise). Class names are open vocabulary
    (matched against node labels case-, plural- and space/underscore-insensitively).

    ``utterance`` keeps the text the query was parsed from (None when built directly)."""

    target: str
    relation: Relation
    anchors: tuple[str, ...]
    utterance: str | None = field(default=None, compare=False)

    def __init__(self, target: str, relation: Relation | str, anchors: Sequence[str] | str,
                 utterance: str | None = None) -> None:
        rel = Relation.parse(relation)
        anchor_t = (anchors,) if isinstance(anchors, str) else tuple(str(a) for a in anchors)
        if not isinstance(target, str) or not target.strip():
            raise ReferError(f"ReferringQuery.target: expected a class name, got {target!r}")
        if any(not a.strip() for a in anchor_t):
            raise ReferError(f"ReferringQuery.anchors: empty class name in {list(anchor_t)!r}")
        if len(anchor_t) != rel.n_anchors:
            raise ReferError(f"ReferringQuery.anchors: relation {rel.value!r} takes {rel.n_anchors} "
                             f"anchor class(es), got {len(anchor_t)}: {list(anchor_t)!r}")
        object.__setattr__(self, "target", target.strip())
        object.__setattr__(self, "relation", rel)
        object.__setattr__(self, "anchors", tuple(a.strip() for a in anchor_t))
        object.__setattr__(self, "utterance", utterance)

    def __str__(self) -> str:
        if self.relation is Relation.BETWEEN:
            return f"the {self.target} between the {self.anchors[0]} and the {self.anchors[1]}"
        return f"the {self.target} {_PHRASE[self.relation]} the {self.anchors[0]}"

    def to_dict(self) -> dict[str, Any]:
        return {"target": self.target, "relation": self.relation.value, "anchors": list(self.anchors),
                "utterance": self.utterance}


_PHRASE = {
    Relation.CLOSEST: "closest to", Relation.FARTHEST: "farthest from", Relation.NEAR: "near",
    Relation.FAR: "far from", Relation.ON: "on", Relation.SUPPORTING: "supporting",
    Relation.ABOVE: "above", Relation.BELOW: "below", Relation.LEFT: "on the left of",
    Relation.RIGHT: "on the right of", Relation.FRONT: "in front of", Relation.BACK: "behind",
}


@dataclass(frozen=True)
class AnchorChoice:
    """One anchor hypothesis and its posterior weight: the anchor node(s), the front direction
    used for a view-dependent relation (a horizontal unit vector, else None) and why."""

    nodes: tuple[Any, ...]
    weight: float
    front: tuple[float, float] | None = None
    note: str = ""


@dataclass(frozen=True)
class CandidateScore:
    """One candidate: P(it is the referent), P(it is of the target class) and the geometric
    numbers the relation read (e.g. ``{"distance": 0.41}``), for the best anchor hypothesis."""

    node: Any
    probability: float
    membership: float
    measures: dict[str, float] = field(default_factory=dict, hash=False)


@dataclass(frozen=True)
class ReferAnswer:
    """The answer to a referring query.

    ``best`` is the most probable referent (None when no candidate has positive probability),
    ``ranked`` every candidate with its probability, highest first (probabilities sum to 1 over
    the candidates when any exists). ``explain()`` prints the candidates, anchors and measures
    that decided it."""

    query: ReferringQuery
    scene: Any
    ranked: tuple[tuple[Any, float], ...]
    candidates: tuple[CandidateScore, ...] = ()
    anchors: tuple[AnchorChoice, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def best(self) -> Any:
        if not self.ranked or not self.ranked[0][1] > 0.0:
            return None
        return self.ranked[0][0]

    @property
    def probability(self) -> float:
        """P(best is the referent); 0.0 when there is no answer."""
        return self.ranked[0][1] if self.ranked and self.best is not None else 0.0

    def __len__(self) -> int:
        return len(self.ranked)

    def to_dict(self) -> dict[str, Any]:
        return {
            "query": self.query.to_dict(),
            "scene": self.scene,
            "best": self.best,
            "ranked": [[n, round(p, 6)] for n, p in self.ranked],
            "candidates": [{"node": c.node, "probability": round(c.probability, 6),
                            "membership": round(c.membership, 6),
                            "measures": {k: _round(v) for k, v in c.measures.items()}} for c in self.candidates],
            "anchors": [{"nodes": list(a.nodes), "weight": round(a.weight, 6),
                         "front": None if a.front is None else [round(x, 3) for x in a.front], "note": a.note}
                        for a in self.anchors],
            "notes": list(self.notes),
        }

    def explain(self, top: int = 10) -> str:
        q = self.query
        lines = [f"query: {q}  [relation {q.relation.value}, {q.relation.family}]"]
        if q.utterance:
            lines.append(f"utterance: {q.utterance!r}")
        lines.append(f"scene: {self.scene}")
        if self.best is None:
            lines.append("answer: none (no candidate of the target class, or no anchor)")
        else:
            lines.append(f"answer: {self.best}  P = {self.probability:.4f}")
        if self.anchors:
            lines.append("anchors (posterior weight):")
            for a in self.anchors[:top]:
                front = "" if a.front is None else f"  front=({a.front[0]:+.2f}, {a.front[1]:+.2f})"
                note = f"  {a.note}" if a.note else ""
                lines.append(f"  {' + '.join(map(str, a.nodes))}: {a.weight:.4f}{front}{note}")
        if self.candidates:
            lines.append("candidates (P referent, P target class, measures for the best anchor):")
            for c in self.candidates[:top]:
                meas = ", ".join(f"{k}={_fmt(v)}" for k, v in c.measures.items())
                lines.append(f"  {c.node}: P={c.probability:.4f}  member={c.membership:.3f}  {meas}".rstrip())
            if len(self.candidates) > top:
                lines.append(f"  ... {len(self.candidates) - top} more")
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


def _round(v: float) -> float | None:
    return None if not math.isfinite(v) else round(float(v), 4)


def _fmt(v: float) -> str:
    return "nan" if not math.isfinite(v) else f"{v:.3f}"

"""Foundation-model evidence events e = (T, phi, c, kappa) of Def. 2, stamped with time t and an id."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sgbelief.errors import InvalidEventError

_ids = itertools.count()
#: slack for floating-point sums of targeting masses
MASS_TOLERANCE = 1e-9


def _auto_id() -> str:
    return f"e{next(_ids)}"


def next_event_id() -> str:
    """The next automatic event id (what an event built without ``id`` gets): for events built with
    :meth:`EvidenceEvent.trusted` from parts already checked."""
    return f"e{next(_ids)}"


@dataclass(frozen=True, slots=True)
class EvidenceEvent:
    """One foundation-model claim (Def. 2).

    - ``targets`` T: element -> mass in [0, 1], masses summing to at most 1;
    - ``predicate`` phi: the asserted predicate (e.g. ``is_chair``);
    - ``confidence`` c: raw model confidence in [0, 1] (c < 0.5 leans to "not phi");
    - ``context`` kappa: opaque tag (model, prompt version, decoding settings) slicing calibration;
    - ``t``: integer time step; ``id``: unique event id (auto-generated when omitted).

    Validated once here; operators never re-validate (hot path).
    """

    targets: Mapping[Any, float]
    predicate: str
    confidence: float
    context: str = "default"
    t: int = 0
    id: str = field(default_factory=_auto_id)

    def __post_init__(self) -> None:
        if not isinstance(self.predicate, str) or not self.predicate.strip():
            raise InvalidEventError("predicate", f"must be a non-empty string, got {self.predicate!r}")
        if not isinstance(self.context, str) or not self.context:
            raise InvalidEventError("context", f"must be a non-empty string, got {self.context!r}")
        c = self.confidence
        if isinstance(c, bool) or not isinstance(c, (int, float)):
            raise InvalidEventError("confidence", f"must be a number, got {type(c).__name__}")
        if not math.isfinite(c) or not 0.0 <= c <= 1.0:
            raise InvalidEventError("confidence", f"must be finite and in [0, 1], got {c!r}")
        if isinstance(self.t, bool) or not isinstance(self.t, int) or self.t < 0:
            raise InvalidEventError("t", f"must be a non-negative integer time step, got {self.t!r}")
        if not isinstance(self.id, str) or not self.id:
            raise InvalidEventError("id", f"must be a non-empty string, got {self.id!r}")
        if not isinstance(self.targets, Mapping) or not self.targets:
            raise InvalidEventError("targets", "must be a non-empty mapping node -> mass")
        total = 0.0
        for node, mass in self.targets.items():
            if isinstance(node, bool) or not isinstance(node, (str, int)):
                raise InvalidEventError("targets", f"node ids must be str or int, got {node!r}")
            if isinstance(mass, bool) or not isinstance(mass, (int, float)) or not math.isfinite(mass):
                raise InvalidEventError("targets", f"mass of {node!r} must be a finite number, got {mass!r}")
            if not 0.0 <= mass <= 1.0:
                raise InvalidEventError("targets", f"mass of {node!r} must be in [0, 1], got {mass!r}")
            total += mass
        if total > 1.0 + MASS_TOLERANCE:
            raise InvalidEventError("targets", f"masses sum to {total:.6g} > 1")
        object.__setattr__(self, "confidence", float(c))

    @classmethod
    def trusted(
        cls, targets: Mapping[Any, float], predicate: str, confidence: float, context: str, t: int, id: str
    ) -> EvidenceEvent:
        """Build without re-validating: for records already validated at a file boundary, or built
        from checked parts (the ConceptGraphs backend). The slots are written through their
        descriptors (the frozen class's ``__setattr__`` refuses, ``object.__setattr__`` looks each
        name up): same event, half the cost on a per-claim path."""
        ev = object.__new__(cls)
        _set_targets(ev, targets)
        _set_predicate(ev, predicate)
        _set_confidence(ev, confidence)
        _set_context(ev, context)
        _set_t(ev, t)
        _set_id(ev, id)
        return ev

    @property
    def claim_sign(self) -> int:
        """+1 when the claim asserts phi (c >= 0.5), -1 when it leans to "not phi"."""
        return 1 if self.confidence >= 0.5 else -1


# the slot descriptors EvidenceEvent.trusted writes through (one attribute look-up each, at import)
_set_targets, _set_predicate, _set_confidence, _set_context, _set_t, _set_id = (
    EvidenceEvent.__dict__[name].__set__ for name in ("targets", "predicate", "confidence", "context", "t", "id"))

"""EvidenceEvent validation (Def. 2): errors name the field."""

from __future__ import annotations

import math

import pytest

from sgbelief.errors import InvalidEventError
from sgbelief.fusion.events import EvidenceEvent


def test_valid_event_and_auto_id() -> None:
    e1 = EvidenceEvent({"a": 0.6, "b": 0.4}, "is_chair", 0.8, "vlm", 3)
    e2 = EvidenceEvent({"a": 1.0}, "is_chair", 0.2)
    assert e1.id != e2.id
    assert e1.claim_sign == 1 and e2.claim_sign == -1


@pytest.mark.parametrize(
    "kwargs,field",
    [
        (dict(confidence=math.nan), "confidence"),
        (dict(confidence=-0.1), "confidence"),
        (dict(confidence=1.5), "confidence"),
        (dict(confidence=math.inf), "confidence"),
        (dict(confidence="0.5"), "confidence"),
        (dict(targets={"a": 1.2}), "targets"),
        (dict(targets={"a": 0.7, "b": 0.6}), "targets"),
        (dict(targets={"a": -0.1}), "targets"),
        (dict(targets={"a": math.nan}), "targets"),
        (dict(targets={}), "targets"),
        (dict(targets={(1, 2): 0.5}), "targets"),
        (dict(predicate=""), "predicate"),
        (dict(predicate="  "), "predicate"),
        (dict(context=""), "context"),
        (dict(t=1.5), "t"),
        (dict(id=""), "id"),
    ],
)
def test_bad_input_names_the_field(kwargs: dict, field: str) -> None:
    base = dict(targets={"a": 1.0}, predicate="is_chair", confidence=0.7, context="vlm", t=0)
    base.update(kwargs)
    with pytest.raises(InvalidEventError) as info:
        EvidenceEvent(**base)
    assert info.value.field == field
    assert field in str(info.value)


def test_events_are_immutable() -> None:
    e = EvidenceEvent({"a": 1.0}, "is_chair", 0.7)
    with pytest.raises(AttributeError):
        e.confidence = 0.1  # type: ignore[misc]

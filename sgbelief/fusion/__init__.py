"""Evidence events, the FusionOperator protocol, calibration, compatibility, queues and operators."""

from __future__ import annotations

from typing import Any

from sgbelief.fusion.channel import CallableChannel, DictChannel, FrameLabels, GeometricChannel, NullChannel, RecordedChannel
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.protocol import Action, FusionOperator, QueueResolution, TargetOutcome, UpdateReport
from sgbelief.fusion.registry import OPERATOR_NAMES, deprecated_make_operator, make_reference_operator, register_operator

__all__ = [
    "Action",
    "CallableChannel",
    "DictChannel",
    "EvidenceEvent",
    "FrameLabels",
    "FusionOperator",
    "GeometricChannel",
    "NullChannel",
    "OPERATOR_NAMES",
    "OperatorConfig",
    "QueueResolution",
    "RecordedChannel",
    "SubsumptionTable",
    "TargetOutcome",
    "UpdateReport",
    "Verdict",
    "make_reference_operator",
    "register_operator",
]


def __getattr__(name: str) -> Any:
    if name == "make_operator":  # the old name of make_reference_operator (sgbelief.make_operator picks the engine)
        return deprecated_make_operator(__name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

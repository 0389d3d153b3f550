"""Evidence events, the FusionOperator protocol, calibration, compatibility, queues and operators."""

from __future__ import annotations

from sgbelief.fusion.channel import CallableChannel, DictChannel, FrameLabels, GeometricChannel, NullChannel, RecordedChannel
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.protocol import Action, FusionOperator, QueueResolution, TargetOutcome, UpdateReport
from sgbelief.fusion.registry import OPERATOR_NAMES, make_operator, register_operator

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
    "make_operator",
    "register_operator",
]

"""The six fusion operators."""

from __future__ import annotations

from sgbelief.fusion.operators.base import BaseOperator
from sgbelief.fusion.operators.baselines import (
    MajorityVoteOperator,
    NaiveBayesOperator,
    OverwriteOperator,
    RefinedOperator,
)
from sgbelief.fusion.operators.calibrated import (
    CalibratedOperator,
    CoModulatedOperator,
    PaperCalibratedOperator,
    PaperCoModulatedOperator,
)

__all__ = [
    "BaseOperator",
    "OverwriteOperator",
    "MajorityVoteOperator",
    "NaiveBayesOperator",
    "RefinedOperator",
    "CalibratedOperator",
    "CoModulatedOperator",
    "PaperCalibratedOperator",
    "PaperCoModulatedOperator",
]

"""The six fusion operators, and the rules of the pair-local baselines."""

from __future__ import annotations

from sgbelief.fusion.operators.base import REFERENCE, BaseOperator, OperatorEngine
from sgbelief.fusion.operators.baselines import (
    MajorityVoteOperator,
    MajorityVoteRule,
    NaiveBayesOperator,
    NaiveBayesRule,
    OverwriteOperator,
    OverwriteRule,
    RefinedOperator,
)
from sgbelief.fusion.operators.calibrated import (
    CalibratedOperator,
    CoModulatedOperator,
    PaperCalibratedOperator,
    PaperCoModulatedOperator,
)
from sgbelief.fusion.operators.compaction import CompactionSchedule

__all__ = [
    "BaseOperator",
    "OperatorEngine",
    "REFERENCE",
    "CompactionSchedule",
    "OverwriteOperator",
    "MajorityVoteOperator",
    "NaiveBayesOperator",
    "RefinedOperator",
    "CalibratedOperator",
    "CoModulatedOperator",
    "PaperCalibratedOperator",
    "PaperCoModulatedOperator",
    "MajorityVoteRule",
    "NaiveBayesRule",
    "OverwriteRule",
]

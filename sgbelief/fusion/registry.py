"""Resolve an operator from its name (or pass an instance through): one place, like MAPIE's resolvers."""

from __future__ import annotations

from typing import Any

from sgbelief.errors import ConfigError
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.operators import (
    CalibratedOperator,
    CoModulatedOperator,
    MajorityVoteOperator,
    NaiveBayesOperator,
    OverwriteOperator,
    PaperCalibratedOperator,
    PaperCoModulatedOperator,
    RefinedOperator,
)
from sgbelief.fusion.protocol import FusionOperator

OPERATORS: dict[str, type] = {
    "overwrite": OverwriteOperator,
    "majority": MajorityVoteOperator,
    "naive_bayes": NaiveBayesOperator,
    "refined": RefinedOperator,
    "cal": CalibratedOperator,
    "comod": CoModulatedOperator,
}
#: names in the paper's table order
OPERATOR_NAMES: tuple[str, ...] = tuple(OPERATORS)
#: the method's operators with the paper's own settings, reported beside the defaults
PAPER_OPERATOR_NAMES: tuple[str, ...] = ("cal_paper", "comod_paper")
OPERATORS["cal_paper"] = PaperCalibratedOperator
OPERATORS["comod_paper"] = PaperCoModulatedOperator


def register_operator(name: str, cls: type) -> None:
    """Make a user-written operator available to :func:`make_operator` and the CLI."""
    OPERATORS[name] = cls


def make_operator(
    name: str | FusionOperator,
    config: OperatorConfig | dict[str, Any] | str | None = None,
    vocabulary: SubsumptionTable | None = None,
) -> FusionOperator:
    """``make_operator("comod", config, vocabulary)``; an operator instance is returned unchanged."""
    if not isinstance(name, str):
        if isinstance(name, FusionOperator):
            return name
        raise TypeError(f"expected an operator name or a FusionOperator, got {type(name).__name__}")
    cls = OPERATORS.get(name)
    if cls is None:
        raise ConfigError(f"unknown operator {name!r}; choose one of {', '.join(OPERATORS)}")
    return cls(config, vocabulary)

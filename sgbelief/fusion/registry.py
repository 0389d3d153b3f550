"""Resolve an operator from its name (or pass an instance through): one place, like MAPIE's resolvers.

This is the fusion layer's registry: the operators it builds run the reference engine (the named
steps). The public :func:`sgbelief.make_operator` (:mod:`sgbelief.api.operators`) resolves names
here and injects the fused engines of :mod:`sgbelief._fast` (``engine="fast"``, its default).
"""

from __future__ import annotations

from collections.abc import Callable
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

#: name -> operator class (or any callable ``factory(config, vocabulary)`` returning a FusionOperator)
OPERATORS: dict[str, Callable[..., Any]] = {
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


def register_operator(name: str, cls: Callable[..., Any]) -> None:
    """Make a user-written operator available to :func:`make_operator` and the CLI: ``cls`` is
    called as ``cls(config, vocabulary)`` and must return a
    :class:`~sgbelief.fusion.protocol.FusionOperator`."""
    OPERATORS[name] = cls


def operator_class(name: str) -> Callable[..., Any]:
    """The class (or factory) registered under ``name``; ConfigError naming the choices otherwise."""
    cls = OPERATORS.get(name)
    if cls is None:
        raise ConfigError(f"unknown operator {name!r}; choose one of {', '.join(OPERATORS)}")
    return cls


def require_operator(operator: object) -> FusionOperator:
    """An operator instance given where a name may be: returned unchanged, TypeError otherwise."""
    if isinstance(operator, FusionOperator):
        return operator
    raise TypeError(f"expected an operator name or a FusionOperator, got {type(operator).__name__}")


def make_operator(
    name: str | FusionOperator,
    config: OperatorConfig | dict[str, Any] | str | None = None,
    vocabulary: SubsumptionTable | None = None,
) -> FusionOperator:
    """``make_operator("comod", config, vocabulary)`` with the reference engine; an operator
    instance is returned unchanged. The public ``sgbelief.make_operator`` chooses the engine."""
    if not isinstance(name, str):
        return require_operator(name)
    return operator_class(name)(config, vocabulary)

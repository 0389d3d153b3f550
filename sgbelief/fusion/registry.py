"""Resolve an operator from its name (or pass an instance through): one place, like MAPIE's resolvers.

This is the fusion layer's registry: :func:`make_reference_operator` builds operators that run the
reference engine (the named steps). The public :func:`sgbelief.make_operator`
(:mod:`sgbelief.api.operators`) resolves names here and injects the fused engines of
:mod:`sgbelief._fast` (``engine="fast"``, its default). The old name of this module's builder,
``make_operator``, warns until sgbelief 0.2.0 removes it (it ran another engine than
``sgbelief.make_operator`` under the same name).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

from sgbelief.errors import ConfigError, SgbeliefDeprecationWarning
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
    members = ("name", "config", "stats", "pair_rule", "update", "update_many", "tick", "probability", "retract",
               "merge_nodes")
    missing = [m for m in members if not hasattr(operator, m)]
    hint = f" (it lacks {', '.join(missing)}; see sgbelief.fusion.protocol.FusionOperator)" if missing else ""
    raise TypeError(f"expected an operator name or a FusionOperator, got {type(operator).__name__}{hint}")


def make_reference_operator(
    name: str | FusionOperator,
    config: OperatorConfig | dict[str, Any] | str | None = None,
    vocabulary: SubsumptionTable | None = None,
) -> FusionOperator:
    """``make_reference_operator("comod", config, vocabulary)``: the operator registered under
    ``name`` running the reference engine (the named steps); an operator instance is returned
    unchanged. ``sgbelief.make_operator(..., engine="reference")`` builds the same operator."""
    if not isinstance(name, str):
        return require_operator(name)
    return operator_class(name)(config, vocabulary)


def deprecated_make_operator(module: str) -> Callable[..., FusionOperator]:
    """:func:`make_reference_operator`, with the warning of its old name ``<module>.make_operator``."""
    warnings.warn(f"{module}.make_operator is deprecated (removed in sgbelief 0.2.0): it builds the reference "
                  "engine; call make_reference_operator (the same), or sgbelief.make_operator (engine='fast' by "
                  "default)", SgbeliefDeprecationWarning, stacklevel=3)
    return make_reference_operator


def __getattr__(name: str) -> Any:
    if name == "make_operator":
        return deprecated_make_operator(__name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""The public ``make_operator``: an operator by name, with the engine chosen explicitly.

``engine="fast"`` (the default) injects the fused loops of :mod:`sgbelief._fast` into the shipped
operator families: :data:`~sgbelief._fast.calibrated.FUSED_CALIBRATED` into the calibrated ones
(``cal``, ``comod`` and their paper variants), :data:`~sgbelief._fast.baselines.FUSED_BASELINES`
into the other :class:`~sgbelief.fusion.operators.base.BaseOperator` subclasses. ``engine="reference"``
gives the named steps of the fusion layer (readable; the fused engines are proven identical to
them). A registered operator of another kind is built as ``factory(config, vocabulary)`` under
either engine, and an operator instance is returned unchanged.
"""

from __future__ import annotations

from typing import Any, Literal

from sgbelief._fast.baselines import FUSED_BASELINES
from sgbelief._fast.calibrated import FUSED_CALIBRATED
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.operators.base import REFERENCE, BaseOperator, OperatorEngine
from sgbelief.fusion.operators.calibrated import CalibratedOperator
from sgbelief.fusion.protocol import FusionOperator
from sgbelief.fusion.registry import operator_class, require_operator

ENGINES = ("fast", "reference")


def engine_for(cls: Any, engine: Literal["fast", "reference"] = "fast") -> OperatorEngine | None:
    """The engine object an operator class is built with (None: a class that takes no engine)."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if not isinstance(cls, type) or not issubclass(cls, BaseOperator):
        return None
    if engine == "reference":
        return REFERENCE
    return FUSED_CALIBRATED if issubclass(cls, CalibratedOperator) else FUSED_BASELINES


def make_operator(
    name: str | FusionOperator,
    config: OperatorConfig | dict[str, Any] | str | None = None,
    vocabulary: SubsumptionTable | None = None,
    *,
    engine: Literal["fast", "reference"] = "fast",
) -> FusionOperator:
    """``make_operator("comod", config, vocabulary)``: the operator registered under ``name``
    (:func:`sgbelief.fusion.registry.register_operator`) running ``engine`` ("fast", the fused
    loop, or "reference", the named steps; same results). An operator instance is returned unchanged."""
    if not isinstance(name, str):
        return require_operator(name)
    cls = operator_class(name)
    chosen = engine_for(cls, engine)
    if chosen is None:
        return cls(config, vocabulary)
    return cls(config, vocabulary, engine=chosen)


__all__ = ["ENGINES", "engine_for", "make_operator"]

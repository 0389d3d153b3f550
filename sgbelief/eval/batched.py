"""Deprecated: the batched engine moved to :mod:`sgbelief._fast.batched` (private; ``sgbelief
replay --engine batched`` chooses it), ``provenance_signature`` to :mod:`sgbelief.testing` and
``random_records`` to :mod:`sgbelief.eval.random_stream`.

The old names still work and warn until sgbelief 0.2.0 removes this module: ``EventColumns``, ``batched_replay`` (it also takes an operator
instance now), ``provenance_signature``, ``random_records`` and ``BATCHED_OPERATORS`` (the shipped
operators that declare a pair rule).
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

from sgbelief.errors import SgbeliefDeprecationWarning

_MOVED = {
    "EventColumns": "sgbelief._fast.batched",
    "batched_replay": "sgbelief._fast.batched",
    "provenance_signature": "sgbelief.testing",
    "random_records": "sgbelief.eval.random_stream",
}
#: what ``BATCHED_OPERATORS`` was: the shipped operators with a pair rule (the batched engine
#: now asks the operator, ``operator.pair_rule``)
_BATCHED_OPERATORS = ("majority", "naive_bayes", "overwrite")


def __getattr__(name: str) -> Any:
    if name == "BATCHED_OPERATORS":
        warnings.warn("sgbelief.eval.batched.BATCHED_OPERATORS is deprecated (removed in sgbelief 0.2.0): the "
                      "batched engine takes any operator whose pair_rule is not None", SgbeliefDeprecationWarning,
                      stacklevel=2)
        return _BATCHED_OPERATORS
    home = _MOVED.get(name)
    if home is None:
        raise AttributeError(f"module 'sgbelief.eval.batched' has no attribute {name!r}")
    warnings.warn(f"sgbelief.eval.batched.{name} moved to {home}.{name}; sgbelief.eval.batched is removed in "
                  "sgbelief 0.2.0", SgbeliefDeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(home), name)


def __dir__() -> list[str]:
    return sorted([*_MOVED, "BATCHED_OPERATORS"])

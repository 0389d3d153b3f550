"""Deprecated: the compound-query retrieval evaluation moved to :mod:`sgbelief.eval.retrieval` (it
replays operators over scenes: it is evaluation). Names are handed on from there, with a
DeprecationWarning, without importing it until one is asked for."""

from __future__ import annotations

import importlib
import warnings
from typing import Any

from sgbelief.errors import SgbeliefDeprecationWarning

_NEW_HOME = "sgbelief.eval.retrieval"


def __getattr__(name: str) -> Any:
    if name.startswith("__"):
        raise AttributeError(name)
    warnings.warn(f"sgbelief.query.retrieval is deprecated; import {name} from {_NEW_HOME}",
                  SgbeliefDeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(_NEW_HOME), name)


def __dir__() -> list[str]:
    return sorted(importlib.import_module(_NEW_HOME).__all__)

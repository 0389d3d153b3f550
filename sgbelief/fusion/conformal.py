"""Deprecated: the conformal sets moved to :mod:`sgbelief.calibration.conformal` (issue #20).
Importing a name from here still works and warns until sgbelief 0.2.0 removes this module."""

from __future__ import annotations

import importlib
import warnings
from typing import Any

from sgbelief.errors import SgbeliefDeprecationWarning

_HOME = "sgbelief.calibration.conformal"


def __getattr__(name: str) -> Any:
    value = getattr(importlib.import_module(_HOME), name)  # AttributeError for an unknown name
    warnings.warn(f"sgbelief.fusion.conformal is deprecated (removed in sgbelief 0.2.0): import {name} from {_HOME}",
                  SgbeliefDeprecationWarning, stacklevel=2)
    return value

"""Deprecated: the Mondrian calibrator moved to :mod:`sgbelief.calibration` (issue #20).

``MondrianCalibrator`` is in :mod:`sgbelief.calibration.mondrian`, ``CalibrationSlice`` in
:mod:`sgbelief.calibration.slice`, Eq. 2 in :mod:`sgbelief.calibration.isotonic`, the conformal
names in :mod:`sgbelief.calibration.conformal`. Importing a name from here still works and warns
until sgbelief 0.2.0 removes this module.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

from sgbelief.errors import SgbeliefDeprecationWarning

#: where each name now lives, searched in this order
_HOMES = (
    "sgbelief.calibration.mondrian",
    "sgbelief.calibration.slice",
    "sgbelief.calibration.isotonic",
    "sgbelief.calibration.config",
    "sgbelief.calibration.conformal",
)


def __getattr__(name: str) -> Any:
    for home in _HOMES:
        module = importlib.import_module(home)
        if name in getattr(module, "__all__", ()):
            warnings.warn(
                f"sgbelief.fusion.calibration is deprecated (removed in sgbelief 0.2.0): import {name} from {home}",
                SgbeliefDeprecationWarning, stacklevel=2,
            )
            return getattr(module, name)
    raise AttributeError(f"module 'sgbelief.fusion.calibration' has no attribute {name!r}")

"""Deprecated: the cyclic-GC settings moved to :mod:`sgbelief._fast.gc` (one place for all of them).

``sgbelief.gc_tuning.relaxed_gc`` and ``REPLAY_GC_THRESHOLD`` still work and warn.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

from sgbelief.errors import SgbeliefDeprecationWarning

_MOVED = {"relaxed_gc": "sgbelief._fast.gc", "REPLAY_GC_THRESHOLD": "sgbelief._fast.gc"}


def __getattr__(name: str) -> Any:
    home = _MOVED.get(name)
    if home is None:
        raise AttributeError(f"module 'sgbelief.gc_tuning' has no attribute {name!r}")
    warnings.warn(f"sgbelief.gc_tuning.{name} moved to {home}.{name}; sgbelief.gc_tuning will be removed",
                  SgbeliefDeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(home), name)


def __dir__() -> list[str]:
    return sorted(_MOVED)

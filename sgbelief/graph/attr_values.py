"""Attribute values as both saved layouts store them: JSON-safe on the way out, the API's tuples on
the way back in."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["jsonable", "restore_node_attr"]


def jsonable(value: Any, where: str) -> Any:
    """``value`` as JSON data (lists for tuples and numpy arrays, string keys); a non-finite float
    or an object JSON cannot hold raises, naming ``where`` (the node / edge and attribute)."""
    if value is None or isinstance(value, (str, bool, int)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{where}: non-finite float {value!r} cannot be saved")
        return value
    if isinstance(value, (list, tuple)):
        return [jsonable(v, where) for v in value]
    if isinstance(value, dict):
        return {str(k): jsonable(v, where) for k, v in value.items()}
    tolist = getattr(value, "tolist", None)  # numpy arrays and scalars
    if callable(tolist):
        return jsonable(tolist(), where)
    raise TypeError(f"{where}: value of type {type(value).__name__} is not JSON-serialisable")


def restore_node_attr(key: str, value: Any) -> Any:
    """Node attributes the API stores as tuples (``centroid``, ``bbox``) come back as tuples of float."""
    if value is None:
        return None
    if key == "centroid":
        return tuple(float(x) for x in value)
    if key == "bbox":
        return tuple(tuple(float(x) for x in corner) for corner in value)
    return value

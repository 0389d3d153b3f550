"""Attribute values as both saved formats hold them: JSON values out, the API's tuples back in."""

from __future__ import annotations

import math
from typing import Any


def jsonable(value: Any, where: str) -> Any:
    """``value`` as plain JSON values (lists for tuples and numpy arrays, str keys); ValueError
    on a non-finite float, TypeError on anything else JSON cannot hold, both naming ``where``."""
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

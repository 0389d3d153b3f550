"""Reading a ConceptGraphs object dict's per-detection claims, and the geometric channel one claim sees.

:func:`read_claims` turns the per-detection lists of a detection / map-object dict (``class_id``,
``class_name``, ``conf``, ``image_idx``) into :class:`Claim` tuples; :class:`EventChannel` is the
channel handed to the operator for one claim: the detection's own label first, then the
configured channel, every answer resolved onto the vocabulary's spelling.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import numpy as np

#: detection-dict key a segmenter-running pipeline may set to the geometric label of that detection
DEFAULT_LABEL_KEY = "geometric_label"

DetectionLabelFn = Callable[[dict, Any, int], "str | None"]


class Claim(NamedTuple):
    """One per-detection claim read from a ConceptGraphs object dict."""

    class_id: int | None
    class_name: str
    confidence: float
    t: int


def read_claims(obj: Mapping[str, Any], class_names: dict[int, str]) -> list[Claim]:
    """The per-detection (class, confidence, frame) history stored in a CG object dict. Names seen
    with a class id are added to ``class_names`` (id -> name)."""
    ids, confs = obj.get("class_id"), obj.get("conf")
    if type(ids) is list and type(confs) is list and len(ids) == 1 and len(confs) == 1:
        # a fresh detection (one entry in lists): every detection routed in a frame
        claim = _read_one(ids[0], confs[0], obj.get("class_name"), obj.get("image_idx"), class_names)
        return [] if claim is None else [claim]
    return _read_all(ids, confs, obj.get("image_idx"), obj.get("class_name"), class_names)


def _read_all(ids: Any, confs: Any, frames: Any, names: Any, class_names: dict[int, str]) -> list[Claim]:
    """:func:`read_claims` of any dict: the per-detection fields as lists, entry by entry."""
    ids, confs, frames = _seq(ids), _seq(confs), _seq(frames)
    n = max(len(ids), len(confs))
    out: list[Claim] = []
    for k in range(n):
        cid = _as_int(ids[k]) if k < len(ids) else None
        if isinstance(names, list) and k < len(names):
            name = str(names[k])
        elif cid is not None and cid in class_names:
            name = class_names[cid]
        elif isinstance(names, str) and (n == 1 or not ids):
            name = names
        elif cid is not None:
            name = str(cid)
        else:
            continue
        if cid is not None and cid >= 0 and name != str(cid):
            class_names.setdefault(cid, name)
        conf = _as_float(confs[k]) if k < len(confs) and confs[k] is not None else 1.0
        t = _as_int(frames[k]) if k < len(frames) else 0
        out.append(Claim(cid, name, min(max(conf, 0.0), 1.0), t if t is not None else 0))
    return out


def _read_one(cid_raw: Any, conf_raw: Any, names: Any, frames: Any, class_names: dict[int, str]) -> Claim | None:
    """:func:`read_claims` of a dict whose ``class_id`` and ``conf`` are one-entry lists (the same
    rules for k = 0, without building the per-field lists)."""
    frames = frames if type(frames) is list else _seq(frames)  # first, as read_claims does
    cid = _as_int(cid_raw)
    if isinstance(names, list) and names:
        name = str(names[0])
    elif cid is not None and cid in class_names:
        name = class_names[cid]
    elif isinstance(names, str):  # n == 1
        name = names
    elif cid is not None:
        name = str(cid)
    else:
        return None
    if cid is not None and cid >= 0 and name != str(cid):
        class_names.setdefault(cid, name)
    conf = _as_float(conf_raw) if conf_raw is not None else 1.0
    t = _as_int(frames[0]) if frames else 0
    return Claim(cid, name, min(max(conf, 0.0), 1.0), t if t is not None else 0)


class EventChannel:
    """Geometric channel for one event: the detection's own label first, then the configured channel.

    A configured channel with ``label_detection(detection, index, t)`` (a :class:`DetectionChannel`
    such as :class:`~sgbelief.fusion.channel.LabelImageChannel`) is asked about entry ``index`` of
    the detection dict; any other channel through ``label(node, t)``. ``resolve`` maps each answer
    onto the vocabulary's spelling (None: it matches nothing).
    """

    __slots__ = ("_label", "_detection", "_fallback", "_fn", "_index", "_resolve", "answers", "asked")

    def __init__(self, label: str | None, detection: dict | None, fallback: Any, fn: DetectionLabelFn | None,
                 index: int = 0, resolve: Callable[[str], str | None] | None = None) -> None:
        self._label = label
        self._detection = detection
        self._fallback = fallback
        self._fn = fn
        self._index = index
        self._resolve = resolve
        #: the labels this channel gave, per node asked (the operator asks once per target), resolved
        self.answers: dict[Any, str] = {}
        #: whether the operator asked at all (the baselines never do)
        self.asked = False

    def label(self, node: Any, t: int) -> str | None:
        self.asked = True
        value = self._ask(node, t)
        if value is not None:
            if self._resolve is not None:
                value = self._resolve(value)
                if value is None:
                    return None
            self.answers[node] = value
        return value

    def _ask(self, node: Any, t: int) -> str | None:
        if self._label is not None:
            return self._label
        if self._fn is not None and self._detection is not None:
            value = self._fn(self._detection, node, t)
            if value is not None:
                return value
        fallback = self._fallback
        if fallback is not None:
            by_detection = getattr(fallback, "label_detection", None)
            if by_detection is not None and self._detection is not None:
                value = by_detection(self._detection, self._index, t)
                if value is not None:
                    return value
            return fallback.label(node, t)
        return None


def _seq(value: Any) -> list[Any]:
    """A per-detection field as a list (None -> []; numpy arrays have no truth value)."""
    if value is None:
        return []
    if isinstance(value, list):
        return value
    return list(value)


def _as_int(value: Any) -> int | None:
    if type(value) is int:
        return value
    if isinstance(value, np.integer):
        return int(value)
    try:
        return int(np.asarray(value).item())
    except (TypeError, ValueError):
        return None


def _as_float(value: Any) -> float:
    if type(value) is float:
        return value
    if isinstance(value, np.floating):
        return float(value)
    return float(np.asarray(value).item())

"""The geometric channel Gamma: the verifiable class label of an element at time t (or None)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class GeometricChannel(Protocol):
    """``label(node, t)`` returns the geometric channel's class label for ``node`` at time ``t``
    (e.g. the panoptic / mesh-annotation / segmenter class), or None when it cannot assert
    (out of vocabulary, unseen, occluded). This feeds both the compatibility verdict and the
    calibration buffer (Alg. 1 line 4)."""

    def label(self, node: Any, t: int) -> str | None: ...


class NullChannel:
    """A channel that never asserts anything (every verdict is "no claim")."""

    def label(self, node: Any, t: int) -> str | None:
        return None


class DictChannel:
    """A static channel: one label per node, whatever the time (e.g. mesh annotations)."""

    def __init__(self, labels: Mapping[Any, str | None]) -> None:
        self.labels = dict(labels)

    def label(self, node: Any, t: int) -> str | None:
        return self.labels.get(node)


class CallableChannel:
    """Wrap a plain function ``f(node, t) -> label | None`` as a channel."""

    def __init__(self, fn: Callable[[Any, int], str | None]) -> None:
        self.fn = fn

    def label(self, node: Any, t: int) -> str | None:
        return self.fn(node, t)


class RecordedChannel:
    """A channel replayed from recorded labels ``{(node, t): label}``.

    ``label(node, t)`` returns the label recorded at exactly (node, t); with ``hold=True`` it
    returns the most recent label recorded for the node at or before t. ``record`` adds labels
    as they arrive (e.g. from an evidence log's ``geometric`` field).
    """

    def __init__(self, labels: Mapping[tuple[Any, int], str | None] | None = None, *, hold: bool = False) -> None:
        self.hold = hold
        self._exact: dict[tuple[Any, int], str | None] = {}
        self._history: dict[Any, list[tuple[int, str | None]]] = {}
        for (node, t), label in (labels or {}).items():
            self.record(node, t, label)

    def record(self, node: Any, t: int, label: str | None) -> None:
        self._exact[(node, t)] = label
        if self.hold:
            hist = self._history.setdefault(node, [])
            hist.append((t, label))
            if len(hist) > 1 and hist[-2][0] > t:
                hist.sort(key=lambda x: x[0])

    def label(self, node: Any, t: int) -> str | None:
        key = (node, t)
        if key in self._exact:
            return self._exact[key]
        if not self.hold:
            return None
        best: str | None = None
        for when, lab in self._history.get(node, ()):
            if when > t:
                break
            best = lab
        return best


class FrameLabels:
    """The labels the geometric channel reported for the elements one event targets.

    Cheap per-event channel for replays: ``FrameLabels({node: label})``.
    """

    __slots__ = ("labels",)

    def __init__(self, labels: Mapping[Any, str | None]) -> None:
        self.labels = labels

    def label(self, node: Any, t: int) -> str | None:
        return self.labels.get(node)

"""The geometric channel Gamma: the verifiable class label of an element at time t (or None)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class GeometricChannel(Protocol):
    """``label(node, t)`` returns the geometric channel's class label for ``node`` at time ``t``
    (e.g. the panoptic / mesh-annotation / segmenter class), or None when it cannot assert
    (out of vocabulary, unseen, occluded). This feeds both the compatibility verdict and the
    calibration buffer (Alg. 1 line 4)."""

    def label(self, node: Any, t: int) -> str | None: ...


@runtime_checkable
class DetectionChannel(Protocol):
    """A channel that labels one per-detection entry of a ConceptGraphs detection / object dict
    (``mask[index]``, ``image_idx[index]``, ``pcd``), e.g. :class:`LabelImageChannel`."""

    def label_detection(self, detection: Mapping[str, Any], index: int, t: int) -> str | None: ...


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


_UNSEEN = object()


class LabelImageChannel:
    """Geometric channel from per-frame label images (semantic segmentation, or instances + a table).

    Register a frame's image with :meth:`set_frame` (or pass ``images``: a mapping or a function
    ``t -> image | None``). An image is an ``H x W`` integer array: class ids (named through
    ``classes``: a sequence, id = position, or a mapping id -> name), or instance ids when the frame
    also has an ``instance_classes`` table (instance id -> class name or class id).

    :meth:`label_mask` gives the majority label under a boolean mask, or None when fewer than
    ``min_pixels`` labelled pixels lie under it or the majority holds less than ``min_purity`` of
    them. Pixels whose id is in ``ignore_ids`` (or whose name is in ``ignore_labels``) are unlabelled.
    A mask of another size than the image is matched by nearest-neighbour sampling of the image.
    :meth:`label_detection` reads a ConceptGraphs detection dict (``mask[k]``, ``image_idx[k]``);
    the backend calls it for the claim ``k`` it routes. ``label(node, t)`` has no mask and returns None.
    ``keep_frames`` bounds how many frames are held (the oldest is dropped first).

    ``vocabulary`` (a :class:`~sgbelief.fusion.compatibility.SubsumptionTable`, or anything with a
    ``table()`` such as the ConceptGraphs backend's ``ClassVocabulary``): the class list is checked
    against it when the channel is built (:meth:`check_vocabulary`); the ConceptGraphs backend
    checks it against its own vocabulary in any case.
    """

    def __init__(
        self,
        images: Mapping[int, Any] | Callable[[int], Any] | None = None,
        *,
        classes: Sequence[str] | Mapping[int, str] | None = None,
        vocabulary: Any = None,
        min_purity: float = 0.5,
        min_pixels: int = 20,
        ignore_ids: Iterable[int] = (),
        ignore_labels: Iterable[str] = (),
        keep_frames: int | None = None,
        mask_key: str = "mask",
        frame_key: str = "image_idx",
    ) -> None:
        if not 0.0 <= min_purity <= 1.0:
            raise ValueError("min_purity must be in [0, 1]")
        if min_pixels < 1:
            raise ValueError("min_pixels must be >= 1")
        self._source = images if callable(images) else None
        self._frames: dict[int, tuple[Any, Mapping[int, Any] | None]] = {}
        #: per frame: (its image, smallest id, id range, id -> name) (see _frame_stats)
        self._stats: dict[int, tuple[Any, int, int, dict[int, str | None], Any]] = {}
        if images is not None and not callable(images):
            for t, img in images.items():
                self.set_frame(t, img)
        if classes is None:
            self.classes: dict[int, str] = {}
        elif isinstance(classes, Mapping):
            self.classes = {int(k): str(v) for k, v in classes.items()}
        else:
            self.classes = {i: str(n) for i, n in enumerate(classes)}
        self.min_purity = float(min_purity)
        self.min_pixels = int(min_pixels)
        self.ignore_ids = frozenset(int(i) for i in ignore_ids)
        self.ignore_labels = frozenset(ignore_labels)
        self.keep_frames = keep_frames
        self.mask_key = mask_key
        self.frame_key = frame_key
        if vocabulary is not None:
            self.check_vocabulary(vocabulary)

    def check_vocabulary(self, vocabulary: Any) -> list[str]:
        """Check the class list against ``vocabulary`` (a subsumption table, or an object with
        ``table()``), spellings folded (case, plural, space / hyphen / underscore). Raises
        :class:`~sgbelief.errors.ChannelMismatchError` when no class name matches; warns
        (``UnmatchedLabelWarning``) naming those that match nothing; returns them."""
        from sgbelief.fusion.label_match import check_class_names

        table = vocabulary.table() if hasattr(vocabulary, "table") and callable(vocabulary.table) else vocabulary
        if table is None or not self.classes:
            return []
        names = list(dict.fromkeys(n for i, n in self.classes.items()
                                   if i not in self.ignore_ids and n not in self.ignore_labels))
        return check_class_names(names, table, what="LabelImageChannel class list")

    def set_frame(self, t: int, image: Any, instance_classes: Mapping[int, Any] | None = None) -> None:
        """The label image of frame ``t`` (and, for an instance image, its instance -> class table)."""
        import numpy as np

        arr = np.asarray(image)
        if arr.ndim != 2 or arr.dtype.kind not in "iub":
            raise ValueError(f"frame {t}: expected an H x W integer label image, got shape {arr.shape} dtype {arr.dtype}")
        self._frames[int(t)] = (arr, instance_classes)
        if self.keep_frames is not None:
            while len(self._frames) > self.keep_frames:
                del self._frames[next(iter(self._frames))]

    def _frame(self, t: int) -> tuple[Any, Mapping[int, Any] | None] | None:
        hit = self._frames.get(int(t))
        if hit is None and self._source is not None:
            value = self._source(int(t))
            if value is None:
                return None
            if isinstance(value, tuple):
                self.set_frame(t, value[0], value[1])
            else:
                self.set_frame(t, value)
            hit = self._frames.get(int(t))
        return hit

    def _name(self, value: Any, table: Mapping[int, Any] | None) -> str | None:
        if table is not None:
            value = table.get(int(value))
            if value is None:
                return None
            if isinstance(value, str):
                return None if value in self.ignore_labels else value
        v = int(value)
        if v in self.ignore_ids:
            return None
        name = self.classes.get(v, str(v)) if self.classes else str(v)
        return None if name in self.ignore_labels else name

    def label_mask(self, mask: Any, t: int) -> str | None:
        """Majority label under ``mask`` in frame ``t`` (None: unseen frame, too few pixels, impure)."""
        import numpy as np

        frame = self._frame(t)
        if frame is None:
            return None
        image, table = frame
        m = np.asarray(mask, dtype=bool)
        if m.shape != image.shape:
            if m.ndim != 2:
                return None
            rows = (np.arange(m.shape[0]) * image.shape[0]) // m.shape[0]
            cols = (np.arange(m.shape[1]) * image.shape[1]) // m.shape[1]
            values = image[rows[:, None], cols[None, :]][m]
        else:
            values = image[m]
        if values.size < self.min_pixels:
            return None
        lo, span, names = self._frame_stats(t, image, table)
        if span < 65536:  # a small id range (class or instance ids): a histogram, not a sort
            hist = np.bincount((values - lo if lo else values).astype(np.intp, copy=False), minlength=1)
            ids = np.flatnonzero(hist)
            counts = hist[ids]
            ids = ids + lo
        else:
            ids, counts = np.unique(values, return_counts=True)
        totals: dict[str, int] = {}
        labelled = 0
        name_of = self._name
        for v, c in zip(ids.tolist(), counts.tolist()):
            name = names.get(v, _UNSEEN)
            if name is _UNSEEN:
                name = names[v] = name_of(v, table)
            if name is None:
                continue
            totals[name] = totals.get(name, 0) + c
            labelled += c
        if labelled < self.min_pixels or not totals:
            return None
        best = max(sorted(totals), key=lambda n: totals[n])  # ties: alphabetical
        return best if totals[best] >= self.min_purity * labelled else None

    def _frame_stats(self, t: int, image: Any, table: Any) -> tuple[int, int, dict[int, str | None]]:
        """(smallest id, id range, id -> name so far) of frame ``t``'s image and instance table,
        computed once per frame."""
        key = int(t)
        held = self._stats.get(key)
        if held is None or held[0] is not image or held[4] is not table:
            if len(self._stats) > len(self._frames) + 8:  # drop the stats of frames no longer held
                for old in [k for k in self._stats if k not in self._frames]:
                    del self._stats[old]
            lo, hi = (int(image.min()), int(image.max())) if image.size else (0, 0)
            held = self._stats[key] = (image, lo, hi - lo, {}, table)
        return held[1], held[2], held[3]

    def label_detection(self, detection: Mapping[str, Any], index: int, t: int) -> str | None:
        """Label of entry ``index`` of a ConceptGraphs detection / object dict (its mask and frame)."""
        masks = detection.get(self.mask_key)
        if masks is None or index >= len(masks):
            return None
        frames = detection.get(self.frame_key)
        frame = t
        if frames is not None and index < len(frames) and frames[index] is not None:
            frame = int(frames[index])
        return self.label_mask(masks[index], frame)

    def label(self, node: Any, t: int) -> str | None:
        return None

"""What the replacement functions of both ConceptGraphs code generations share.

A generation's replacements (:mod:`.generation_main`, :mod:`.generation_ali_dev`) are the methods of
one object, built by the installer (:class:`~sgbelief.adapters.conceptgraphs.patching.Patcher`)
with the original ConceptGraphs functions it captured, so they call the originals for the geometric
work and the :class:`~sgbelief.adapters.conceptgraphs.map_beliefs.MapBeliefs` below them for the
beliefs. Nothing here looks anything up in ConceptGraphs' modules or in the installer.

Per frame, a patched merge records the list positions its detections touched (targets, new
objects, objects the script appended itself) and re-registers only those; the labels written are
those of the nodes whose beliefs changed (:meth:`MapBeliefs.take_changed_nodes`). A frame's
detections are all routed before ConceptGraphs' geometric merges of that frame run, in row order
(:meth:`GenerationFunctions.merge_pass`).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from sgbelief.adapters.conceptgraphs import geometry as geo
from sgbelief.adapters.conceptgraphs.standins import MapObjectList

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.adapters.conceptgraphs.map_beliefs import MapBeliefs

NEG_INF = float("-inf")

#: an association row's geometric merge of one detection into one map object: (obj, det) -> obj
MergeOne = Callable[[dict, dict], dict]


class BeliefLabelledObject(dict):
    """An ``ali-dev`` map object whose ``class_name`` always holds the belief label.

    ``belief_label`` is the label the beliefs gave at the last relabel (set by the patched merges
    for the objects whose beliefs changed). While the backend is active, a write to
    ``class_name`` (the pipeline's per-frame ``Counter`` relabel loop) stores ``belief_label``
    instead: a constant-time write that reads no beliefs. Copies and pickles are plain dicts, so
    saved maps never reference sgbelief.
    """

    __slots__ = ("backend", "belief_label", "__weakref__")

    def __init__(self, obj: Mapping[Any, Any] | Iterable[Any] = (), /, backend: Any = None) -> None:
        dict.__init__(self, obj)
        self.backend = backend
        self.belief_label: str | None = None

    def __setitem__(self, key: Any, value: Any) -> None:
        if key == "class_name":
            label = self.belief_label
            if label is not None and (self.backend is None or self.backend.active):
                value = label
        dict.__setitem__(self, key, value)

    def set_belief_label(self, label: str | None) -> None:
        """Hold ``label`` and write it into ``class_name`` (None: keep what is there)."""
        self.belief_label = label
        if label is not None:
            dict.__setitem__(self, "class_name", label)

    def __reduce_ex__(self, protocol: Any) -> Any:
        return (dict, (dict(self),))

    def __copy__(self) -> dict:
        return dict(self)

    def __deepcopy__(self, memo: dict) -> dict:
        return copy.deepcopy(dict(self), memo)


def as_numpy(scores: Any, *, keep_dtype: bool = False) -> np.ndarray:
    """An association-score matrix (a torch tensor or an array) as a float numpy array (in its own
    floating dtype with ``keep_dtype``)."""
    if hasattr(scores, "detach"):
        scores = scores.detach().cpu().numpy()
    if keep_dtype:
        arr = np.asarray(scores)
        if arr.dtype.kind == "f":
            return arr
    return np.asarray(scores, dtype=float)


def candidate_matrix(scores: np.ndarray, threshold: float) -> list[dict[int, float]]:
    """Per row, position -> score of the positions whose score is finite, above ``threshold`` and
    positive (the targeting candidates of :meth:`MapBeliefs.targets_for`, in position order), for a
    whole frame in a few array operations: the scores come with the positions, no second pass."""
    rows, cols = np.nonzero(np.isfinite(scores) & (scores > threshold) & (scores > 0))
    out: list[dict[int, float]] = [{} for _ in range(scores.shape[0])]
    for r, c, v in zip(rows.tolist(), cols.tolist(), scores[rows, cols].tolist()):
        out[r][c] = v
    return out


def vote_dtype_scalar(class_ids: Any, cid: int) -> Any:
    """``cid`` as the numpy scalar type ``np.unique(np.asarray(class_ids))`` would give (int64 if not integral)."""
    dtype = getattr(class_ids, "dtype", None)
    if not isinstance(dtype, np.dtype):  # a list (or a torch tensor, whose dtype is not numpy's)
        try:
            dtype = np.asarray(class_ids[0]).dtype
        except (IndexError, KeyError, TypeError):
            dtype = np.dtype(np.int64)
    return dtype.type(cid) if dtype.kind in "iu" else np.int64(cid)


def same_list_type(objects: Any) -> type:
    """The list class to build a new map list with: the input's (a ConceptGraphs list class), else
    the stand-in :class:`MapObjectList`."""
    cls = type(objects)
    return cls if issubclass(cls, list) and cls is not list else MapObjectList


def counter_update(fn: Callable[[], Any]) -> None:
    """Run a ConceptGraphs logging-counter update; a tracker of another shape is not an error."""
    try:
        fn()
    except (AttributeError, KeyError, TypeError):
        pass


class GenerationFunctions:
    """Replacement functions for one ConceptGraphs code generation (subclasses: one per generation).

    Args:
        backend: the belief bookkeeping the functions route detections into.
        originals: ConceptGraphs' own functions captured by the installer, by name
            (``merge_obj2_into_obj1``, ``filter_objects``, ...); the geometric work goes through them,
            and through :mod:`.geometry` when one is absent.
        helpers: ConceptGraphs objects called through but never replaced, by name
            (``compute_overlap_matrix[_general]``, the ``tracker``).
    """

    #: ``main`` or ``ali-dev``
    generation: ClassVar[str]
    #: the ConceptGraphs module-level names these functions replace (methods of the same names)
    replaced_names: ClassVar[tuple[str, ...]]

    def __init__(self, backend: MapBeliefs, originals: Mapping[str, Any] | None = None,
                 helpers: Mapping[str, Any] | None = None) -> None:
        self.backend = backend
        self.originals: dict[str, Any] = dict(originals or {})
        self.helpers: dict[str, Any] = dict(helpers or {})
        #: list positions of the map objects the current per-frame merge touched
        self.touched: set[int] = set()
        #: map-list length after the last label sync; objects appended beyond it by the script itself
        #: (the first frame's ``extend``) are registered at the next per-frame merge
        self.synced_len = 0
        #: ids of the map objects a detection was merged into since the last sync
        self.merged: set[int] = set()

    def original(self, name: str) -> Any:
        """ConceptGraphs' own function ``name``, or None when none was captured."""
        return self.originals.get(name)

    def helper(self, name: str) -> Any:
        return self.helpers.get(name)

    def replacements(self) -> dict[str, Callable[..., Any]]:
        """Name -> replacement function, for every name in :attr:`replaced_names`."""
        return {name: getattr(self, name) for name in self.replaced_names}

    # ---------------------------------------------------------------- frame bookkeeping
    def sync_labels(self, objects: Any, indices: Iterable[int] | None = None) -> None:
        """Register and refresh the objects at ``indices`` (default: every object), then relabel
        the objects whose beliefs changed.

        The per-frame merges pass the positions their detections touched, so a frame costs
        O(its detections), not O(map size)."""
        positions = range(len(objects)) if indices is None else sorted(i for i in indices if i < len(objects))
        self.synced_len = len(objects)
        backend = self.backend
        seen: list[tuple[int, Any]] = []
        # an object whose node was added this frame has its geometry already, unless a detection
        # was merged into it since: its summary is computed once, not twice
        fresh, merged = backend.fresh_geometry, self.merged
        node_of, refresh = backend.frame_node, backend.refresh_node_geometry
        for k in positions:
            obj = objects[k]
            node = node_of(obj)  # resolved once in the frame (a target, a new object)
            if id(obj) not in fresh or id(obj) in merged:
                refresh(node, obj)
            seen.append((k, node))
        fresh.clear()
        merged.clear()
        backend.flush()
        self.write_labels(objects, seen, backend.take_changed_nodes())

    def write_labels(self, objects: Any, seen: list[tuple[int, Any]], changed: set[Any]) -> None:
        """Write belief labels into the map objects (``seen``: (position, node) just registered;
        ``changed``: nodes whose beliefs changed). ``main`` reads labels on demand through
        :meth:`get_most_common_class`, so nothing is written; ``ali-dev`` overrides this."""

    def frame_start(self, objects: Any) -> set[int]:
        """The touched-position set for a per-frame merge, seeded with objects the script appended itself."""
        touched = self.touched
        touched.clear()
        self.merged.clear()
        self.backend.fresh_geometry.clear()  # only objects registered during this merge count as fresh
        start = self.synced_len if self.synced_len <= len(objects) else 0
        touched.update(range(start, len(objects)))
        return touched

    def mark_removed(self, before: list, after: Any) -> None:
        kept = {id(o) for o in after}
        for obj in before:
            if id(obj) not in kept:
                self.backend.mark_filtered(obj)

    # ---------------------------------------------------------------- shared loops
    def assign(self, detection_list: Any, objects: Any, agg_sim: Any, threshold: float, merge_one: MergeOne) -> Any:
        """Association loop: a new object when the row has no candidate, else route the claims
        (``targeting``: whole to the argmax, or spread over the candidates) and merge the geometry
        into the argmax (every row routed first, then
        the merges in row order: :meth:`merge_pass`)."""
        backend = self.backend
        # the frame's events in one update_many call; each object resolved to its node once
        with backend.batch(), backend.frame_lookups():
            return self._assign(detection_list, objects, agg_sim, threshold, merge_one)

    def _assign(self, detection_list: Any, objects: Any, agg_sim: Any, threshold: float, merge_one: MergeOne) -> Any:
        backend = self.backend
        touched = self.frame_start(objects)
        scores = as_numpy(agg_sim)  # one conversion per frame, not one per row
        n_rows = scores.shape[0]
        if scores.shape[1]:
            best_of, max_of = scores.argmax(axis=1).tolist(), scores.max(axis=1).tolist()
            n = min(scores.shape[1], len(objects))  # candidates of every row at once (see targets_for)
            cands = candidate_matrix(scores[:, :n], threshold) if backend.targeting == "spread" else None
        else:
            best_of, max_of, cands = [0] * n_rows, [NEG_INF] * n_rows, None
        merges: list[tuple[int | None, dict]] = []  # (position, detection), in row order
        for i in range(n_rows):
            det = detection_list[i]
            top = max_of[i]
            if top <= threshold or top == NEG_INF:
                objects.append(det)
                backend.frame_node(det)
                touched.add(len(objects) - 1)
                continue
            j = best_of[i]
            targets = backend.targets_for(scores[i], j, objects, threshold, touched,
                                          candidates=None if cands is None else cands[i])
            backend.route_detection(det, targets)
            merges.append((j, det))
        self.merge_pass(objects, merges, merge_one)
        self.sync_labels(objects, touched)
        backend.end_frame()
        return objects

    def merge_pass(self, objects: Any, rows: Iterable[tuple[int | None, dict]], merge_one: MergeOne,
                   on_new: Callable[[dict], Any] | None = None) -> None:
        """ConceptGraphs' side of a frame, run once every detection of the frame is routed: in row
        order, each matched detection ``(j, det)`` merged into ``objects[j]``, and ``on_new(det)``
        for each new object ``(None, det)``.

        The frame's events are applied before the first merge: a queued claim's channel reads the
        dict it came from (a map object registered in this frame), which a merge changes. The map
        is the one routing each detection right before its own merge gives."""
        merged = self.merged
        flushed = False
        for j, det in rows:
            if j is None:
                if on_new is not None:
                    on_new(det)
                continue
            if not flushed:
                self.backend.flush()
                flushed = True
            objects[j] = merge_one(objects[j], det)
            merged.add(id(objects[j]))

    def overlap_merge_loop(self, objects: Any, overlap: np.ndarray, ratio_thresh: float, visual_thresh: float,
                           text_thresh: float, merge_one: MergeOne, use_text: bool) -> tuple[Any, list]:
        """ConceptGraphs' overlap merge: pairs by decreasing overlap; the beliefs of ``i`` migrate into ``j``."""
        backend = self.backend
        x, y = np.asarray(overlap).nonzero()
        ratios = np.asarray(overlap)[x, y]
        order = np.argsort(ratios)[::-1]
        kept = np.ones(len(objects), dtype=bool)
        for i, j, ratio in zip(x[order], y[order], ratios[order]):
            if not ratio > ratio_thresh:
                break
            vis = geo.cosine(objects[i]["clip_ft"], objects[j]["clip_ft"])
            txt = geo.cosine(objects[i]["text_ft"], objects[j]["text_ft"]) if use_text else vis
            if vis > visual_thresh and txt > text_thresh and kept[j]:
                # as in ConceptGraphs, i is not checked for an earlier merge; the backend's
                # tombstones make sure its evidence still migrates only once
                backend.migrate(objects[j], objects[i])
                objects[j] = merge_one(objects[j], objects[i])
                self.merged.add(id(objects[j]))
                kept[i] = False
        index_updates: list[int | None] = []
        cur = 0
        for keep in kept:
            index_updates.append(cur if keep else None)
            cur += int(keep)
        before = list(objects)
        new = same_list_type(objects)([o for o, k in zip(objects, kept) if k])
        for obj, keep in zip(before, kept):
            if not keep:
                backend.identity.retire(backend.identity.lookup(obj) or "")
        # the pass is ConceptGraphs' map-wide step (periodic, and at the end of the run): the
        # consensus is refitted on the objects as merged, which the labels are read from
        backend.refit_consensus()
        self.sync_labels(new)
        return new, index_updates

    # ---------------------------------------------------------------- labels out (both)
    def get_most_common_class(self, objects: Iterable[Mapping[str, Any]]) -> list:
        """Per object: class id from the beliefs (``unknown_class_id`` when nothing commits).

        Objects the backend never saw fall back to ConceptGraphs' majority vote.
        """
        backend = self.backend
        classes = []
        for d in objects:
            cid = backend.class_id_of(d) if backend.active else None
            if cid is None:
                values, counts = np.unique(np.asarray(d["class_id"]), return_counts=True)
                classes.append(values[np.argmax(counts)])
            else:
                # the dtype the vote would return, from one element: the per-frame cost must not
                # grow with the object's detection history
                classes.append(vote_dtype_scalar(d["class_id"], cid))
        return classes

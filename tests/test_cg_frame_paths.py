"""The ConceptGraphs adapter's per-frame fast paths equal the plain ones (issue #34).

Each fast path is checked against the path it replaces, on inputs drawn by hypothesis:
the one-entry claim reader against the entry-by-entry reader, the per-frame memoised node
look-ups against ``ensure_node``, ``refresh_node_geometry`` against ``refresh_geometry``, the
scored candidate matrix against the row-by-row candidates, ``IdentityMap.find`` + ``register(fp)``
against ``lookup`` + ``register``, the fingerprint's entry reader against ``.item()`` alone,
``EvidenceEvent.trusted`` against the validating constructor
and ``SceneGraph.add_node``'s box check against the generator it replaced.
"""

from __future__ import annotations

import copy
import uuid
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
from sgbelief.adapters.conceptgraphs.claims import _read_all, read_claims
from sgbelief.adapters.conceptgraphs.generation_base import candidate_matrix
from sgbelief.adapters.conceptgraphs.geometry import geometry_summary
from sgbelief.adapters.conceptgraphs.identity import IdentityMap, _plain
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.graph.scene_graph import SceneGraphModel

CLASSES = ["chair", "table", "sofa"]

# ---------------------------------------------------------------- claims

ids_st = st.one_of(st.integers(-2, 4), st.integers(-2, 4).map(np.int64), st.none(), st.just("x"))
names_st = st.one_of(st.none(), st.sampled_from(CLASSES), st.lists(st.sampled_from(CLASSES), max_size=2),
                     st.just([]))
confs_st = st.one_of(st.floats(-0.5, 1.5, allow_nan=False), st.floats(0, 1).map(np.float32), st.none())
frames_st = st.one_of(st.none(), st.lists(st.integers(0, 9), max_size=2), st.integers(0, 9).map(lambda t: (t,)))


@settings(max_examples=300, deadline=None)
@given(cid=ids_st, conf=confs_st, names=names_st, frames=frames_st,
       known=st.dictionaries(st.integers(0, 4), st.sampled_from(CLASSES), max_size=3))
def test_one_entry_reader_equals_the_entry_by_entry_reader(cid: Any, conf: Any, names: Any, frames: Any,
                                                          known: dict[int, str]) -> None:
    obj = {"class_id": [cid], "conf": [conf], "class_name": names, "image_idx": frames}
    fast_names, plain_names = dict(known), dict(known)
    try:
        plain = _read_all([cid], [conf], frames, names, plain_names)
    except (TypeError, ValueError) as exc:
        with pytest.raises(type(exc)):
            read_claims(obj, fast_names)
        assert fast_names == plain_names
        return
    assert read_claims(obj, fast_names) == plain
    assert fast_names == plain_names


# ---------------------------------------------------------------- scored candidates

@settings(max_examples=200, deadline=None)
@given(rows=st.integers(1, 5), cols=st.integers(1, 7), data=st.data(),
       threshold=st.sampled_from([float("-inf"), 0.0, 1.2, 0.5]))
def test_scored_candidates_equal_the_row_by_row_candidates(rows: int, cols: int, data: st.DataObject,
                                                          threshold: float) -> None:
    values = data.draw(st.lists(st.sampled_from([float("-inf"), -1.0, 0.0, 0.5, 1.2, 1.3, 2.0, float("nan")]),
                                min_size=rows * cols, max_size=rows * cols))
    scores = np.asarray(values, dtype=float).reshape(rows, cols)
    got = candidate_matrix(scores, threshold)
    for i in range(rows):
        s = scores[i]
        plain = np.flatnonzero(np.isfinite(s) & (s > threshold) & (s > 0)).tolist()  # targets_for's own pass
        assert list(got[i]) == plain
        assert got[i] == {j: float(s[j]) for j in plain}


def _backend(**kwargs: Any) -> ConceptGraphsBackend:
    return ConceptGraphsBackend("comod", context="t", class_names=CLASSES, print_summary=False, **kwargs)


def _det(k: int, *, uid: bool = False, t: int = 1, cls: int = 0, points: int = 5) -> dict:
    rng = np.random.default_rng(k)
    d: dict[str, Any] = {"image_idx": [t], "mask_idx": [k], "color_path": [f"f{t}.jpg"], "class_id": [cls],
                         "class_name": [CLASSES[cls]], "conf": [0.8], "num_detections": 1,
                         "pcd_np": rng.random((points, 3)) + k}
    if uid:
        d = {"id": uuid.UUID(int=k + 1), **d}
    return d


@settings(max_examples=40, deadline=None)
@given(data=st.data(), uid=st.booleans())
def test_targets_with_scored_candidates_equal_targets_from_the_row(data: st.DataObject, uid: bool) -> None:
    n = data.draw(st.integers(1, 6))
    row = np.asarray(data.draw(st.lists(st.sampled_from([float("-inf"), 0.0, 0.4, 1.2, 1.3]),
                                        min_size=n, max_size=n)), dtype=float)
    best = int(row.argmax())
    threshold = data.draw(st.sampled_from([float("-inf"), 0.5]))
    out = []
    for scored in (False, True):
        backend = _backend(targeting="spread")  # the candidates are read only when claims spread
        objects = [_det(k, uid=uid) for k in range(n)]
        touched: set[int] = set()
        cands = candidate_matrix(row[None, :], threshold)[0] if scored else None
        with backend.frame_lookups():
            out.append((backend.targets_for(row, best, objects, threshold, touched, candidates=cands), touched))
    assert out[0] == out[1]


# ---------------------------------------------------------------- memoised node look-ups

#: a step: (kind, object index); kinds: ask for an object's node, merge one object into another,
#: filter an object away, register a stale copy's node
steps_st = st.lists(st.tuples(st.sampled_from(["node", "node", "node", "migrate", "filter", "copy"]),
                              st.integers(0, 5), st.integers(0, 5)), max_size=25)


def _run(steps: list[tuple[str, int, int]], *, memo: bool, uid: bool, on_filter: str) -> list[Any]:
    backend = _backend(on_filter=on_filter)
    objects: list[dict] = [_det(k, uid=uid) for k in range(6)]
    seen: list[Any] = []
    with backend.frame_lookups() if memo else _nothing():
        ask = backend.frame_node if memo else backend.ensure_node
        for kind, a, b in steps:
            if kind == "node":
                seen.append(ask(objects[a]))
            elif kind == "migrate" and a != b:
                backend.migrate(objects[a], objects[b])
            elif kind == "filter":
                backend.mark_filtered(objects[a])
            elif kind == "copy":
                objects[a] = copy.deepcopy(objects[a])
            seen.append(sorted(map(str, backend.graph.nodes())))
    backend.flush()
    seen.append(backend.graph.evidence_count())
    return seen


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


@settings(max_examples=80, deadline=None)
@given(steps=steps_st, uid=st.booleans(), on_filter=st.sampled_from(["mark", "remove"]))
def test_frame_node_equals_ensure_node(steps: list[tuple[str, int, int]], uid: bool, on_filter: str) -> None:
    assert _run(steps, memo=True, uid=uid, on_filter=on_filter) == _run(steps, memo=False, uid=uid,
                                                                         on_filter=on_filter)


def test_frame_lookups_resolve_each_object_once() -> None:
    backend = _backend()
    obj = _det(0)
    calls = []
    plain = backend.ensure_node

    def counted(o: dict) -> Any:
        calls.append(o)
        return plain(o)

    backend.ensure_node = counted  # type: ignore[method-assign]
    with backend.frame_lookups():
        nodes = {backend.frame_node(obj) for _ in range(3)}
    assert len(nodes) == 1 and len(calls) == 1
    backend.frame_node(obj)  # outside a frame: no memo
    assert len(calls) == 2


# ---------------------------------------------------------------- geometry

class _Cloud:
    """An open3d-like cloud (answers its own bounds)."""

    def __init__(self, pts: np.ndarray) -> None:
        self.pts = pts

    def has_points(self) -> bool:
        return len(self.pts) > 0

    def get_center(self) -> np.ndarray:
        return self.pts.mean(axis=0)

    def get_min_bound(self) -> np.ndarray:
        return self.pts.min(axis=0)

    def get_max_bound(self) -> np.ndarray:
        return self.pts.max(axis=0)


@settings(max_examples=60, deadline=None)
@given(k=st.integers(0, 50), points=st.integers(0, 6), cloud=st.booleans(), uid=st.booleans(),
       shift=st.floats(-5, 5))
def test_refresh_node_geometry_equals_refresh_geometry(k: int, points: int, cloud: bool, uid: bool,
                                                       shift: float) -> None:
    attrs = []
    for fast in (False, True):
        backend = _backend()
        obj = _det(k, uid=uid, points=max(points, 1))
        node = backend.ensure_node(obj)
        pts = np.asarray(obj["pcd_np"]).reshape(-1, 3)[:points] + shift  # the merge moved the object
        if cloud:
            obj["pcd"] = _Cloud(pts)
        else:
            obj["pcd_np"] = pts
        if fast:
            backend.refresh_node_geometry(node, obj)
        else:
            backend.refresh_geometry(obj)
        attrs.append(dict(backend.graph.nx.nodes[node]))
    assert attrs[0] == attrs[1]


def test_geometry_type_check_is_per_class_and_per_instance_otherwise() -> None:
    pts = np.arange(6.0).reshape(2, 3)
    assert geometry_summary({"pcd": _Cloud(pts)}) == ((1.5, 2.5, 3.5), ((0.0, 1.0, 2.0), (3.0, 4.0, 5.0)))
    # an object whose bounds are per-instance attributes is still read as a cloud, not as points
    inst = type("Bare", (), {})()
    inst.has_points, inst.get_center = (lambda: True), (lambda: np.zeros(3))
    inst.get_min_bound, inst.get_max_bound = (lambda: np.zeros(3)), (lambda: np.ones(3))
    assert geometry_summary({"pcd": inst}) == ((0.0, 0.0, 0.0), ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)))
    assert geometry_summary({"pcd": type("Bare", (), {})()}) == (None, None)  # neither a cloud nor points


# ---------------------------------------------------------------- identity

@settings(max_examples=80, deadline=None)
@given(keys=st.lists(st.tuples(st.integers(0, 4), st.integers(0, 4), st.booleans()), max_size=12))
def test_find_and_register_with_its_fingerprint_equal_lookup_and_register(keys: list[tuple[int, int, bool]]) -> None:
    objs = [({"id": uuid.UUID(int=i + 1)} if uid else {}) | {"image_idx": [i], "mask_idx": [m]} for i, m, uid in keys]
    fast, plain = IdentityMap(), IdentityMap()
    for obj in objs:
        node, fp = fast.find(obj)
        assert node == plain.lookup(obj)
        if node is None:
            assert fast.register(obj, fp) == plain.register(obj)
    assert fast._by_fp == plain._by_fp and fast._known == plain._known


def _plain_by_item(value: Any) -> Any:
    """The fingerprint's entry reader without its type check (``.item()`` or the value itself)."""
    try:
        return value.item()
    except AttributeError:
        return value


@settings(max_examples=100, deadline=None)
@given(value=st.one_of(st.integers(), st.text(max_size=4), st.booleans(), st.integers(-9, 9).map(np.int64),
                       st.floats(width=32, allow_nan=False).map(np.float32), st.integers(0, 9).map(np.array),
                       st.none(), st.floats(allow_nan=False)))
def test_fingerprint_entry_reader_equals_reading_by_item(value: Any) -> None:
    fast, plain = _plain(value), _plain_by_item(value)
    assert fast == plain and type(fast) is type(plain)


# ---------------------------------------------------------------- events and nodes

@settings(max_examples=100, deadline=None)
@given(targets=st.dictionaries(st.text(min_size=1, max_size=3), st.floats(0, 0.3), min_size=1, max_size=3),
       pred=st.sampled_from(["is_chair", "is_table"]), conf=st.floats(0, 1), t=st.integers(0, 100))
def test_trusted_event_equals_the_validated_event(targets: dict[str, float], pred: str, conf: float, t: int) -> None:
    plain = EvidenceEvent(targets, pred, conf, "ctx", t, "e-1")
    fast = EvidenceEvent.trusted(targets, pred, conf, "ctx", t, "e-1")
    assert fast == plain and hash(fast.id) == hash(plain.id) and fast.targets is targets
    with pytest.raises(AttributeError):
        fast.predicate = "is_sofa"  # type: ignore[misc]  # still frozen


coord = st.floats(-3, 3, allow_nan=False)


@settings(max_examples=100, deadline=None)
@given(lo=st.tuples(coord, coord, coord), hi=st.tuples(coord, coord, coord))
def test_add_node_box_check_equals_the_pairwise_generator(lo: tuple, hi: tuple) -> None:
    g = SceneGraphModel()
    bad = any(a > b for a, b in zip(lo, hi))  # the check it replaced
    if bad:
        with pytest.raises(ValueError, match="exceeds"):
            g.add_node("n", bbox=(lo, hi), extra=1)
        assert "n" not in g
    else:
        g.add_node("n", bbox=(lo, hi), extra=1)
        assert g.nx.nodes["n"] == {"bbox": (lo, hi), "extra": 1}

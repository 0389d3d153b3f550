"""A new map object's registration: the fast paths equal the plain ones (issue #34).

Checked with hypothesis: a new object's own claims routed by ``_route_own(det, node)`` against
``route_detection(det, {node: 1.0})`` (the same queued events in the same order, the same per-node
bookkeeping, the same graph once applied, the same errors); the whole registration against the
sequence it replaced (``identity.register``, ``geometry_summary``, ``SceneGraph.add_node``,
``route_detection``); the point check of ``SceneGraph.add_node`` against ``float()`` of each
coordinate; ``IdentityMap``'s uid look-up against the try/except it replaced.
"""

from __future__ import annotations

import json
import math
import re
import uuid
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
from sgbelief.adapters.conceptgraphs.geometry import geometry_summary
from sgbelief.adapters.conceptgraphs.identity import IdentityMap
from sgbelief.graph.persistence import graph_to_dict
from sgbelief.graph.scene_graph import _as_point, _as_point_plain

CLASSES = ["chair", "table", "sofa"]
EVENT_ID = re.compile(r'"e\d+"')


def _backend(**kwargs: Any) -> ConceptGraphsBackend:
    return ConceptGraphsBackend("comod", context="t", class_names=CLASSES, print_summary=False, **kwargs)


def _saved(backend: ConceptGraphsBackend) -> str:
    """The backend's graph as saved, its event ids renamed in order of appearance."""
    backend.flush()
    names: dict[str, str] = {}
    return EVENT_ID.sub(lambda m: names.setdefault(m.group(0), f'"ev{len(names)}"'),
                        json.dumps(graph_to_dict(backend.graph), sort_keys=True, default=str))


# ---------------------------------------------------------------- a new object's own claims

claim_st = st.tuples(st.one_of(st.integers(-1, 3), st.none()), st.sampled_from([0.2, 0.55, 0.9, 1.0]),
                     st.integers(-1, 4))
label_st = st.one_of(st.none(), st.sampled_from(CLASSES),
                     st.lists(st.one_of(st.none(), st.sampled_from(CLASSES)), max_size=3))


def _claims_det(claims: list[tuple[Any, float, int]], label: Any, names: bool) -> dict:
    d: dict[str, Any] = {"class_id": [c for c, _, _ in claims], "conf": [p for _, p, _ in claims],
                         "image_idx": [t for _, _, t in claims], "mask_idx": [7], "num_detections": len(claims)}
    if names:
        d["class_name"] = [CLASSES[c] if c is not None and 0 <= c < 3 else "sofa" for c, _, _ in claims]
    if label is not None:
        d["geometric_label"] = label
    return d


def _route_state(backend: ConceptGraphsBackend, det: dict, node: str, fast: bool, prior: dict | None) -> tuple:
    if prior is not None:  # the node already holds routed claims (a uid registered again)
        backend.route_detection(prior, {node: 1.0})
    try:
        n = backend._route_own(det, node) if fast else backend.route_detection(det, {node: 1.0})
    except Exception as exc:  # noqa: BLE001 - the same error either way
        n = (type(exc).__name__, str(exc))
    pending = [(e.targets, e.predicate, e.confidence, e.context, e.t, type(ch).__name__,
                getattr(ch, "_label", None), getattr(ch, "_index", None), getattr(ch, "_detection", None) is det, name)
               for e, ch, name in backend._pending]
    ids = [int(e.id[1:]) for e, _, _ in backend._pending]
    state = (n, pending, [b - a for a, b in zip(ids, ids[1:])],
             {k: list(v.items()) for k, v in backend._names_per_node.items()},
             {k: sorted(v) for k, v in backend._preds_per_node.items()},
             list(backend._detections_per_node.items()), sorted(backend._changed), backend._routed_detections,
             backend._has_channel, dict(backend.class_names), sorted(det))
    return state + (_saved(backend),)


@settings(max_examples=200, deadline=None)
@given(claims=st.lists(claim_st, max_size=3), label=label_st, names=st.booleans(), prior=st.booleans(),
       mapped=st.booleans(), channel=st.booleans(), batched=st.booleans())
def test_own_claims_route_as_the_general_routing(claims: list, label: Any, names: bool, prior: bool, mapped: bool,
                                                 channel: bool, batched: bool) -> None:
    out = []
    for fast in (False, True):
        kwargs: dict[str, Any] = {}
        if mapped:
            kwargs["confidence_map"] = lambda c: 1.5 * c if c > 0.95 else 0.8 * c  # > 1 is an error
        if channel:
            kwargs["channel"] = lambda det, node, t: "chair"
        backend = _backend(**kwargs)
        backend.graph.add_node("n0")
        prior_det = _claims_det([(1, 0.7, 0)], None, True) if prior else None
        backend._batch_open = batched
        out.append(_route_state(backend, _claims_det(claims, label, names), "n0", fast, prior_det))
    assert out[0] == out[1]


# ---------------------------------------------------------------- the whole registration

class PlainRegistration(ConceptGraphsBackend):
    """The registration as it was: register, summary, ``SceneGraph.add_node``, ``route_detection``."""

    def _register_new(self, obj: dict, fp: Any) -> Any:
        node = self.identity.register(obj, fp)
        if node not in self.graph:
            centroid, bbox = geometry_summary(obj)
            self.graph.add_node(node, centroid=centroid, bbox=bbox, source="conceptgraphs")
            self.fresh_geometry.add(id(obj))
        self.route_detection(obj, {node: 1.0})
        return node


def _obj(k: int, cls: int, conf: float, uid: bool, points: int) -> dict:
    rng = np.random.default_rng(k)
    d: dict[str, Any] = {"image_idx": [k % 3], "mask_idx": [k], "color_path": [f"f{k % 3}.jpg"], "class_id": [cls],
                         "class_name": [CLASSES[cls]], "conf": [conf], "num_detections": 1,
                         "pcd_np": rng.random((points, 3)) + k}
    if uid:
        d = {"id": uuid.UUID(int=k % 4 + 1), **d}
    return d


@settings(max_examples=80, deadline=None)
@given(objs=st.lists(st.tuples(st.integers(0, 6), st.integers(0, 2), st.sampled_from([0.3, 0.8]),
                               st.booleans(), st.integers(0, 4)), max_size=8),
       tau_t=st.sampled_from([0.1, 1.0]), on_filter=st.sampled_from(["mark", "remove"]), batched=st.booleans())
def test_registration_equals_the_plain_registration(objs: list, tau_t: float, on_filter: str, batched: bool) -> None:
    out = []
    for cls in (PlainRegistration, ConceptGraphsBackend):
        backend = cls("comod", context="t", class_names=CLASSES, print_summary=False, tau_t=tau_t,
                      on_filter=on_filter)
        nodes, kept = [], []
        with backend.batch() if batched else _nothing():
            for k, c, conf, uid, points in objs:
                obj = _obj(k, c, conf, uid, points)
                kept.append(obj)  # held: their id()s are not reused
                nodes.append(backend.ensure_node(obj))
                if k == 5:  # a filtered object's uid may come back
                    backend.mark_filtered(obj)
        out.append((nodes, _saved(backend), [id(o) in backend.fresh_geometry for o in kept],
                    {k: list(v.items()) for k, v in backend._names_per_node.items()},
                    list(backend._detections_per_node.items()), repr(backend.summary())))
    assert out[0] == out[1]


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


# ---------------------------------------------------------------- points and uids

number = st.one_of(st.floats(allow_nan=True), st.integers(-5, 5), st.floats(-3, 3).map(np.float64),
                   st.just("1.5"), st.just("x"), st.none(), st.booleans())


@settings(max_examples=300, deadline=None)
@given(values=st.lists(number, min_size=0, max_size=4), as_tuple=st.booleans())
def test_point_check_equals_float_of_each_coordinate(values: list, as_tuple: bool) -> None:
    value = tuple(values) if as_tuple else list(values)
    try:
        plain = _as_point_plain(value, "p")
    except (TypeError, ValueError) as exc:
        with pytest.raises(type(exc), match=re.escape(str(exc))):
            _as_point(value, "p")
        return
    fast = _as_point(value, "p")
    assert type(fast) is tuple and all(type(x) is float for x in fast)
    assert [math.isnan(x) or x for x in fast] == [math.isnan(x) or x for x in plain]


def _uid_node_plain(m: IdentityMap, uid: Any) -> str:
    """The look-up it replaced: try the table, str() on a miss and on an unhashable id."""
    try:
        return m._uid_nodes[uid]
    except KeyError:
        node = m._uid_nodes[uid] = str(uid)
        return node
    except TypeError:
        return str(uid)


@settings(max_examples=100, deadline=None)
@given(uids=st.lists(st.one_of(st.integers(1, 4).map(lambda i: uuid.UUID(int=i)), st.text(max_size=2),
                               st.just(["unhashable"])), max_size=8))
def test_uid_lookup_equals_the_try_except_lookup(uids: list) -> None:
    fast, plain = IdentityMap(), IdentityMap()
    assert [fast._uid_node(u) for u in uids] == [_uid_node_plain(plain, u) for u in uids]
    assert fast._uid_nodes == plain._uid_nodes


# ---------------------------------------------------------------- the first label of a new object

#: a routed detection: (class, confidence, target nodes, the channel's label or None)
routed_st = st.tuples(st.integers(0, 2), st.sampled_from([0.2, 0.6, 0.95]),
                      st.sampled_from([("n0",), ("n1",), ("n0", "n1"), ("n2",)]),
                      st.one_of(st.none(), st.sampled_from(CLASSES)))


@settings(max_examples=150, deadline=None)
@given(routed=st.lists(routed_st, max_size=6),
       rule=st.sampled_from(["most_frequent", "first", {"is_chair": "sofa"}, {"is_table": "table"}]),
       abstain=st.booleans(), merge=st.booleans(), queued=st.booleans())
def test_one_class_label_equals_the_committed_class(routed: list, rule: Any, abstain: bool, merge: bool,
                                                    queued: bool) -> None:
    backend = _backend(label_rule=rule, abstain=abstain,
                       channel=lambda det, node, t: det.get("geometric_label_for_test"))
    for n in ("n0", "n1", "n2", "n3"):
        backend.graph.add_node(n)
    with backend.batch():
        for t, (c, conf, nodes, label) in enumerate(routed):
            det = {"class_id": [c], "conf": [conf], "image_idx": [t], "class_name": [CLASSES[c]]}
            if label is not None:
                det["geometric_label_for_test"] = label
            backend.route_detection(det, {n: 1.0 / len(nodes) + 0.01 * k for k, n in enumerate(nodes)})
    if merge:
        backend.flush()
        backend.operator.merge_nodes(backend.graph, "n2", "n3")  # a node without claims merged in
    if queued:  # a claim still queued: the general path applies it first
        backend._batch_open = True
        backend.route_detection({"class_id": [0], "conf": [0.9], "image_idx": [9]}, {"n0": 1.0})
    for node in list(backend.graph.nodes()):
        fast = backend._one_class_label(node)
        hit = backend.committed_class(node)
        plain = backend.unknown_label if hit is None else hit[1]
        if fast is not None:
            assert fast == plain
        assert backend.node_label(node) == plain
    backend._batch_open = False

"""ConceptGraphs backend: per-frame work independent of history and map size; GC checkpoints."""

from __future__ import annotations

import gc
import sys
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
from sgbelief.adapters.conceptgraphs.functions import make_functions
from sgbelief.graph.provenance import ProvenanceStore

CLASSES = ("chair", "table", "sofa", "bed")


def _map(backend: ConceptGraphsBackend, n_obj: int, n_det: int) -> tuple[list[dict], list[Any]]:
    """A map of ``n_obj`` objects built frame by frame with ``n_det`` detections each (every object
    sees every class once ``n_det >= 4``, so maps of any history hold the same (node, predicate) pairs)."""
    objs: list[dict] = []
    nodes: list[Any] = []
    for o in range(n_obj):
        cid = o % len(CLASSES)
        obj = {"class_id": [cid], "conf": [0.8], "image_idx": [0], "mask_idx": [o], "class_name": [CLASSES[cid]]}
        nodes.append(backend.ensure_node(obj))
        objs.append(obj)
    for t in range(1, n_det):
        for o in range(n_obj):
            frame_detection(backend, objs[o], nodes[o], (o + t) % len(CLASSES), t)
    return objs, nodes


def frame_detection(backend: ConceptGraphsBackend, obj: dict, node: Any, cid: int, t: int) -> None:
    det = {"class_id": [cid], "conf": [0.8], "image_idx": [t], "class_name": [CLASSES[cid]],
           backend.label_key: CLASSES[cid]}
    backend.route_detection(det, {node: 1.0})
    obj["class_id"].append(cid)
    obj["class_name"].append(CLASSES[cid])


def _calls_in_one_frame(op: str, n_obj: int, n_det: int) -> Counter[str]:
    """Work of one frame (route one detection per object, read every label): Python and C calls by
    name, plus the number of bytecodes executed (``"<opcodes>"``; catches loops in comprehensions)."""
    backend = ConceptGraphsBackend(op, class_names=CLASSES)
    objs, nodes = _map(backend, n_obj, n_det)
    calls: Counter[str] = Counter()

    def prof(frame: Any, event: str, arg: Any) -> None:
        if event == "call":
            calls[frame.f_code.co_qualname] += 1
        elif event == "c_call":
            calls[getattr(arg, "__qualname__", repr(arg))] += 1

    def local(frame: Any, event: str, arg: Any) -> Any:
        if event == "opcode":
            calls["<opcodes>"] += 1
        return local

    def trace(frame: Any, event: str, arg: Any) -> Any:
        frame.f_trace_opcodes = True
        return local

    enabled = gc.isenabled()
    old_trace, old_profile = sys.gettrace(), sys.getprofile()  # e.g. a coverage tracer
    gc.disable()
    sys.setprofile(prof)
    sys.settrace(trace)
    try:
        for o, obj in enumerate(objs):
            frame_detection(backend, obj, nodes[o], o % len(CLASSES), n_det)
        labels = [backend.class_id_of(obj) for obj in objs]
    finally:
        sys.settrace(old_trace)
        sys.setprofile(old_profile)
        if enabled:
            gc.enable()
    assert len(labels) == n_obj
    return calls


@pytest.mark.parametrize("op", ["majority", "naive_bayes"])
def test_per_frame_work_does_not_grow_with_detections_per_object(op: str) -> None:
    # the same calls, one for one, whether the objects carry 5 or 120 detections
    assert _calls_in_one_frame(op, 4, 5) == _calls_in_one_frame(op, 4, 120)


def test_per_object_label_work_does_not_grow_with_map_size() -> None:
    # calls = per-frame constant + per-object work x objects: the per-object part is the same at 8 and 40
    c4, c8, c40 = (_calls_in_one_frame("majority", n, 8) for n in (4, 8, 40))
    for name in c40.keys() | c4.keys():
        assert c40[name] - c4[name] == 9 * (c8[name] - c4[name]), name


def test_label_reads_never_scan_every_pair(monkeypatch: pytest.MonkeyPatch) -> None:
    backend = ConceptGraphsBackend("majority", class_names=CLASSES)
    objs, _nodes = _map(backend, 3, 6)

    def scan(*_a: Any, **_k: Any) -> Any:
        raise AssertionError("a label read scanned every (node, predicate) pair")

    monkeypatch.setattr(ProvenanceStore, "predicates_of", scan)
    assert all(backend.label_of(o) in CLASSES for o in objs)
    assert all(backend.class_id_of(o) in range(len(CLASSES)) for o in objs)


def test_labels_follow_the_beliefs_and_merges() -> None:
    backend = ConceptGraphsBackend("majority", class_names=CLASSES)
    a = {"class_id": [2, 2, 0], "conf": [0.9, 0.9, 0.6], "image_idx": [0, 1, 2], "mask_idx": [0, 0, 0]}
    b = {"class_id": [3, 3, 3], "conf": [0.95] * 3, "image_idx": [0, 1, 2], "mask_idx": [1] * 3}
    backend.ensure_node(a)
    backend.ensure_node(b)
    assert backend.label_of(a) == "sofa" and backend.label_of(b) == "bed"
    backend.migrate(a, b)  # b's evidence (and predicate) moves to a's node
    node = backend.node_of(a)
    assert backend._predicates_of(node) == {"is_sofa", "is_chair", "is_bed"}
    assert backend.committed_predicate(node) == "is_bed"  # mean 3.85/5 beats is_sofa's 2.8/4
    assert backend.label_of(b) == "bed"


def test_external_graph_evidence_is_still_read() -> None:
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.api.operators import make_operator
    from sgbelief.graph.scene_graph import SceneGraphModel

    g = SceneGraphModel(create_nodes=True)
    op = make_operator("majority")
    for t in range(5):  # evidence the backend never routed
        op.update(g, EvidenceEvent({"cg-0": 1.0}, "is_sofa", 0.99, "other", t))
    backend = ConceptGraphsBackend("majority", graph=g, class_names=CLASSES)
    obj = {"class_id": [0], "conf": [0.6], "image_idx": [9], "mask_idx": [0]}
    node = backend.ensure_node(obj)
    assert node == "cg-0"
    assert backend.committed_predicate(node) == "is_sofa"


def test_get_most_common_class_keeps_the_vote_dtype_without_reading_the_history() -> None:
    backend = ConceptGraphsBackend("majority", class_names=CLASSES)
    fns = make_functions(backend, "main")
    seen32 = {"class_id": [np.int32(1)] * 3, "conf": [0.9] * 3, "image_idx": [0, 1, 2], "mask_idx": [0] * 3}
    seen_py = {"class_id": [3, 3], "conf": [0.9, 0.9], "image_idx": [0, 1], "mask_idx": [1, 1]}
    backend.ensure_node(seen32)
    backend.ensure_node(seen_py)
    unseen = {"class_id": [2, 0, 2], "conf": [0.9] * 3, "image_idx": [5, 6, 7], "mask_idx": [9] * 3}
    out = fns.get_most_common_class([seen32, seen_py, unseen])
    assert [int(x) for x in out] == [1, 3, 2]
    assert type(out[0]) is np.int32 and type(out[1]) is np.int64  # what np.unique(np.asarray(ids)) gives
    arr = {"class_id": np.array([3, 3], dtype=np.int16), "conf": [0.9, 0.9], "image_idx": [4, 5], "mask_idx": [2, 2]}
    backend.ensure_node(arr)
    assert type(fns.get_most_common_class([arr])[0]) is np.int16
    # a seen object's history is not read again (only its first element, for the dtype)
    reads: list[int] = []

    class Ids(Sequence):
        def __init__(self, items: list[int]) -> None:
            self.items = items

        def __len__(self) -> int:
            return len(self.items)

        def __getitem__(self, k: Any) -> Any:
            reads.append(k)
            return self.items[k]

    seen32["class_id"] = Ids([1] * 500)
    reads.clear()
    assert int(fns.get_most_common_class([seen32])[0]) == 1 and reads == [0]


def test_gc_checkpoint_freezes_and_uninstall_unfreezes() -> None:
    backend = ConceptGraphsBackend("majority", class_names=CLASSES)
    _map(backend, 3, 4)
    gc.unfreeze()
    try:
        backend.end_frame()  # checkpoints are off by default
        assert gc.get_freeze_count() == 0
        backend.gc_checkpoints = True
        backend.end_frame()
        assert gc.get_freeze_count() > 0
        frozen = gc.get_freeze_count()
        _map(backend, 3, 4)
        backend.gc_checkpoint()  # only what is new since the last checkpoint joins
        assert gc.get_freeze_count() > frozen
        backend.uninstall()
        assert gc.get_freeze_count() == 0
    finally:
        gc.unfreeze()


def _frame_opcodes_through_the_merge(generation: str, n_obj: int, relabel_loop: bool = False) -> Counter[str]:
    """Bytecodes (and calls) of sgbelief code in one patched per-frame merge of one detection into a
    map of ``n_obj`` objects (the geometric merge stubbed out: only the backend's own work counts).

    Keys: a code object's qualname (calls) and ``"<opcodes> qualname"`` (bytecodes executed in it).
    ``relabel_loop``: then run the ``ali-dev`` script's inline relabel loop (``rerun_realtime_mapping.py``:
    ``obj["class_name"] = most_common_class_name`` where the vote's name differs), with a class
    list on which every object's vote differs from its belief label, so every object is written."""
    import torch

    backend = ConceptGraphsBackend("majority", class_names=CLASSES)
    keep = lambda *a, **k: a[1] if generation == "main" else k.get("obj1", a[0] if a else None)  # noqa: E731
    fns = make_functions(backend, generation, originals={"merge_obj2_into_obj1": keep})
    objs = [{"class_id": [o % 4], "conf": [0.8], "image_idx": [0], "mask_idx": [o], "class_name": CLASSES[o % 4],
             "id": f"obj-{o}"} for o in range(n_obj)]
    fns.sync_labels(objs)  # the map as a previous frame left it: every object registered
    det = {"class_id": [1], "conf": [0.9], "image_idx": [1], "mask_idx": [0], "class_name": [CLASSES[1]], "id": "det"}
    sims = torch.full((1, n_obj), float("-inf"))
    sims[0, 3] = 1.5
    script_names = CLASSES[1:] + CLASSES[:1]  # the script's class list: its vote names differ from the beliefs'
    counts: Counter[str] = Counter()

    def tracer(name: str) -> Any:
        def local(frame: Any, event: str, arg: Any) -> Any:
            if event == "opcode":
                counts[name] += 1
            return local
        return local

    def trace(frame: Any, event: str, arg: Any) -> Any:
        if "sgbelief" not in frame.f_code.co_filename:
            return None
        counts[frame.f_code.co_qualname] += 1
        frame.f_trace_opcodes = True
        return tracer(f"<opcodes> {frame.f_code.co_qualname}")

    old = sys.gettrace()
    sys.settrace(trace)
    try:
        if generation == "main":
            out = fns.merge_detections_to_objects(None, [det], objs, sims)
        else:
            idx = fns.match_detections_to_objects(sims, 1.1)
            out = fns.merge_obj_matches([det], objs, idx, 0.05, False, 0.1, 10, "iou", "cpu")
            if relabel_loop:
                for obj in out:
                    name = script_names[Counter(obj["class_id"]).most_common(1)[0][0]]
                    if obj["class_name"] != name:
                        obj["class_name"] = name
    finally:
        sys.settrace(old)
    assert len(out) == n_obj
    if relabel_loop:  # the script wrote every object, and every object kept its belief label
        assert all(o["class_name"] == backend.label_of(o) for o in out)
        assert [o["class_name"] for o in out[4:8]] == list(CLASSES)
    return counts


@pytest.mark.parametrize("generation", ["main", "ali-dev"])
def test_per_frame_merge_work_does_not_grow_with_map_size(generation: str) -> None:
    # one detection into a map of 12 or 120 objects: the backend executes the same bytecodes
    small = _frame_opcodes_through_the_merge(generation, 12)
    large = _frame_opcodes_through_the_merge(generation, 120)
    assert small == large


def test_ali_dev_relabel_loop_reads_no_beliefs_whatever_the_map_size() -> None:
    # the ali-dev script writes class_name on every object whose vote differs from its belief label
    # (here all of them): each write costs the same few bytecodes in BeliefLabelledObject.__setitem__
    # and reads no belief; everything else the frame does is the same at 12 and 120 objects
    setitem = "BeliefLabelledObject.__setitem__"
    small = _frame_opcodes_through_the_merge("ali-dev", 12, relabel_loop=True)
    large = _frame_opcodes_through_the_merge("ali-dev", 120, relabel_loop=True)
    writes = (small.pop(setitem), large.pop(setitem))
    ops = (small.pop(f"<opcodes> {setitem}"), large.pop(f"<opcodes> {setitem}"))
    assert writes == (12, 120)
    assert ops[0] / writes[0] == ops[1] / writes[1] <= 40  # a constant per write: no loop, no call
    assert small == large
    assert small == _frame_opcodes_through_the_merge("ali-dev", 12) - Counter({setitem: 12})


# a frame: per detection (class id, confidence, matched object index or None for a new object)
_frames = st.lists(st.lists(st.tuples(st.integers(0, 3), st.floats(0.05, 0.99), st.one_of(st.none(), st.integers(0, 30))),
                            min_size=1, max_size=4), min_size=1, max_size=12)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames=_frames, op=st.sampled_from(["majority", "comod"]), wrong=st.integers(0, 3))
def test_ali_dev_labels_after_each_frame_equal_the_labels_read_from_the_beliefs(frames: list, op: str,
                                                                                   wrong: int) -> None:
    # relabelling only what changed must leave every object's class_name equal to a fresh read of its
    # beliefs, after the patched merge and after the script's relabel loop, whatever the frames
    import torch

    channel = (lambda det, node, t: CLASSES[(det["class_id"][0] + wrong) % 4]) if op == "comod" else None
    backend = ConceptGraphsBackend(op, class_names=CLASSES, channel=channel)
    def merge(obj1: dict, obj2: dict, **_geometry: Any) -> dict:
        # ConceptGraphs' merge with the geometry left out: the per-detection lists are concatenated
        for key in ("class_id", "conf", "image_idx", "mask_idx"):
            obj1[key] = obj1[key] + obj2[key]
        return obj1

    fns = make_functions(backend, "ali-dev", originals={"merge_obj2_into_obj1": merge})
    objects: list[dict] = []
    for t, frame in enumerate(frames):
        dets = [{"class_id": [c], "conf": [conf], "image_idx": [t], "mask_idx": [k], "class_name": CLASSES[c],
                 "id": f"d{t}-{k}"} for k, (c, conf, _j) in enumerate(frame)]
        if not objects:
            objects.extend(dets)  # the script's first frame
            continue
        match = [None if j is None else j % len(objects) for _c, _conf, j in frame]
        sims = torch.full((len(dets), len(objects)), float("-inf"))
        for i, j in enumerate(match):
            if j is not None:
                sims[i, j] = 1.5
        idx = fns.match_detections_to_objects(sims, 1.1)
        objects = fns.merge_obj_matches(dets, objects, idx, 0.05, False, 0.1, 10, "iou", "cpu")
        assert all(o["class_name"] == backend.label_of(o) for o in objects)
        for obj in objects:  # the script's relabel loop
            name = CLASSES[Counter(obj["class_id"]).most_common(1)[0][0]]
            if obj["class_name"] != name:
                obj["class_name"] = name
        assert all(o["class_name"] == backend.label_of(o) for o in objects)

"""The ConceptGraphs backend's default vocabulary (the run's class list), a channel that cannot be
silently off, and the summary of what the backend did."""

from __future__ import annotations

import json
import sys
import types
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("open3d")

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend, LabelImageChannel  # noqa: E402
from sgbelief.adapters.conceptgraphs.backend import summary_path  # noqa: E402
from sgbelief.adapters.conceptgraphs.standins import DetectionList, make_detection  # noqa: E402
from sgbelief.errors import ChannelMismatchError  # noqa: E402
from sgbelief.fusion.label_match import UnmatchedLabelWarning  # noqa: E402

CLASSES = ["chair", "table", "desk", "sofa", "couch", "tv", "lamp", "wall"]


def cfg() -> SimpleNamespace:
    return SimpleNamespace(downsample_voxel_size=0.05, dbscan_remove_noise=False, dbscan_eps=0.1, dbscan_min_points=10,
                           spatial_sim_type="iou", device="cpu")


def det(name: str, t: int, conf: float = 0.9, label: str | None = None, seed: int = 0) -> dict:
    d = make_detection(0.2 * np.random.default_rng(seed + t).random((40, 3)), CLASSES.index(name)
                       if name in CLASSES else 0, name, conf, t, seed=seed + t)
    if label is not None:
        d["geometric_label"] = label
    return d


def drive(backend: ConceptGraphsBackend, dets: list[dict]) -> list:
    """Every detection merged into one map object (ConceptGraphs main's per-frame merge)."""
    f = backend.functions("main")
    objects: list = []
    for d in dets:
        if not objects:  # the first frame: the script appends its detections itself
            objects = DetectionList([d])
            continue
        objects = f.merge_detections_to_objects(cfg(), DetectionList([d]), objects, torch.tensor([[1.5]]))
    return objects


# ---------------------------------------------------------------- the default vocabulary
def test_default_vocabulary_is_the_class_list() -> None:
    b = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False)
    v = b.vocabulary
    assert b.vocabulary_source == "class_names=" and v.class_names == tuple(CLASSES)
    assert v.predicate("table") == "is_table" and v.predicate("desk") == "is_desk"  # separate classes
    assert v.predicate("Couch") == v.predicate("sofas") == "is_sofa"  # synonyms, case and plural folded
    assert v.predicate("wall") is None  # background: no predicate
    assert b.table.outcome("is_table", "desk") == 0 and b.table.outcome("is_tv", "sofa") == 0
    assert b.table.outcome("is_lamp", "lamp") == 1
    assert b.operator.vocabulary is b.table  # the operator verifies against the same table
    merged = ConceptGraphsBackend("comod", class_names=CLASSES, merge=["is_table_or_desk"], print_summary=False)
    assert merged.vocabulary.predicate("desk") == merged.vocabulary.predicate("table") == "is_table_or_desk"
    closed = ConceptGraphsBackend("comod", vocabulary="scannet", print_summary=False)
    assert closed.vocabulary.class_names is None and "is_lamp" not in closed.table  # the closed table, by name
    replica = ConceptGraphsBackend("comod", class_names="replica", print_summary=False)
    assert replica.vocabulary.predicate("tv-screen") == "is_tv" and len(replica.table.predicates) > 90


def test_a_merged_predicate_writes_the_channels_own_label() -> None:
    """The issue's miss: a table the detector mostly calls desk, the channel says table."""
    dets = [det("desk" if k % 3 else "table", k, label="table") for k in range(9)]
    separate = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False)
    assert separate.label_of(drive(separate, dets)[0]) == "table"
    merged = ConceptGraphsBackend("comod", class_names=CLASSES, merge=True, print_summary=False)
    obj = drive(merged, [dict(d, geometric_label="table") for d in dets])[0]
    assert merged.committed_predicate(merged.node_of(obj)) == "is_table_or_desk"
    assert merged.label_of(obj) == "table" and merged.class_id_of(obj) == CLASSES.index("table")


def test_no_class_list_grows_from_detected_names_with_one_warning() -> None:
    b = ConceptGraphsBackend("comod", print_summary=False)
    assert not b.class_list_known
    with pytest.warns(UserWarning, match="no class list is known") as rec:
        drive(b, [det("chair", 0, label="chair"), det("table", 1, label="chair"), det("lamp", 2, label="chair")])
    assert sum("no class list" in str(w.message) for w in rec) == 1
    assert set(b.vocabulary.class_names) == {"chair", "table", "lamp"}
    assert b.table.outcome("is_lamp", "chair") == 0


def test_learnt_class_list_from_ali_dev_object_classes() -> None:
    """ali-dev's ObjectClasses (its constructor reads the classes file) hands the list over when patched."""
    names = ["conceptgraph", "conceptgraph.slam", "conceptgraph.slam.utils", "conceptgraph.slam.mapping",
             "conceptgraph.slam.slam_classes", "conceptgraph.utils", "conceptgraph.utils.general_utils"]
    mods = {n: types.ModuleType(n) for n in names}

    def merge_obj2_into_obj1(obj1, obj2, downsample_voxel_size, dbscan_remove_noise, dbscan_eps,  # noqa: ANN001, ANN202
                             dbscan_min_points, spatial_sim_type, device, run_dbscan=True):
        return obj1

    class ObjectClasses:
        def __init__(self, classes_file_path, bg_classes, skip_bg):  # noqa: ANN001
            self.classes = [c for c in ["Chair", "Sofa", "wall"] if not (skip_bg and c in bg_classes)]
            self.bg_classes = bg_classes

        def get_classes_arr(self):  # noqa: ANN202
            return self.classes

        def get_bg_classes_arr(self):  # noqa: ANN202
            return self.bg_classes

    mods["conceptgraph.slam.utils"].merge_obj2_into_obj1 = merge_obj2_into_obj1
    mods["conceptgraph.utils.general_utils"].ObjectClasses = ObjectClasses
    saved = {n: sys.modules.get(n) for n in names}
    sys.modules.update(mods)
    try:
        b = ConceptGraphsBackend("comod", print_summary=False)
        with b.patch():
            assert b.generation == "ali-dev" and not b.class_list_known
            ObjectClasses("classes.txt", bg_classes=["wall"], skip_bg=True)
            assert b.class_list_known and b.vocabulary.class_names == ("Chair", "Sofa")
            assert b.vocabulary_source == "ObjectClasses" and b.class_names == {0: "Chair", 1: "Sofa"}
        assert "__init__" in ObjectClasses.__dict__ and not getattr(ObjectClasses.__init__, "_sgbelief_replacement", 0)
    finally:
        for n, m in saved.items():
            if m is None:
                sys.modules.pop(n, None)
            else:
                sys.modules[n] = m


# ---------------------------------------------------------------- a channel cannot be silently off
def test_channel_labels_resolve_case_plural_space_and_underscore() -> None:
    b = ConceptGraphsBackend("comod", class_names=["office chair", "table", "sofa", "shelf"], print_summary=False)
    r = b.labels
    assert [r.resolve(x) for x in ("Office_Chairs", "office-chair", "TABLES", "shelves", "couch")] == \
        ["office chair", "office chair", "table", "shelf", "couch"]
    assert r.unmatched == {}


def test_unmatched_labels_are_warned_once_each_and_counted() -> None:
    b = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False)
    dets = [det("chair", k, label=["chair", "Car", "cars", "automobile"][k % 4]) for k in range(12)]
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        drive(b, dets)
    unmatched = [str(w.message) for w in rec if issubclass(w.category, UnmatchedLabelWarning)]
    assert len(unmatched) == 2 and any("'Car'" in m for m in unmatched) and any("'automobile'" in m for m in unmatched)
    s = b.summary()
    assert s.channel["unmatched"] == {"Car": 3, "cars": 3, "automobile": 3} and s.channel["matched"] == 3
    assert s.classes["chair"].claims == 12 and s.classes["chair"].verified == 3
    assert s.classes["chair"].unverifiable == 9
    assert "'Car' x3" in s.format()


def test_a_channel_that_matches_nothing_by_frame_20_raises() -> None:
    b = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False)
    with pytest.warns(UnmatchedLabelWarning):
        with pytest.raises(ChannelMismatchError, match="in 20 frames") as info:
            drive(b, [det("chair", k, label="Stuhl" if k % 2 else "Tisch") for k in range(25)])
    assert "'Stuhl'" in str(info.value) and "'Tisch'" in str(info.value) and "chair" in str(info.value)
    silent = ConceptGraphsBackend("comod", class_names=CLASSES, channel=lambda d, n, t: None, print_summary=False)
    with pytest.raises(ChannelMismatchError, match="gave no label in 20 frames"):
        drive(silent, [det("chair", k) for k in range(25)])
    ok = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnmatchedLabelWarning)
        drive(ok, [det("chair", k, label="chair" if k == 19 else "Stuhl") for k in range(25)])  # one match is enough
    majority = ConceptGraphsBackend("majority", class_names=CLASSES, channel=lambda d, n, t: None, print_summary=False)
    drive(majority, [det("chair", k) for k in range(25)])  # the operator never asks: nothing to check


def test_label_image_channel_checks_its_classes_against_the_vocabulary() -> None:
    vocab = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=False).vocabulary
    with pytest.warns(UnmatchedLabelWarning, match="'tablee'"):
        LabelImageChannel(classes=["unlabelled", "Chair", "tablee"], ignore_ids=[0], vocabulary=vocab)
    with pytest.raises(ChannelMismatchError, match="none of"):
        LabelImageChannel(classes=["Stuhl", "Tisch"], vocabulary=vocab)
    seg = LabelImageChannel(classes=["unlabelled", "Chairs", "TABLE"], ignore_ids=[0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ConceptGraphsBackend("comod", class_names=CLASSES, channel=seg, print_summary=False)  # all match
    with pytest.raises(ChannelMismatchError):  # the backend checks a channel's class list too
        ConceptGraphsBackend("comod", class_names=CLASSES, channel=LabelImageChannel(classes=["Stuhl"]))


# ---------------------------------------------------------------- the summary
def test_summary_counts_on_a_constructed_stream(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Object A: 6 tv claims the channel calls sofa (refused), 2 sofa claims (verified); object B: 4
    lamp claims, no label (unverifiable)."""
    b = ConceptGraphsBackend("comod", class_names=CLASSES, print_summary=sys.stdout)
    a = drive(b, [det("tv" if k < 6 else "sofa", k, label="sofa") for k in range(8)])
    f = b.functions("main")
    lamp = [det("lamp", 10 + k, seed=100) for k in range(4)]
    objects = f.merge_detections_to_objects(cfg(), DetectionList([lamp[0]]), a, torch.tensor([[float("-inf")]]))
    for d in lamp[1:]:
        objects = f.merge_detections_to_objects(cfg(), DetectionList([d]), objects, torch.tensor([[-1.0, 1.5]]))
    s = b.summary(objects)
    assert (s.objects, s.detections) == (2, 12)
    assert (s.classes["tv"].claims, s.classes["tv"].refused, s.classes["tv"].verified) == (6, 6, 0)
    assert (s.classes["sofa"].claims, s.classes["sofa"].verified) == (2, 2)
    assert (s.classes["lamp"].claims, s.classes["lamp"].unverifiable) == (4, 4)
    assert s.classes["tv"].committed == 1 and s.classes["tv"].differ == 1  # vote tv, label sofa
    assert [(d["vote"], d["label"]) for d in s.differing] == [("tv", "sofa")]
    assert s.classes["lamp"].committed + s.classes["lamp"].unknown == 1
    assert s.labelled + s.unknown == 2
    out = b.save(tmp_path / "beliefs.json")
    data = json.loads(summary_path(out).read_text())
    assert summary_path(out).name == "beliefs.summary.json"
    assert data["format"] == "sgbelief.cg_summary" and data["classes"]["tv"]["refused"] == 6
    b.uninstall()  # never installed: nothing restored, nothing printed
    assert capsys.readouterr().out == ""

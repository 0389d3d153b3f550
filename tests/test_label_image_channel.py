"""LabelImageChannel on constructed masks; the backend asks it per claim; mesh channel from a detection's points;
label rule; unknown objects in the summary; MappingTracker counters."""

from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np
import pytest

from sgbelief.fusion.channel import DetectionChannel, GeometricChannel, LabelImageChannel

CLASSES = ["unlabeled", "chair", "table", "sofa"]


def image() -> np.ndarray:
    img = np.zeros((40, 60), dtype=np.int32)
    img[0:20, 0:30] = 1  # chair
    img[0:20, 30:60] = 2  # table
    img[20:40, 0:60] = 3  # sofa
    return img


def box(r0: int, r1: int, c0: int, c1: int, shape: tuple[int, int] = (40, 60)) -> np.ndarray:
    m = np.zeros(shape, dtype=bool)
    m[r0:r1, c0:c1] = True
    return m


def test_majority_purity_and_min_pixels() -> None:
    ch = LabelImageChannel(classes=CLASSES, min_purity=0.6, min_pixels=20, ignore_ids=[0])
    ch.set_frame(3, image())
    assert isinstance(ch, GeometricChannel) and isinstance(ch, DetectionChannel)
    assert ch.label_mask(box(2, 10, 2, 20), 3) == "chair"
    assert ch.label_mask(box(10, 30, 5, 20), 3) is None  # half chair, half sofa: purity 0.5 < 0.6
    assert ch.label_mask(box(5, 21, 5, 20), 3) == "chair"  # 15/16 rows chair
    assert ch.label_mask(box(0, 2, 0, 5), 3) is None  # 10 pixels < min_pixels
    assert ch.label_mask(box(2, 10, 2, 20), 4) is None  # unseen frame
    assert ch.label("node", 3) is None  # no mask: no claim


def test_unlabelled_pixels_do_not_vote() -> None:
    img = image()
    img[0:20, 0:20] = 0
    ch = LabelImageChannel(classes=CLASSES, min_purity=0.9, min_pixels=10, ignore_ids=[0])
    ch.set_frame(0, img)
    assert ch.label_mask(box(0, 20, 10, 30), 0) == "chair"  # the unlabelled half abstains
    ch2 = LabelImageChannel(classes=CLASSES, min_purity=0.9, min_pixels=10, ignore_labels=["unlabeled"])
    ch2.set_frame(0, img)
    assert ch2.label_mask(box(0, 20, 10, 30), 0) == "chair"
    assert ch2.label_mask(box(0, 20, 0, 20), 0) is None  # nothing labelled under it


def test_instance_image_with_class_table_and_resized_mask() -> None:
    inst = np.zeros((40, 60), dtype=np.int32)
    inst[0:20, :] = 7
    inst[20:, :] = 9
    ch = LabelImageChannel(min_pixels=5)
    ch.set_frame(1, inst, {7: "armchair", 9: "sofa", 0: None})
    assert ch.label_mask(box(0, 10, 0, 30), 1) == "armchair"
    # a mask at twice the resolution of the label image
    assert ch.label_mask(box(50, 80, 0, 120, shape=(80, 120)), 1) == "sofa"
    with pytest.raises(ValueError, match="frame 2"):
        ch.set_frame(2, np.zeros((4, 4, 3)))


def test_frames_from_a_function_and_bounded_memory() -> None:
    calls = []

    def source(t: int):  # noqa: ANN202
        calls.append(t)
        return image() if t < 10 else None

    ch = LabelImageChannel(source, classes=CLASSES, keep_frames=2, min_pixels=5)
    for t in range(5):
        assert ch.label_mask(box(25, 35, 0, 10), t) == "sofa"
    assert len(ch._frames) == 2
    assert ch.label_mask(box(25, 35, 0, 10), 12) is None


def test_label_detection_reads_the_claims_mask_and_frame() -> None:
    ch = LabelImageChannel(classes=CLASSES, min_pixels=5)
    ch.set_frame(0, image())
    img1 = image()
    img1[:] = 2
    ch.set_frame(1, img1)
    det = {"mask": [box(2, 10, 2, 20), box(2, 10, 2, 20)], "image_idx": [0, 1]}
    assert ch.label_detection(det, 0, 99) == "chair"
    assert ch.label_detection(det, 1, 99) == "table"
    assert ch.label_detection(det, 5, 0) is None
    assert ch.label_detection({}, 0, 0) is None


# ---------------------------------------------------------------- through the backend
torch = pytest.importorskip("torch")
pytest.importorskip("open3d")

from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend  # noqa: E402
from sgbelief.adapters.conceptgraphs.standins import DetectionList, MapObjectList, make_detection  # noqa: E402


def cfg() -> SimpleNamespace:
    return SimpleNamespace(downsample_voxel_size=0.05, dbscan_remove_noise=False, dbscan_eps=0.1, dbscan_min_points=10,
                           spatial_sim_type="iou", device="cpu", merge_overlap_thresh=0.5, merge_visual_sim_thresh=0.5,
                           merge_text_sim_thresh=0.5, obj_min_points=1, obj_min_detections=1)


def stream(n: int = 30, names: tuple[str, str] = ("table", "chair")) -> list[dict]:
    """One chair, called `names[0]` more often (at lower confidence), every detection masking the chair's pixels."""
    feat = np.random.default_rng(7).normal(size=16)
    r = np.random.default_rng(1).random(n)
    out = []
    for k in range(n):
        wrong = k % 2 == 0 or k % 7 == 1
        name = names[0] if wrong else names[1]
        conf = 0.5 + 0.15 * r[k] if wrong else 0.8 + 0.15 * r[k]
        det = make_detection(0.2 * np.random.default_rng(k).random((100, 3)), CLASSES.index(name) if name in CLASSES
                             else 0, name, conf, k, feature=feat, seed=k)
        det["mask"] = [box(2, 10, 2, 20)]
        out.append(det)
    return out


def run(backend: ConceptGraphsBackend, dets: list[dict]) -> MapObjectList:
    f = backend.functions("main")
    objects = MapObjectList()
    for det in dets:
        if not objects:
            objects.append(det)
            continue
        objects = f.merge_detections_to_objects(cfg(), DetectionList([det]), objects, torch.tensor([[1.5]]))
    return objects


def test_backend_asks_the_label_image_channel_per_claim() -> None:
    ch = LabelImageChannel(lambda t: image(), classes=CLASSES, min_pixels=5)
    backend = ConceptGraphsBackend("comod", channel=ch, class_names=CLASSES)
    objects = run(backend, copy.deepcopy(stream()))
    assert len(objects) == 1
    assert backend.label_of(objects[0]) == "chair"
    s = backend.summary(objects)
    assert (s.objects, s.labelled, s.unknown) == (1, 1, 0)


def test_summary_counts_unknown_objects() -> None:
    backend = ConceptGraphsBackend("comod", class_names=CLASSES)
    det = make_detection(0.2 * np.random.default_rng(0).random((50, 3)), 3, "sofa", 0.5, 0)
    backend.ensure_node(det)
    s = backend.summary()
    assert s.unknown == 1 and s.labelled == 0 and s.objects == 1


def test_label_rule_for_predicates_covering_several_names() -> None:
    dets = []
    for k, name in enumerate(["desk", "desk", "table", "desk", "table"]):
        d = make_detection(0.2 * np.random.default_rng(k).random((60, 3)), 2, name, 0.9, k, seed=k)
        d["geometric_label"] = "table"
        dets.append(d)
    # table and desk are separate classes unless merged; merged, the committed predicate covers both
    # and the default rule writes the channel's own name (table), not the name detected most often
    for rule, want in [("most_frequent", "table"), ("first", "desk"), ({"is_table_or_desk": "table"}, "table")]:
        backend = ConceptGraphsBackend("comod", label_rule=rule, class_names=["chair", "desk", "table"],
                                       merge=["is_table_or_desk"])
        objects = run(backend, copy.deepcopy(dets))
        assert backend.committed_predicate(backend.node_of(objects[0])) == "is_table_or_desk"
        assert backend.label_of(objects[0]) == want, rule
    for d in dets:  # no channel label: the name detected most often
        d.pop("geometric_label")
    backend = ConceptGraphsBackend("comod", class_names=["chair", "desk", "table"], merge=True)
    assert backend.label_of(run(backend, copy.deepcopy(dets))[0]) == "desk"
    with pytest.raises(ValueError, match="label_rule"):
        ConceptGraphsBackend("comod", label_rule="vote")


def test_open_vocabulary_lets_geometry_contradict_an_unshipped_class() -> None:
    """The issue's case: a sofa the detector keeps calling `lamp` (a class outside the ScanNet table)."""
    from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary

    names = ["sofa", "lamp", "chair", "table"]
    dets = stream(45, ("lamp", "sofa"))
    for d in dets:
        d["geometric_label"] = "sofa"
    old = ConceptGraphsBackend("comod", vocabulary="scannet")  # the closed ScanNet table: is_lamp is unverified
    objs = run(old, copy.deepcopy(dets))
    assert "is_lamp" not in old.table
    new = ConceptGraphsBackend("comod", class_names=names)  # the default: the class list's own vocabulary
    objs = run(new, copy.deepcopy(dets))
    assert new.table.outcome("is_lamp", "sofa") == 0
    assert new.label_of(objs[0]) == "sofa"
    same = ConceptGraphsBackend("comod", vocabulary=ClassVocabulary.open_vocabulary(names))
    assert same.table.specs == new.table.specs
    b = new.beliefs(objs[0])
    assert b["is_lamp"].mean < b["is_sofa"].mean


def test_point_cloud_channel_labels_from_detection_points() -> None:
    from sgbelief.adapters.conceptgraphs.channels import PointCloudChannel

    class Points:
        def __init__(self) -> None:
            self.calls = 0

        def label_points(self, pts: np.ndarray) -> str | None:
            self.calls += 1
            return "chair" if pts[:, 0].mean() < 1 else "table"

    inner = Points()
    ch = PointCloudChannel(inner, max_points=10, map_to_mesh=np.diag([1.0, 1, 1, 1]))
    det = make_detection(0.2 * np.random.default_rng(0).random((100, 3)), 1, "table", 0.9, 0)
    assert ch.label_detection(det, 0, 0) == "chair"
    assert ch.label_detection(det, 0, 1) == "chair" and inner.calls == 1  # cached per cloud
    far = {"pcd_np": np.full((5, 3), 3.0)}
    assert ch.label_detection(far, 0, 0) == "table"
    with pytest.raises(TypeError):
        PointCloudChannel(object())


def test_merge_obj_matches_updates_the_mapping_tracker() -> None:
    from sgbelief.adapters.conceptgraphs.functions import make_functions

    class Tracker:
        curr_object_count = 0
        curr_frame_idx = 4

        def __init__(self) -> None:
            self.total_merges = 0
            self.total_objects = 0
            self.object_dict: dict = {}

        def increment_total_merges(self, n: int) -> None:
            self.total_merges += n

        def increment_total_objects(self, n: int) -> None:
            self.total_objects += n

    tracker = Tracker()
    backend = ConceptGraphsBackend("comod")
    f = make_functions(backend, "ali-dev", helpers={"tracker": tracker})
    dets = [make_detection(0.2 * np.random.default_rng(k).random((60, 3)) + 3 * k, 0, "chair", 0.8, 0,
                           mask_idx=k, generation="ali-dev", seed=k) for k in range(3)]
    objects = MapObjectList([dets[0]])
    objects = f.merge_obj_matches(DetectionList(dets[1:]), objects, [0, None], 0.05, False, 0.1, 10, "iou", "cpu")
    assert tracker.total_merges == 1
    assert tracker.total_objects == 2  # ConceptGraphs adds len(objects) - tracker.curr_object_count (here 0)
    assert tracker.object_dict["id"] == dets[2]["id"]

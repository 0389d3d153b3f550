"""The README's ConceptGraphs blocks run as written, inside a stand-in ConceptGraphs pipeline."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("open3d")

import cg_fake_conceptgraph as fake  # noqa: E402

from sgbelief.adapters.conceptgraphs.standins import DetectionList, make_detection  # noqa: E402

README = Path(__file__).resolve().parents[1] / "README.md"
H, W = 48, 64
SEGMENTER_CLASSES = ["unlabelled", "chair", "table", "sofa"]


def _section_blocks() -> list[str]:
    text = README.read_text()
    section = text[text.index("## Swapping it into ConceptGraphs"):]
    section = section[:section.index("\n## ", 1)]
    return re.findall(r"```python\n(.*?)```", section, flags=re.S)


def _cfg() -> Any:
    from types import SimpleNamespace

    return SimpleNamespace(downsample_voxel_size=0.05, dbscan_remove_noise=False, dbscan_eps=0.1,
                           dbscan_min_points=10, spatial_sim_type="iou", device="cpu")


def _segmenter(image_rgb: np.ndarray) -> np.ndarray:
    """A stand-in segmenter: a chair (id 1) in the image's left half, unlabelled elsewhere."""
    ids = np.zeros(image_rgb.shape[:2], dtype=np.int64)
    ids[:, : image_rgb.shape[1] // 2] = 1
    return ids


def _detection(class_id: int, frame: int, seed: int) -> dict:
    det = make_detection(0.2 * np.random.default_rng(seed).random((80, 3)), class_id, SEGMENTER_CLASSES[class_id],
                         0.9, frame, feature=np.ones(16), seed=seed)
    mask = np.zeros((H, W), dtype=bool)
    mask[10:40, 5:25] = True  # on the chair
    det["mask"] = [mask]
    return det


def test_install_without_conceptgraphs_raises_and_patches_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
    from sgbelief.adapters.conceptgraphs.backend import ConceptGraphsNotFoundError

    for name in list(sys.modules):
        if name == "conceptgraph" or name.startswith("conceptgraph."):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if not Path(p, "conceptgraph").is_dir()])
    backend = ConceptGraphsBackend("comod", print_summary=False)
    with pytest.raises(ConceptGraphsNotFoundError, match="conceptgraph.slam.utils") as info:
        backend.install()
    assert isinstance(info.value, ImportError)
    assert backend.generation is None and not backend.active
    backend.uninstall()  # nothing to undo


def test_readme_has_the_two_conceptgraphs_blocks() -> None:
    blocks = _section_blocks()
    assert len(blocks) == 2
    assert "backend.install()" in blocks[0] and "LabelImageChannel" in blocks[1]


def test_readme_three_line_change_patches_the_pipeline() -> None:
    mods = fake.install()
    ns: dict[str, Any] = {}
    try:
        exec(compile(_section_blocks()[0], "README.md", "exec"), ns)
        backend = ns["backend"]
        assert backend.generation == "main"
        pipe = mods["conceptgraph.slam.cfslam_pipeline_batch"]
        classes, _colours = pipe.create_or_load_colors(_cfg(), "gsa_classes_test")  # the script's first step
        assert backend.vocabulary.class_names == tuple(classes) == tuple(fake.CLASSES)
        assert backend.vocabulary_source == "create_or_load_colors"
        objects = pipe.MapObjectList(device="cpu")  # as the script calls it (kwargs accepted while patched)
        objects.append(_detection(2, 0, 0))
        objects = pipe.merge_detections_to_objects(_cfg(), DetectionList([_detection(2, 1, 1)]), objects,
                                                   torch.tensor([[1.5]]))
        assert backend.routed_detections == 2
    finally:
        if "backend" in ns:
            ns["backend"].uninstall()
        fake.uninstall()


def test_readme_label_image_block_connects_the_segmenter(capsys: pytest.CaptureFixture[str]) -> None:
    mods = fake.install()
    image_rgb = np.zeros((H, W, 3), dtype=np.uint8)
    # what the run script has in its frame loop: the frame index, the image, a segmenter
    ns: dict[str, Any] = {"SEGMENTER_CLASSES": SEGMENTER_CLASSES, "segmenter": _segmenter, "frame_idx": 0,
                          "image_rgb": image_rgb}
    try:
        exec(compile(_section_blocks()[1], "README.md", "exec"), ns)
        backend, seg = ns["backend"], ns["seg"]
        pipe = mods["conceptgraph.slam.cfslam_pipeline_batch"]
        pipe.create_or_load_colors(_cfg(), "gsa_classes_test")  # the run loads its class list
        objects = pipe.MapObjectList(device="cpu")
        objects.append(_detection(1, 0, 0))  # the first frame: the script appends its detections itself
        backend.keep_reports = True
        for frame in (1, 2):
            seg.set_frame(frame, _segmenter(image_rgb))  # the block's per-frame line
            # the detector calls the chair a table: the segmenter's chair contradicts it
            det = _detection(2, frame, frame)
            assert seg.label_detection(det, 0, frame) == "chair"
            objects = pipe.merge_detections_to_objects(_cfg(), DetectionList([det]), objects, torch.tensor([[1.5]]))
        verdicts = [o.verdict.symbol for r in backend.reports if r.predicate == "is_table" for o in r.targets]
        assert verdicts == ["⊥", "⊥"]
        assert backend.operator.stats["refused"] == 2
        assert [int(c) for c in objects.get_most_common_class()] == [1]  # the beliefs: chair
        s = backend.summary()
        assert (s.classes["table"].claims, s.classes["table"].refused) == (2, 2)
        assert s.classes["chair"].claims == 1 and s.channel["matched"] >= 2 and not s.channel["unmatched"]
        assert [(d["vote"], d["label"]) for d in s.differing] == [("table", "chair")] and s.labelled == 1
        assert s.classes["table"].differ == 1 and "table" in s.format()
        backend.uninstall()  # prints the summary (to stderr by default)
        err = capsys.readouterr().err
        assert "3 claims routed" in err and "labels that differ from the vote (ranking 1): cg-0: table -> chair" in err
    finally:
        if "backend" in ns:
            ns["backend"].uninstall()
        fake.uninstall()

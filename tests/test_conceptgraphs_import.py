"""`sgbelief import-cg`: restricted unpickling of saved ConceptGraphs maps and replay."""

from __future__ import annotations

import gzip
import json
import os
import pickle
import uuid
from pathlib import Path

import numpy as np
import pytest

from sgbelief.adapters.conceptgraphs.unpickler import UnsafePickleError, load_cg_result
from sgbelief.cli import main as cli_main


def saved_object(class_ids, confs, frames, *, ali_dev=False, seed=0):
    rng = np.random.default_rng(seed)
    n = len(class_ids)
    obj = {
        "image_idx": list(frames), "mask_idx": list(range(n)),
        "color_path": [Path(f"/data/frame{f:06d}.jpg") for f in frames],
        "class_id": list(class_ids), "num_detections": n,
        "mask": [np.ones((4, 4), dtype=bool)] * n, "xyxy": [np.array([0.0, 0, 2, 2])] * n,
        "conf": [np.float32(c) for c in confs], "contain_number": [None] * n,
        "inst_color": rng.random(3), "is_background": False,
        "clip_ft": rng.normal(size=8).astype(np.float32),
        "pcd_np": rng.random((50, 3)), "bbox_np": rng.random((8, 3)), "pcd_color_np": rng.random((50, 3)),
    }
    if ali_dev:
        obj.update({"id": uuid.uuid4(), "class_name": "chair", "captions": [None] * n, "n_points": 50,
                    "curr_obj_num": seed, "num_obj_in_class": 0, "new_counter": 0})
    else:
        obj.update({"class_name": [["chair", "table"][c] for c in class_ids], "n_points": [50] * n,
                    "pixel_area": [np.int64(16)] * n, "text_ft": rng.normal(size=8).astype(np.float32)})
    return obj


def write_map(path, ali_dev=False):
    results = {
        "objects": [saved_object([0, 0, 1, 0], [0.9, 0.8, 0.6, 0.85], [0, 1, 2, 3], ali_dev=ali_dev, seed=1),
                    saved_object([1, 1, 1], [0.9, 0.7, 0.8], [1, 2, 3], ali_dev=ali_dev, seed=2)],
        "bg_objects": None,
        "cfg": {"dataset_root": "/data", "spatial_sim_type": "overlap"},
        "class_names": ["chair", "table"],
        "class_colors": {"0": [1.0, 0.0, 0.0], "1": [0.0, 1.0, 0.0], "-1": [0, 0, 0]},
    }
    with gzip.open(path, "wb") as f:
        pickle.dump(results, f)
    return path


@pytest.mark.parametrize("ali_dev", [False, True])
def test_import_saved_map_replays_every_detection(tmp_path, capsys, ali_dev):
    src = write_map(tmp_path / "full_pcd_test.pkl.gz", ali_dev=ali_dev)
    out = tmp_path / "out"
    assert cli_main(["import-cg", str(src), "--operator", "majority", "--out", str(out)]) == 0
    labels = json.loads((out / "labels.json").read_text())
    assert set(labels) == {"cg-0", "cg-1"}
    assert labels["cg-0"]["majority"] == "chair" and labels["cg-1"]["majority"] == "table"
    assert labels["cg-0"]["num_detections"] == 4
    from sgbelief import SceneGraph

    g = SceneGraph.load(out / "graph.json")
    assert g.evidence_count() == 7  # 4 + 3 detections, each once
    assert g.probability("cg-1", "is_table") > 0.5  # the map's own class list: table is its own class
    summary = json.loads((out / "summary.json").read_text())
    assert summary["classes"]["table"]["claims"] == 4 and summary["classes"]["chair"]["claims"] == 3
    assert summary["vocabulary"] and summary["objects"] == 2
    assert "imported 2 objects, 7 detections" in capsys.readouterr().out


def test_omegaconf_cfg_is_allowed(tmp_path):
    omegaconf = pytest.importorskip("omegaconf")
    path = tmp_path / "m.pkl.gz"
    with gzip.open(path, "wb") as f:
        pickle.dump({"objects": [], "cfg": omegaconf.OmegaConf.create({"a": 1, "b": [1, 2]})}, f)
    assert load_cg_result(path)["cfg"]["a"] == 1


class _Hostile:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_hostile_pickle_is_refused_and_nothing_runs(tmp_path, capsys):
    marker = tmp_path / "pwned"
    path = tmp_path / "evil.pkl.gz"
    with gzip.open(path, "wb") as f:
        pickle.dump({"objects": [_Hostile(marker)], "class_names": []}, f)
    with pytest.raises(UnsafePickleError, match="refusing to load global '(posix|os|nt).system'"):
        load_cg_result(path)
    assert cli_main(["import-cg", str(path), "--out", str(tmp_path / "o")]) == 1
    assert "refusing to load global" in capsys.readouterr().err
    assert not marker.exists()


@pytest.mark.parametrize("target", ["builtins.eval", "subprocess.Popen", "torch._utils._rebuild_tensor_v2"])
def test_other_globals_refused(tmp_path, target):
    module, name = target.rsplit(".", 1)
    data = b"\x80\x04c" + module.encode() + b"\n" + name.encode() + b"\n."
    from sgbelief.adapters.conceptgraphs.unpickler import restricted_loads

    with pytest.raises(UnsafePickleError):
        restricted_loads(data)


def test_import_with_a_confidence_map_reads_scores_as_probabilities(tmp_path, capsys):
    """--confidence-map: a ScoreCalibration saved with to_dict() maps each detection's score before
    it enters the event. A map sending every score to 0.9 commits both objects' classes that the raw
    scores leave below (scores 0.3-0.45 are evidence against, sgbelief's reading); a file that is not a
    calibration is refused, naming the file and the field."""
    from sgbelief.calibration.scores import ScoreCalibration

    results = {"objects": [saved_object([0, 0, 0], [0.3, 0.4, 0.45], [0, 1, 2], seed=1),
                           saved_object([1, 1], [0.35, 0.4], [1, 2], seed=2)],
               "bg_objects": None, "cfg": {}, "class_names": ["chair", "table"]}
    src = tmp_path / "full_pcd_low.pkl.gz"
    with gzip.open(src, "wb") as f:
        pickle.dump(results, f)
    cal = ScoreCalibration(scores=(0.0, 1.0), probabilities=(0.9, 0.9), n=100)
    (tmp_path / "map.json").write_text(json.dumps(cal.to_dict()))
    for name, extra in (("raw", []), ("mapped", ["--confidence-map", str(tmp_path / "map.json")])):
        assert cli_main(["import-cg", str(src), "--out", str(tmp_path / name), *extra]) == 0
    raw = json.loads((tmp_path / "raw" / "labels.json").read_text())
    mapped = json.loads((tmp_path / "mapped" / "labels.json").read_text())
    assert [raw[k]["belief"] for k in ("cg-0", "cg-1")] == ["unknown", "unknown"]
    assert [mapped[k]["belief"] for k in ("cg-0", "cg-1")] == ["chair", "table"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**cal.to_dict(), "scores": [1.0, 0.0]}))
    capsys.readouterr()
    assert cli_main(["import-cg", str(src), "--out", str(tmp_path / "x"), "--confidence-map", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "--confidence-map" in err and "bad.json" in err and "strictly ascending" in err

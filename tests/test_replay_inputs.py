"""`sgbelief replay` is honest about mismatched inputs: a truth or nodes file of another map is an
error, a partial one a warning with counts, a class with no positives is n/a (not IoU 1.0) and left
out of mIoU, and a missing file or an unknown vocabulary name gets one clear line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief.errors import InputMismatchWarning

TRUTH = {"s/car": {"is_car": 1, "is_pedestrian": 0, "is_bicycle": 0},
         "s/ped": {"is_car": 0, "is_pedestrian": 1, "is_bicycle": 0}}


def _log(d: Path) -> Path:
    lines = [json.dumps({"format": "sgbelief.events", "version": 1})]
    t = 0
    for k in range(20):
        for node, label, pred, c in (("s/car", "car", "is_car", 0.8), ("s/ped", "person", "is_pedestrian", 0.7),
                                     ("s/car", "car", "is_bicycle", 0.6)):
            lines.append(json.dumps({"t": t, "targets": {node: 1.0}, "predicate": pred, "confidence": c,
                                     "context": "vlm", "geometric": {node: label}}))
            t += 1
    (d / "events.jsonl").write_text("\n".join(lines) + "\n")
    return d / "events.jsonl"


def _truth(d: Path, truth: dict, name: str = "truth.json") -> Path:
    (d / name).write_text(json.dumps(truth))
    return d / name


def _replay(*args: str) -> int:
    return main(["replay", *args, "--vocab", "kitti360", "--operators", "majority,comod", "--no-progress"])


def test_a_truth_file_of_another_map_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ev = _log(tmp_path)
    other = _truth(tmp_path, {"scene0000_00/0001": {"is_car": 1}, "scene0000_00/0002": {"is_car": 0}}, "other.json")
    assert _replay(str(ev), "--truth", str(other), "--json", str(tmp_path / "m.json")) == 1
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "other.json" in err and "shares no node with the evidence log" in err and "s/car" in err
    assert not (tmp_path / "m.json").exists() and "mIoU" not in out


def test_a_partial_truth_warns_with_counts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ev = _log(tmp_path)
    part = _truth(tmp_path, {"s/car": TRUTH["s/car"], "elsewhere/1": {"is_car": 1}})
    assert _replay(str(ev), "--truth", str(part)) == 0
    out, err = capsys.readouterr()
    warned = [line for line in err.splitlines() if "warning" in line]
    assert len(warned) == 1 and "truth.json: 1 of the 2 nodes with evidence in" in warned[0]
    assert "are not in this truth file (e.g. s/ped); they are not scored" in warned[0]
    assert "truth: 1 of the 2 nodes of" in out and "the other 1 stay at the prior" in out


def test_a_class_with_no_positives_is_na_and_out_of_the_mean(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    ev = _log(tmp_path)
    truth = _truth(tmp_path, TRUTH)
    out_json = tmp_path / "m.json"
    assert _replay(str(ev), "--truth", str(truth), "--json", str(out_json)) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line for line in out.splitlines() if line.startswith(("majority", "comod"))}
    assert rows["comod"].split()[3] == "n/a/n/a/n/a"  # was 1.000/1.000/1.000, lifting the mean
    assert rows["majority"].split()[3] == "n/a/0.000/n/a"  # committed on a class nobody is: precision 0
    assert "n/a: is_bicycle has no positives in the truth file" in out
    assert "mIoU: unweighted mean IoU over these 2 predicates (is_car, is_pedestrian)" in out
    doc = json.loads(out_json.read_text())
    per = doc["comod"]["per_predicate"]
    assert math.isnan(per["is_bicycle"]["iou"])
    assert doc["comod"]["mean_iou"] == pytest.approx((per["is_car"]["iou"] + per["is_pedestrian"]["iou"]) / 2)


def test_a_nodes_file_of_another_map_is_an_error_and_a_partial_one_warns(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from sgbelief.eval.formats import read_nodes

    ev = _log(tmp_path)
    truth = _truth(tmp_path, TRUTH)
    box = {"scene": "s", "label": "car", "centroid": [0.5, 0.5, 0.5], "bbox_min": [0, 0, 0], "bbox_max": [1, 1, 1]}
    other = tmp_path / "other_nodes.json"
    other.write_text(json.dumps({"format": "sgbelief.nodes", "version": 1, "nodes": {"x/1": box}}))
    read_nodes(other)  # a valid nodes file: only the ids are wrong
    assert _replay(str(ev), "--truth", str(truth), "--nodes", str(other), "--save-graph", str(tmp_path / "g")) == 1
    err = capsys.readouterr().err
    assert "other_nodes.json" in err and "nodes file shares no node" in err
    assert not (tmp_path / "g").exists()
    part = tmp_path / "part_nodes.json"
    part.write_text(json.dumps({"format": "sgbelief.nodes", "version": 1, "nodes": {"s/car": box}}))
    assert _replay(str(ev), "--truth", str(truth), "--nodes", str(part), "--save-graph", str(tmp_path / "g")) == 0
    err = capsys.readouterr().err
    assert "part_nodes.json: 1 of the 2 nodes with evidence in" in err and "not in this nodes file (e.g. s/ped)" in err
    assert (tmp_path / "g" / "comod").is_dir()


def test_the_coverage_check_from_python() -> None:
    from sgbelief.errors import FormatError
    from sgbelief.eval.replay import check_coverage

    with pytest.raises(FormatError, match="t.json: truth file shares no node"):
        check_coverage("truth file", {"a": 1}, {"b", "c"}, path="t.json", log="e.jsonl", missing_means="-")
    with pytest.warns(InputMismatchWarning, match="1 of the 2 nodes with evidence in e.jsonl"):
        assert check_coverage("truth file", {"b": 1}, {"b", "c"}, path="t.json", log="e.jsonl", missing_means="-") == 1


def test_a_missing_events_file_is_one_line_naming_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth = _truth(tmp_path, TRUTH)
    assert _replay(str(tmp_path / "nope.jsonl"), "--truth", str(truth)) == 1
    err = capsys.readouterr().err
    assert err == f"sgbelief replay: error: {tmp_path / 'nope.jsonl'}: no such file or directory\n"


def test_an_unknown_vocabulary_name_lists_the_shipped_ones(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ev = _log(tmp_path)
    truth = _truth(tmp_path, TRUTH)
    assert main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown vocabulary 'kitti'" in err and "kitti360, scannet" in err

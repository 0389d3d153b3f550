"""`sgbelief replay` end to end: table, JSON, saved graphs, bad lines with line numbers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief.graph.scene_graph import SceneGraph


def _write_stream(d: Path, bad_line: str | None = None) -> tuple[Path, Path]:
    lines = [json.dumps({"format": "sgbelief.events", "version": 1})]
    truth = {"s/car": {"is_car": 1, "is_pedestrian": 0}, "s/ped": {"is_car": 0, "is_pedestrian": 1}}
    t = 0
    for k in range(40):
        for node, label, pred, c in (("s/car", "car", "is_car", 0.8), ("s/ped", "person", "is_pedestrian", 0.7),
                                     ("s/car", "car", "is_pedestrian", 0.9)):  # the last one: contradicted
            lines.append(json.dumps({"t": t, "targets": {node: 1.0}, "predicate": pred, "confidence": c - 0.01 * (k % 7),
                                     "context": "vlm", "geometric": {node: label}}))
            t += 1
    if bad_line is not None:
        lines.insert(5, bad_line)
    (d / "events.jsonl").write_text("\n".join(lines) + "\n")
    (d / "truth.json").write_text(json.dumps(truth))
    return d / "events.jsonl", d / "truth.json"


def test_replay_writes_table_json_and_graphs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ev, truth = _write_stream(tmp_path)
    out = tmp_path / "m.json"
    rc = main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--json", str(out),
               "--save-graph", str(tmp_path / "graphs"), "--no-progress"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "comod" in text and "majority" in text and "120 events" in text
    doc = json.loads(out.read_text())
    assert set(doc) == {"overwrite", "majority", "naive_bayes", "refined", "cal", "comod"}
    for op, d in doc.items():
        assert set(d["per_predicate"]) == {"is_car", "is_pedestrian"}
        assert {"mean_iou", "brier", "refusals", "quarantined", "released", "events_per_s"} <= set(d)
    assert doc["comod"]["refusals"] == 40 and doc["cal"]["refusals"] == 0  # one ⊥ per contradicted claim
    g = SceneGraph.load(tmp_path / "graphs" / "comod")
    assert g.probability("s/car", "is_pedestrian") == 0.5  # every contradicted claim refused


def test_bad_line_stops_without_partial_results(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = json.dumps({"t": 3, "targets": {"s/car": 1.0}, "predicate": "is_car", "confidence": 1.7, "context": "vlm", "geometric": {}})
    ev, truth = _write_stream(tmp_path, bad)
    out = tmp_path / "m.json"
    rc = main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--json", str(out), "--no-progress"])
    assert rc == 1
    err = capsys.readouterr().err
    assert "events.jsonl:6" in err and "confidence" in err
    assert not out.exists()
    rc = main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--json", str(out),
               "--skip-bad-lines", "--no-progress"])
    assert rc == 0 and json.loads(out.read_text())["comod"]["skipped_lines"] == 1


def test_unknown_predicate_is_reported_with_its_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = json.dumps({"t": 3, "targets": {"s/car": 1.0}, "predicate": "is_carr", "confidence": 0.7, "context": "vlm", "geometric": {}})
    ev, truth = _write_stream(tmp_path, bad)
    assert main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert ":6" in err and "is_carr" in err and "is_car" in err


def test_several_scenes_with_workers_save_binary_graphs(tmp_path: Path) -> None:
    scenes = []
    for name in ("scene_a", "scene_b"):
        d = tmp_path / name
        d.mkdir()
        scenes.append(_write_stream(d))
    truth = tmp_path / "truth.json"
    truth.write_text(scenes[0][1].read_text())
    rc = main(["replay", str(scenes[0][0]), str(scenes[1][0]), "--truth", str(truth), "--vocab", "kitti360",
               "--operators", "majority,comod", "--workers", "2", "--save-graph", str(tmp_path / "g"),
               "--graph-format", "npz", "--no-progress"])
    assert rc == 0
    for name in ("scene_a", "scene_b"):
        g = SceneGraph.load(tmp_path / "g" / "comod" / name)
        assert (tmp_path / "g" / "comod" / name / "graph.npz").exists()
        assert g.probability("s/car", "is_pedestrian") == 0.5

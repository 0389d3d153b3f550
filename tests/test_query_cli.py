from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief import SceneGraph


@pytest.fixture
def saved_map(tmp_path: Path) -> Path:
    g = SceneGraph()
    g.add_node("c", bbox=((0.3, 0.8, 0), (0.8, 1.3, 0.95)), label="chair", scene="r")
    g.add_node("w", bbox=((1.6, -0.5, 0.9), (1.7, 1.0, 2.0)), label="window", scene="r")
    g.add_node("far", bbox=((-2.8, 2.0, 0), (-2.3, 2.5, 0.9)), label="chair", scene="r")
    g.provenance.record("c", "is_chair", "e1", 0, 3.0, 0.0)  # Beta(4, 1) -> 0.8
    g.provenance.record("far", "is_chair", "e2", 0, 8.0, 0.0)  # 0.9, but not near a window
    out = tmp_path / "map"
    g.save(out)
    return out


def test_query_cli_table_and_json(saved_map, capsys):
    assert main(["query", str(saved_map), "is_chair & is_near_window"]) == 0
    out = capsys.readouterr().out
    assert "c" in out and "0.8000" in out and "far" not in out.split("\n", 2)[2]
    assert main(["query", str(saved_map), "chair near window", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["query"] == "chair_near_window"
    assert [r["node"] for r in doc["results"]] == ["c"]
    assert doc["results"][0]["components"][1] == {"predicate": "is_near_window", "kind": "geometric",
                                                  "negated": False, "value": True, "factor": 1.0, "evidence": True}
    assert main(["query", str(saved_map), "is_chair", "--tau", "0.85", "--json"]) == 0
    assert [r["node"] for r in json.loads(capsys.readouterr().out)["results"]] == ["far"]


def test_query_cli_errors(saved_map, capsys):
    assert main(["query", str(saved_map), "is_chair & & is_near_window"]) == 1
    err = capsys.readouterr().err
    assert "position 11" in err and "^" in err
    assert main(["query", str(saved_map), "is_chiar"]) == 1
    assert "known predicates" in capsys.readouterr().err
    assert main(["query", str(saved_map / "missing"), "is_chair"]) == 1


def test_retrieval_cli_on_scannet_folders(tmp_path, capsys):
    pytest.importorskip("open3d")
    from sgbelief.adapters.scannet import LABELS_TSV, write_label_map, write_scene_files
    from sgbelief.eval.formats import write_events

    write_label_map(tmp_path / LABELS_TSV)
    write_scene_files(tmp_path / "scene0001_00", "scene0001_00", [
        ("floor", (-3, -3, -0.01), (3, 3, 0.0)),
        ("office chair", (0.3, 0.8, 0), (0.8, 1.3, 0.95)),  # 1: near the window
        ("window", (1.6, -0.5, 0.9), (1.7, 1.0, 2.0)),
        ("chair", (-2.8, 2.0, 0), (-2.3, 2.5, 0.9)),  # 3: far from the window
        ("desk", (-2.5, -2.5, 0), (-1.5, -1.9, 0.75)),  # 4: unobstructed workspace
    ])
    events = []
    for t in range(6):
        for node, pred, conf in [("scene0001_00/1", "is_chair", 0.9), ("scene0001_00/3", "is_chair", 0.9),
                                 ("scene0001_00/4", "is_table_or_desk", 0.85), ("scene0001_00/4", "is_chair", 0.3)]:
            events.append({"t": t, "targets": {node: 1.0}, "predicate": pred, "confidence": conf,
                           "context": "vlm", "geometric": {node: None}})
    write_events(tmp_path / "events.jsonl", events)
    rc = main(["retrieval", "--scenes", str(tmp_path), "--events", str(tmp_path / "events.jsonl"),
               "--vocab", "scannet", "--operators", "naive_bayes,overwrite", "--json"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    rows = {(s["query"], s["operator"]): s for s in report[0]["scores"]}
    cnw = rows[("chair_near_window", "naive_bayes")]
    assert (cnw["n"], cnw["positives"]) == (3, 1)  # pool: nodes asked is_chair
    assert cnw["f1"] == pytest.approx(1.0)
    uws = rows[("unobstructed_workspace_surface", "naive_bayes")]
    assert (uws["n"], uws["positives"], uws["f1"]) == (1, 1, pytest.approx(1.0))
    assert rows[("accessible_bookshelf", "overwrite")]["n"] == 0
    # text table
    rc = main(["retrieval", "--scenes", str(tmp_path), "--events", str(tmp_path / "events.jsonl"),
               "--operators", "naive_bayes"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "chair near window" in out and "naive_bayes" in out


def test_retrieval_cli_on_simulated_suite(tmp_path, capsys):
    from sgbelief.eval.formats import write_events, write_nodes, write_truth

    nodes = {
        "d/1": {"scene": "d", "label": "car", "centroid": (0, 0, 0), "bbox_min": (0, 0, 0), "bbox_max": (4, 2, 1.5),
                "track": [[0, 0, 0, 0], [1, 0.1, 0, 0]], "attributes": {"road_distance_px": 5.0}},
        "d/2": {"scene": "d", "label": "car", "centroid": (50, 0, 0), "bbox_min": (50, 0, 0),
                "bbox_max": (54, 2, 1.5), "track": [[0, 50, 0, 0], [1, 60, 0, 0]],
                "attributes": {"road_distance_px": 0.0},
                "geometric_predicates": {"is_at_intersection": True}},
    }
    write_nodes(tmp_path / "nodes.json", {"suite": "t", "nodes": nodes})
    write_truth(tmp_path / "truth.json", {"d/1": {"is_car": 1}, "d/2": {"is_car": 1}})
    write_events(tmp_path / "events.jsonl", [
        {"t": t, "targets": {n: 1.0}, "predicate": "is_car", "confidence": 0.9, "context": "vlm",
         "geometric": {n: "car"}} for t in range(4) for n in ("d/1", "d/2")])
    rc = main(["retrieval", "--suite", str(tmp_path), "--vocab", "kitti360", "--operators", "naive_bayes", "--json"])
    assert rc == 0
    rows = {s["query"]: s for s in json.loads(capsys.readouterr().out)[0]["scores"]}
    assert (rows["parked_car_near_crossing"]["n"], rows["parked_car_near_crossing"]["positives"]) == (2, 1)
    assert rows["parked_car_near_crossing"]["f1"] == pytest.approx(1.0)
    assert rows["moving_car_in_traffic"]["positives"] == 1
    assert rows["car_at_intersection"]["positives"] == 1  # precomputed geometric value; d/1 undecidable

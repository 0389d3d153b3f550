"""`sgbelief replay` end to end: table, JSON, saved graphs, bad lines with line numbers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief import SceneGraph


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
    # every contradicted claim refused; the 40 'car' labels are 40 observations of "not a pedestrian"
    assert g.probability("s/car", "is_pedestrian") < 0.05
    assert all(e.status.value != "committed" or e.d_alpha == 0.0 for e in g.provenance.entries("s/car", "is_pedestrian"))


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
        assert g.probability("s/car", "is_pedestrian") < 0.05  # refused; the car labels say otherwise


def _replay_json(tmp_path: Path, ev: Path, truth: Path, engine: str, tag: str, *extra: str) -> dict:
    out = tmp_path / f"{tag}.json"
    rc = main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--json", str(out), "--no-progress",
               "--engine", engine, "--save-graph", str(tmp_path / f"g_{tag}"), *extra])
    assert rc == 0
    doc = json.loads(out.read_text())
    for d in doc.values():
        d.pop("events_per_s")
    return doc


@pytest.mark.parametrize("engine", ["batched", "auto"])
def test_batched_engine_gives_the_streaming_results(tmp_path: Path, engine: str) -> None:
    from sgbelief.testing import provenance_signature

    bad = json.dumps({"t": 3, "targets": {"s/car": 1.0}, "predicate": "is_car", "confidence": 1.7, "context": "vlm", "geometric": {}})
    ev, truth = _write_stream(tmp_path, bad)  # a skipped line: default ids follow the file's line numbers
    config = tmp_path / "ops.yaml"
    config.write_text("t_prov: 9\n")  # several compactions inside the stream
    extra = ("--skip-bad-lines", "--config", str(config))
    streamed = _replay_json(tmp_path, ev, truth, "streaming", "s", *extra)
    waved = _replay_json(tmp_path, ev, truth, engine, "b", *extra)
    assert waved == streamed
    assert streamed["majority"]["stats"]["compacted"] > 0
    for name in ("majority", "naive_bayes", "overwrite", "comod"):
        a = SceneGraph.load(tmp_path / "g_s" / name)
        b = SceneGraph.load(tmp_path / "g_b" / name)
        assert provenance_signature(a) == provenance_signature(b)


def test_batched_engine_needs_ordered_times_and_names_the_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    back = json.dumps({"t": 1, "targets": {"s/car": 1.0}, "predicate": "is_car", "confidence": 0.7, "context": "vlm", "geometric": {}})
    ev, truth = _write_stream(tmp_path)
    lines = ev.read_text().splitlines()
    lines.insert(20, back)  # line 21 goes back in time
    ev.write_text("\n".join(lines) + "\n")
    args = ["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--no-progress", "--operators", "majority"]
    assert main([*args, "--engine", "batched"]) == 1
    err = capsys.readouterr().err
    assert "events.jsonl:21" in err and "must not decrease" in err
    assert main([*args, "--engine", "auto"]) == 1  # one rule for every engine: rejected too
    assert "events.jsonl:21" in capsys.readouterr().err
    bad = json.dumps({"t": 3, "targets": {"s/car": 1.0}, "predicate": "is_carr", "confidence": 0.7, "context": "vlm", "geometric": {}})
    (tmp_path / "unknown").mkdir()
    ev2, _ = _write_stream(tmp_path / "unknown", bad)
    assert main(["replay", str(ev2), "--truth", str(truth), "--vocab", "kitti360", "--no-progress", "--engine", "batched"]) == 1
    err = capsys.readouterr().err
    assert ":6" in err and "is_carr" in err


def test_which_runs_the_batched_engine_takes(monkeypatch: pytest.MonkeyPatch) -> None:
    import sgbelief._fast.batched as batched
    from sgbelief.eval.formats import EventRecord
    from sgbelief.eval.replay import _batchable, make_runs, replay
    from sgbelief.fusion.compatibility import SubsumptionTable

    runs = make_runs(["majority", "naive_bayes", "overwrite", "refined", "cal", "comod"], SubsumptionTable.shipped("kitti360"))
    assert [_batchable(r) for r in runs] == [True, True, True, False, False, False]
    seen = []
    real = batched.batched_replay
    monkeypatch.setattr(batched, "batched_replay", lambda cols, op, *a, **k: seen.append(op.name) or real(cols, op, *a, **k))
    recs = [EventRecord(t, {"v": 1.0}, "is_car", 0.8, "vlm", {"v": "car"}) for t in range(30)]
    replay(recs, runs, engine="batched")
    assert seen == ["majority", "naive_bayes", "overwrite"]
    assert all(r.events == 30 for r in runs) and runs[0].operator.stats["committed"] == 30
    assert not _batchable(runs[0])  # its graph is no longer empty


@pytest.mark.parametrize("engine", ["streaming", "batched", "auto"])
def test_event_times_going_back_are_rejected_by_every_engine(tmp_path: Path, engine: str,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """One rule for both engines (issue: the streaming engine used to accept it): t never decreases."""
    lines = [json.dumps({"t": t, "targets": {"s/car": 1.0}, "predicate": "is_car", "confidence": 0.8,
                         "context": "vlm", "geometric": {"s/car": "car"}}) for t in (0, 1, 5, 3, 6)]
    ev = tmp_path / "events.jsonl"
    ev.write_text("\n".join(lines) + "\n")
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"s/car": {"is_car": 1}}))
    rc = main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--engine", engine, "--no-progress"])
    assert rc != 0
    err = capsys.readouterr().err
    assert "events.jsonl:4" in err and "t goes back from 5 to 3" in err, err


def test_replay_says_which_predicates_its_miou_averages(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One meaning per number: replay names the predicates behind mIoU, and --predicates picks them."""
    ev, truth = _write_stream(tmp_path)
    base = ["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--no-progress", "--operators", "majority"]
    assert main(base) == 0
    assert "mean IoU over these 2 predicates (is_car, is_pedestrian)" in capsys.readouterr().out
    out = tmp_path / "one.json"
    assert main([*base, "--predicates", "is_car", "--json", str(out)]) == 0
    assert "over these 1 predicates (is_car)" in capsys.readouterr().out
    assert set(json.loads(out.read_text())["majority"]["per_predicate"]) == {"is_car"}
    assert main([*base, "--predicates", "is_unicorn"]) != 0
    assert "not in the truth file" in capsys.readouterr().err


def test_saved_graphs_carry_the_nodes_geometry(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A log with a nodes.json beside it: the saved maps have boxes and attributes (not {}), so
    geometric queries on them work; without one, replay says so."""
    from sgbelief.eval.formats import write_events, write_nodes, write_truth

    nodes = {"d/1": {"scene": "d", "label": "car", "centroid": (0, 0, 0), "bbox_min": (-2, -1, 0),
                     "bbox_max": (2, 1, 1.5), "attributes": {"road_distance_px": 5.0}},
             "d/2": {"scene": "d", "label": "building", "centroid": (30, 0, 0), "bbox_min": (25, -5, 0),
                     "bbox_max": (35, 5, 10)}}
    write_nodes(tmp_path / "nodes.json", {"suite": "t", "nodes": nodes})
    write_truth(tmp_path / "truth.json", {"d/1": {"is_car": 1}, "d/2": {"is_car": 0}})
    write_events(tmp_path / "events.jsonl", [
        {"t": t, "targets": {"d/1": 1.0}, "predicate": "is_car", "confidence": 0.9, "context": "vlm",
         "geometric": {"d/1": "car"}} for t in range(4)])
    args = ["replay", str(tmp_path / "events.jsonl"), "--truth", str(tmp_path / "truth.json"), "--vocab", "kitti360",
            "--operators", "comod", "--no-progress", "--save-graph", str(tmp_path / "maps")]
    assert main(args) == 0
    g = SceneGraph.load(tmp_path / "maps" / "comod")
    assert set(g.nodes()) == {"d/1", "d/2"}  # every element of the map, claimed or not
    assert g.node_attrs("d/1")["bbox"] == ((-2.0, -1.0, 0.0), (2.0, 1.0, 1.5))
    assert g.node_attrs("d/1")["attributes"] == {"road_distance_px": 5.0}
    (tmp_path / "nodes.json").unlink()
    capsys.readouterr()
    assert main(args) == 0
    assert "carry no geometry" in capsys.readouterr().err

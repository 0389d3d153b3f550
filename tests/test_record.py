"""``sgbelief record`` and sgbelief.viz.rerun_log: recordings written, then read back with rerun's
own reader (``rerun.chunk.RrdReader``); skipped where rerun-sdk (``sgbelief[rerun]``) is missing,
except the test of the message a user gets without it."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from sgbelief.cli import main
from sgbelief.graph.persistence import load_graph
from test_viz_map import ROUNDS, _cg_object, write_scene


def _read(path: Path) -> dict[str, list]:
    """entity path -> the record batches of its chunks (rerun's reader)."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        out.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return out


def _column(batches: list, name: str) -> list:
    vals: list = []
    for rb in batches:
        if name in rb.schema.names:
            vals += rb.column(name).to_pylist()
    return vals


def _texts(batches: list) -> list[str]:
    """The lines of a TextLog entity (one list per row)."""
    return [t for row in _column(batches, "TextLog:text") if row for t in row]


def _scalars(batches: list) -> list[tuple[int, float]]:
    """(t, value) of a Scalars entity, in time order."""
    rows = []
    for rb in batches:
        if "Scalars:scalars" in rb.schema.names:
            rows += [(t, v[0]) for t, v in zip(rb.column("t").to_pylist(), rb.column("Scalars:scalars").to_pylist())
                     if v is not None]
    return sorted(rows)


def test_record_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rerun")
    ev, truth = write_scene(tmp_path)
    out = tmp_path / "map.rrd"
    assert main(["record", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--operator", "comod",
                 "--out", str(out), "--save-graph", str(tmp_path / "graph"), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert f"{3 * ROUNDS} events replayed" in text and f"wrote {out}" in text and "40 refused claims" in text
    assert "comod" in text and "IoU/P/R" in text  # --truth: the replay's score table
    assert not list(tmp_path.glob(".map.rrd*"))  # the temporary file is gone
    ents = _read(out)
    objects = {p for p in ents if p.startswith("/sgbelief/map/objects/")}
    assert objects == {"/sgbelief/map/objects/s/car", "/sgbelief/map/objects/s/ped"}  # s/tree: no claim, no box
    beliefs = {p for p in ents if p.startswith("/sgbelief/beliefs/")}
    assert beliefs == {"/sgbelief/beliefs/s/car/is_car", "/sgbelief/beliefs/s/car/is_pedestrian",
                       "/sgbelief/beliefs/s/ped/is_pedestrian"}
    # one point per time step that touched the pair: here one claim per step
    series = _scalars(ents["/sgbelief/beliefs/s/car/is_car"])
    assert len(series) == ROUNDS and [t for t, _ in series] == [3 * k for k in range(ROUNDS)]
    g = load_graph(tmp_path / "graph")
    assert series[-1][1] == pytest.approx(g.probability("s/car", "is_car"))
    # the box label carries the committed predicate and its probability
    labels = _column(ents["/sgbelief/map/objects/s/car"], "Boxes3D:labels")
    assert labels[-1] == [f"car {g.probability('s/car', 'is_car'):.2f}"]
    # every refused claim is an event, and the car carries the refused-site marker with the count
    logs = [t for t in _texts(ents["/sgbelief/events"]) if t.startswith("⊥ refused")]
    assert len(logs) == ROUNDS and all("s/car is_pedestrian" in t and "verdict ⊥" in t for t in logs)
    assert _column(ents["/sgbelief/map/refused/s/car"], "Points3D:labels")[-1] == [f"⊥ ×{ROUNDS}"]
    assert "/sgbelief/map/ego_trajectory" in ents and "/sgbelief/map/ego" in ents


def test_record_without_nodes_file_logs_beliefs_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rerun")
    ev, _ = write_scene(tmp_path, with_nodes=False)
    out = tmp_path / "m.rrd"
    assert main(["record", str(ev), "--vocab", "kitti360", "--operator", "cal", "--out", str(out), "--no-progress"]) == 0
    assert "no nodes.json" in capsys.readouterr().err
    ents = _read(out)
    assert not any(p.startswith("/sgbelief/map/objects/") for p in ents)
    assert len(_scalars(ents["/sgbelief/beliefs/s/ped/is_pedestrian"])) == ROUNDS
    assert "/sgbelief/events" not in ents or not any(
        t.startswith("⊥") for t in _texts(ents["/sgbelief/events"]))  # cal refuses nothing


def test_record_bad_line_names_the_line_and_leaves_no_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("rerun")
    ev, _ = write_scene(tmp_path)
    lines = ev.read_text().splitlines()
    lines.insert(4, json.dumps({"t": 1, "targets": {"s/car": 1.0}, "predicate": "is_car", "confidence": 3.0,
                                "context": "vlm", "geometric": {}}))
    ev.write_text("\n".join(lines) + "\n")
    out = tmp_path / "m.rrd"
    assert main(["record", str(ev), "--vocab", "kitti360", "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "events.jsonl:5" in err and "confidence" in err
    assert not out.exists() and not list(tmp_path.glob(".m.rrd*"))


def test_record_without_rerun_names_the_extra(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun -> ImportError
    ev, _ = write_scene(tmp_path)
    assert main(["record", str(ev), "--vocab", "kitti360", "--out", str(tmp_path / "m.rrd")]) == 1
    err = capsys.readouterr().err
    assert "sgbelief record: error:" in err and "pip install 'sgbelief[rerun]'" in err
    from sgbelief.viz.rerun_log import RerunMissingError, require_rerun

    with pytest.raises(RerunMissingError, match=r"sgbelief\[rerun\]"):
        require_rerun()


def test_log_frame_into_the_users_recording(tmp_path: Path) -> None:
    rr = pytest.importorskip("rerun")
    from sgbelief.adapters.conceptgraphs.backend import ConceptGraphsBackend
    from sgbelief.adapters.conceptgraphs.importer import import_result
    backend = ConceptGraphsBackend("comod")
    results = {"objects": [_cg_object([0, 0, 1, 0], [0.9, 0.8, 0.6, 0.85], [0, 1, 2, 3], (0.0, 0.0, 0.5), 1),
                           _cg_object([1, 1, 1], [0.9, 0.7, 0.8], [1, 2, 3], (2.0, 1.0, 0.4), 2)],
               "class_names": ["chair", "table"]}
    import_result(results, backend)
    rec = rr.RecordingStream("cg-user", recording_id="cg-user")
    path = tmp_path / "user.rrd"
    rec.save(str(path))
    rec.set_time("t", sequence=3)
    rec.log("camera/rgb", rr.Points3D(np.zeros((1, 3))))  # what the user's own script logs
    n = backend.log_to_rerun(3, recording=rec)  # = log_frame(backend.graph, 3, recording=rec, tau=backend.tau)
    rec.flush()
    rec.disconnect()
    ents = _read(path)
    assert "/camera/rgb" in ents  # the user's entities stay
    assert {"/sgbelief/map/objects/cg-0", "/sgbelief/map/objects/cg-1"} <= set(ents)
    series = [p for p in ents if p.startswith("/sgbelief/beliefs/")]
    assert len(series) == len(backend.graph.provenance) and n >= len(series) + 2
    label = _column(ents["/sgbelief/map/objects/cg-0"], "Boxes3D:labels")[-1][0]
    pred = backend.committed_predicate("cg-0")
    assert label.startswith(pred.removeprefix("is_").replace("_", " ") if pred else "?")
    assert all(_scalars(ents[p])[0][0] == 3 for p in series)


def test_entity_paths_escape_node_ids() -> None:
    rr = pytest.importorskip("rerun")
    from sgbelief.viz.rerun_log import entity_path

    assert entity_path(rr, "sgbelief", "beliefs", "d04/0056", "is_car") == "sgbelief/beliefs/d04/0056/is_car"
    odd = entity_path(rr, "p", "a b#c")
    assert odd.startswith("p/") and odd != "p/a b#c"

"""CLI on bad input and faults, end to end in a subprocess (issue #21): a clear one-line error, rc != 0,
no traceback, no file overwritten."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from sgbelief.cli import main

ROOT = Path(__file__).resolve().parents[1]


def sgbelief(*args: str, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "sgbelief.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=cwd)


def _stream(d: Path, n: int = 30) -> tuple[Path, Path]:
    lines = [json.dumps({"format": "sgbelief.events", "version": 1})]
    for t in range(n):
        lines.append(json.dumps({"t": t, "id": f"e{t}", "targets": {"s/car": 1.0}, "predicate": "is_car",
                                 "confidence": 0.8, "context": "vlm", "geometric": {"s/car": "car"}}))
    (d / "events.jsonl").write_text("\n".join(lines) + "\n")
    (d / "truth.json").write_text(json.dumps({"s/car": {"is_car": 1}}))
    return d / "events.jsonl", d / "truth.json"


def _no_traceback(proc: subprocess.CompletedProcess[str]) -> None:
    assert "Traceback" not in proc.stderr, proc.stderr


def test_replay_non_utf8_log_names_file_and_line(tmp_path: Path) -> None:
    ev, truth = _stream(tmp_path)
    with open(ev, "ab") as fh:
        fh.write(b"\xe9\xff binary garbage\n")
    proc = sgbelief("replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--operators", "majority")
    _no_traceback(proc)
    assert proc.returncode == 1 and f"{ev}:32: not UTF-8" in proc.stderr


def test_replay_non_utf8_log_with_skip_bad_lines(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ev, truth = _stream(tmp_path)
    with open(ev, "ab") as fh:
        fh.write(b"\xe9\xff binary garbage\n")
    rc = main(["replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--operators", "majority",
               "--skip-bad-lines", "--no-progress"])
    out = capsys.readouterr().out
    assert rc == 0 and "30 events replayed" in out and "(1 bad lines skipped)" in out


def test_replay_empty_log_is_an_error_and_keeps_saved_graphs(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    ev, truth = _stream(tmp_path)
    saved = tmp_path / "graphs"
    common = ["--truth", str(truth), "--vocab", "kitti360", "--operators", "majority", "--save-graph", str(saved),
              "--no-progress"]
    assert main(["replay", str(ev), *common]) == 0
    graph = saved / "majority" / "graph.json"
    before = graph.read_bytes()
    ev.write_text("")
    proc = sgbelief("replay", str(ev), *common, "--json", str(tmp_path / "m.json"))
    _no_traceback(proc)
    assert proc.returncode == 1 and f"{ev}: no evidence events to replay (the log is empty" in proc.stderr
    assert graph.read_bytes() == before and not (tmp_path / "m.json").exists()
    capsys.readouterr()
    ev.write_text(json.dumps({"format": "sgbelief.events", "version": 1}) + "\n\n")  # a header only
    assert main(["replay", str(ev), *common]) == 1
    assert "no evidence events" in capsys.readouterr().err and graph.read_bytes() == before
    ev.write_text("{}\n[]\n")  # only bad lines, skipped
    assert main(["replay", str(ev), *common, "--skip-bad-lines"]) == 1
    assert "all 2 event lines were malformed" in capsys.readouterr().err and graph.read_bytes() == before
    # several scenes: each one is checked before its graphs are saved
    assert main(["replay", str(ev), str(tmp_path / "events.jsonl"), *common]) == 1
    assert graph.read_bytes() == before


def test_import_cg_truncated_or_corrupt_map_is_a_clear_error(tmp_path: Path) -> None:
    import gzip
    import pickle

    raw = gzip.compress(pickle.dumps({"objects": [{"class_id": [0], "conf": [0.9], "image_idx": [k]}
                                                  for k in range(200)], "class_names": ["chair"]}))
    src = tmp_path / "pcd_x.pkl.gz"
    out = tmp_path / "out"
    src.write_bytes(raw[: len(raw) // 2])
    proc = sgbelief("import-cg", str(src), "--out", str(out))
    _no_traceback(proc)
    assert proc.returncode == 1 and f"{src}: truncated gzip stream" in proc.stderr, proc.stderr
    assert not out.exists()


def test_query_into_a_closed_pipe_exits_quietly(tmp_path: Path) -> None:
    from sgbelief import SceneGraph

    g = SceneGraph()
    for i in range(6000):
        g.add_node(f"scene/{i:05d}")
        g.provenance.record(f"scene/{i:05d}", "is_car", f"e{i}", 0, 3.0, 0.0)
    g.save(tmp_path / "map")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-m", "sgbelief.cli", "query", str(tmp_path / "map"), "is_car"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    head = [proc.stdout.readline() for _ in range(2)]  # `| head -2`
    proc.stdout.close()
    err = proc.stderr.read().decode()
    rc = proc.wait(timeout=120)
    assert len(head) == 2 and "BrokenPipeError" not in err and "Traceback" not in err, err
    assert rc == 141 and err == ""

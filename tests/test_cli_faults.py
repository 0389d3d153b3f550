"""CLI on bad input and faults, end to end in a subprocess (issue #21): a clear one-line error, rc != 0,
no traceback, no file overwritten."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

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
    proc = sgbelief("replay", str(ev), "--truth", str(truth), "--vocab", "kitti360", "--operators", "majority",
                    "--skip-bad-lines")
    _no_traceback(proc)
    assert proc.returncode == 0 and "30 events replayed" in proc.stdout and "1 bad lines skipped" in proc.stdout

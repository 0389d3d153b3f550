"""`sgbelief bench` on a tiny suite: tables, JSON and non-empty figures."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.cli import main


@pytest.mark.slow
def test_bench_tiny_indoor(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    rc = main(["bench", "--suite", "indoor", "--scale", "0.15", "--out", str(out), "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "Per-class IoU" in text and "Table 5" in text and "Cross-VLM" in text and "Real detector" in text
    doc = json.loads((out / "results.json").read_text())
    res = doc["suites"]["indoor"]
    assert set(res["table2"]) == {"overwrite", "majority", "naive_bayes", "refined", "cal", "comod"}
    assert res["calibration"]["calibrated_ece"] < res["calibration"]["raw_ece"]
    assert "retrieval" in res, res.get("retrieval_error")
    for name in ("figure1.png", "reliability.png"):
        png = out / name
        assert png.exists() and png.stat().st_size > 10_000
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for r in doc["real_calibration"].values():
        assert r["calibrated_ece"] < r["raw_ece"]

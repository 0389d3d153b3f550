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


@pytest.mark.slow
def test_bench_workers_identical_to_serial(tmp_path: Path) -> None:
    from sgbelief.eval.benchmark import run_bench

    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if k not in ("events_per_s", "seconds", "sim_stats")}
        if isinstance(x, list):
            return [strip(v) for v in x]
        return x

    kw = dict(seed=3, scale=0.1, retrieval=False, real_data=False, operators=("majority", "comod"))
    serial = run_bench(["indoor", "outdoor"], out=tmp_path / "a", **kw)
    parallel = run_bench(["indoor", "outdoor"], out=tmp_path / "b", workers=2, **kw)
    assert strip(serial["suites"]) == strip(parallel["suites"])

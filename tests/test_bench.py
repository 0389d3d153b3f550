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
    assert set(res["table2"]) == {"overwrite", "majority", "naive_bayes", "refined", "cal", "comod",
                                  "cal_paper", "comod_paper"}
    assert set(res["table2_segmenter"]) == set(res["table2"])
    assert "shipped default" in text and "belief-preservation pool" in text and "Figure 1(a)" in text
    assert res["belief_preservation_pool"] > 0
    assert all("pool_brier_vlm_a" in v for v in res["vlm_swap"].values())
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


@pytest.mark.slow
def test_grid_smallest_cell_smoke() -> None:
    """The grid's smallest cell, seeded: every operator scored, the summary and the table complete
    (figures are not asserted: this is a smoke test, not a result)."""
    from sgbelief.eval.grid import GridCell, render_grid, run_grid, summarize

    cell = GridCell("indoor", "vlm_a", "parametric", "oracle")
    rows = run_grid([0], cells=[cell], scale=0.1)
    assert {r["operator"] for r in rows} == {"overwrite", "majority", "naive_bayes", "refined", "cal", "comod",
                                            "cal_paper", "comod_paper"}
    assert all(0.0 <= r["mean_iou"] <= 1.0 for r in rows)
    again = run_grid([0], cells=[cell], scale=0.1, operators=("majority", "comod"))
    assert [r["mean_iou"] for r in again] == [r["mean_iou"] for r in rows if r["operator"] in ("majority", "comod")]
    summary = summarize(rows)
    assert set(summary["targets"]) == {"highest_mean_iou_in_every_cell", "mean_margin_over_best_baseline_ge_0.10",
                                       "is_car_commit_precision_ge_0.95",
                                       "calibrated_brier_shift_le_0.01_and_baselines_move_more"}
    assert summary["targets"]["is_car_commit_precision_ge_0.95"] is None  # no outdoor oracle cell here
    text = render_grid(summary, seeds=[0], config_note="the shipped default")
    assert cell.label in text and "mean over cells" in text


def test_parse_seeds() -> None:
    from sgbelief.cli.bench import parse_seeds

    assert parse_seeds("100-104") == [100, 101, 102, 103, 104]
    assert parse_seeds("0,2, 5-6") == [0, 2, 5, 6]
    with pytest.raises(SystemExit, match="not a seed"):
        parse_seeds("a-b")

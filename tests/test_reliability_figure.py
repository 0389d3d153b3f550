"""The reliability diagram's legend hides none of its points: the indoor suite's raw claims are all
right in every bin (observed frequency 1), so its points run along the top edge of the panel."""

from __future__ import annotations

import numpy as np
import pytest

from sgbelief.eval.benchmark import _plot_reliability
from sgbelief.eval.metrics import reliability_bins


@pytest.mark.parametrize("case", ["all_right", "all_wrong", "diagonal"])
def test_no_point_under_the_legend(case: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(0)
    c = rng.random(2000)
    y = {"all_right": np.ones_like(c), "all_wrong": np.zeros_like(c), "diagonal": rng.random(2000) < c}[case]
    raw, cal = reliability_bins(c, y), reliability_bins(np.clip(c * 0.9 + 0.05, 0, 1), y)
    fig, ax = plt.subplots(figsize=(4, 4.6))
    _plot_reliability(ax, raw, cal, case)
    fig.canvas.draw()
    box = ax.get_legend().get_window_extent()
    points = np.concatenate([line.get_xydata() for line in ax.get_lines() if line.get_marker() == "o"])
    assert len(points) >= 10
    xy = ax.transData.transform(points)
    inside = (xy[:, 0] >= box.x0) & (xy[:, 0] <= box.x1) & (xy[:, 1] >= box.y0) & (xy[:, 1] <= box.y1)
    assert not inside.any(), points[inside]
    lo, hi = ax.get_ylim()
    assert lo <= 0.0 and hi > 1.0  # a point at frequency 1 is not cut by the frame
    plt.close(fig)

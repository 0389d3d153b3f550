"""run_scenes: process pool and Ray give the serial results, in input order."""

from __future__ import annotations

import pytest

from sgbelief.eval.parallel import random_scene_summary as scene_summary
from sgbelief.eval.parallel import run_scenes


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise RuntimeError("scene 3 failed")
    return x


def test_process_pool_equals_serial_in_order() -> None:
    seeds = [5, 1, 4, 0, 3, 2]
    serial = run_scenes(scene_summary, seeds, workers=1)
    pooled = run_scenes(scene_summary, seeds, workers=2)
    assert [r["seed"] for r in pooled] == seeds
    assert pooled == serial
    assert run_scenes(scene_summary, iter(seeds[:2]), workers=2, chunksize=2) == serial[:2]


def test_errors_and_bad_arguments() -> None:
    with pytest.raises(RuntimeError, match="scene 3"):
        run_scenes(_fail_on_three, range(5), workers=2)
    with pytest.raises(ValueError):
        run_scenes(_fail_on_three, [1], executor="dask")
    assert run_scenes(_fail_on_three, [], workers=2) == []


def test_ray_local_mode_equals_serial() -> None:
    ray = pytest.importorskip("ray")
    seeds = [2, 0, 1]
    try:
        out = run_scenes(scene_summary, seeds, workers=2, executor="ray")
    finally:
        ray.shutdown()
    assert out == run_scenes(scene_summary, seeds)

"""ScanNet axis alignment: <sceneId>.txt's axisAlignment matrix is applied to the mesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("open3d")

from sgbelief.adapters.scannet import LABELS_TSV, load_scene, read_axis_alignment, write_label_map, write_scene_files  # noqa: E402
from sgbelief.errors import FormatError  # noqa: E402

BOXES = [("floor", (-2, -2, -0.01), (2, 2, 0.0)), ("table", (0, 0, 0), (1, 0.5, 0.75))]


def _scene(tmp_path: Path, meta: str | None) -> Path:
    write_label_map(tmp_path / LABELS_TSV)
    d = write_scene_files(tmp_path / "scene0007_00", "scene0007_00", BOXES)
    d = Path(tmp_path / "scene0007_00")
    if meta is not None:
        (d / "scene0007_00.txt").write_text(meta)
    return d


def test_alignment_is_applied(tmp_path: Path) -> None:
    # rotate 90 degrees about z and shift by (10, 0, 1)
    m = "0 -1 0 10 1 0 0 0 0 0 1 1 0 0 0 1"
    d = _scene(tmp_path, f"colorHeight = 968\naxisAlignment = {m}\nsceneType = Office\n")
    aligned = load_scene(d)
    raw = load_scene(d, axis_align=False)
    table_raw = next(o for o in raw.objects.values() if o.raw_label == "table")
    table = next(o for o in aligned.objects.values() if o.raw_label == "table")
    expected = np.column_stack([10 - table_raw.points[:, 1], table_raw.points[:, 0], table_raw.points[:, 2] + 1])
    np.testing.assert_allclose(table.points, expected, atol=1e-6)
    assert read_axis_alignment(d / "scene0007_00.txt").shape == (4, 4)


def test_missing_metadata_means_identity(tmp_path: Path) -> None:
    d = _scene(tmp_path, None)
    a, b = load_scene(d), load_scene(d, axis_align=False)
    np.testing.assert_allclose(a.vertices, b.vertices)


def test_malformed_alignment_names_field_and_line(tmp_path: Path) -> None:
    d = _scene(tmp_path, "sceneType = Office\naxisAlignment = 1 0 0\n")
    with pytest.raises(FormatError, match=r"scene0007_00.txt:2.*axisAlignment"):
        load_scene(d)

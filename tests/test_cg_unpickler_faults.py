"""Restricted loading of ConceptGraphs maps on damaged files (issue #21): truncations, flips and fuzzed
bytes give a FormatError naming the file, never a bare EOFError / zlib.error."""

from __future__ import annotations

import gzip
import pickle
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.adapters.conceptgraphs.unpickler import load_cg_result
from sgbelief.errors import FormatError, SgbeliefError

DOC = {"objects": [{"class_id": [0, 1], "conf": [np.float32(0.9), np.float32(0.4)], "image_idx": [k, k + 1],
                    "bbox_np": np.arange(24.0).reshape(8, 3), "color_path": [Path(f"/d/{k}.jpg")]}
                   for k in range(30)], "class_names": ["chair", "table"]}
PLAIN = pickle.dumps(DOC)
ZIPPED = gzip.compress(PLAIN, mtime=0)


@pytest.mark.parametrize("data,msg", ids=["half", "header", "no-stop", "third", "flip", "plain-half"], argvalues=[
    (ZIPPED[: len(ZIPPED) // 2], "truncated gzip stream"),
    (ZIPPED[:11], "truncated gzip stream"),
    (gzip.compress(PLAIN[:-1]), "not a readable ConceptGraphs pickle"),  # STOP opcode missing
    (gzip.compress(PLAIN[: len(PLAIN) // 3]), "not a readable ConceptGraphs pickle"),
    (ZIPPED[:40] + bytes([ZIPPED[40] ^ 0xFF]) + ZIPPED[41:], "corrupt gzip stream"),
    (PLAIN[: len(PLAIN) // 2], "pickle"),
])
def test_damaged_maps_name_the_file(tmp_path: Path, data: bytes, msg: str) -> None:
    p = tmp_path / "pcd_x.pkl.gz"
    p.write_bytes(data)
    with pytest.raises(FormatError, match=msg) as ei:
        load_cg_result(p)
    assert str(p) in str(ei.value)


def test_intact_map_loads(tmp_path: Path) -> None:
    p = tmp_path / "pcd_x.pkl.gz"
    p.write_bytes(ZIPPED)
    assert len(load_cg_result(p)["objects"]) == 30


def _mutations(raw: bytes) -> st.SearchStrategy[bytes]:
    n = len(raw)
    return st.one_of(
        st.integers(0, n - 1).map(lambda k: raw[:k]),
        st.tuples(st.integers(0, n - 1), st.integers(1, 255)).map(
            lambda a: raw[:a[0]] + bytes([raw[a[0]] ^ a[1]]) + raw[a[0] + 1:]),
        st.binary(max_size=64),
    )


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
          derandomize=True)
@given(data=st.one_of(_mutations(ZIPPED), _mutations(PLAIN)))
def test_fuzz_pkl_gz_gives_project_errors(tmp_path: Path, data: bytes) -> None:
    p = tmp_path / "pcd_x.pkl.gz"
    p.write_bytes(data)
    try:
        load_cg_result(p)
    except SgbeliefError:
        pass
    assert p.read_bytes() == data


def test_import_cg_writes_labels_atomically(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import sgbelief.graph.persistence as persistence
    from sgbelief.cli import main

    p = tmp_path / "pcd_x.pkl.gz"
    p.write_bytes(ZIPPED)
    written: list[str] = []
    real = persistence.atomic_write_text

    def spy(path: object, text: object) -> None:
        written.append(Path(str(path)).name)
        real(path, text)  # type: ignore[arg-type]

    monkeypatch.setattr(persistence, "atomic_write_text", spy)
    monkeypatch.setattr(Path, "write_text", lambda *a, **k: pytest.fail("non-atomic write_text"))
    assert main(["import-cg", str(p), "--operator", "majority", "--out", str(tmp_path / "out")]) == 0
    assert "labels.json" in written and (tmp_path / "out" / "labels.json").exists()

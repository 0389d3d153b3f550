"""Saved graphs on hostile input and faults (issue #21): duplicate node ids, string versions, fuzzed
graph.json / graph.npz, stale temp files of killed saves (SIGKILL in a subprocess)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sgbelief.errors import FormatError, SgbeliefError

from sgbelief import SceneGraph

ROOT = Path(__file__).resolve().parents[1]


def _graph() -> SceneGraph:
    g = SceneGraph()
    for i in range(4):
        g.add_node(f"n{i}", centroid=(float(i), 0.0, 0.0), label="car")
        g.provenance.record(f"n{i}", "is_car", f"e{i}", i, 1.0 + i, 0.5)
    return g


@pytest.fixture(scope="module")
def saved_json(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return _graph().save(tmp_path_factory.mktemp("g") / "graph.json").read_bytes()


@pytest.fixture(scope="module")
def saved_npz(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return _graph().save(tmp_path_factory.mktemp("g") / "graph.npz").read_bytes()


def test_duplicate_node_ids_in_graph_json_are_rejected(tmp_path: Path, saved_json: bytes) -> None:
    doc = json.loads(saved_json)
    nodes = doc["graph"]["nodes"]
    nodes.append({**nodes[1], "label": "other"})
    p = tmp_path / "graph.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=r"field 'graph.nodes\[4\].id': duplicate node id 'n1'"):
        SceneGraph.load(p)


@pytest.mark.parametrize("version", ["1", True, 0, 2, 1.0])
def test_graph_json_version_must_be_the_integer_1(tmp_path: Path, saved_json: bytes, version: object) -> None:
    doc = json.loads(saved_json)
    doc["version"] = version
    p = tmp_path / "graph.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match="version"):
        SceneGraph.load(p)


def _mutations(raw: bytes) -> st.SearchStrategy[bytes]:
    """Truncations, byte flips, inserted garbage and plain random bytes of a valid file."""
    n = len(raw)
    return st.one_of(
        st.integers(0, n - 1).map(lambda k: raw[:k]),
        st.tuples(st.integers(0, n - 1), st.integers(1, 255)).map(lambda a: raw[:a[0]] + bytes([raw[a[0]] ^ a[1]]) + raw[a[0] + 1:]),
        st.tuples(st.integers(0, n), st.binary(min_size=1, max_size=16)).map(lambda a: raw[:a[0]] + a[1] + raw[a[0]:]),
        st.binary(max_size=64),
    )


@pytest.mark.parametrize("name", ["graph.json", "graph.npz"])
def test_fuzz_saved_graph_loaders_give_project_errors(tmp_path: Path, saved_json: bytes, saved_npz: bytes,
                                                      name: str) -> None:
    raw = saved_json if name == "graph.json" else saved_npz
    held = _graph()
    before = held.provenance.to_dict()

    @settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
              derandomize=True)
    @given(data=_mutations(raw))
    def check(data: bytes) -> None:
        p = tmp_path / name
        p.write_bytes(data)
        try:
            SceneGraph.load(p)
        except SgbeliefError:
            pass
        assert p.read_bytes() == data

    check()
    assert held.provenance.to_dict() == before


# ----------------------------------------------------------------------------- killed saves

_CHILD = r"""
import sys, time
from pathlib import Path
from sgbelief.graph.persistence import atomic_write_binary
target, payload = Path(sys.argv[1]), Path(sys.argv[2]).read_bytes()
def write(fh):
    fh.write(payload[: len(payload) // 2])
    fh.flush()
    print("writing", flush=True)
    time.sleep(60)
    fh.write(payload[len(payload) // 2:])
atomic_write_binary(target, write)
"""


def _killed_save(target: Path, payload: bytes) -> None:
    (target.parent / "payload.bin").write_bytes(payload)
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(target), str(target.parent / "payload.bin")],
                            stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "writing"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    (target.parent / "payload.bin").unlink()


def _temps(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir() if p.name.endswith(".tmp"))


@pytest.mark.parametrize("fmt", ["json", "npz"])
def test_sigkill_during_save_keeps_old_file_and_next_save_removes_the_temp(tmp_path: Path, fmt: str) -> None:
    g = _graph()
    target = g.save(tmp_path / "map", format=fmt)
    old = target.read_bytes()
    g.add_node("big", blob="x" * 200_000)
    new_payload = (old + b"\0" * 300_000)
    _killed_save(target, new_payload)
    assert target.read_bytes() == old  # the old file is intact ...
    assert SceneGraph.load(tmp_path / "map").evidence_count() == 4
    stale = _temps(tmp_path / "map")
    assert len(stale) == 1 and stale[0].startswith(f".{target.name}.")  # ... and the killed save left its temp
    other = tmp_path / "map" / f".other.json.{os.getpid() + 1}.abcdefgh.tmp"  # another target's: kept
    other.write_text("x")
    g.save(tmp_path / "map", format=fmt)
    assert _temps(tmp_path / "map") == [other.name]
    assert "big" in SceneGraph.load(tmp_path / "map")


def test_temps_of_live_writers_and_recent_legacy_temps_are_kept(tmp_path: Path) -> None:
    target = tmp_path / "graph.json"
    live = tmp_path / f".graph.json.{os.getppid()}.abcdefgh.tmp"  # the parent process is alive
    legacy_new = tmp_path / ".graph.json.abcdefgh.tmp"
    legacy_old = tmp_path / ".graph.json.zyxwvuts.tmp"
    for p in (live, legacy_new, legacy_old):
        p.write_text("partial")
    old = time.time() - 3600
    os.utime(legacy_old, (old, old))
    from sgbelief.graph.persistence import remove_stale_temp_files

    assert remove_stale_temp_files(target) == [legacy_old]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, legacy_new.name])

"""``sgbelief retrieval --workers N / --executor ray``: the parallel output equals the serial one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief.eval.sim_config import load_sim_config
from sgbelief.eval.simulate import simulate
from sgbelief.eval.retrieval import RetrievalSource, evaluate_retrieval, evaluate_sources

OPERATORS = "majority,naive_bayes,comod"


@pytest.fixture(scope="module")
def suites(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two small simulated suites (outdoor and indoor) written as retrieval sources."""
    root = tmp_path_factory.mktemp("suites")
    out = []
    for name, scenes in (("outdoor", ["d00"]), ("indoor", ["scene0000_00", "scene0001_00"])):
        cfg = load_sim_config(name, scenes=scenes, scale=0.3)
        simulate(cfg, seed=5).write(root / name, profile="vlm_a", channel="oracle")
        out.append(root / name)
    return out


def _retrieval(suites: list[Path], tmp_path: Path, *extra: str) -> tuple[list, str]:
    out = tmp_path / f"scores{len(extra)}{'_'.join(extra)}.json"
    argv = ["retrieval", "--operators", OPERATORS, "--out", str(out), *extra]
    for s in suites:
        argv += ["--suite", str(s)]
    assert main(argv) == 0
    return json.loads(out.read_text()), out.read_text()


def test_cli_workers_output_identical_to_serial(suites: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    serial, serial_text = _retrieval(suites, tmp_path)
    serial_table = capsys.readouterr().out
    pooled, pooled_text = _retrieval(suites, tmp_path, "--workers", "2")
    assert capsys.readouterr().out == serial_table
    assert pooled_text == serial_text  # byte-identical JSON, sources and cells in the same order
    assert [r["source"] for r in serial] == [f"suite:{s.name}" for s in suites]
    cells = [(s["operator"], s["query"]) for s in serial[0]["scores"]]
    assert [c[0] for c in cells][:1] == ["majority"] and cells[-1][0] == "comod"
    assert any(s["n"] > 0 for r in serial for s in r["scores"])  # the suites exercise real pools


def test_evaluate_sources_splits_operators_like_the_joint_run(suites: list[Path]) -> None:
    src = RetrievalSource("suite", str(suites[0]))
    joint = evaluate_retrieval(src.load(), OPERATORS.split(","))
    [(name, split)] = evaluate_sources([src], OPERATORS.split(","), workers=1)
    assert name == f"suite:{suites[0].name}" and split == joint


def test_bad_workers_and_unknown_source_kind(suites: list[Path]) -> None:
    assert main(["retrieval", "--suite", str(suites[0]), "--workers", "-1"]) == 2
    with pytest.raises(ValueError, match="kind"):
        RetrievalSource("kitti", str(suites[0])).load()


def test_cli_ray_local_mode_equals_serial(suites: list[Path], tmp_path: Path) -> None:
    ray = pytest.importorskip("ray")
    serial, _ = _retrieval(suites[:1], tmp_path)
    try:
        on_ray, _ = _retrieval(suites[:1], tmp_path, "--executor", "ray", "--workers", "2")
    finally:
        ray.shutdown()
    assert on_ray == serial

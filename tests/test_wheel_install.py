"""sgbelief works as an installed package, not only from a checkout: the wheel is built, installed
into a fresh virtualenv that cannot see the source tree, and its ``sgbelief replay`` scores a small
simulated log with a shipped vocabulary and the shipped operator defaults, from another directory.

Offline and quick: the wheel is built without build isolation (setuptools and wheel are in the
dev extra), and the fresh environment reaches the project environment's site-packages for the
dependencies only, through a plain path line in a ``.pth`` file (a plain path does not run the
editable install's finder, so the checkout stays out of reach: the test checks where sgbelief is
imported from)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

from sgbelief.version import __version__

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow  # ~15 s: a wheel, a virtualenv, two replays

pytest.importorskip("setuptools")
pytest.importorskip("wheel")


def _run(args: list[str], cwd: Path, env: dict[str, str] | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{args} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc


def _clean_env() -> dict[str, str]:
    """The environment without anything that would point Python back at the checkout."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "SGBELIEF_CONFIG_DIR",
                                                            "PYTHONSTARTUP", "PIP_REQUIRE_VIRTUALENV")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    env["PIP_NO_INDEX"] = "1"  # nothing from the network: the wheel is installed with --no-deps
    return env


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("wheel")
    # build from a copy of the tracked project files, so the checkout gets no build/ or egg-info
    src = base / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(ROOT / "sgbelief", src / "sgbelief", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    env = _clean_env()
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(base / "dist"),
          str(src)], cwd=base, env=env)
    wheel = next((base / "dist").glob("sgbelief-*.whl"))
    # a fresh virtualenv; the dependencies come from this environment's site-packages
    target = base / "venv"
    venv.EnvBuilder(with_pip=True, clear=True).create(target)
    py = target / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     cwd=base, env=env).stdout.strip())
    (site / "_project_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([str(py), "-m", "pip", "install", "--no-deps", "-q", str(wheel)], cwd=base, env=env)
    return {"base": base, "wheel": wheel, "python": py, "sgbelief": target / "bin" / "sgbelief", "site": site}


def test_the_wheel_carries_configs_data_license_and_types(installed: dict[str, Path]) -> None:
    names = set(zipfile.ZipFile(installed["wheel"]).namelist())
    assert installed["wheel"].name.startswith(f"sgbelief-{__version__}-")
    for member in ("sgbelief/py.typed", "sgbelief/configs/vocab/kitti360.yaml", "sgbelief/configs/vocab/scannet.yaml",
                   "sgbelief/configs/operators/default.yaml", "sgbelief/configs/sim/outdoor.yaml",
                   "sgbelief/configs/queries/kitti360.yaml"):
        assert member in names, member
    assert any(n.startswith("sgbelief/data/detector_confidences/") for n in names)
    assert any(n.endswith(".dist-info/licenses/LICENSE") or n.endswith(".dist-info/LICENSE") for n in names)


def test_the_installed_package_is_the_wheel_and_knows_its_version(installed: dict[str, Path], tmp_path: Path) -> None:
    code = ("import importlib.metadata as m, sgbelief, sgbelief.resources as r; "
            "print(sgbelief.__file__); print(sgbelief.__version__); print(m.version('sgbelief')); print(r.config_dir())")
    out = _run([str(installed["python"]), "-c", code], cwd=tmp_path, env=_clean_env()).stdout.split("\n")
    assert Path(out[0]).is_relative_to(installed["site"]), out[0]  # not the checkout
    assert out[1] == out[2] == __version__
    assert Path(out[3]).is_relative_to(installed["site"])
    version = _run([str(installed["sgbelief"]), "--version"], cwd=tmp_path, env=_clean_env()).stdout
    assert version.strip() == f"sgbelief {__version__}"


def test_the_installed_command_replays_a_simulated_log_from_another_directory(
        installed: dict[str, Path], tmp_path: Path) -> None:
    from sgbelief.eval.replay import make_runs, replay, score_run
    from sgbelief.eval.formats import iter_events, read_truth
    from sgbelief.eval.simulate import simulate
    from sgbelief.fusion.compatibility import SubsumptionTable
    from sgbelief.fusion.config import OperatorConfig

    data = tmp_path / "data"
    simulate("outdoor", 0, scale=0.05).write(data, profile="vlm_a", channel="oracle")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    proc = _run([str(installed["sgbelief"]), "replay", "../data/events.jsonl", "--truth", "../data/truth.json",
                 "--vocab", "kitti360", "--operators", "majority,comod", "--json", "scores.json",
                 "--save-graph", "maps", "--no-progress"], cwd=elsewhere, env=_clean_env())
    assert "events replayed from ../data/events.jsonl" in proc.stdout and "comod" in proc.stdout
    assert "warning" not in proc.stderr and "error" not in proc.stderr
    assert (elsewhere / "maps" / "comod" / "graph.json").is_file()
    got = json.loads((elsewhere / "scores.json").read_text())
    # the same replay through the checkout's code gives the same scores
    truth = read_truth(data / "truth.json")
    runs = make_runs(["majority", "comod"], SubsumptionTable.shipped("kitti360"), OperatorConfig.default())
    replay(iter_events(data / "events.jsonl"), runs)
    preds = sorted({p for row in truth.values() for p in row})
    for run in runs:
        want = score_run(run, truth, preds)
        assert got[run.name]["mean_iou"] == pytest.approx(want.mean_iou, abs=1e-12)
        assert got[run.name]["refusals"] == want.refusals
        assert got[run.name]["per_predicate"]["is_car"]["tp"] == want.per_predicate["is_car"].tp
    assert got["comod"]["refusals"] > 0 and got["comod"]["mean_iou"] > got["majority"]["mean_iou"]

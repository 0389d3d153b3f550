"""The files a user of a package looks for: a license that says what pyproject says, a citation
file naming the software and the method's paper, a changelog, type information, one version."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml

from sgbelief import __version__

ROOT = Path(__file__).resolve().parents[1]
PAPER = "Belief Consistency Between Foundation-Model Evidence and Geometric Perception in Persistent Robotic Maps"


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_license_is_the_one_pyproject_names() -> None:
    assert _pyproject()["project"]["license"] == {"text": "MIT"}
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def test_citation_names_the_software_and_the_paper() -> None:
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["version"] == __version__ and cff["license"] == "MIT" and cff["authors"]
    paper = next(r for r in cff["references"] if r["title"] == PAPER)
    assert [a["family-names"] for a in paper["authors"]] == ["Heckman", "Biggie", "Crowe", "Roy"]
    assert [a["given-names"] for a in paper["authors"]] == ["Christoffer", "Harel", "Brendan", "Nicholas"]


def test_one_place_for_the_version() -> None:
    project = _pyproject()
    assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "sgbelief.version.__version__"}
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert "## [Unreleased]" in changelog and f"## [{__version__}]" in changelog


def test_typed_package_data() -> None:
    assert (ROOT / "sgbelief" / "py.typed").is_file()
    assert "py.typed" in _pyproject()["tool"]["setuptools"]["package-data"]["sgbelief"]

"""Locating the project's shipped configuration and data files."""

from __future__ import annotations

import os
from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parent


def config_dir() -> Path:
    """The ``configs/`` directory: ``$SGBELIEF_CONFIG_DIR`` if set, else the repository's."""
    env = os.environ.get("SGBELIEF_CONFIG_DIR")
    if env:
        return Path(env)
    return _PACKAGE_DIR.parent / "configs"


def config_path(*parts: str) -> Path:
    """Path of a shipped config file, e.g. ``config_path('vocab', 'scannet.yaml')``."""
    path = config_dir().joinpath(*parts)
    if not path.exists():
        raise FileNotFoundError(f"shipped config {'/'.join(parts)!r} not found under {config_dir()}")
    return path


def data_path(*parts: str) -> Path:
    """Path of a data file shipped inside the package (``sgbelief/data``)."""
    return _PACKAGE_DIR.joinpath("data", *parts)

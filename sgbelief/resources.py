"""Locating the package's shipped configuration and data files.

Both live inside the package (``sgbelief/configs``, ``sgbelief/data``) and are found through
:mod:`importlib.resources`, so they are there whether sgbelief runs from a checkout, an editable
install or a wheel. ``$SGBELIEF_CONFIG_DIR`` replaces the shipped configs directory as a whole.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

CONFIG_DIR_ENV = "SGBELIEF_CONFIG_DIR"


def _package_root() -> Path:
    # setuptools installs sgbelief as a plain directory (wheel or editable), so the traversable
    # is a real path; as_file would only matter for a zipped install, which setuptools never makes.
    return Path(str(resources.files("sgbelief")))


def config_dir() -> Path:
    """The configs directory: ``$SGBELIEF_CONFIG_DIR`` if set, else the package's ``configs/``."""
    env = os.environ.get(CONFIG_DIR_ENV)
    if env:
        return Path(env)
    return _package_root() / "configs"


def config_path(*parts: str) -> Path:
    """Path of a shipped config file, e.g. ``config_path('vocab', 'scannet.yaml')``."""
    path = config_dir().joinpath(*parts)
    if not path.exists():
        where = f"${CONFIG_DIR_ENV}={config_dir()}" if os.environ.get(CONFIG_DIR_ENV) else str(config_dir())
        raise FileNotFoundError(f"shipped config {'/'.join(parts)!r} not found under {where}")
    return path


def data_path(*parts: str) -> Path:
    """Path of a data file shipped inside the package (``sgbelief/data``)."""
    return _package_root().joinpath("data", *parts)

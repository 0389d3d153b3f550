"""sgbelief.query.retrieval is a deprecated re-export of sgbelief.eval.retrieval (PEP 562): importing
it imports nothing of eval; each name asked for warns and is the new home's object."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_names_come_from_the_new_home_with_a_warning() -> None:
    import sgbelief.eval.retrieval as new
    import sgbelief.query.retrieval as old

    with pytest.warns(DeprecationWarning, match="sgbelief.eval.retrieval"):
        assert old.evaluate_retrieval is new.evaluate_retrieval
    with pytest.warns(DeprecationWarning):
        from sgbelief.query.retrieval import RetrievalSource
    assert RetrievalSource is new.RetrievalSource
    assert set(new.__all__) <= set(dir(old))
    with pytest.warns(DeprecationWarning), pytest.raises(AttributeError):
        old.no_such_name  # noqa: B018


def test_importing_the_shim_loads_no_evaluation() -> None:
    code = ("import sys, sgbelief.query.retrieval; "
            "print(' '.join(m for m in sys.modules if m.startswith('sgbelief.eval') or m.startswith('sgbelief.adapters')))")
    out = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": ""}).stdout.split()
    assert out == []

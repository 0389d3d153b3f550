"""The public SceneGraph (sgbelief.api.scene_graph) over the model's: conveniences, loaders that build
the class they are given, the engine choice, and a model module that imports neither io nor query."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import sgbelief
from sgbelief.api.scene_graph import ENGINES, SceneGraph, provenance_store
from sgbelief.graph import scene_graph as model
from sgbelief.graph.persistence import graph_to_dict, load_graph, save_graph
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance import ProvenanceStore
from sgbelief.query import run_query

ROOT = Path(__file__).resolve().parents[1]


def _fill(g: model.SceneGraphModel) -> model.SceneGraphModel:
    g.add_node("c", bbox=((0.3, 0.8, 0.0), (0.8, 1.3, 0.95)), label="chair")
    g.add_node("w", bbox=((1.6, -0.5, 0.9), (1.7, 1.0, 2.0)), label="window")
    g.provenance.record("c", "is_chair", "e1", 0, 3.0, 0.0)
    return g


def test_public_name_is_the_api_subclass_of_the_model() -> None:
    assert sgbelief.SceneGraph is SceneGraph
    assert issubclass(SceneGraph, model.SceneGraphModel)
    for name in ("save", "load", "query"):
        assert hasattr(SceneGraph, name)
        assert not hasattr(model.SceneGraphModel, name), f"the model class grew {name!r}"


def test_the_models_old_name_warns_and_is_the_model() -> None:
    """One name, one class: the model was also called SceneGraph (with the reference store as its
    default, unlike sgbelief.SceneGraph); the old name warns until 0.2.0."""
    import pytest

    import sgbelief.graph as graph_pkg
    from sgbelief.errors import SgbeliefDeprecationWarning

    with pytest.warns(SgbeliefDeprecationWarning, match="SceneGraphModel"):
        assert model.SceneGraph is model.SceneGraphModel
    with pytest.warns(SgbeliefDeprecationWarning):
        assert graph_pkg.SceneGraph is model.SceneGraphModel


def test_model_module_imports_neither_io_nor_query() -> None:
    code = ("import sys, sgbelief.graph.scene_graph, sgbelief.graph; "
            "print(' '.join(sorted(m for m in sys.modules if m.startswith('sgbelief'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": ""}).stdout.split()
    assert "sgbelief.graph.scene_graph" in out
    for upper in ("sgbelief.query", "sgbelief.graph.persistence", "sgbelief.graph.binary", "sgbelief.api"):
        assert upper not in out, f"importing the model imported {upper}"


@pytest.mark.parametrize("suffix", ["json", "npz"])
def test_loaders_build_the_class_they_are_given(tmp_path: Path, suffix: str) -> None:
    g = _fill(model.SceneGraphModel())
    path = save_graph(g, tmp_path / f"g.{suffix}")
    plain = load_graph(path)
    assert type(plain) is model.SceneGraphModel  # the model class by default
    public = load_graph(path, graph_type=SceneGraph)
    assert type(public) is SceneGraph
    assert type(SceneGraph.load(path)) is SceneGraph

    class Mine(SceneGraph):
        pass

    assert type(Mine.load(path)) is Mine  # the classmethod passes its own class
    assert graph_to_dict(plain) == graph_to_dict(public) == graph_to_dict(g)


def test_conveniences_are_the_free_functions(tmp_path: Path) -> None:
    g = _fill(SceneGraph())
    assert g.save(tmp_path / "m") == tmp_path / "m" / "graph.json"
    assert graph_to_dict(SceneGraph.load(tmp_path / "m")) == graph_to_dict(load_graph(tmp_path / "m"))
    expr = "is_chair & is_near_window"
    assert g.query(expr).to_dict() == run_query(g, expr).to_dict()
    assert g.query("is_chair & !is_near_window", tau=0.1).nodes == []


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_engine_chooses_the_provenance_store(engine: str) -> None:
    g = SceneGraph(engine=engine, prior=(2.0, 3.0))  # type: ignore[arg-type]
    assert isinstance(g.provenance, EntryLog)  # the journalled store is an EntryLog, not a ProvenanceStore
    assert isinstance(g.provenance, ProvenanceStore) == (engine == "reference")
    assert (g.provenance.prior_alpha, g.provenance.prior_beta) == (2.0, 3.0)
    g.add_node("a")
    assert g.probability("a", "is_x") == pytest.approx(0.4)
    assert isinstance(provenance_store(engine), EntryLog)


def test_unknown_engine_is_a_clear_error() -> None:
    assert set(ENGINES) == {"fast", "reference"}
    with pytest.raises(ValueError, match="engine must be one of"):
        SceneGraph(engine="turbo")  # type: ignore[arg-type]

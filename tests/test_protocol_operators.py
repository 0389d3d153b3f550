"""An operator written against the FusionOperator protocol alone behaves as a BaseOperator subclass
through every code path: the conformance suite, ``replay`` (streaming, batched, auto) and ``bench``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from sgbelief.api.operators import engine_for, make_operator
from sgbelief.eval.random_stream import random_records
from sgbelief.eval.replay import make_runs, replay, score_run
from sgbelief.fusion import registry
from sgbelief.fusion.protocol import FusionOperator
from sgbelief.fusion.registry import OPERATOR_NAMES, PAPER_OPERATOR_NAMES
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.testing import check_fusion_operator, conformance_table, provenance_signature

TABLE = conformance_table()
CONFIG = {"t_prov": 12, "tau_rev": 0.05, "t_cor": 4, "t_disagree": 3}


class ProtocolOnly:
    """Every member of the protocol, handed on to a wrapped operator; nothing inherited."""

    def __init__(self, inner: FusionOperator) -> None:
        self.inner = inner
        self.name = inner.name

    @property
    def config(self) -> Any:
        return self.inner.config

    @property
    def stats(self) -> dict[str, int]:
        return self.inner.stats

    @property
    def pair_rule(self) -> Any:
        return self.inner.pair_rule

    def update(self, graph: SceneGraphModel, event: Any, channel: Any = None, *, report: bool = True) -> Any:
        return self.inner.update(graph, event, channel, report=report)

    def update_many(self, graph: SceneGraphModel, items: Any) -> Any:
        return self.inner.update_many(graph, items)

    def tick(self, graph: SceneGraphModel, t: int) -> Any:
        return self.inner.tick(graph, t)

    def probability(self, graph: SceneGraphModel, node: Any, predicate: str) -> float:
        return self.inner.probability(graph, node, predicate)

    def retract(self, graph: SceneGraphModel, event_id: str) -> list[str]:
        return self.inner.retract(graph, event_id)

    def merge_nodes(self, graph: SceneGraphModel, keep: Any, absorb: Any) -> None:
        self.inner.merge_nodes(graph, keep, absorb)


def _wrapped(name: str) -> Any:
    """A registry factory: the shipped operator ``name`` (fast engine) behind :class:`ProtocolOnly`."""
    cls = registry.operator_class(name)
    engine = engine_for(cls, "fast")
    return lambda config, vocabulary: ProtocolOnly(cls(config, vocabulary, engine=engine))


def test_the_wrapper_implements_nothing_but_the_protocol() -> None:
    op = ProtocolOnly(make_operator("comod", None, TABLE))
    assert isinstance(op, FusionOperator)
    assert not any(isinstance(op, cls) for cls in type(op.inner).__mro__ if cls is not object)


@pytest.mark.parametrize("name", OPERATOR_NAMES)
def test_a_protocol_only_operator_passes_the_conformance_suite(name: str) -> None:
    check_fusion_operator(ProtocolOnly(make_operator(name, None, TABLE)))


@pytest.mark.parametrize("engine", ["streaming", "batched", "auto"])
def test_replay_gives_the_wrapped_operators_results(engine: str) -> None:
    names = [*OPERATOR_NAMES, *PAPER_OPERATOR_NAMES]
    recs = random_records(5, 1500, n_nodes=20, predicates=tuple(TABLE.predicates), labels=("car", "person", None))
    direct = make_runs(names, TABLE, CONFIG)
    wrapped = make_runs([ProtocolOnly(make_operator(n, CONFIG, TABLE)) for n in names], TABLE, CONFIG)
    replay(recs, direct, engine=engine)
    replay(recs, wrapped, engine=engine)
    truth = {f"n{i:05d}": {"is_car": i % 2, "is_pedestrian": 1 - i % 2} for i in range(20)}
    for d, w in zip(direct, wrapped):
        assert w.name == d.name and w.events == d.events == len(recs)
        assert provenance_signature(w.graph) == provenance_signature(d.graph), d.name
        assert w.operator.stats == d.operator.stats, d.name
        sd, sw = score_run(d, truth).as_dict(), score_run(w, truth).as_dict()
        sd.pop("events_per_s"), sw.pop("events_per_s")
        assert sw == sd, d.name
        assert d.operator.stats["compacted"] > 0  # the stream crosses compactions


def _strip(x: Any) -> Any:
    """A results document without its timing fields."""
    if isinstance(x, dict):
        return {k: _strip(v) for k, v in x.items() if k not in ("events_per_s", "seconds", "generation_s")}
    if isinstance(x, list):
        return [_strip(v) for v in x]
    return x


@pytest.mark.slow
def test_bench_gives_the_wrapped_operators_results(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from sgbelief.eval.benchmark import run_bench

    kw: dict[str, Any] = dict(seed=2, scale=0.1, retrieval=True, real_data=False)
    direct = run_bench(["indoor"], out=tmp_path / "direct", **kw)
    for name in [*OPERATOR_NAMES, *PAPER_OPERATOR_NAMES]:
        monkeypatch.setitem(registry.OPERATORS, name, _wrapped(name))
    assert isinstance(make_operator("comod", None, TABLE), ProtocolOnly)
    wrapped = run_bench(["indoor"], out=tmp_path / "wrapped", **kw)
    assert "retrieval" in direct["suites"]["indoor"], direct["suites"]["indoor"].get("retrieval_error")
    assert _strip(wrapped["suites"]) == _strip(direct["suites"])

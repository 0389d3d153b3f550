"""Batched (wave) replay = streaming replay, bit for bit, on seeded random streams."""

from __future__ import annotations

import pytest

from sgbelief.eval.batched import (
    BATCHED_OPERATORS,
    EventColumns,
    batched_replay,
    provenance_signature,
    random_records,
)
from sgbelief.eval.replay import make_runs, replay


def _streaming(records, name, config=None):
    run = make_runs([name], None, config)[0]
    replay(records, [run])
    return run


@pytest.mark.parametrize("name", BATCHED_OPERATORS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_equals_streaming(name: str, seed: int) -> None:
    # small T_prov so the stream crosses many compactions; some masses fall under tau_T
    config = {"t_prov": 7 + seed, "tau_t": 0.15}
    records = random_records(seed, 600, n_nodes=12 + 5 * seed)
    run = _streaming(records, name, config)
    graph, stats = batched_replay(EventColumns.from_records(records), name, None, config)
    assert provenance_signature(graph) == provenance_signature(run.graph)
    assert stats == run.operator.stats
    assert graph.provenance.n_compacted > 0


def test_batched_without_compaction_and_default_ids() -> None:
    records = [r._replace(id=None) for r in random_records(5, 200, n_nodes=8)]
    run = _streaming(records, "majority")
    graph, stats = batched_replay(EventColumns.from_records(records), "majority")
    assert provenance_signature(graph) == provenance_signature(run.graph)
    assert graph.provenance.reconstruct(*next(graph.provenance.pairs())) == pytest.approx(
        graph.provenance.alpha_beta(*next(graph.provenance.pairs())))


def test_batched_rejects_calibrated_operators() -> None:
    with pytest.raises(ValueError, match="streaming"):
        batched_replay(EventColumns.from_records(random_records(0, 5)), "comod")

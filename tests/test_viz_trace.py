"""sgbelief.viz.trace: a pair's belief over time read from its provenance, and its figure
(one marker per event), with and without compaction; the bench's band drawing."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from sgbelief.graph.provenance_log import EntryVerdict
from sgbelief.fusion.channel import FrameLabels  # noqa: E402
from sgbelief.fusion.config import OperatorConfig  # noqa: E402
from sgbelief.fusion.registry import OPERATOR_NAMES, make_reference_operator  # noqa: E402
from sgbelief.api.scene_graph import SceneGraph  # noqa: E402
from sgbelief.testing import conformance_table, random_stream  # noqa: E402
from sgbelief.viz.trace import belief_trace  # noqa: E402
from sgbelief.viz.trace_figure import EVENT_MARKERS_GID, draw_belief_band, trace_figure  # noqa: E402

TABLE = conformance_table()


def _run(name: str, n: int, seed: int, t_prov: int = 100_000) -> tuple[SceneGraph, list]:
    config = OperatorConfig.from_mapping({"t_prov": t_prov, "tau_t": 0.1})
    op, graph = make_reference_operator(name, config, TABLE), SceneGraph(create_nodes=True)
    stream = random_stream(n, n_nodes=5, seed=seed)
    for ev, labels in stream:
        op.update(graph, ev, FrameLabels(labels))
    return graph, stream


def _markers(fig) -> list[int]:
    return [sum(len(c.get_offsets()) for c in ax.collections if c.get_gid() == EVENT_MARKERS_GID) for ax in fig.axes]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(OPERATOR_NAMES), seed=st.integers(0, 10_000), t_prov=st.sampled_from([5, 40, 100_000]))
def test_trace_ends_at_the_pairs_belief(name: str, seed: int, t_prov: int) -> None:
    """Eq. 4: replaying a pair's log from the prior gives its belief, compacted or not."""
    graph, _ = _run(name, 120, seed, t_prov)
    for node, pred in graph.provenance.pairs():
        tr = belief_trace(graph, node, pred)
        a, b = graph.provenance.alpha_beta(node, pred)
        assert tr.final == (pytest.approx(a, rel=1e-9, abs=1e-9), pytest.approx(b, rel=1e-9, abs=1e-9))
        if tr.events:
            assert tr.events[-1].mean == pytest.approx(a / (a + b), abs=1e-9)
            assert all(e.lower <= e.mean <= e.upper for e in tr.events)
            assert [e.t for e in tr.events] == sorted(e.t for e in tr.events)


@pytest.mark.parametrize("name", ["cal", "comod"])
def test_one_trace_event_per_claim_and_one_marker_per_event(name: str) -> None:
    graph, stream = _run(name, 200, 4)
    node, pred = max(graph.provenance.pairs(), key=lambda k: len(graph.provenance.entries(*k)))
    claims = [ev for ev, _ in stream if ev.predicate == pred and ev.targets.get(node, 0.0) > 0.1]
    # claims of a rival class at the node count against this one (exclusive_evidence: rivals): one event each
    rivals = {e.event_id for e in graph.provenance.entries(node, pred) if e.verdict is EntryVerdict.EXCLUSION}
    tr = belief_trace(graph, node, pred)
    assert [e.event_id for e in tr.events] == [ev.id for ev, _ in stream if ev in claims or ev.id in rivals]
    assert {e.event_id for e in tr.events if e.verdict == "exclusion"} == rivals
    refused = {e.event_id for e in graph.provenance.entries(node, pred) if e.status.value in
               ("refused", "resolved", "expired", "dismissed")}
    recorded = {e.event_id: e.verdict.symbol for e in graph.provenance.entries(node, pred)
                if e.verdict is not None and e.verdict.is_claim}
    assert {e.event_id: e.verdict for e in tr.events if e.event_id not in rivals} == recorded  # the claims' verdicts
    if name == "comod":  # only comod refuses: there ⊥ means refused (cal commits ⊥ claims)
        assert {e.event_id for e in tr.events if e.verdict == "⊥"} == refused
    if name == "comod":
        assert refused  # the stream holds contradicted claims
    fig = trace_figure(graph, node, [pred])
    try:
        assert _markers(fig) == [len(claims) + len(rivals)]
        assert "now Beta(" in fig.axes[0].get_title(loc="left")
    finally:
        plt.close(fig)


def test_compacted_history_is_drawn_as_buckets() -> None:
    graph, stream = _run("comod", 300, 2, t_prov=20)
    assert graph.provenance.n_compacted > 0
    node, pred = max(graph.provenance.pairs(), key=lambda k: len(graph.provenance.entries(*k)))
    tr = belief_trace(graph, node, pred)
    buckets = [e for e in tr.events if e.status == "compacted"]
    assert buckets and all(e.folded >= 1 for e in buckets)
    claims = sum(1 for ev, _ in stream if ev.predicate == pred and ev.targets.get(node, 0.0) > 0.1)
    assert len(tr.events) < claims  # folded history: fewer steps, the same end point (Eq. 4)
    a, b = graph.provenance.alpha_beta(node, pred)
    assert tr.final == (pytest.approx(a), pytest.approx(b))
    fig = trace_figure(graph, node)
    try:
        assert sum(_markers(fig)) >= len(tr.events)  # one per event of every panel
        panel = next(ax for ax in fig.axes if ax.get_title(loc="left").startswith(pred))
        labels = panel.get_legend_handles_labels()[1]
        assert any(t.startswith("compacted:") for t in labels)
    finally:
        plt.close(fig)


def test_trace_of_a_pair_without_entries_is_empty() -> None:
    tr = belief_trace(SceneGraph(create_nodes=True), "x", "is_car")
    assert tr.events == () and tr.final == (1.0, 1.0) and tr.steps() == ([], [], [], [])


def test_draw_belief_band_linear_and_step() -> None:
    fig, ax = plt.subplots()
    try:
        draw_belief_band(ax, [0, 1, 2], [0.5, 0.6, 0.7], [0.1, 0.2, 0.3], [0.9, 0.9, 0.95], colour="#3f7fbf", name="cal")
        draw_belief_band(ax, [0, 1, 2], [0.5, 0.4, 0.3], [0.1, 0.1, 0.1], [0.9, 0.8, 0.7], colour="#d9534f", name="comod",
                         step=True)
        labels = ax.get_legend_handles_labels()[1]
        assert labels == ["cal: mean", "cal: 90% interval", "comod: mean", "comod: 90% interval"]
        assert [ln.get_drawstyle() for ln in ax.lines] == ["default", "steps-post"]
        assert len(ax.collections) == 2 and not math.isnan(ax.get_ylim()[0])
    finally:
        plt.close(fig)

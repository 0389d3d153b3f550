"""``geometric_evidence: label``: a decisive geometric label observes the predicates it asserts.

A sofa the detector keeps calling ``tv`` is observed as a sofa by the channel; before this option
nothing carried that label into ``is_sofa`` and the object ended ``unknown`` or ``tv``.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.api.operators import make_operator
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.open_vocab import derive_table
from sgbelief.fusion.rules import label_observations
from sgbelief.graph.provenance import EntryStatus, EntryVerdict
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.testing import check_fast_matches_reference

CLASSES = ["sofa", "tv", "chair", "table", "desk", "otherprop"]
LABEL = {"geometric_evidence": "label"}


@pytest.fixture(scope="module")
def table() -> SubsumptionTable:
    return derive_table(CLASSES, "indoor", merge=True)  # table and desk: one predicate


def _tv_claims(n: int, label: str | None = "sofa") -> list[tuple[EvidenceEvent, FrameLabels]]:
    return [(EvidenceEvent({"v": 1.0}, "is_tv", 0.9, "det", t, f"e{t}"), FrameLabels({"v": label})) for t in range(n)]


def test_asserted_by_reads_the_positive_sets(table: SubsumptionTable) -> None:
    assert table.asserted_by("sofa") == ("is_sofa",)
    assert table.asserted_by("desk") == table.asserted_by("table") == ("is_table_or_desk",)
    assert table.asserted_by("otherprop") == ()  # ambiguous: asserts nothing
    assert table.asserted_by("no such label") == ()


def test_label_observations_skip_the_claim_and_repeat_once_per_frame() -> None:
    seen: dict = {}
    assert label_observations(("is_sofa", "is_seat"), "is_tv", "v", 3, seen) == ["is_sofa", "is_seat"]
    assert label_observations(("is_sofa", "is_seat"), "is_tv", "v", 3, seen) == []  # same frame
    assert label_observations(("is_sofa",), "is_tv", "w", 3, seen) == ["is_sofa"]  # another node
    assert label_observations(("is_sofa",), "is_sofa", "v", 4, seen) == []  # the claim observes it itself
    assert label_observations(("is_sofa",), "is_tv", "v", 4, seen) == ["is_sofa"]  # the next frame


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_sofa_called_tv_is_committed_as_a_sofa(table: SubsumptionTable, engine: str) -> None:
    op = make_operator("comod", LABEL, table, engine=engine)
    assert op.observes_label
    g = SceneGraphModel(create_nodes=True)
    for event, labels in _tv_claims(6):
        op.update(g, event, labels)
    assert g.probability("v", "is_tv") < 0.5  # every claim refused, every label against it
    b = g.belief("v", "is_sofa")
    assert (b.alpha, b.beta) == (7.0, 1.0)  # one pseudo-count per frame's label on Beta(1, 1)
    entries = g.provenance.entries("v", "is_sofa")
    assert [e.verdict for e in entries] == [EntryVerdict.GEOMETRIC] * 6
    assert all(e.status is EntryStatus.COMMITTED and e.stance == 1 for e in entries)
    assert [e.event_id for e in entries] == [f"e{t}" for t in range(6)]


@pytest.mark.parametrize(("name", "config"), [("comod", {"geometric_evidence": "verdict"}),
                                              ("comod", {"geometric_evidence": "none"}),
                                              ("comod", None), ("cal", LABEL)])
def test_other_settings_leave_the_label_s_own_predicate_alone(table: SubsumptionTable, name: str, config) -> None:
    """``verdict`` (the operator default) and ``none`` observe the claimed pair only; ``cal`` uses
    the channel only to calibrate, whatever ``geometric_evidence`` says."""
    op = make_operator(name, config, table)
    assert not op.observes_label
    assert op.observes_geometry == (name == "comod" and config != {"geometric_evidence": "none"})
    g = SceneGraphModel(create_nodes=True)
    for event, labels in _tv_claims(4):
        op.update(g, event, labels)
    assert ("v", "is_sofa") not in g.provenance


def test_several_claims_in_one_frame_see_one_label(table: SubsumptionTable) -> None:
    op = make_operator("comod", LABEL, table)
    g = SceneGraphModel(create_nodes=True)
    for k, pred in enumerate(["is_tv", "is_chair", "is_tv"]):
        op.update(g, EvidenceEvent({"v": 1.0}, pred, 0.8, "det", 5, f"f{k}"), FrameLabels({"v": "sofa"}))
    assert len(g.provenance.entries("v", "is_sofa")) == 1


def test_retracting_the_claim_retracts_its_label_observation(table: SubsumptionTable) -> None:
    op = make_operator("comod", LABEL, table)
    g = SceneGraphModel(create_nodes=True)
    for event, labels in _tv_claims(2):
        op.update(g, event, labels)
    op.retract(g, "e1")
    assert [e.event_id for e in g.provenance.entries("v", "is_sofa")] == ["e0"]
    op.update(g, *_tv_claims(2)[1])  # the retracted id and frame are free again
    assert [e.event_id for e in g.provenance.entries("v", "is_sofa")] == ["e0", "e1"]


def test_label_observations_are_not_counted_as_claims(table: SubsumptionTable) -> None:
    """The support stratum counts claims: a graph reloaded with label observations at (v, psi)
    recounts the claims there as zero, as the live counter has it."""
    op = make_operator("comod", LABEL, table)
    g = SceneGraphModel(create_nodes=True)
    for event, labels in _tv_claims(3):
        op.update(g, event, labels)
    assert op._claims_in_log(g.provenance, "v", "is_sofa") == 0
    assert op._claims_in_log(g.provenance, "v", "is_tv") == 3


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["a", "b", "c"]), st.sampled_from(["is_tv", "is_sofa", "is_chair"]),
                          st.floats(0.0, 1.0), st.sampled_from(["sofa", "tv", "chair", "desk", "otherprop", None]),
                          st.integers(0, 2)), max_size=50))
def test_both_engines_agree_with_label_observations(table: SubsumptionTable, raw) -> None:
    stream, t = [], 0
    for i, (node, pred, c, label, dt) in enumerate(raw):
        t += dt
        stream.append((EvidenceEvent({node: 1.0}, pred, c, "det", t, f"e{i}"), {node: label}))
    check_fast_matches_reference("comod", stream, {**LABEL, "t_prov": 20, "calibration": {"target_size": 5}},
                                 vocabulary=table, final_tick=t + 50)

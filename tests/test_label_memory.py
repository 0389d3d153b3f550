"""Recalled verdicts: the channel's earlier labels of an element refuse a claim it does not see
(``recalled_verdicts: unanimous``, docs/method.md §8), and with ``retroactive`` its later labels
withdraw the claims it committed unseen: the rule by hand, the memory, the operator."""

from __future__ import annotations

import pytest

from sgbelief import SceneGraph, make_operator
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.label_memory import LabelMemory
from sgbelief.fusion.consensus import MapConsensus
from sgbelief.fusion.rules import consensus_agrees, labels_contested, recalled_outcome
from sgbelief.graph.provenance import EntryStatus, EntryVerdict

CLASSES = ["bed", "chair", "sofa"]


def _table() -> SubsumptionTable:
    labels = [*CLASSES, "otherprop"]
    specs = {f"is_{k}": {"positive": [k], "negative": [j for j in CLASSES if j != k]} for k in CLASSES}
    return SubsumptionTable(specs, name="three", labels=labels)  # otherprop decides nothing


def test_recalled_outcome_by_hand() -> None:
    out = {"bed": 1, "chair": 0, "sofa": 0}
    assert recalled_outcome(out, {"chair": 3}) == 0
    assert recalled_outcome(out, {"chair": 2, "sofa": 1, "otherprop": 4}) == 0  # silent labels do not count
    assert recalled_outcome(out, {"bed": 2}) == 1
    assert recalled_outcome(out, {"bed": 1, "chair": 5}) is None  # the channel changed its mind
    assert recalled_outcome(out, {"otherprop": 3}) is None
    assert recalled_outcome(out, {}) is None
    assert recalled_outcome(out, {"chair": 1}, min_labels=2) is None
    assert recalled_outcome(out, {"chair": 2}, min_labels=2) == 0


def test_label_memory_counts_frames_once_and_follows_merges() -> None:
    mem = LabelMemory()
    mem.add("a", 1, "chair")
    mem.add("a", 1, "bed")  # the same frame again: its first label counts
    mem.add("a", 2, "chair")
    mem.add("b", 1, "bed")
    assert mem.counts == {"a": {"chair": 2}, "b": {"bed": 1}}
    out = _table().outcome_tables()["is_bed"]
    assert mem.recalled("a", out) == 0 and mem.recalled("b", out) == 1 and mem.recalled("c", out) is None
    mem.merge("a", "b")
    assert mem.counts == {"a": {"chair": 2, "bed": 1}}
    assert mem.recalled("a", out) is None


def _run(engine: str, labels_then: list[str | None], config: dict | None = None):
    """Three claims 'bed' on v with the channel's labels ``labels_then``, then five it does not see."""
    op = make_operator("comod", config, _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    items = []
    for t, lab in enumerate(labels_then):
        items.append((EvidenceEvent({"v": 1.0}, "is_bed", 0.8, "det", t, f"seen{t}"), FrameLabels({"v": lab})))
    t0 = len(labels_then)
    for i in range(5):
        items.append((EvidenceEvent({"v": 1.0}, "is_bed", 0.8, "det", t0 + i, f"unseen{i}"), FrameLabels({"v": None})))
    op.update_many(g, items)
    return op, g


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_claim_the_elements_earlier_labels_contradict_is_refused(engine: str) -> None:
    op, g = _run(engine, ["chair", "chair", "chair"])
    entries = [e for e in g.provenance.entries("v", "is_bed") if e.event_id and e.event_id.startswith("unseen")]
    assert entries and all(e.status is EntryStatus.REFUSED for e in entries)
    assert g.probability("v", "is_bed") < 0.5
    # Eq. 4 holds and a refused claim retracts like any other
    assert g.provenance.alpha_beta("v", "is_bed") == pytest.approx(g.provenance.reconstruct("v", "is_bed"))
    before = g.provenance.alpha_beta("v", "is_bed")
    op.retract(g, "unseen2")
    assert not g.provenance.has_event("unseen2")
    assert g.provenance.alpha_beta("v", "is_bed") == pytest.approx(before)


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_without_recall_or_when_the_channel_changed_its_mind_the_claims_count(engine: str) -> None:
    _, g_off = _run(engine, ["chair", "chair", "chair"], {"recalled_verdicts": "none"})
    _, g_on = _run(engine, ["chair", "chair", "chair"])
    unseen = [e for e in g_off.provenance.entries("v", "is_bed") if e.event_id and e.event_id.startswith("unseen")]
    assert unseen and all(e.status is EntryStatus.COMMITTED for e in unseen)  # each one moves the belief
    assert g_off.probability("v", "is_bed") > g_on.probability("v", "is_bed")
    _, g_mixed = _run(engine, ["chair", "bed", "otherprop"])
    unseen = [e for e in g_mixed.provenance.entries("v", "is_bed") if e.event_id and e.event_id.startswith("unseen")]
    assert unseen and not any(e.status is EntryStatus.REFUSED for e in unseen)
    _, g_bed = _run(engine, ["bed", "bed"])  # a recalled ⊤ only lets the claims through
    assert g_bed.probability("v", "is_bed") > 0.5


def test_the_paper_variant_and_cal_do_not_recall() -> None:
    assert make_operator("comod_paper", None, _table()).config.recalled_verdicts == "none"
    assert not make_operator("cal", None, _table()).recalls_verdicts
    assert make_operator("comod", None, _table()).recalls_verdicts
    assert make_operator("comod", None, _table()).withdraws_unadjudicated  # the default: retroactive
    assert not make_operator("comod", {"recalled_verdicts": "unanimous"}, _table()).withdraws_unadjudicated
    assert not make_operator("comod_paper", None, _table()).withdraws_unadjudicated
    # a withdrawal moves the refused pair's belief: such a configuration does not claim Property 2
    assert not make_operator("comod", {"geometric_evidence": "none"}, _table()).claims_property2
    assert make_operator("comod", {"geometric_evidence": "none", "recalled_verdicts": "unanimous",
                                   "contested_labels": "refuse"}, _table()).claims_property2
    # a claim at an element whose labels contradict each other is weighed: not Property 2 either
    assert not make_operator("comod", {"geometric_evidence": "none", "recalled_verdicts": "unanimous"},
                             _table()).claims_property2


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_merged_elements_share_their_labels(engine: str) -> None:
    op = make_operator("comod", None, _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    op.update_many(g, [(EvidenceEvent({"a": 1.0}, "is_bed", 0.8, "det", 0, "e0"), FrameLabels({"a": "chair"}))])
    g.ensure_node("b")
    op.merge_nodes(g, "b", "a")
    op.update_many(g, [(EvidenceEvent({"b": 1.0}, "is_bed", 0.8, "det", 1, "e1"), FrameLabels({"b": None}))])
    (e1,) = [e for e in g.provenance.entries("b", "is_bed") if e.event_id == "e1"]
    assert e1.status is EntryStatus.REFUSED


# ----------------------------------------------------------------------------- retroactive
def test_held_predicates_are_judged_once_by_the_elements_labels() -> None:
    tables = _table().outcome_tables()
    mem = LabelMemory()
    mem.hold("v", "is_bed", tables["is_bed"])
    mem.hold("v", "is_sofa", tables["is_sofa"])
    mem.add("v", 1, "otherprop")  # decides nothing: both stay held
    assert mem.judged("v", tables) == ([], [])
    mem.add("v", 2, "chair")  # denies bed and sofa, unanimously
    assert mem.judged("v", tables) == (["is_bed", "is_sofa"], [])
    mem.add("v", 3, "chair")
    assert mem.judged("v", tables) == ([], [])  # judged once
    mem.add("v", 4, "bed")  # the channel changed its mind on bed: the withdrawal lapses, once
    assert mem.judged("v", tables) == ([], ["is_bed"])
    mem.add("v", 5, "bed")
    assert mem.judged("v", tables) == ([], [])
    mem.hold("w", "is_bed", tables["is_bed"])
    mem.add("w", 1, "bed")  # asserts: released, never withdrawn
    assert mem.judged("w", tables) == ([], [])
    mem.add("w", 2, "chair")
    assert mem.judged("w", tables) == ([], [])
    mem.hold("w", "is_bed", tables["is_bed"])  # a label already asserts bed: nothing to hold
    assert mem.judged("w", tables) == ([], [])
    strict = LabelMemory(min_labels=2)
    strict.hold("u", "is_bed", tables["is_bed"])
    strict.add("u", 1, "chair")
    assert strict.judged("u", tables) == ([], [])  # one denial is not enough yet: still held
    strict.add("u", 2, "sofa")
    assert strict.judged("u", tables) == (["is_bed"], [])


def _retro_stream(labels_then: list[str | None], rival: bool = False) -> list:
    """Three 'bed' claims on v unseen (and one 'sofa' with ``rival``), then claims of 'chair' on v
    with the channel's labels ``labels_then``."""
    items = [(EvidenceEvent({"v": 1.0}, "is_bed", 0.8, "det", t, f"bed{t}"), FrameLabels({"v": None}))
             for t in range(3)]
    if rival:
        items.append((EvidenceEvent({"v": 1.0}, "is_sofa", 0.8, "det", 3, "sofa3"), FrameLabels({"v": None})))
    t0 = 4
    items += [(EvidenceEvent({"v": 1.0}, "is_chair", 0.8, "det", t0 + i, f"chair{i}"), FrameLabels({"v": lab}))
              for i, lab in enumerate(labels_then)]
    return items


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_later_unanimous_labels_withdraw_the_claims_committed_unseen(engine: str) -> None:
    """The regression of issue #30: claims committed while the channel looked away stay committed
    after the element's labels, all of them, deny the class (the labels came with other classes'
    claims, so no refusal ever touched the pair)."""
    plain = {"exclusive_evidence": "none"}  # the chair claims then say nothing of bed
    on = make_operator("comod", {**plain, "recalled_verdicts": "retroactive"}, _table(), engine=engine)
    off = make_operator("comod", {**plain, "recalled_verdicts": "unanimous"}, _table(), engine=engine)
    graphs = []
    for op in (on, off):
        g = SceneGraph(create_nodes=True)
        op.update_many(g, _retro_stream(["chair", "otherprop", "chair"]))
        graphs.append(g)
    g_on, g_off = graphs
    beds = [e for e in g_on.provenance.entries("v", "is_bed") if e.event_id.startswith("bed")]
    assert len(beds) == 3 and all(e.status is EntryStatus.WITHDRAWN for e in beds)
    assert on.stats["withdrawn"] == 3 and off.stats["withdrawn"] == 0
    assert g_on.probability("v", "is_bed") <= 0.5 < g_off.probability("v", "is_bed")  # recall alone leaves them
    assert g_on.provenance.alpha_beta("v", "is_bed") == pytest.approx((1.0, 1.0))  # nothing else was said of bed
    # Eq. 4: the belief is the prior plus what is still counted, on every pair
    for node, pred in g_on.provenance.pairs():
        assert g_on.provenance.alpha_beta(node, pred) == pytest.approx(g_on.provenance.reconstruct(node, pred))
    # a withdrawn claim retracts like any other
    on.retract(g_on, "bed1")
    assert not g_on.provenance.has_event("bed1")
    assert g_on.provenance.alpha_beta("v", "is_bed") == pytest.approx((1.0, 1.0))


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_withdrawn_claims_evidence_against_its_rivals_goes_with_it(engine: str) -> None:
    op = make_operator("comod", {"recalled_verdicts": "retroactive"}, _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    op.update_many(g, _retro_stream(["chair"], rival=True))
    entries = g.provenance.entries("v", "is_bed") + g.provenance.entries("v", "is_sofa")
    unseen = [e for e in entries if not e.event_id.startswith("chair")]
    assert any(e.verdict is EntryVerdict.EXCLUSION for e in unseen)  # the sofa claim counted against bed
    assert all(e.status is EntryStatus.WITHDRAWN for e in unseen)  # gone with the claims
    # the chair claim, seen and verified, still counts against both
    assert all(e.status is EntryStatus.COMMITTED for e in entries if e.event_id.startswith("chair"))
    for pred in ("is_bed", "is_sofa"):
        assert g.provenance.alpha_beta("v", pred) == pytest.approx(g.provenance.reconstruct("v", pred))
        assert g.probability("v", pred) < 0.5


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_label_that_ever_asserted_the_class_withdraws_nothing(engine: str) -> None:
    op = make_operator("comod", {"recalled_verdicts": "retroactive"}, _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    op.update_many(g, _retro_stream(["bed", "chair", "chair"]))
    assert op.stats["withdrawn"] == 0
    assert all(e.status is EntryStatus.COMMITTED for e in g.provenance.entries("v", "is_bed"))


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_withdrawal_lapses_when_a_later_label_asserts_the_class(engine: str) -> None:
    """The channel denied bed, then said bed: the labels no longer agree, the unseen bed claims count
    again, exactly as before they were withdrawn."""
    plain = {"exclusive_evidence": "none"}
    op = make_operator("comod", {**plain, "recalled_verdicts": "retroactive"}, _table(), engine=engine)
    fwd = make_operator("comod", {**plain, "recalled_verdicts": "unanimous"}, _table(), engine=engine)
    g, g_fwd = SceneGraph(create_nodes=True), SceneGraph(create_nodes=True)
    stream = _retro_stream(["chair", "otherprop", "bed"])
    op.update_many(g, stream[:5])  # three unseen bed claims, then the chair claim labelled chair
    assert g.probability("v", "is_bed") <= 0.5 and op.stats["withdrawn"] == 3
    op.update_many(g, stream[5:])
    fwd.update_many(g_fwd, stream)
    assert op.stats["reinstated"] == 3
    beds = [e for e in g.provenance.entries("v", "is_bed") if e.event_id.startswith("bed")]
    assert all(e.status is EntryStatus.COMMITTED for e in beds)
    assert g.provenance.alpha_beta("v", "is_bed") == pytest.approx(g_fwd.provenance.alpha_beta("v", "is_bed"))
    assert g.provenance.alpha_beta("v", "is_bed") == pytest.approx(g.provenance.reconstruct("v", "is_bed"))


@pytest.mark.parametrize("fmt", ["npz", "json"])
def test_withdrawn_entries_survive_a_save_and_a_load(tmp_path, fmt: str) -> None:
    op = make_operator("comod", None, _table())
    g = SceneGraph(create_nodes=True)
    op.update_many(g, _retro_stream(["chair", "otherprop", "chair"], rival=True))
    path = g.save(tmp_path / f"g.{fmt}")
    h = SceneGraph.load(path)

    def statuses(graph):
        return sorted((e.event_id, e.predicate, e.status.value) for e in graph.provenance.iter_entries())

    assert statuses(h) == statuses(g)
    assert any(s == "withdrawn" for *_, s in statuses(h))
    for pred in ("is_bed", "is_sofa", "is_chair"):
        assert h.provenance.alpha_beta("v", pred) == pytest.approx(g.provenance.alpha_beta("v", pred))


def test_labels_contested_by_hand() -> None:
    out = {"bed": 1, "chair": 0, "sofa": 0}
    assert labels_contested(out, {"bed": 1, "chair": 5})  # asserted once, denied five times
    assert labels_contested(out, {"bed": 4, "sofa": 1, "otherprop": 2})
    assert not labels_contested(out, {"chair": 3, "sofa": 2})  # unanimous denial
    assert not labels_contested(out, {"bed": 2, "otherprop": 7})  # silent labels do not count
    assert not labels_contested(out, {})
    mem = LabelMemory()
    mem.add("v", 0, "bed")
    assert not mem.contested("v", out) and not mem.contested("w", out)
    mem.add("v", 1, "chair")
    assert mem.contested("v", out)


def _seen(engine: str, labels: list[str], config: dict | None = None):
    """One confident 'bed' claim on v per frame, the channel labelling v ``labels[t]`` in frame t."""
    op = make_operator("comod", config, _table(), engine=engine)
    g = SceneGraph(create_nodes=True)
    op.update_many(g, [(EvidenceEvent({"v": 1.0}, "is_bed", 0.9, "det", t, f"e{t}"), FrameLabels({"v": lab}))
                       for t, lab in enumerate(labels)])
    return op, g


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_channel_that_contradicts_itself_refuses_nothing_more(engine: str) -> None:
    """A sofa the channel labels 'bed' once and 'chair' after: from the first 'chair' on, the
    element's labels are contested and the 'bed' claims of the 'chair' frames are weighed (the ⊥
    verdict recorded), not refused; with ``contested_labels: refuse`` they are refused."""
    labels = ["bed", "chair", "chair", "chair"]
    op, g = _seen(engine, labels, {"contested_labels": "weigh"})
    entries = {e.event_id: e for e in g.provenance.entries("v", "is_bed") if e.verdict is not EntryVerdict.GEOMETRIC}
    assert op.weighs_contested and not op.claims_property2
    assert entries["e0"].verdict is EntryVerdict.CORROBORATES
    for t in (1, 2, 3):
        assert entries[f"e{t}"].verdict is EntryVerdict.CONTRADICTS
        assert entries[f"e{t}"].status is EntryStatus.COMMITTED
    assert g.provenance.alpha_beta("v", "is_bed") == pytest.approx(g.provenance.reconstruct("v", "is_bed"))
    op_r, g_r = _seen(engine, labels, {"contested_labels": "refuse"})
    assert not op_r.weighs_contested
    refused = [e for e in g_r.provenance.entries("v", "is_bed") if e.status is EntryStatus.REFUSED]
    assert sorted(e.event_id for e in refused) == ["e1", "e2", "e3"]
    assert g.probability("v", "is_bed") > g_r.probability("v", "is_bed")


@pytest.mark.parametrize("engine", ["fast", "reference"])
def test_a_unanimous_channel_still_refuses(engine: str) -> None:
    """Labels that only ever deny the class (a chair filed under sofa in every frame) refuse every
    claim, as before: only a channel that has also asserted the class is overruled."""
    _, g = _seen(engine, ["chair", "sofa", "chair"])
    claims = [e for e in g.provenance.entries("v", "is_bed") if e.verdict is not EntryVerdict.GEOMETRIC]
    assert len(claims) == 3 and all(e.status is EntryStatus.REFUSED for e in claims)
    assert g.probability("v", "is_bed") < 0.5
    op = make_operator("comod_paper", None, _table())
    assert op.config.contested_labels == "refuse" and not op.weighs_contested


def test_consensus_agrees_by_hand() -> None:
    assert consensus_agrees(True, 0.5) and consensus_agrees(True, 0.9) and not consensus_agrees(True, 0.49)
    assert consensus_agrees(False, 0.2) and not consensus_agrees(False, 0.5)
    assert not consensus_agrees(True, None) and not consensus_agrees(False, None)  # no fit: the refusal stands


@pytest.mark.parametrize("engine", ["fast", "reference"])
@pytest.mark.parametrize("q, refused", [(0.9, False), (0.1, True), (None, True)])
def test_at_a_contested_element_the_consensus_decides(engine: str, monkeypatch, q, refused) -> None:
    """``contested_labels: consensus`` (the default): the 'bed' claims of the 'chair' frames, at an
    element the channel has also labelled 'bed', are weighed when the consensus' posterior of bed at
    v is at least one half, refused when it is below or when there is no fit. The claims of the
    first, unanimous 'chair' frames are refused whatever the posterior."""
    monkeypatch.setattr(MapConsensus, "posterior", lambda self, node, pred: q)
    op, g = _seen(engine, ["chair", "bed", "chair", "chair"])
    assert op.config.contested_labels == "consensus" and op.weighs_contested
    status = {e.event_id: e.status for e in g.provenance.entries("v", "is_bed") if e.verdict is not EntryVerdict.GEOMETRIC}
    assert status["e0"] in (EntryStatus.REFUSED, EntryStatus.RESOLVED)  # unanimous until e1 (then resolved by it)
    assert status["e1"] is EntryStatus.COMMITTED  # corroborated
    for t in (2, 3):
        assert (status[f"e{t}"] is not EntryStatus.COMMITTED) == refused
        assert (status[f"e{t}"] is EntryStatus.REFUSED) == refused

"""What a provenance entry records of its event (issue #22): the verdict (⊤ / ⊥ / ∅, or a
geometric observation) and the raw confidence, written by every calibrated writer (reference
steps and fused loop), kept by both stores and both file formats (old files load with None),
summarised by compaction (verdict counts, the Lambda-hat sum) and shown by ``sgbelief explain``.
Lambda-hat and the weight are read back from the increments (Eq. 3 inverted)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sgbelief.api.operators import make_operator
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.cli import main
from sgbelief.errors import FormatError
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.protocol import Action
from sgbelief.fusion.rules import ENTRY_VERDICT, claim_increments, claim_lambda_hat, claim_weight
from sgbelief.graph.compaction import FoldSummary
from sgbelief.graph.provenance import EntryStatus, EntryVerdict, ProvenanceStore
from sgbelief.testing import conformance_table, random_stream, store_state

TABLE = conformance_table()


# ------------------------------------------------------------------ Eq. 3 inverted
@settings(max_examples=500, deadline=None)
@given(lam=st.floats(1e-6, 1e6), weight=st.floats(1e-6, 1e3))
def test_lambda_hat_and_weight_are_read_back_from_the_increments(lam: float, weight: float) -> None:
    da, db = claim_increments(lam, weight)
    assert math.isclose(claim_lambda_hat(da, db), lam, rel_tol=1e-14)  # type: ignore[arg-type]
    assert math.isclose(claim_weight(da, db), weight, rel_tol=1e-14)
    # a common scale (a revision released at w/k) leaves Lambda-hat unchanged
    assert math.isclose(claim_lambda_hat(da / 3.0, db / 3.0), lam, rel_tol=1e-14)  # type: ignore[arg-type]


def test_lambda_hat_is_none_for_increments_no_claim_has() -> None:
    assert claim_lambda_hat(1.0, 0.0) is None and claim_lambda_hat(-0.5, 1.0) is None
    assert claim_lambda_hat(math.inf, 1.0) is None and claim_lambda_hat(math.nan, 1.0) is None
    assert claim_lambda_hat(0.0, 2.0) == 0.0


# ------------------------------------------------------------------ what the operators write
def _replay(name: str, engine: str, *, n: int = 200, seed: int = 3, t_prov: int = 10**6,
            t_compact: int | None = None) -> tuple[SceneGraph, list[Any], list[Any]]:
    config = OperatorConfig.from_mapping({"t_prov": t_prov, "t_compact": t_compact, "tau_t": 0.1})
    op = make_operator(name, config, TABLE, engine=engine)  # type: ignore[arg-type]
    graph = SceneGraph(engine=engine, create_nodes=True)  # type: ignore[arg-type]
    stream = random_stream(n, n_nodes=5, seed=seed)
    reports = [op.update(graph, ev, FrameLabels(labels)) for ev, labels in stream]
    return graph, [ev for ev, _ in stream], reports


@pytest.mark.parametrize("engine", ["reference", "fast"])
@pytest.mark.parametrize("name", ["comod", "cal", "comod_paper"])
def test_every_calibrated_entry_records_its_verdict_and_confidence(name: str, engine: str) -> None:
    graph, events, reports = _replay(name, engine)
    confidence = {ev.id: ev.confidence for ev in events}
    prov = graph.provenance
    n_geo = 0
    # a silent claim weighed again after a consensus refit (sgbelief.fusion.reweigh) holds the
    # increments of the calibration of now, not those its report gave when it arrived
    reweighed = {(r.event_id, r.node, r.predicate) for rep in reports for r in rep.resolutions if r.kind == "reweighed"}
    assert bool(reweighed) == (name != "comod_paper")  # the paper's operators have no consensus
    for report in reports:
        entries = prov.event_entries(report.event_id)
        claims = {e.node: e for e in entries if e.verdict is not None and e.verdict.is_claim}  # not observations
        n_geo += sum(e.verdict is EntryVerdict.GEOMETRIC for e in entries)
        for e in entries:
            assert e.confidence == confidence[report.event_id] and type(e.confidence) is float
            if e.verdict is EntryVerdict.GEOMETRIC:  # one pseudo-count in the label's direction
                assert (e.d_alpha == 0.0) != (e.d_beta == 0.0)
        for o in report.targets:
            if o.action is Action.BELOW_THRESHOLD:
                assert o.node not in claims
                continue
            entry = claims[o.node]
            assert entry.verdict is ENTRY_VERDICT[o.verdict]
            if o.action is Action.COMMITTED and (report.event_id, o.node, report.predicate) not in reweighed:
                assert (entry.d_alpha, entry.d_beta) == (o.d_alpha, o.d_beta)  # the report's increments
            lam = claim_lambda_hat(entry.d_alpha, entry.d_beta)
            assert lam is not None and lam > 0.0
    assert (n_geo > 0) == (name == "comod")  # comod_paper and cal do not observe the label


def test_baselines_record_no_verdict() -> None:
    graph, _, _ = _replay("majority", "fast")
    assert all(e.verdict is None and e.confidence is None for e in graph.provenance.iter_entries())


# ------------------------------------------------------------------ stores and formats
def _states_equal(a: ProvenanceStore, b: ProvenanceStore) -> None:
    sa, sb = store_state(a), store_state(b)
    for key in ("pairs", "to_dict"):  # (a JSON load rebuilds the index and queue orders)
        assert sa[key] == sb[key], key


@pytest.mark.parametrize("fmt", ["json", "npz"])
@pytest.mark.parametrize("engine", ["reference", "fast"])
def test_verdicts_and_confidences_round_trip(tmp_path: Path, fmt: str, engine: str) -> None:
    graph, _, _ = _replay("comod", "fast", t_prov=12, t_compact=6)
    assert any(e.verdict is not None for e in graph.provenance.iter_entries())
    path = graph.save(tmp_path / "map", format=fmt)
    again = SceneGraph.load(path, engine=engine)  # type: ignore[arg-type]
    _states_equal(graph.provenance, again.provenance)
    for key in graph.provenance.pairs():
        assert again.explain(*key).to_dict() == graph.explain(*key).to_dict()
    verdicts = {type(e.verdict) for e in again.provenance.iter_entries() if e.status is not EntryStatus.COMPACTED}
    assert verdicts == {EntryVerdict}


def test_the_reference_and_journalled_stores_keep_the_new_fields() -> None:
    from sgbelief._fast.journal import JournalledProvenanceStore

    for store in (ProvenanceStore(), JournalledProvenanceStore()):
        store.commit("a", "is_p", "e1", 1, 0.6, 0.4, 1, EntryVerdict.CORROBORATES, 0.8)
        store.commit("a", "is_p", "e2", 2, 0.5, 0.0, 1, EntryVerdict.GEOMETRIC, 0.8)
        store.record("a", "is_p", "e3", 3, 0.1, 0.9, EntryStatus.REFUSED, 1, EntryVerdict.CONTRADICTS, 0.3)
        store.commit("a", "is_p", "e4", 4, 0.2, 0.2)  # the old signature: nothing recorded
        got = [(e.verdict, e.confidence) for e in store.entries("a", "is_p")]
        assert got == [(EntryVerdict.CORROBORATES, 0.8), (EntryVerdict.GEOMETRIC, 0.8),
                       (EntryVerdict.CONTRADICTS, 0.3), (None, None)]
        store.compact(3)
        summary = store.entries("a", "is_p")[0].summary
        assert summary is not None and summary.verdicts == {"⊤": 1, "geometric": 1}
        assert summary.n_lambda_hat == 1 and math.isclose(summary.mean_lambda_hat, 1.5)  # type: ignore[arg-type]


def test_old_json_rows_load_without_verdicts(tmp_path: Path) -> None:
    graph, _, _ = _replay("comod", "fast", n=80)
    path = graph.save(tmp_path / "map")
    doc = json.loads(path.read_text())
    for pair in doc["provenance"]["pairs"]:
        pair["entries"] = [row[:8] for row in pair["entries"]]  # what files before verdicts hold
        if "fold_summary" in pair:
            for k in ("verdicts", "lambda_hat_sum", "n_lambda_hat"):
                pair["fold_summary"].pop(k, None)
    path.write_text(json.dumps(doc))
    old = SceneGraph.load(path)
    assert all(e.verdict is None and e.confidence is None for e in old.provenance.iter_entries())
    key = max(old.provenance.pairs(), key=lambda k: len(old.provenance.entries(*k)))
    story = old.explain(*key)
    assert story.not_recorded.endswith("carry no verdict or confidence (·; ⊥ is known from a refusal status)")
    assert all(e.confidence is None and (e.verdict is None or e.verdict == "⊥") for e in story.events)


def test_old_npz_files_load_without_verdicts(tmp_path: Path) -> None:
    graph, _, _ = _replay("comod", "fast", n=80)
    path = graph.save(tmp_path / "map", format="npz")
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files if k not in ("entry_verdict", "entry_confidence")}
    np.savez(path, **arrays)
    for engine in ("reference", "fast"):
        old = SceneGraph.load(path, engine=engine)  # type: ignore[arg-type]
        assert all(e.verdict is None and e.confidence is None for e in old.provenance.iter_entries())


def test_bad_verdict_codes_and_confidences_are_rejected(tmp_path: Path) -> None:
    graph, _, _ = _replay("comod", "fast", n=30)
    path = graph.save(tmp_path / "map")
    doc = json.loads(path.read_text())
    row = doc["provenance"]["pairs"][0]["entries"][0]
    for bad, message in ((("x", 0.5), "verdict code"), ((7, 0.5), "verdict code"), ((1, 1.5), "confidence")):
        row[8:10] = bad
        path.write_text(json.dumps(doc))
        with pytest.raises(FormatError, match=rf"pairs\[0\]\.entries\[0\]: {message}"):
            SceneGraph.load(path)
    npz = graph.save(tmp_path / "bin", format="npz")
    with np.load(npz, allow_pickle=False) as f:
        arrays = {k: f[k] for k in f.files}
    arrays["entry_verdict"] = arrays["entry_verdict"].copy()
    arrays["entry_verdict"][0] = 9
    np.savez(npz, **arrays)
    with pytest.raises(FormatError, match="array 'entry_verdict': code 9 at entry 0"):
        SceneGraph.load(npz)


# ------------------------------------------------------------------ compaction
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), t_prov=st.sampled_from([4, 10, 30]), engine=st.sampled_from(["fast", "reference"]))
def test_compaction_keeps_verdict_counts_and_mean_lambda_hat(seed: int, t_prov: int, engine: str) -> None:
    compacted, _, _ = _replay("comod", engine, n=150, seed=seed, t_prov=t_prov, t_compact=max(1, t_prov // 2))
    # the same horizon (it also bounds how long a silent claim's weight follows the refits), no pass
    full, _, _ = _replay("comod", engine, n=150, seed=seed, t_prov=t_prov, t_compact=10**6)
    assert full.provenance.n_compacted == 0
    assert compacted.provenance.n_compacted > 0
    folded_any = False
    for key in full.provenance.pairs():
        story, whole = compacted.explain(*key), full.explain(*key)
        assert story.verdicts == whole.verdicts and story.n_claims == whole.n_claims
        if whole.mean_lambda_hat is not None:
            assert math.isclose(story.mean_lambda_hat, whole.mean_lambda_hat, rel_tol=1e-12)  # type: ignore[arg-type]
        folded_any = folded_any or story.folded is not None
        if story.folded is not None:
            assert sum(story.folded.verdicts.values()) == story.folded.n  # every folded entry had one
    assert folded_any


def test_summaries_written_before_verdicts_load_with_none() -> None:
    s = FoldSummary.from_dict({"counts": {"committed": 3}, "t_first": 1, "first_event_id": "a", "last_event_id": "b"})
    assert s.verdicts == {} and s.n_lambda_hat == 0 and s.mean_lambda_hat is None
    with pytest.raises(ValueError, match="unknown verdict"):
        FoldSummary.from_dict({"counts": {}, "t_first": None, "first_event_id": None, "last_event_id": None,
                               "verdicts": {"?": 1}})


# ------------------------------------------------------------------ the CLI
def test_explain_shows_verdicts_and_lambda_hat_of_a_replayed_comod_map(tmp_path: Path, capsys: Any) -> None:
    lines = [json.dumps({"format": "sgbelief.events", "version": 1})]
    t = 0
    for k in range(30):
        for node, label, pred, c in (("s/car", "car", "is_car", 0.8), ("s/car", "car", "is_pedestrian", 0.9)):
            lines.append(json.dumps({"t": t, "id": f"e{t}", "targets": {node: 1.0}, "predicate": pred,
                                     "confidence": c - 0.01 * (k % 7), "context": "vlm", "geometric": {node: label}}))
            t += 1
    (tmp_path / "events.jsonl").write_text("\n".join(lines) + "\n")
    (tmp_path / "truth.json").write_text(json.dumps({"s/car": {"is_car": 1, "is_pedestrian": 0}}))
    (tmp_path / "op.yaml").write_text("t_prov: 20\nt_compact: 10\n")
    assert main(["replay", str(tmp_path / "events.jsonl"), "--truth", str(tmp_path / "truth.json"), "--vocab",
                 "kitti360", "--operators", "comod", "--config", str(tmp_path / "op.yaml"), "--no-progress",
                 "--save-graph", str(tmp_path / "maps")]) == 0
    capsys.readouterr()
    assert main(["explain", str(tmp_path / "maps" / "comod"), "s/car", "is_pedestrian", "--limit", "0"]) == 0
    out = capsys.readouterr().out
    # every label observed; the early claims contradicted, the later ones (calibrated: the model's
    # 0.9 on a car now denies "pedestrian") corroborated
    # (exclusion: the 29 is_car claims that committed count against is_pedestrian, exclusive_evidence: rivals)
    assert "verdicts: 30 geometric, 29 exclusion, 18 ⊤, 12 ⊥; mean Λ̂ " in out
    assert "compacted (t=" in out and "mean Λ̂" in out
    assert " ⊤ " in out and " geo " in out and "e59" in out
    assert "key: v: verdict" in out and "· = not recorded" in out
    assert "Not committed: P = " in out and "30 claims, mean Λ̂ " in out
    assert main(["explain", str(tmp_path / "maps" / "comod"), "s/car", "is_pedestrian", "--json"]) == 0
    story = json.loads(capsys.readouterr().out)["stories"][0]
    assert story["verdicts"] == {"⊤": 18, "⊥": 12, "geometric": 30, "exclusion": 29} and story["n_claims"] == 30
    assert story["folded"]["verdicts"]["⊥"] > 0 and story["folded"]["mean_lambda_hat"] > 0
    claim = next(e for e in story["events"] if e["verdict"] == "⊤")
    assert claim["confidence"] is not None and claim["recorded"]
    assert math.isclose(claim["lambda_hat"], claim["d_alpha"] / claim["d_beta"])
    assert math.isclose(claim["weight"], claim["d_alpha"] + claim["d_beta"])

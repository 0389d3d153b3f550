"""Smoke runs of benchmark scripts at tiny sizes (they must keep working; no timing is asserted)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def test_latency_benchmark_reports_both_schedules() -> None:
    out = subprocess.run(
        [sys.executable, str(BENCH / "bench_latency.py"), "--events", "24000", "--pairs", "600",
         "--events-per-step", "10", "--operator", "majority", "--intervals", "default,10", "--json"],
        capture_output=True, text=True, check=True, timeout=900,
    ).stdout
    res = json.loads(out.strip().splitlines()[-1])
    default, short = res["schedules"]["default"], res["schedules"]["10"]
    assert default["steps"] == short["steps"] == 2400
    assert default["compaction_passes"] == 2 and short["compaction_passes"] == 239
    # the same horizon: a short interval folds at least what the default schedule folded
    assert short["compacted_entries"] >= default["compacted_entries"] > 0
    assert short["max_step_ratio_to_first"] > 0 and short["throughput_ratio_to_first"] > 0


def test_ab_benchmark_compares_two_checkouts() -> None:
    """Smoke test: the same checkout as old and new gives positive costs for both sides."""
    root = str(BENCH.parent)
    out = subprocess.run(
        [sys.executable, str(BENCH / "bench_ab.py"), "--old", root, "--new", root, "--operators", "majority",
         "--rounds", "1", "--repeat", "1", "--new-mode", "many", "--json"],
        capture_output=True, text=True, check=True, timeout=900,
    ).stdout
    res = json.loads(out.strip().splitlines()[-1])
    assert (res["old_mode"], res["new_mode"]) == ("update", "many")
    row = res["operators"]["majority"]
    assert row["old_min"] > 1.0 and row["new_min"] > 1.0 and row["speedup"] > 0


def test_large_map_benchmark_round_trips_and_reports_every_step(tmp_path: Path) -> None:
    """Smoke test: both formats round-trip (``--verify``), the load is deferred and then
    materialised, and the object floor and every named query are reported."""
    out = subprocess.run(
        [sys.executable, str(BENCH / "bench_large_map.py"), "--nodes", "3000", "--verify", "--json"],
        capture_output=True, text=True, check=True, timeout=900, env={**os.environ, "BENCH_TMP": str(tmp_path)},
    ).stdout
    res = json.loads(out.strip().splitlines()[-1])
    assert res["verified_equal"] is True and res["npz_load_deferred"] is True
    assert res["log_entries"] > 0 and res["named_queries"] == len(res["query_s"]) > 0
    for step in ("npz_save", "save_floor", "npz_load", "objects_floor", "npz_materialize", "json_save", "json_load"):
        assert res[f"{step}_s"] >= 0
    assert res["npz_load_materialized_json_equiv_mb_per_s"] > 0 and res["objects_floor_json_equiv_mb_per_s"] > 0
    assert res["save_floor_json_equiv_mb_per_s"] > 0


def test_throughput_benchmark_reports_both_normalisations() -> None:
    """Smoke test: a subset of operators, events/s and reference iterations per event for each
    setting; an unknown operator name is refused with the valid names."""
    script = str(BENCH / "bench_throughput.py")
    out = subprocess.run(
        [sys.executable, script, "--operators", "majority", "--repeat", "1", "--scale", "0.1", "--json"],
        capture_output=True, text=True, check=True, timeout=900,
    ).stdout
    res = json.loads(out.strip().splitlines()[-1])
    assert list(res["operators"]) == ["majority"] and res["reference_loop_events_per_s"] > 0
    row = res["operators"]["majority"]
    assert set(row["ref_iterations_per_event"]) == {"report", "no_report", "replay", "many"}
    assert all(v > 1.0 for v in row["ref_iterations_per_event"].values())  # no operator beats one dict increment
    assert row["events_per_s_many"] > 0 and 0 < row["ratio_to_ref_many"] < 1
    bad = subprocess.run([sys.executable, script, "--operators", "majority,nope"], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 2 and "nope" in bad.stderr and "comod" in bad.stderr


def test_vote_diff_summary_counts_ties_and_reasons(tmp_path: Path, capsys) -> None:
    """cg_vote_diff.py: ConceptGraphs' vote with each branch's tie rule, the vote with ties at
    random, and the reason per differing object, on a hand-written run record."""
    sys.path.insert(0, str(BENCH))
    try:
        import cg_vote_diff as D
    finally:
        sys.path.remove(str(BENCH))
    classes = ["chair", "sofa", "stool"]
    assert D.vote(["stool", "chair"], "main", classes) == "chair"  # np.unique: the lowest class id
    assert D.vote(["stool", "chair"], "ali-dev", classes) == "stool"  # Counter: the first seen
    assert D.vote(["stool", "chair"], "main", classes, reverse=True) == "stool"
    objects = [{"class_ids": ["stool", "chair"], "routed": {"stool": 1, "chair": 1}, "node": "a"},  # tie
               {"class_ids": ["sofa", "sofa", "chair"], "routed": {"sofa": 2, "chair": 2}, "node": "b"},  # split
               {"class_ids": ["sofa", "sofa", "chair"], "routed": {"sofa": 2, "chair": 1}, "node": "c"},  # ranking
               {"class_ids": ["sofa"], "routed": {"sofa": 1}, "node": "d"}]  # unknown
    rec = {"seed": 0, "branch": "main", "confidences": "uniform", "channel": "none", "classes": classes,
           "truth": ["stool", "chair", "sofa", "sofa"], "labels": ["stool", "chair", "chair", "unknown"],
           "acc": 0.5, "objects": objects}
    assert [D.why_differs(o, lab) for o, lab in zip(objects, rec["labels"])] == ["tie", "split", "ranking", "unknown"]
    path = tmp_path / "runs.jsonl"
    path.write_text(json.dumps(rec) + "\n")
    D.summarise([str(path)])
    out = capsys.readouterr().out
    assert "vote                       0.500" in out  # chair (wrong), sofa (wrong), sofa, sofa
    assert "vote, ties at random       0.625" in out  # the tie counts 1/2
    assert "comod                      0.500" in out
    rows = {}
    for line in out.splitlines():
        if line.strip().startswith("differ,"):
            words = line.replace(",", " ").split()  # differ REASON N objects: vote right V comod right C
            rows[words[1]] = (int(words[2]), int(words[6]), int(words[9]))
    assert rows == {"tie": (1, 0, 1), "split": (1, 0, 1), "ranking": (1, 1, 0), "unknown": (1, 1, 0)}


def test_vote_diff_summary_names_the_rooms_that_read_their_scores(tmp_path: Path, capsys) -> None:
    """cg_vote_diff.py --summarise: the rooms whose rank test read the scores, with their p-value
    and gap to the vote, and the mean gap over the rooms counted."""
    sys.path.insert(0, str(BENCH))
    try:
        import cg_vote_diff as D
    finally:
        sys.path.remove(str(BENCH))
    classes = ["chair", "stool"]
    objects = [{"class_ids": ["chair", "chair"], "routed": {"chair": 2}, "node": "a"},
               {"class_ids": ["stool", "chair"], "routed": {"stool": 1, "chair": 1}, "node": "b"}]  # a tie

    def room(seed: int, labels: list[str], p: float, read: bool) -> dict:
        return {"seed": seed, "branch": "main", "confidences": "low", "channel": "none", "classes": classes,
                "truth": ["chair", "chair"], "labels": labels, "acc": sum(x == "chair" for x in labels) / 2,
                "objects": objects, "readings": {"det": {"p": p, "reads_scores": read, "claims": 4}}}

    path = tmp_path / "runs.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in (room(0, ["chair", "chair"], 0.40, False),
                                                       room(1, ["chair", "stool"], 0.02, True))) + "\n")
    D.summarise([str(path)])
    out = capsys.readouterr().out
    assert "scores read in 1 of 2 rooms (seed, rank test p, comod - vote: 1 0.020 -0.500)" in out
    # the counted room equals the vote (1.0), and the vote with its tie at random is 0.75
    assert "counted rooms: comod - vote +0.000, comod - vote with ties at random +0.250" in out

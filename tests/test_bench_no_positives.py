"""The bench applies replay's rule: a class or a compound with no positives is n/a, not a score."""

from __future__ import annotations

import math

from sgbelief.eval.benchmark import render_markdown
from sgbelief.eval.metrics import per_predicate_scores, retrieval_f1
from sgbelief.eval.retrieval import CompoundScore, format_scores


def _score(query: str, operator: str, retrieved: set[str], positives: set[str], n: int = 4) -> CompoundScore:
    s = retrieval_f1(retrieved, positives)
    return CompoundScore(query, query.replace("_", " "), "", operator, n, len(positives), len(positives) / n,
                         len(retrieved), s.tp, s.fp, s.fn, s.precision, s.recall, s.f1)


SCORES = [_score("car_near_car", "comod", {"a"}, {"a", "b"}), _score("jaywalking", "comod", {"c"}, set()),
          _score("car_near_car", "majority", set(), {"a", "b"}), _score("jaywalking", "majority", set(), set())]


def test_retrieval_table_prints_na_for_a_compound_with_no_positives() -> None:
    assert math.isnan(SCORES[1].f1) and math.isnan(SCORES[3].f1)
    rows = {line.split()[0]: line.split() for line in format_scores(SCORES).splitlines()[2:4]}
    assert rows["car"][-2:] == ["0.667", "0.000"]
    assert rows["jaywalking"][-2:] == ["n/a", "n/a"]  # was 0.000 and 1.000


def test_bench_markdown_prints_na_and_names_the_classes_without_positives() -> None:
    truth = {"n1": {"is_car": 1, "is_pedestrian": 0, "is_traffic_sign": 0},
             "n2": {"is_car": 0, "is_pedestrian": 0, "is_traffic_sign": 1}}
    per = per_predicate_scores({"n1": {"is_car": 0.9}, "n2": {"is_traffic_sign": 0.9, "is_pedestrian": 0.8}}, truth,
                               ["is_car", "is_pedestrian", "is_traffic_sign"])
    sc = {"per_predicate": {p: s.as_dict() for p, s in per.items()}, "mean_iou": 1.0, "brier": 0.1, "refusals": 0}
    results = {"meta": {"seed": 0, "tau": 0.5}, "suites": {"outdoor": {
        "title": "outdoor", "events": 3, "table2": {"comod": sc},
        "vlm_swap": {"comod": {"brier_vlm_a": 0.1, "brier_vlm_b": 0.1, "delta": 0.0, "mean_iou_vlm_a": 1.0,
                               "mean_iou_vlm_b": 1.0}},
        "retrieval": [s.to_dict() for s in SCORES]}}}
    md = render_markdown(results)
    row = next(line for line in md.splitlines() if line.startswith("| **comod**"))
    assert "| n/a (0.00 / n/a) |" in row
    assert "n/a: is_pedestrian has no positives in this suite's truth" in md
    jay = next(line for line in md.splitlines() if line.startswith("| jaywalking"))
    assert jay.endswith("| n/a | n/a |")
    assert "n/a: a compound with no positives in its pool has no F1." in md

"""Table 4 (component beliefs against one monolithic compound prompt) over several seeds.

    python benchmarks/compound_heldout.py --seeds 100-104 --out results/compound_heldout
    python benchmarks/compound_heldout.py --seeds 100-104 --out results/compound_heldout --reuse

Runs ``sgbelief bench --seed N --operators comod --no-real`` for each seed (the table needs only
the operator it compares), then averages every cell of Table 4 over the seeds and counts, per
compound, the seeds on which the operator's intersection F1 beats both cold baselines. ``--reuse``
only aggregates the ``seed<N>/results.json`` files already in ``--out``. The held-out seeds
(100-104) were not looked at while the monolithic channel was written (docs/simulation.md).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sgbelief.cli.bench import parse_seeds  # noqa: E402



def _cells(rep: dict[str, Any], row: dict[str, Any]) -> dict[str, float | None]:
    sw = rep.get("swap", {}).get("rows", {}).get(row["query"], {})
    return {"pool_n": row["pool_n"], "pos_rate": row["pool_rate"], "pool_f1": row["pool_operator"]["f1"], "n": row["n"],
            "cold_raw": row["cold_raw"]["f1"], "cold_m": None if row["cold_m"] is None else row["cold_m"]["f1"],
            "operator": None if row["operator"] is None else row["operator"]["f1"],
            "swap_operator": sw.get("operator"), "swap_cold_m": sw.get("cold_m"), "swap_cold_raw": sw.get("cold_raw")}


def aggregate(per_seed: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """suite -> query -> {title, group, cell: [values per seed], wins, scored}."""
    out: dict[str, Any] = {}
    for _seed, results in sorted(per_seed.items()):
        for suite, res in results["suites"].items():
            rep = res.get("compound_table")
            if rep is None:
                continue
            for row in rep["rows"]:
                q = out.setdefault(suite, {}).setdefault(row["query"], {"title": row["title"], "group": row["group"],
                                                                       "values": {}, "wins": 0, "scored": 0})
                cells = _cells(rep, row)
                for k, v in cells.items():
                    q["values"].setdefault(k, []).append(v)
                if cells["operator"] is not None and cells["cold_m"] is not None:
                    q["scored"] += 1
                    q["wins"] += int(cells["operator"] > max(cells["cold_raw"], cells["cold_m"]))
    return out


def _mean(xs: list[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return sum(v) / len(v) if v else None


def _fmt(x: float | None, d: int = 3) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:.{d}f}"


def render(agg: dict[str, Any], seeds: list[int]) -> str:
    lines = [f"Table 4 averaged over seeds {seeds[0]}-{seeds[-1]} ({len(seeds)} seeds; comod, shipped default "
             f"configuration; F1 at P > 0.5; '–' where the intersection had n < 20 on every seed)", ""]
    for suite, rows in agg.items():
        lines += [f"**{suite}**", "",
                  "| compound | pool n | pos % | F1 comod | ∩ n | cold raw | cold + M | comod | comod wins | "
                  "max swap \\|ΔF1\\| raw / +M / comod |", "|---|---|---|---|---|---|---|---|---|---|"]
        for q in rows.values():
            v = q["values"]
            sw = {k: [x for x in v[k] if x is not None] for k in ("swap_cold_raw", "swap_cold_m", "swap_operator")}
            lines.append(
                f"| {q['title']} | {_mean(v['pool_n']):.0f} | {100 * _mean(v['pos_rate']):.1f} | {_fmt(_mean(v['pool_f1']))} | "
                f"{_mean(v['n']):.0f} | {_fmt(_mean(v['cold_raw']))} | {_fmt(_mean(v['cold_m']))} | "
                f"{_fmt(_mean(v['operator']))} | {q['wins']}/{q['scored']} | "
                + " / ".join(_fmt(max(x) if x else None) for x in sw.values()) + " |")
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="100-104", help="seeds as a list or a range (default: %(default)s, held out)")
    ap.add_argument("--out", type=Path, default=Path("results/compound_heldout"), help="output folder (default: %(default)s)")
    ap.add_argument("--reuse", action="store_true", help="aggregate existing seed<N>/results.json only (default: run)")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    per_seed: dict[int, dict[str, Any]] = {}
    for seed in seeds:
        path = args.out / f"seed{seed}" / "results.json"
        if not args.reuse:
            from sgbelief.eval.benchmark import run_bench

            print(f"seed {seed}: sgbelief bench --seed {seed} --operators comod --no-real", file=sys.stderr, flush=True)
            run_bench(["outdoor", "indoor"], seed=seed, out=path.parent, operators=["comod"], real_data=False)
        per_seed[seed] = json.loads(path.read_text(encoding="utf-8"))
    agg = aggregate(per_seed)
    md = render(agg, seeds)
    (args.out / "compound_table.md").write_text(md + "\n", encoding="utf-8")
    (args.out / "compound_table.json").write_text(json.dumps({"seeds": seeds, "suites": agg}, indent=1) + "\n",
                                                  encoding="utf-8")
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

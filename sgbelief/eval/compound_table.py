"""Table 4: component beliefs against one monolithic compound prompt (§"Compositional retrieval").

For each named compound Q, on top of the operator's full pool (``sgbelief.eval.retrieval``):

* **intersection** I(Q): the pool nodes the monolithic prompt answered (visible elements: an
  unoccluded view, :mod:`sgbelief.eval.sim_monolithic`); the positives are the pool's, restricted;
* **cold raw**: retrieved when the prompt's raw confidence c > tau;
* **cold + M**: retrieved when the Mondrian isotonic recalibration of c (the calibrator the
  operators use, :class:`~sgbelief.calibration.mondrian.MondrianCalibrator`, at their finest level:
  one slice per (model, Q)) gives p_hat > tau. ``calibrated_probability`` reads the finest fitted
  slice, so the coarser levels of the operators' hierarchy would only be read for a compound with
  no verifiable outcome outside a fold, which then stays raw (c itself); leaving them out gives the
  same numbers five times faster. It is fitted on the *verifiable* outcomes: the geometric
  channel's label of the element in the crop's frame decides the object part (the vocabulary's
  outcome, as for a component claim), the map geometry the relations; an undecided label gives no
  outcome. Cross-fitted over ``folds`` = 10 folds of elements: an element's answers are
  recalibrated by a calibrator that never saw any outcome of that element (any compound);
* **operator**: the operator's retrieved set (P(Q) > tau) restricted to I(Q);
* n(I) < ``min_n`` = 20: cold + M and operator are "–" (too few for 10 folds), as in the paper.

The cost note counts model calls: the operator pays one call per component claim and reuses a
predicate's claims for every compound over it; the monolithic prompt pays one call per (element,
compound).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from sgbelief.calibration.config import CalibrationConfig
from sgbelief.calibration.mondrian import MondrianCalibrator, by_context_and_predicate
from sgbelief.eval.metrics import retrieval_f1
from sgbelief.eval.sim_monolithic import MonolithicRecord

__all__ = ["MIN_N", "FOLDS", "Cell", "CompoundRow", "ModelView", "suite_compound_table", "suite_folder_table",
           "bench_section", "assign_folds", "cross_fitted_probabilities",
           "verifiable_outcome", "intersection", "compare_compounds", "compound_cost", "compound_report",
           "render_markdown", "format_text"]

#: intersections smaller than this are marked "–" (too few elements for stable 10-fold cross-fitting)
MIN_N = 20
#: folds of the cross-fitted recalibration
FOLDS = 10

_Plans = tuple[Mapping[str, Mapping[Any, "bool | None"]], Mapping[str, tuple[Any, Sequence[Any], set[Any]]]]


@dataclass(frozen=True)
class Cell:
    """F1 of one approach on one set: retrieved (commits), true positives, F1."""

    commits: int
    tp: int
    f1: float

    @classmethod
    def of(cls, retrieved: set[Any], positives: set[Any]) -> Cell:
        s = retrieval_f1(retrieved, positives)
        return cls(len(retrieved), s.tp, s.f1)


@dataclass(frozen=True)
class CompoundRow:
    """One row of Table 4."""

    query: str
    title: str
    group: str
    pool_n: int
    pool_positives: int
    pool_operator: Cell
    n: int
    positives: int
    cold_raw: Cell
    cold_m: Cell | None  # None: n < min_n
    operator: Cell | None  # None: n < min_n

    @property
    def pool_rate(self) -> float:
        return self.pool_positives / self.pool_n if self.pool_n else 0.0

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["pool_rate"] = self.pool_rate
        return d


def assign_folds(nodes: Sequence[Any], folds: int = FOLDS, seed: int = 0) -> dict[Any, int]:
    """Element -> fold in [0, folds): a seeded permutation of the sorted elements, dealt round robin."""
    order = sorted(set(nodes), key=str)
    perm = np.random.default_rng(seed).permutation(len(order))
    return {order[int(j)]: k % folds for k, j in enumerate(perm)}


def cross_fitted_probabilities(
    items: Sequence[tuple[Any, str, str, float, int | None]],
    fold_of: Mapping[Any, int],
    folds: int = FOLDS,
    *,
    calibrator: Callable[[], Any] | None = None,
) -> list[float]:
    """Recalibrated probability of each ``(element, context, query, c, outcome)`` item, fitted on
    the verifiable outcomes (outcome not None) of the *other* folds' elements only.

    ``calibrator()`` makes a fresh calibrator with ``add(context, predicate, c, y)``, ``refit_all()``
    and ``calibrated_probability(c, context, predicate)`` (default: the operators'
    ``MondrianCalibrator()`` at its finest level, one slice per (context, predicate))."""
    make = calibrator or (lambda: MondrianCalibrator(groups=(by_context_and_predicate,)))
    out = [math.nan] * len(items)
    for f in range(folds):
        members = [i for i, it in enumerate(items) if fold_of[it[0]] == f]
        if not members:
            continue
        cal = make()
        for node, ctx, q, c, y in items:
            if y is not None and fold_of[node] != f:
                cal.add(ctx, q, c, y)
        cal.refit_all()
        for i in members:
            _, ctx, q, c, _ = items[i]
            out[i] = cal.calibrated_probability(c, ctx, q)
    return out


def verifiable_outcome(label_outcome: int | None, relations: Sequence[bool | None]) -> int | None:
    """The outcome the geometric side can verify for a compound claim: the channel's outcome of the
    object part (None: undecided -> no outcome; 0 -> 0), then every relation literal from the map
    geometry (an undefined relation does not hold)."""
    if label_outcome is None:
        return None
    if label_outcome == 0:
        return 0
    return int(all(bool(r) for r in relations))


def intersection(pool: Sequence[Any], answered: set[Any]) -> list[Any]:
    """The apples-to-apples set: pool nodes the monolithic prompt answered, in pool order."""
    return [v for v in pool if v in answered]


def compare_compounds(
    plans: _Plans,
    records: Sequence[MonolithicRecord],
    vocabulary: Any,
    operator_retrieved: Mapping[str, set[Any]],
    *,
    tau: float = 0.5,
    calibration: CalibrationConfig | None = None,
    alpha: float = 0.1,
    seed: int = 0,
    folds: int = FOLDS,
    min_n: int = MIN_N,
) -> list[CompoundRow]:
    """Table 4's rows (see the module docstring). ``plans``: :func:`sgbelief.eval.retrieval.retrieval_plans`;
    ``records``: the monolithic answers (one profile); ``operator_retrieved``: the operator's
    retrieved set per query over its full pool."""
    geo_values, compound_plans = plans
    by_query: dict[str, dict[Any, MonolithicRecord]] = {}
    for r in records:
        by_query.setdefault(r.query, {})[r.node] = r
    # the scored items: every intersection element of every compound with n >= min_n
    inter: dict[str, list[Any]] = {}
    items: list[tuple[Any, str, str, float, int | None]] = []
    for key, (nq, pool, _pos) in compound_plans.items():
        answered = by_query.get(key, {})
        inter[key] = intersection(pool, set(answered))
        if len(inter[key]) < min_n:
            continue
        obj = next(lit.name for lit in nq.belief if not lit.negated)
        for v in inter[key]:
            r = answered[v]
            rel = [None if (x := geo_values.get(lit.name, {}).get(v)) is None else (bool(x) != lit.negated)
                   for lit in nq.geometric]
            items.append((v, r.context, key, r.confidence, verifiable_outcome(vocabulary.outcome(obj, r.geometric), rel)))
    fold_of = assign_folds([it[0] for it in items], folds, seed)
    cfg = calibration or CalibrationConfig()
    p_cal = cross_fitted_probabilities(items, fold_of, folds, calibrator=lambda: MondrianCalibrator(
        cfg, alpha, groups=(by_context_and_predicate,)))
    recal: dict[tuple[str, Any], float] = {(it[2], it[0]): p for it, p in zip(items, p_cal)}
    rows: list[CompoundRow] = []
    for key, (nq, pool, positives) in compound_plans.items():
        answered = by_query.get(key, {})
        inter_k = inter[key]
        inter_set = set(inter_k)
        pos_i = positives & inter_set
        raw = {v for v in inter_k if answered[v].confidence > tau}
        small = len(inter_k) < min_n
        cold_m = None if small else Cell.of({v for v in inter_k if recal[(key, v)] > tau}, pos_i)
        op = None if small else Cell.of(operator_retrieved.get(key, set()) & inter_set, pos_i)
        rows.append(CompoundRow(key, nq.title, nq.group, len(pool), len(positives),
                                Cell.of(operator_retrieved.get(key, set()), positives), len(inter_k), len(pos_i),
                                Cell.of(raw, pos_i), cold_m, op))
    return rows


def compound_cost(plans: _Plans, events: Sequence[Any], records: Sequence[MonolithicRecord]) -> dict[str, Any]:
    """Model calls per answered compound: the operator's component claims (one call each, shared by
    every compound over the predicate) against one monolithic call per (element, compound)."""
    _geo, compound_plans = plans
    preds: dict[str, list[str]] = {}
    answers = 0
    for key, (nq, pool, _pos) in compound_plans.items():
        for lit in nq.belief:
            if not lit.negated:
                preds.setdefault(lit.name, []).append(key)
        answers += len(pool)
    calls = {p: 0 for p in preds}
    for rec in events:
        if rec.predicate in calls:
            calls[rec.predicate] += 1
    total = sum(calls.values())
    mono_calls = len(records)
    visible = len({r.node for r in records})
    return {"operator_calls": total, "operator_answers": answers,
            "operator_calls_per_answer": total / answers if answers else math.nan,
            "per_predicate": {p: {"calls": calls[p], "compounds": len(ks)} for p, ks in preds.items()},
            "monolithic_calls": mono_calls, "monolithic_answers": mono_calls,
            "monolithic_calls_per_answer": 1.0 if mono_calls else math.nan,
            "visible_elements": visible, "compounds": len(compound_plans)}


def compound_report(rows: Sequence[CompoundRow], *, operator: str, config_note: str, tau: float,
                    cost: Mapping[str, Any], swap_rows: Sequence[CompoundRow] | None = None,
                    swap_note: str = "", folds: int = FOLDS, min_n: int = MIN_N) -> dict[str, Any]:
    """The JSON-able report of one suite (what bench stores and both renderers read)."""
    rep: dict[str, Any] = {"operator": operator, "config_note": config_note, "tau": tau, "folds": folds,
                           "min_n": min_n, "rows": [r.to_dict() for r in rows], "cost": dict(cost)}
    if swap_rows is not None:
        by = {r.query: r for r in swap_rows}
        swap = {}
        for r in rows:
            b = by.get(r.query)
            if b is None:
                continue

            def delta(x: Cell | None, y: Cell | None) -> float | None:
                return None if x is None or y is None else abs(y.f1 - x.f1)

            swap[r.query] = {"cold_raw": delta(r.cold_raw, b.cold_raw), "cold_m": delta(r.cold_m, b.cold_m),
                             "operator": delta(r.operator, b.operator),
                             "f1_b": {"cold_raw": b.cold_raw.f1, "cold_m": None if b.cold_m is None else b.cold_m.f1,
                                      "operator": None if b.operator is None else b.operator.f1}}
        rep["swap"] = {"note": swap_note, "rows": swap}
    return rep


# ------------------------------------------------------------------------------------- rendering
def _f(x: Any, d: int = 3) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{d}f}"


def _cell(c: Mapping[str, Any] | None) -> str:
    return "–" if c is None else _f(c["f1"])


def _swap(rep: Mapping[str, Any], q: str) -> str:
    s = rep.get("swap", {}).get("rows", {}).get(q)
    if s is None:
        return "–"
    return " / ".join(_f(s[k]) for k in ("cold_raw", "cold_m", "operator"))


def _notes(rep: Mapping[str, Any]) -> list[str]:
    c = rep["cost"]
    op = rep["operator"]
    per = ", ".join(f"{p} {v['calls']:,} calls shared by {v['compounds']} compound{'s' if v['compounds'] != 1 else ''}"
                    for p, v in c["per_predicate"].items())
    lines = [
        f"Operator: `{op}`, configuration: {rep['config_note']}. F1 at P > τ = {rep['tau']}. Full pool: nodes targeted "
        f"by the VLM-typed predicate's claims; intersection: pool nodes the cold monolithic prompt answered (an "
        f"unoccluded view). cold raw: commit at raw confidence > τ; cold + M: the operators' Mondrian isotonic "
        f"recalibration, {rep['folds']}-fold cross-fitted by element on the verifiable outcomes (no element's own "
        f"outcome in its calibration fold). \"–\": intersection n < {rep['min_n']}.",
        f"Model calls per answered compound: operator {_f(c['operator_calls_per_answer'], 2)} ({c['operator_calls']:,} "
        f"component claims for {c['operator_answers']:,} (element, compound) answers over the full pools; {per}); "
        f"monolithic {_f(c['monolithic_calls_per_answer'], 2)} ({c['monolithic_calls']:,} calls: one per visible "
        f"element and compound). One more compound over a mapped predicate costs the operator 0 calls and the "
        f"monolithic prompt {c['visible_elements']:,}.",
    ]
    sparse = [r for r in rep["rows"] if r["pool_n"] and r["positives"] < 0.01 * max(r["n"], 1) and r["n"] >= rep["min_n"]]
    if sparse:
        lines.append("Sparse compounds (< 1 % positive on the intersection), commits (true positives): " + "; ".join(
            f"{r['title']}: cold raw {r['cold_raw']['commits']} ({r['cold_raw']['tp']}), "
            f"{op} {r['operator']['commits']} ({r['operator']['tp']}) of {r['positives']} positives" for r in sparse) + "."
            + (" With no positive, F1 is 1 when nothing is committed and 0 otherwise." if any(
                r["positives"] == 0 for r in sparse) else ""))
    if "swap" in rep:
        lines.append(f"Model swap ({rep['swap']['note']}): |ΔF1| on the intersection, cold raw / cold + M / {op}.")
    return lines


def render_markdown(rep: Mapping[str, Any], title: str = "") -> list[str]:
    """Table 4 as markdown lines (full pool | intersection | model-swap agreement), then its notes."""
    op = rep["operator"]
    swap = "swap" in rep
    head = f"| compound | pool n | pos % | F1 {op} | ∩ n | cold raw | cold + M | {op} |" + (
        f" swap \\|ΔF1\\| raw / +M / {op} |" if swap else "")
    out = ([title, ""] if title else []) + [head, "|---" * (9 if swap else 8) + "|"]
    group = None
    for r in rep["rows"]:
        if r["group"] and r["group"] != group:
            group = r["group"]
            out.append(f"| *{group}* |" + " |" * (8 if swap else 7))
        op_i = r["operator"]
        best = _f(op_i["f1"]) if op_i is not None else "–"
        if op_i is not None and r["cold_m"] is not None and op_i["f1"] > max(r["cold_raw"]["f1"], r["cold_m"]["f1"]):
            best = f"**{best}**"
        out.append(f"| {r['title']} | {r['pool_n']:,} | {100 * r['pool_rate']:.1f} | {_f(r['pool_operator']['f1'])} | "
                   f"{r['n']:,} | {_cell(r['cold_raw'])} | {_cell(r['cold_m'])} | {best} |"
                   + (f" {_swap(rep, r['query'])} |" if swap else ""))
    return out + [""] + _notes(rep)


def format_text(rep: Mapping[str, Any], title: str = "") -> str:
    """Table 4 as plain text (``sgbelief retrieval``)."""
    op = rep["operator"]
    swap = "swap" in rep
    w = max([len("compound")] + [len(r["title"]) for r in rep["rows"]])
    head = (f"{'compound'.ljust(w)}  {'pool n':>7} {'pos %':>6} {'F1':>6}  {'∩ n':>6} {'raw':>6} {'+M':>6} "
            f"{op[:6]:>6}" + (f"  {'swap |ΔF1| raw/+M/' + op:>26}" if swap else ""))
    lines = ([title] if title else []) + [f"{'':{w}}  {'full pool (' + op + ')':^21}  {'intersection':^27}", head,
                                          "-" * len(head)]
    group = None
    for r in rep["rows"]:
        if r["group"] and r["group"] != group:
            group = r["group"]
            lines.append(f"[{group}]")
        lines.append(f"{r['title'].ljust(w)}  {r['pool_n']:>7d} {100 * r['pool_rate']:>6.1f} "
                     f"{_f(r['pool_operator']['f1']):>6}  {r['n']:>6d} {_cell(r['cold_raw']):>6} {_cell(r['cold_m']):>6} "
                     f"{_cell(r['operator']):>6}" + (f"  {_swap(rep, r['query']):>26}" if swap else ""))
    notes = [textwrap.fill(n.replace("`", ""), width=max(100, len(head))) for n in _notes(rep)]
    return "\n".join(lines + [""] + notes)


# ------------------------------------------------------------------------------------ one suite
@dataclass(frozen=True)
class ModelView:
    """One foundation model's side of the comparison: its monolithic answers and the operator's
    replayed map (``operator``, ``graph``) under the same model."""

    records: Sequence[MonolithicRecord]
    operator: Any
    graph: Any
    name: str = ""


def suite_compound_table(data: Any, view: ModelView, *, operator: str, config_note: str, tau: float = 0.5,
                         calibration: CalibrationConfig | None = None, alpha: float = 0.1, seed: int = 0,
                         swap: ModelView | None = None) -> dict[str, Any]:
    """Table 4's report for one retrieval source (:class:`sgbelief.eval.retrieval.RetrievalData`):
    ``view`` is the first model, ``swap`` (optional) the second one on the same suite."""
    from sgbelief.eval.retrieval import retrieval_plans, retrieved_sets

    plans = retrieval_plans(data)

    def rows_of(v: ModelView) -> list[CompoundRow]:
        found = retrieved_sets(data, v.operator, v.graph, plans, tau=tau)
        return compare_compounds(plans, v.records, data.vocabulary, found, tau=tau, calibration=calibration,
                                 alpha=alpha, seed=seed)

    rows = rows_of(view)
    swap_rows = rows_of(swap) if swap is not None else None
    note = f"{view.name} → {swap.name}" if swap is not None else ""
    return compound_report(rows, operator=operator, config_note=config_note, tau=tau,
                           cost=compound_cost(plans, data.events, view.records), swap_rows=swap_rows, swap_note=note)


#: the default operator of Table 4 (the paper's)
TABLE_OPERATOR = "comod"
#: the second model of the swap column and the folder its view is written to (``sgbelief retrieval --suite``)
SWAP_PROFILE = "vlm_b"
SWAP_DIR = "model_swap"
#: the operator configuration named in the notes when it is the shipped one
DEFAULT_CONFIG_NOTE = "the shipped default (sgbelief/configs/operators/default.yaml)"


def bench_section(suite: Any, data: Any, runs_a: Mapping[str, Any], runs_b: Mapping[str, Any], *, config: Any,
                  data_dir: Any, profiles: tuple[str, str] = ("vlm_a", SWAP_PROFILE),
                  operator: str = TABLE_OPERATOR) -> dict[str, Any]:
    """Table 4 for one simulated suite inside ``sgbelief bench``: ``{"compound_table": report}``, or
    ``{"compound_table_error": why}`` (reported in the results, never dropped silently).

    The monolithic channel of ``suite`` (the profiles' views, oracle channel) against the
    operator's replays under both models (``runs_a`` / ``runs_b``: name -> ``OperatorRun``). The
    first view is written to ``data_dir/monolithic.jsonl``, the second model's events and answers
    to ``data_dir/model_swap/``, so ``sgbelief retrieval --suite data_dir`` prints the same table."""
    if operator not in runs_a or operator not in runs_b:
        return {"compound_table_error": f"it compares {operator!r}, which the run's operators leave out"}
    try:
        return {"compound_table": _bench_table(suite, data, runs_a[operator], runs_b[operator], config, data_dir,
                                               profiles)}
    except Exception as exc:  # reported in the results, never silently dropped
        return {"compound_table_error": f"{type(exc).__name__}: {exc}"}


def _bench_table(suite: Any, data: Any, run_a: Any, run_b: Any, config: Any, data_dir: Any,
                 profiles: tuple[str, str]) -> dict[str, Any]:
    from pathlib import Path

    from sgbelief.eval.formats import write_events
    from sgbelief.eval.sim_monolithic import monolithic_channel, write_monolithic
    from sgbelief.fusion.config import OperatorConfig

    channel = monolithic_channel(suite)
    first, second = profiles
    recs_a = channel.records(first, "oracle")
    recs_b = channel.records(second, "oracle")
    out = Path(data_dir)
    write_monolithic(out / "monolithic.jsonl", recs_a)
    write_monolithic(out / SWAP_DIR / "monolithic.jsonl", recs_b)
    write_events(out / SWAP_DIR / "events.jsonl", suite.events_for(second, "oracle"))
    ctx = suite.config.vlm.profiles
    for run in (run_a, run_b):  # the retrieval replay's graph holds every node; a bench replay only the targeted ones
        for v in data.nodes:
            if not run.graph.has_node(v):
                run.graph.add_node(v)
    note = DEFAULT_CONFIG_NOTE if config == OperatorConfig.default() else "a user configuration (meta.config)"
    return suite_compound_table(
        data, ModelView(recs_a, run_a.operator, run_a.graph, ctx[first].context),
        operator=run_a.name, config_note=note, tau=config.tau, calibration=config.calibration,
        alpha=config.alpha, swap=ModelView(recs_b, run_b.operator, run_b.graph, ctx[second].context))


def suite_folder_table(path: Any, *, vocab: Any = None, queries: Any = None, operator: str = TABLE_OPERATOR,
                       operator_config: Any = None, tau: float = 0.5) -> dict[str, Any] | None:
    """Table 4 from a suite folder written by ``sgbelief bench`` (``sgbelief retrieval --suite``):
    None when the folder has no ``monolithic.jsonl``; the swap column when ``model_swap/`` holds
    the second model's ``events.jsonl`` and ``monolithic.jsonl``."""
    from dataclasses import replace
    from pathlib import Path

    from sgbelief.eval.formats import read_events
    from sgbelief.eval.retrieval import recorded_channel_factory, replay_operator, suite_retrieval_data
    from sgbelief.eval.sim_monolithic import read_monolithic
    from sgbelief.fusion.config import OperatorConfig

    folder = Path(path)
    if not (folder / "monolithic.jsonl").is_file():
        return None
    config = OperatorConfig.from_yaml(operator_config) if operator_config else OperatorConfig.default()
    note = DEFAULT_CONFIG_NOTE if operator_config is None else f"`{operator_config}`"
    data = suite_retrieval_data(folder, vocab, queries=queries)
    records = read_monolithic(folder / "monolithic.jsonl")
    op, graph = replay_operator(data, operator, config)
    ctx = records[0].context if records else "first model"
    swap = None
    swap_dir = folder / SWAP_DIR
    if (swap_dir / "events.jsonl").is_file() and (swap_dir / "monolithic.jsonl").is_file():
        events_b = read_events(swap_dir / "events.jsonl")
        data_b = replace(data, events=events_b, channel_factory=recorded_channel_factory(events_b))
        recs_b = read_monolithic(swap_dir / "monolithic.jsonl")
        op_b, graph_b = replay_operator(data_b, operator, config)
        swap = ModelView(recs_b, op_b, graph_b, recs_b[0].context if recs_b else "second model")
    return suite_compound_table(data, ModelView(records, op, graph, ctx), operator=op.name, config_note=note,
                                tau=tau, calibration=config.calibration, alpha=config.alpha, swap=swap)

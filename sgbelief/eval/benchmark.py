"""``sgbelief bench``: reproduce the paper's tables on the simulated suites and on real detector scores.

For each suite (outdoor = KITTI-360-like, indoor = ScanNet-like) the seeded simulator produces one
claim stream with two confidence profiles (vlm_a, vlm_b) and two geometric channels (oracle,
segmenter). The six operators replay the stream and are scored on the end-of-stream map:

- Table 2: per-class IoU at tau = 0.5 (vlm_a, oracle channel);
- Table 5: comod with the oracle vs the segmenter channel (IoU / precision / recall, ⊥ rate);
- cross-VLM invariance: Brier score under vlm_a and vlm_b, and its change;
- calibration: raw vs calibrated ECE on a 50/50 split of the verified claims, conformal coverage;
- an ablation of the likelihood-ratio reference (``calibration.lr_reference``: slice vs uniform);
- compound-query retrieval F1 per operator (Table 3 full-pool columns);
- real detector confidences (COCO): per-class isotonic calibration, ECE, coverage (Fig. 1b).

Figures: reliability diagrams, the single-element trace of cal vs comod on a contradicted element
and the final Beta posteriors (Fig. 1 a-c).
"""

from __future__ import annotations

import json
import math
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sgbelief.api.operators import make_operator
from sgbelief.eval.formats import EventRecord
from sgbelief.eval.metrics import conformal_coverage, reliability_bins
from sgbelief.eval.replay import OperatorRun, OperatorScores, make_runs, replay, score_run, to_event
from sgbelief.calibration.mondrian import MondrianCalibrator
from sgbelief.eval.compound_table import bench_section, render_markdown as compound_markdown
from sgbelief.fusion.compatibility import SubsumptionTable
from sgbelief.fusion.config import OperatorConfig
from sgbelief.fusion.registry import OPERATOR_NAMES, PAPER_OPERATOR_NAMES
from sgbelief.graph.belief import BetaBelief
from sgbelief.graph.persistence import atomic_write_text
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.viz.trace_figure import draw_belief_band


@dataclass(frozen=True)
class SuiteSpec:
    name: str
    vocab: str
    predicates: tuple[str, ...]
    title: str


SUITES: dict[str, SuiteSpec] = {
    "outdoor": SuiteSpec("outdoor", "kitti360", ("is_car", "is_pedestrian", "is_traffic_sign"), "KITTI-360-like (simulated)"),
    "indoor": SuiteSpec("indoor", "scannet", ("is_chair", "is_bookshelf", "is_table_or_desk"), "ScanNet-like (simulated)"),
}

Progress = Callable[[str], None]


def _noop(_: str) -> None:
    pass


# ----------------------------------------------------------------------------- replays
def score_operators(
    events: Sequence[EventRecord], operators: Sequence[str], table: SubsumptionTable, truth: dict, preds: Sequence[str],
    config: OperatorConfig,
) -> dict[str, OperatorScores]:
    """Each operator's scores on ``events`` (one replay; the grid scores its cells with this)."""
    return _replay(events, operators, table, truth, preds, config)[0]


def _replay(
    events: Sequence[EventRecord], operators: Sequence[str], table: SubsumptionTable, truth: dict, preds: Sequence[str],
    config: OperatorConfig,
) -> tuple[dict[str, OperatorScores], dict[str, OperatorRun]]:
    """Replay ``events`` under each operator: (scores, runs) by operator name."""
    runs = make_runs(operators, table, config)
    replay(events, runs)
    return {r.name: score_run(r, truth, preds, tau=config.tau) for r in runs}, {r.name: r for r in runs}


def _bot_rate(sc: OperatorScores) -> float:
    s = sc.stats
    decided = s.get("targets", 0) - s.get("below_tau_t", 0)
    return s.get("refused", 0) / decided if decided else math.nan


def _scores_dict(scores: dict[str, OperatorScores]) -> dict[str, Any]:
    return {k: v.as_dict() for k, v in scores.items()}


# ------------------------------------------------------------------------ calibration
def _verified_claims(events: Sequence[EventRecord], table: SubsumptionTable, preds: Sequence[str]) -> tuple[np.ndarray, ...]:
    """(confidence, outcome, context, predicate) of every claim the geometric channel verified."""
    c, y, k, p = [], [], [], []
    for rec in events:
        if rec.predicate not in preds:
            continue
        for node, mass in rec.targets.items():
            out = table.outcome(rec.predicate, rec.geometric.get(node))
            if out is not None and mass > 0.1:
                c.append(rec.confidence), y.append(out), k.append(rec.context), p.append(rec.predicate)
                break
    return np.array(c, float), np.array(y, int), np.array(k, object), np.array(p, object)


def calibration_split(
    c: np.ndarray, y: np.ndarray, keys: Sequence[tuple[str, str]], *, seed: int, alpha: float = 0.1,
) -> dict[str, Any]:
    """Fit the Mondrian isotonic calibrator on a random half, evaluate raw vs calibrated on the other half."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(c))
    fit, ev = perm[: len(c) // 2], perm[len(c) // 2 :]
    cal = MondrianCalibrator(alpha=alpha)
    for i in fit:
        cal.add(keys[i][0], keys[i][1], float(c[i]), int(y[i]))
    cal.refit_all()
    p_cal = np.array([cal.calibrated_probability(float(c[i]), *keys[i]) for i in ev])
    raw_bins = reliability_bins(c[ev], y[ev])
    cal_bins = reliability_bins(p_cal, y[ev])
    sets = [cal.prediction_set(float(c[i]), *keys[i]).labels for i in ev]
    cov = conformal_coverage(sets, y[ev])
    return {
        "n_fit": int(len(fit)),
        "n_eval": int(len(ev)),
        "raw_ece": raw_bins.ece,
        "calibrated_ece": cal_bins.ece,
        "coverage": cov.coverage,
        "mean_set_size": cov.mean_set_size,
        "alpha": alpha,
        "_bins": (raw_bins, cal_bins),
    }


def real_detector_report(seed: int, alpha: float = 0.1) -> dict[str, Any]:
    """Per-class isotonic calibration of real COCO detector scores (netcal records), 50/50 split by image."""
    from sgbelief.eval.detector_records import load_detector_records, split_half

    out: dict[str, Any] = {}
    for name in ("rfcn-resnet-101-iou-0.60", "ssd-resnet-50-v1-iou-0.60"):
        rec = load_detector_records(name)
        a, b = split_half(rec, seed)
        c = np.concatenate([a.score, b.score]).astype(float)
        y = np.concatenate([a.matched, b.matched]).astype(int)
        keys = [(name, str(int(k))) for k in np.concatenate([a.class_id, b.class_id])]
        # split_half already separated images: fit on the first block, evaluate on the second
        n_a = len(a.score)
        cal = MondrianCalibrator(alpha=alpha)
        for i in range(n_a):
            cal.add(keys[i][0], keys[i][1], float(c[i]), int(y[i]))
        cal.refit_all()
        ev = np.arange(n_a, len(c))
        p_cal = np.array([cal.calibrated_probability(float(c[i]), *keys[i]) for i in ev])
        raw_bins, cal_bins = reliability_bins(c[ev], y[ev]), reliability_bins(p_cal, y[ev])
        sets = [cal.prediction_set(float(c[i]), *keys[i]).labels for i in ev]
        cov = conformal_coverage(sets, y[ev])
        out[name] = {
            "n_fit": int(n_a), "n_eval": int(len(ev)), "raw_ece": raw_bins.ece, "calibrated_ece": cal_bins.ece,
            "coverage": cov.coverage, "mean_set_size": cov.mean_set_size, "alpha": alpha, "_bins": (raw_bins, cal_bins),
        }
    return out


# ------------------------------------------------------------------------------ trace
#: the operators Figure 1(a) traces
TRACE_OPERATORS = ("cal", "comod", "comod_paper")
#: Figure 1(a)'s element: the pair with the most geometry-contradicted claims among pairs with at least this many claims
TRACE_MIN_CLAIMS = 10
TRACE_RULE = (f"the (element, predicate) with the largest share of claims that assert it (c >= 0.5) while the "
              f"geometric channel labels the element as not it, among pairs with >= {TRACE_MIN_CLAIMS} claims "
              f"(ties: more claims, then the first in the log)")


def _contradicted_pair(events: Sequence[EventRecord], table: SubsumptionTable, preds: Sequence[str], *,
                       tau_t: float = 0.1) -> tuple[str, str] | None:
    """Figure 1(a)'s element, chosen by :data:`TRACE_RULE` (the truth is not consulted)."""
    claims: dict[tuple[str, str], int] = {}
    contra: dict[tuple[str, str], int] = {}
    for rec in events:
        if rec.predicate not in preds:
            continue
        for node, mass in rec.targets.items():
            if mass <= tau_t:
                continue
            key = (node, rec.predicate)
            claims[key] = claims.get(key, 0) + 1
            if rec.confidence >= 0.5 and table.outcome(rec.predicate, rec.geometric.get(node)) == 0:
                contra[key] = contra.get(key, 0) + 1
    eligible = [k for k in contra if claims[k] >= TRACE_MIN_CLAIMS]
    return max(eligible, key=lambda k: (contra[k] / claims[k], claims[k])) if eligible else None


def belief_preservation_pool(events: Sequence[EventRecord], preds: Sequence[str], *, tau_t: float = 0.1,
                             strong: float = 0.8, weak: float = 0.65) -> set[tuple[str, str]]:
    """The cross-VLM paragraph's pool: pairs where the model first gives a confident verdict
    (max(c, 1 - c) >= ``strong``) and a weaker one later (max(c, 1 - c) < ``weak``). Defined on one
    view (vlm_a) and held fixed under the model swap."""
    seen_strong: set[tuple[str, str]] = set()
    pool: set[tuple[str, str]] = set()
    for rec in events:
        if rec.predicate not in preds:
            continue
        sure = max(rec.confidence, 1.0 - rec.confidence)
        for node, mass in rec.targets.items():
            if mass <= tau_t:
                continue
            key = (node, rec.predicate)
            if key in seen_strong and sure < weak:
                pool.add(key)
            if sure >= strong:
                seen_strong.add(key)
    return pool


def brier_on_pairs(graph: SceneGraph, truth: dict, pairs: set[tuple[str, str]]) -> float:
    """Mean (p - y)^2 of the end-of-stream beliefs over ``pairs`` (nan for an empty pool)."""
    prov = graph.provenance
    # fsum: the mean does not depend on the set's iteration order (string hashing varies per process)
    errs = [(prov.mean(n, p) - truth.get(n, {}).get(p, 0)) ** 2 for n, p in pairs]
    return math.fsum(errs) / len(errs) if errs else math.nan


def element_trace(
    events: Sequence[EventRecord], table: SubsumptionTable, pair: tuple[str, str], config: OperatorConfig,
) -> dict[str, Any]:
    """Posterior mean and 90 % interval of one (node, predicate) after each event that targets it."""
    node, pred = pair
    ops = {name: make_operator(name, config, table) for name in TRACE_OPERATORS}
    graphs = {name: SceneGraph(create_nodes=True) for name in ops}
    trace: dict[str, list] = {name: [] for name in ops}
    contradictions: list[int] = []
    k = 0
    for i, rec in enumerate(events):
        ev, labels = to_event(rec, f"e{i}")
        for name, op in ops.items():
            op.update(graphs[name], ev, labels)
        if rec.predicate == pred and rec.targets.get(node, 0.0) > config.tau_t:
            k += 1
            if rec.confidence >= 0.5 and table.outcome(pred, rec.geometric.get(node)) == 0:
                contradictions.append(k)
            for name in ops:
                b = graphs[name].provenance.belief(node, pred)
                lo, hi = b.interval(0.9)
                trace[name].append((k, b.mean, lo, hi))
    final = {name: graphs[name].provenance.alpha_beta(node, pred) for name in ops}
    return {"node": node, "predicate": pred, "events": k, "contradictions": contradictions, "trace": trace, "final": final}


# ---------------------------------------------------------------------------- figures
_TRACE_COLOURS = {"cal": "#3f7fbf", "comod": "#d9534f", "comod_paper": "#8c8c8c"}

def _plot_reliability(ax: Any, raw: Any, cal: Any, title: str) -> None:
    ax.plot([0, 1], [0, 1], ls="--", color="0.6", lw=1)
    for bins, color, label in ((raw, "#7b3fa0", f"raw (ECE {raw.ece:.3f})"), (cal, "#f0745a", f"calibrated (ECE {cal.ece:.3f})")):
        m = bins.counts > 0
        ax.plot(bins.mean_confidence[m], bins.accuracy[m], marker="o", color=color, label=label)
    # the raw bins' counts (how much each point rests on), as a bar strip along the bottom
    edges = np.linspace(0.0, 1.0, len(raw.counts) + 1)
    share = raw.counts / max(1, int(raw.counts.sum()))
    ax.bar(edges[:-1], 0.25 * share / max(share.max(), 1e-12), width=np.diff(edges), align="edge", color="0.85",
           zorder=0, label=f"raw claims per bin (n = {int(raw.counts.sum())}; tallest = {int(raw.counts.max())})")
    ax.set_xlabel("confidence / calibrated probability")
    ax.set_ylabel("observed frequency")
    # a little room above 1: a bin whose claims are all right (observed frequency 1) stays in view
    ax.set_xlim(0, 1), ax.set_ylim(0, 1.05)
    ax.set_title(title, fontsize=9)
    # under the axes, where no point can be: inside, some panel always has points in the corner
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), borderaxespad=0.0)


def make_figures(results: dict[str, Any], out: Path, real: dict[str, Any], sim_cal: dict[str, Any], traces: dict[str, Any]) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import stats

    paths: list[Path] = []
    # Figure 1: (a) trace, (b) reliability, (c) final posteriors
    suite = next((s for s in ("outdoor", "indoor") if traces.get(s)), None)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.8))
    if suite is not None:
        tr = traces[suite]
        truth = tr.get("truth", 0)
        for name, color in _TRACE_COLOURS.items():
            arr = np.array(tr["trace"][name])
            draw_belief_band(axes[0], arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3], colour=color, name=name)
        for k in tr["contradictions"]:
            axes[0].axvline(k, color="0.85", lw=0.6, zorder=0)
        axes[0].axhline(0.5, color="0.5", ls=":", lw=1)
        axes[0].set_ylim(0, 1)
        axes[0].set_xlabel(f"claim at {tr['node']} ({tr['predicate']}); grey: geometry says not")
        axes[0].set_ylabel(f"posterior mean (truth: {truth})")
        axes[0].set_title(f"(a) {tr['events']} claims, {len(tr['contradictions'])} asserted against the geometry", fontsize=9)
        axes[0].legend(fontsize=7)
        xs = np.linspace(0.001, 0.999, 400)
        for name, color in _TRACE_COLOURS.items():
            a, b = tr["final"][name]
            axes[2].plot(xs, stats.beta(a, b).pdf(xs), color=color, label=f"{name}: Beta({a:.1f}, {b:.1f}), mean {a / (a + b):.2f}")
        axes[2].axvline(float(truth), color="k", lw=2, label=f"truth ({truth})")
        axes[2].set_xlabel("P(predicate)")
        axes[2].set_title(f"(c) final Beta posteriors (truth {truth})", fontsize=9)
        axes[2].legend(fontsize=7)
    raw, cal = next(iter(real.values()))["_bins"] if real else sim_cal[next(iter(sim_cal))]["_bins"]
    _plot_reliability(axes[1], raw, cal, f"(b) reliability, real detector ({next(iter(real)) if real else 'sim'}), held-out half")
    fig.tight_layout()
    p = out / "figure1.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    # reliability diagrams for every calibration source
    sources = [(f"sim {k}", v) for k, v in sim_cal.items()] + [(f"real {k}", v) for k, v in real.items()]
    fig, axes = plt.subplots(1, len(sources), figsize=(4 * len(sources), 4.6), squeeze=False)
    for ax, (title, rep) in zip(axes[0], sources):
        _plot_reliability(ax, *rep["_bins"], title)
    fig.tight_layout()
    p = out / "reliability.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths


# ----------------------------------------------------------------------------- driver
def run_bench(
    suites: Sequence[str] = ("outdoor", "indoor"),
    *,
    seed: int = 0,
    out: str | Path = "results/bench",
    operators: Sequence[str] = OPERATOR_NAMES,
    config: OperatorConfig | None = None,
    fm_source: str | None = None,
    scale: float | None = None,
    retrieval: bool = True,
    real_data: bool = True,
    progress: Progress = _noop,
    workers: int = 1,
    executor: str = "local",
) -> dict[str, Any]:
    """Run the whole benchmark; writes results.json, results.md and figures into ``out``.

    ``workers`` > 1 (or ``executor="ray"``) runs the suites in parallel; results are identical.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config_note = "the shipped default (sgbelief/configs/operators/default.yaml)" if config is None else "a user config"
    config = config or OperatorConfig.default()
    if config == OperatorConfig.default():
        config_note = "the shipped default (sgbelief/configs/operators/default.yaml)"
    started = time.perf_counter()
    results: dict[str, Any] = {"meta": {"seed": seed, "suites": list(suites), "operators": list(operators),
                                        "python": platform.python_version(), "machine": platform.machine(),
                                        "config_note": config_note, "tau": config.tau, "config": config.model_dump()},
                               "suites": {}}
    jobs = [_SuiteJob(name, seed, str(out), tuple(operators), config.model_dump(), fm_source, scale, retrieval)
            for name in suites]
    sim_cal: dict[str, Any] = {}
    traces: dict[str, Any] = {}
    if workers > 1 or executor != "local":
        from sgbelief.eval.parallel import run_scenes

        progress(f"{len(jobs)} suites on {workers} workers ({executor})")
        outcomes = run_scenes(_bench_suite, jobs, workers=workers, executor=executor)
    else:
        outcomes = [_bench_suite(job, progress) for job in jobs]
    for name, (res, cal_report, trace) in zip(suites, outcomes):
        results["suites"][name] = res
        if cal_report is not None:
            sim_cal[name] = cal_report
        if trace is not None:
            traces[name] = trace
    real: dict[str, Any] = {}
    if real_data:
        progress("real detector confidences: per-class calibration")
        real = real_detector_report(seed, config.alpha)
        results["real_calibration"] = {k: {kk: v for kk, v in r.items() if not kk.startswith("_")} for k, r in real.items()}
    progress("figures")
    figs = make_figures(results, out, real, sim_cal, traces)
    results["figures"] = [str(p.name) for p in figs]
    results["meta"]["seconds"] = time.perf_counter() - started
    atomic_write_text(out / "results.json", json.dumps(_jsonable(results), indent=2))
    atomic_write_text(out / "results.md", render_markdown(results))
    return results


@dataclass(frozen=True)
class _SuiteJob:
    name: str
    seed: int
    out: str
    operators: tuple[str, ...]
    config: dict[str, Any]
    fm_source: str | None
    scale: float | None
    retrieval: bool


def _bench_suite(job: _SuiteJob, progress: Progress = _noop) -> tuple[dict[str, Any], dict[str, Any] | None, dict[str, Any] | None]:
    """Everything bench measures on one simulated suite (module-level so it can run in a worker)."""
    from sgbelief.eval.simulate import simulate

    name, seed, operators = job.name, job.seed, list(job.operators)
    config = OperatorConfig.from_mapping(job.config)
    spec = SUITES[name]
    progress(f"{name}: simulating")
    suite = simulate(name, seed, fm_source=job.fm_source, scale=job.scale)
    table = SubsumptionTable.shipped(spec.vocab)
    preds = list(spec.predicates)
    data_dir = Path(job.out) / "data" / name
    suite.write(data_dir, profile="vlm_a", channel="oracle")
    ev_a = suite.events_for("vlm_a", "oracle")
    res: dict[str, Any] = {"title": spec.title, "events": len(ev_a), "sim_stats": _jsonable(suite.stats)}
    paper = [p for p in PAPER_OPERATOR_NAMES if p.removesuffix("_paper") in operators]
    progress(f"{name}: six operators, vlm_a + oracle channel ({len(ev_a)} events)")
    main, main_runs = _replay(ev_a, operators + paper, table, suite.truth, preds, config)
    res["table2"] = _scores_dict(main)
    progress(f"{name}: six operators, vlm_b (confidence swap)")
    swap, swap_runs = _replay(suite.events_for("vlm_b", "oracle"), operators + paper, table, suite.truth, preds, config)
    pool = belief_preservation_pool(ev_a, preds, tau_t=config.tau_t)
    pool_a = {op: brier_on_pairs(run.graph, suite.truth, pool) for op, run in main_runs.items()}
    pool_b = {op: brier_on_pairs(run.graph, suite.truth, pool) for op, run in swap_runs.items()}
    res["vlm_swap"] = {op: {"brier_vlm_a": main[op].brier, "brier_vlm_b": swap[op].brier,
                            "delta": swap[op].brier - main[op].brier,
                            "pool_brier_vlm_a": pool_a[op], "pool_brier_vlm_b": pool_b[op],
                            "pool_delta": pool_b[op] - pool_a[op],
                            "mean_iou_vlm_a": main[op].mean_iou, "mean_iou_vlm_b": swap[op].mean_iou}
                       for op in operators + paper}
    res["belief_preservation_pool"] = len(pool)
    cal_report = trace = None
    progress(f"{name}: six operators, vlm_a + segmenter channel")
    seg = score_operators(suite.events_for("vlm_a", "segmenter"), operators + paper, table, suite.truth, preds, config)
    res["table2_segmenter"] = _scores_dict(seg)
    if "comod" in operators:
        res["table5"] = {"oracle": main["comod"].as_dict(), "segmenter": seg["comod"].as_dict(),
                         "bot_rate_oracle": _bot_rate(main["comod"]), "bot_rate_segmenter": _bot_rate(seg["comod"]),
                         "segmenter_miou": suite.stats.get("segmenter_miou")}
    c, y, k, p = _verified_claims(ev_a, table, preds)
    if len(c) > 20:
        cal_report = calibration_split(c, y, list(zip(k, p)), seed=seed, alpha=config.alpha)
        res["calibration"] = {kk: v for kk, v in cal_report.items() if not kk.startswith("_")}
    pair = _contradicted_pair(ev_a, table, preds, tau_t=config.tau_t)
    if pair is None:
        res["trace_note"] = f"no element of this suite qualifies for Figure 1(a) ({TRACE_RULE})"
    else:
        progress(f"{name}: trace of contradicted element {pair}")
        trace = element_trace(ev_a, table, pair, config)
        trace["truth"] = int(suite.truth.get(pair[0], {}).get(pair[1], 0))
        trace["rule"] = TRACE_RULE
        res["trace"] = {k2: v for k2, v in trace.items() if k2 != "trace"}
    if job.retrieval:
        progress(f"{name}: compound-query retrieval, monolithic prompt")
        try:
            from sgbelief.eval.retrieval import evaluate_retrieval, suite_retrieval_data

            rdata = suite_retrieval_data(data_dir, spec.vocab)
            res["retrieval"] = [sc.to_dict() for sc in evaluate_retrieval(rdata, operators, operator_config=config)]
        except Exception as exc:  # reported in the results, never silently dropped
            res["retrieval_error"] = f"{type(exc).__name__}: {exc}"
        if "retrieval" in res:  # Table 4: against the monolithic prompt
            res.update(bench_section(suite, rdata, main_runs, swap_runs, config=config, data_dir=data_dir))
    return res, cal_report, trace


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items() if not str(k).startswith("_")}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, BetaBelief):
        return [x.alpha, x.beta]
    return x


# --------------------------------------------------------------------------- markdown
def _f(x: Any, d: int = 3) -> str:
    """A number as the tables print it; n/a where it is undefined (nan, or None once in JSON)."""
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{d}f}"


def _summary_table(results: dict[str, Any]) -> list[str]:
    """The demo's subset of the robustness grid: mean IoU per (suite, profile, channel) cell."""
    rows: list[tuple[str, dict[str, float]]] = []
    for name, res in results["suites"].items():
        if "table2" in res:
            rows.append((f"{name} / vlm_a / oracle", {op: sc["mean_iou"] for op, sc in res["table2"].items()}))
        if "table2_segmenter" in res:
            rows.append((f"{name} / vlm_a / segmenter", {op: sc["mean_iou"] for op, sc in res["table2_segmenter"].items()}))
        if "vlm_swap" in res:
            rows.append((f"{name} / vlm_b / oracle", {op: v["mean_iou_vlm_b"] for op, v in res["vlm_swap"].items()}))
    if not rows:
        return []
    ops = list(rows[0][1])
    out = ["## Summary: mean IoU per cell (a subset of `sgbelief bench --grid`; parametric confidences)", "",
           "| suite / profile / channel | " + " | ".join(ops) + " |", "|---" * (len(ops) + 1) + "|"]
    for label, row in rows:
        best = max((o for o in row if o in OPERATOR_NAMES), key=row.__getitem__)
        out.append(f"| {label} | " + " | ".join(f"**{_f(row[o])}**" if o == best else _f(row[o]) for o in ops) + " |")
    return out + [""]


def render_markdown(results: dict[str, Any]) -> str:
    lines = [f"# sgbelief bench (seed {results['meta']['seed']})", "",
             f"Operator configuration for every table: {results['meta'].get('config_note', 'the shipped default')}. "
             f"Rows `cal_paper` / `comod_paper`: the same with the paper's own settings (lr_reference slice, "
             f"no support strata, no geometric evidence). Mean IoU averages the suite's evaluated predicates. "
             f"Best of the six operators in bold.", ""]
    lines += _summary_table(results)
    for name, res in results["suites"].items():
        preds = list(SUITES[name].predicates)
        short = [p.removeprefix("is_") for p in preds]
        lines += [f"## {res['title']} — {res['events']} events", ""]
        for key, channel in (("table2", "oracle"), ("table2_segmenter", "segmenter")):
            if key not in res:
                continue
            lines += [f"### Per-class IoU (precision / recall) at tau = {results['meta'].get('tau', 0.5)} "
                      f"(Table 2 layout; vlm_a, {channel} channel)", "",
                      "| operator | " + " | ".join(short) + " | mean IoU | Brier | ⊥ refusals |",
                      "|---|" + "---|" * (len(short) + 3)]
            best = max((op for op in res[key] if op in OPERATOR_NAMES), key=lambda o: res[key][o]["mean_iou"])
            for op, sc in res[key].items():
                pp = sc["per_predicate"]
                name_ = f"**{op}**" if op == best else op
                lines.append(f"| {name_} | " + " | ".join(f"{_f(pp[p]['iou'])} ({_f(pp[p]['precision'], 2)} / "
                                                          f"{_f(pp[p]['recall'], 2)})" for p in preds)
                             + f" | {_f(sc['mean_iou'])} | {_f(sc['brier'], 4)} | {sc['refusals']} |")
            first = next(iter(res[key].values()))["per_predicate"]
            empty = [p for p in preds if first[p]["tp"] + first[p]["fn"] == 0]
            if empty:
                lines.append(f"\nn/a: {', '.join(empty)} {'has' if len(empty) == 1 else 'have'} no positives in this "
                             "suite's truth, so IoU and recall are undefined there; left out of the mean IoU.")
            lines.append("")
        if "table5" in res:
            t5 = res["table5"]
            lines += ["", f"### comod: oracle vs segmenter channel (Table 5 layout; segmenter mIoU {_f(t5.get('segmenter_miou'))})", "",
                      "| predicate | IoU oracle | P | R | IoU segmenter | P | R | ΔIoU |", "|---|---|---|---|---|---|---|---|"]
            for p in preds:
                o, s = t5["oracle"]["per_predicate"][p], t5["segmenter"]["per_predicate"][p]
                lines.append(f"| {p} | {_f(o['iou'])} | {_f(o['precision'])} | {_f(o['recall'])} | {_f(s['iou'])} | "
                             f"{_f(s['precision'])} | {_f(s['recall'])} | {_f(s['iou'] - o['iou'])} |")
            lines.append(f"| mean | {_f(t5['oracle']['mean_iou'])} | | | {_f(t5['segmenter']['mean_iou'])} | | | "
                         f"{_f(t5['segmenter']['mean_iou'] - t5['oracle']['mean_iou'])} |")
            lines.append(f"\n⊥-emission rate: oracle {_f(t5['bot_rate_oracle'])}, segmenter {_f(t5['bot_rate_segmenter'])}")
        lines += ["", f"### Cross-VLM invariance: Brier under vlm_a → vlm_b (belief-preservation pool of "
                  f"{res.get('belief_preservation_pool', 0)} pairs: a confident claim, then a weaker one; and all pairs "
                  f"with evidence)", "",
                  "| operator | pool Brier vlm_a | pool vlm_b | pool Δ | all-pairs Brier vlm_a | vlm_b | Δ | "
                  "mean IoU vlm_a | vlm_b |", "|---|---|---|---|---|---|---|---|---|"]
        for op, v in res["vlm_swap"].items():
            lines.append(f"| {op} | {_f(v.get('pool_brier_vlm_a'), 4)} | {_f(v.get('pool_brier_vlm_b'), 4)} | "
                         f"{v.get('pool_delta', math.nan):+.4f} | {_f(v['brier_vlm_a'], 4)} | {_f(v['brier_vlm_b'], 4)} | "
                         f"{v['delta']:+.4f} | {_f(v['mean_iou_vlm_a'])} | {_f(v['mean_iou_vlm_b'])} |")
        if "calibration" in res:
            c = res["calibration"]
            lines += ["", f"### Calibration of verified claims (50/50 split, n_eval = {c['n_eval']})", "",
                      f"raw ECE {_f(c['raw_ece'])} → calibrated ECE {_f(c['calibrated_ece'])}; conformal coverage "
                      f"{_f(c['coverage'])} at 1 − α = {1 - c['alpha']:.2f}, mean set size {_f(c['mean_set_size'])}"]
        if "trace" in res:
            t = res["trace"]
            fin = ", ".join(f"{k} {v[0] / (v[0] + v[1]):.3f}" for k, v in t["final"].items())
            lines += ["", f"Figure 1(a) element ({t.get('rule', TRACE_RULE)}): {t['node']} / {t['predicate']}, "
                      f"{t['events']} claims, {len(t['contradictions'])} asserted while the geometric channel said not; "
                      f"final mean {fin} (truth {t.get('truth', '?')})."]
        elif "trace_note" in res:
            lines += ["", f"Figure 1(a): {res['trace_note']}."]
        if "retrieval" in res:
            lines += ["", "### Compound-query retrieval, full pool (Table 3 layout): F1 at p > tau", ""]
            ops = list(dict.fromkeys(r["operator"] for r in res["retrieval"]))
            lines += ["| compound | n | pos % | " + " | ".join(ops) + " |", "|---|---|---|" + "---|" * len(ops)]
            by = {}
            for r in res["retrieval"]:
                by.setdefault(r["title"] or r["query"], {})[r["operator"]] = r
            for q, row in by.items():
                first = next(iter(row.values()))
                lines.append(f"| {q} | {first['n']} | {100 * first['pos_rate']:.1f} | "
                             + " | ".join(_f(row[o]["f1"]) if o in row else "–" for o in ops) + " |")
            if any(r["positives"] == 0 for r in res["retrieval"]):
                lines.append("\nn/a: a compound with no positives in its pool has no F1.")
        elif "retrieval_error" in res:
            lines += ["", f"Retrieval table not produced: {res['retrieval_error']}"]
        if "compound_table" in res:
            lines += [""] + compound_markdown(res["compound_table"], "### Compound retrieval: component beliefs against "
                                                                    "one monolithic compound prompt (Table 4 layout)")
        elif "compound_table_error" in res:
            lines += ["", f"Table 4 not produced: {res['compound_table_error']}"]
        lines.append("")
    if "real_calibration" in results:
        lines += ["## Real detector confidences (COCO val, netcal records; per-class isotonic, 50/50 split by image)", "",
                  "| detector | n eval | raw ECE | calibrated ECE | coverage (1 − α = 0.9) | mean set size |", "|---|---|---|---|---|---|"]
        for k, r in results["real_calibration"].items():
            lines.append(f"| {k} | {r['n_eval']} | {_f(r['raw_ece'])} | {_f(r['calibrated_ece'])} | {_f(r['coverage'])} | {_f(r['mean_set_size'])} |")
    lines += ["", f"Figures: {', '.join(results.get('figures', []))}. Total time {results['meta'].get('seconds', 0):.1f} s.", ""]
    return "\n".join(lines)

"""Diagnostics of a simulated suite: realised statistics and the most contradicted pair.

Read-only views of a :class:`~sgbelief.eval.simulate.SimulatedSuite` (the generator never uses
them). A claim's diagnostic verdict comes from the vocabulary's positive / negative sets and the
claim's sign (c >= 0.5 asserts, else denies), independently of any update operator.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from sgbelief.eval.sim_config import SimConfig, load_vocabulary
from sgbelief.eval.simulate import SimulatedSuite


def _verdict_sets(cfg: SimConfig) -> dict[str, tuple[set[str], set[str]]]:
    vocab = load_vocabulary(cfg.vocabulary)
    return {p: (set(s.get("positive", [])), set(s.get("negative", []))) for p, s in vocab["predicates"].items()}


def _diag_verdict(sets: tuple[set[str], set[str]], label: str | None, confidence: float) -> int:
    """Diagnostic compatibility (+1 corroborates, -1 contradicts, 0 no claim), sign from c >= 0.5."""
    if label is None:
        return 0
    pos, neg = sets
    v = 1 if label in pos else (-1 if label in neg else 0)
    return v if confidence >= 0.5 else -v


def suite_statistics(suite: SimulatedSuite, *, profile: str | None = None, channel: str | None = None,
                     tau_t: float = 0.1) -> dict[str, Any]:
    """Realised statistics of a suite view (diagnostics only; the generator never uses them).

    ``bottom_rate`` = contradicting (node, event) pairs / targeted pairs with mass > tau_t, using the
    vocabulary's positive / negative sets and the claim's sign (c >= 0.5 asserts, else denies).
    """
    cfg = suite.config
    sets = _verdict_sets(cfg)
    events = suite.events_for(profile, channel)
    labels = Counter(n.label for n in suite.nodes.nodes.values())
    n_nodes = sum(labels.values())
    verdicts: Counter[int] = Counter()
    tiny = total_masses = 0
    low = 0
    for e in events:
        low += e.confidence < 0.5
        for node, m in e.targets.items():
            total_masses += 1
            if m <= tau_t:
                tiny += 1
                continue
            verdicts[_diag_verdict(sets[e.predicate], e.geometric.get(node), e.confidence)] += 1
    targeted = sum(verdicts.values())
    preds = Counter(e.predicate for e in events)
    return {
        "suite": cfg.name, "profile": profile or suite.profile, "channel": channel or suite.channel,
        "events": len(events), "nodes": n_nodes,
        "label_frequency": {k: round(v / n_nodes, 4) for k, v in labels.most_common()},
        "claims_per_predicate": dict(preds.most_common()),
        "positive_rate": {p: round(sum(r.get(p, 0) for r in suite.truth.values()) / max(len(suite.truth), 1), 4)
                          for p in cfg.evaluated_predicates},
        "low_confidence_fraction": round(low / max(len(events), 1), 4),
        "multi_target_fraction": round(sum(len(e.targets) > 1 for e in events) / max(len(events), 1), 4),
        "masses_at_or_below_tau_t": round(tiny / max(total_masses, 1), 4),
        "hallucinated_fraction": round(sum(c.hallucinated for c in suite.claims) / max(len(suite.claims), 1), 4),
        "targeted_pairs": targeted,
        "bottom_rate": round(verdicts[-1] / max(targeted, 1), 4),
        "corroborate_rate": round(verdicts[1] / max(targeted, 1), 4),
        "no_claim_rate": round(verdicts[0] / max(targeted, 1), 4),
        "segmenter_miou": suite.stats.get("segmenter_miou"),
        "generation_s": suite.stats.get("generation_s"),
    }


def most_contradicted(suite: SimulatedSuite, *, profile: str | None = None, channel: str | None = None,
                      tau_t: float = 0.1, predicates: list[str] | None = None) -> dict[str, Any] | None:
    """The (node, predicate) pair with the most contradicted events (Figure 1(a) trace candidate).

    Returns ``{"node", "predicate", "events", "contradictions", "truth"}`` or None if nothing contradicts.
    """
    sets = _verdict_sets(suite.config)
    wanted = set(predicates or suite.config.evaluated_predicates)
    n_ev: Counter[tuple[str, str]] = Counter()
    n_bot: Counter[tuple[str, str]] = Counter()
    for e in suite.events_for(profile, channel):
        if e.predicate not in wanted:
            continue
        for node, m in e.targets.items():
            if m <= tau_t:
                continue
            n_ev[(node, e.predicate)] += 1
            if _diag_verdict(sets[e.predicate], e.geometric.get(node), e.confidence) < 0:
                n_bot[(node, e.predicate)] += 1
    if not n_bot:
        return None
    (node, pred), k = max(n_bot.items(), key=lambda kv: (kv[1], n_ev[kv[0]], kv[0]))
    return {"node": node, "predicate": pred, "events": n_ev[(node, pred)], "contradictions": k,
            "truth": suite.truth[node][pred]}

"""Conformance checks for FusionOperator implementations (cf. scikit-learn's ``check_estimator``).

``check_fusion_operator(op)`` runs an operator on a small seeded stream and asserts the whole
:class:`~sgbelief.fusion.protocol.FusionOperator` contract: it satisfies the runtime-checkable
protocol (name, config, stats, pair_rule, update, update_many, tick, probability, retract); every
report lists each targeted node once with a verdict and an action; masses <= tau_T are never
applied; ``stats`` holds every counter and counts the events; beliefs stay finite and positive;
each belief equals prior + sum of its logged increments (Eq. 4); probability is in [0, 1] and
equals the belief mean; ``update(..., report=False)`` and ``update_many`` leave what ``update``
leaves (and ``update_many`` returns the reports' queue resolutions); an operator with a
``pair_rule`` gives the same map through the batched engine; ``retract`` removes an event
exactly; and the graph round-trips through save/load.

``check_fast_matches_reference(name)`` proves a shipped operator's fused engine equal to its
reference steps. ``random_stream`` is a seeded stream of events for tests,
``provenance_signature`` everything observable about a map (for equality tests).

``check_store_matches_reference(make_store, operations)`` does the same for a provenance store:
a store that builds its entries differently (a journal, deferred loading) must be observably the
reference :class:`~sgbelief.graph.provenance.ProvenanceStore` under any sequence of calls.

``check_isotonic_matches_reference(outcomes, fast)`` does the same for a calibration slice's
isotonic store (:class:`~sgbelief.calibration.isotonic.IsotonicStore`): the incremental merge of
:mod:`sgbelief._fast.isotonic` must hold and fit what the reference refit does, knot for knot.
"""

from __future__ import annotations

import copy
import math
import random
import tempfile
from array import array
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from sgbelief._fast.batched import EventColumns, batched_replay
from sgbelief._fast.signature import float_bits, provenance_signature
from sgbelief.api.operators import make_operator
from sgbelief.calibration.isotonic import IsotonicStoreFactory, RefitIsotonic, interpolate
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.errors import RetractionError
from sgbelief.fusion.operators.base import REFERENCE
from sgbelief.fusion.protocol import STAT_KEYS, Action, FusionOperator, LinearRule, ResetRule, UpdateReport
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance import EntryStatus, ProvenanceEntry, ProvenanceStore

_LABELS = ("car", "truck", "person", "building", None)


def _table() -> SubsumptionTable:
    return SubsumptionTable(
        {
            "is_car": {"positive": ["car", "truck"], "negative": ["person", "building"]},
            "is_pedestrian": {"positive": ["person"], "negative": ["car", "truck", "building"]},
        },
        name="conformance",
    )


def random_stream(
    n_events: int = 300, n_nodes: int = 12, seed: int = 0, predicates: tuple[str, ...] = ("is_car", "is_pedestrian")
) -> list[tuple[EvidenceEvent, dict[Any, str | None]]]:
    """A seeded stream of (event, geometric labels) with one- and two-target events."""
    rng = random.Random(seed)
    truth = {f"n{i}": rng.choice(_LABELS[:4]) for i in range(n_nodes)}
    out = []
    for t in range(n_events):
        nodes = rng.sample(sorted(truth), 2 if rng.random() < 0.3 else 1)
        if len(nodes) == 1:
            targets = {nodes[0]: 1.0}
        else:
            m = rng.uniform(0.02, 0.98)
            targets = {nodes[0]: m, nodes[1]: 1.0 - m}
        ev = EvidenceEvent(targets, rng.choice(predicates), rng.random(), rng.choice(["vlm_a", "vlm_b"]), t, f"ev{t}")
        labels = {v: (truth[v] if rng.random() < 0.7 else None) for v in nodes}
        out.append((ev, labels))
    return out


def _beliefs(graph: SceneGraph) -> dict[Any, tuple[float, float]]:
    prov = graph.provenance
    return {k: prov.alpha_beta(*k) for k in prov.pairs()}


def check_fusion_operator(operator: FusionOperator, *, n_events: int = 300, seed: int = 0) -> None:
    """Raise AssertionError when ``operator`` breaks the FusionOperator contract (see the module
    docstring). ``operator`` must be fresh (no event applied yet); it is used, copies of it too."""
    assert isinstance(operator, FusionOperator), (
        f"{operator!r} does not implement FusionOperator (name, config, stats, pair_rule, update, "
        f"update_many, tick, probability, retract, merge_nodes)"
    )
    assert isinstance(operator.name, str) and operator.name, "operator.name must be a non-empty string"
    missing = [k for k in STAT_KEYS if k not in operator.stats]
    assert not missing, f"operator.stats must hold every counter of STAT_KEYS; missing {missing}"
    rule = operator.pair_rule
    assert rule is None or isinstance(rule, (LinearRule, ResetRule)), "pair_rule must be None, a LinearRule or a ResetRule"
    tau_t = operator.config.tau_t
    stream = random_stream(n_events, seed=seed)
    items = [(event, FrameLabels(labels)) for event, labels in stream]
    twins = {how: copy.deepcopy(operator) for how in ("report=False", "update_many", "batched")}
    graph = SceneGraph(create_nodes=True)
    resolutions = []
    for event, channel in items:
        report = operator.update(graph, event, channel)
        assert isinstance(report, UpdateReport), "update() must return an UpdateReport"
        assert report.event_id == event.id and report.t == event.t
        assert sorted(map(str, (o.node for o in report.targets))) == sorted(map(str, event.targets)), (
            "the report must list every targeted node exactly once"
        )
        for o in report.targets:
            assert isinstance(o.verdict, Verdict) and isinstance(o.action, Action)
            if o.mass <= tau_t:
                assert o.action is Action.BELOW_THRESHOLD, "mass <= tau_T must be discarded"
                assert o.d_alpha == 0.0 and o.d_beta == 0.0
        resolutions += report.resolutions
    assert operator.stats["events"] == n_events, 'stats["events"] must count the events applied'
    # the same stream without reports, through update_many and (with a pair rule) in waves
    lean, lean_graph = twins["report=False"], SceneGraph(create_nodes=True)
    for event, channel in items:
        report = lean.update(lean_graph, event, channel, report=False)
        assert report.targets == (), "update(..., report=False) must return a report without targets"
    many, many_graph = twins["update_many"], SceneGraph(create_nodes=True)
    many_res = many.update_many(many_graph, items)
    assert list(many_res) == resolutions, "update_many must return the queue resolutions the reports hold"
    for how, (op, g) in {"update(..., report=False)": (lean, lean_graph), "update_many": (many, many_graph)}.items():
        assert _beliefs(g) == _beliefs(graph), f"{how} must give the beliefs update() gives on the same stream"
        assert op.stats == operator.stats, f"{how} must count what update() counts"
    if rule is not None:
        waved, waved_graph = twins["batched"], SceneGraph(create_nodes=True)
        batched_replay(EventColumns.from_records([event for event, _ in stream]), waved, graph=waved_graph)
        assert provenance_signature(waved_graph) == provenance_signature(many_graph), (
            "an operator with a pair_rule must give through the batched engine the map it gives event by event"
        )
        assert waved.stats == many.stats, "the batched engine must count what update_many counts"
    # retract the last event with entries, on a copy: its entries go, Eq. 4 still holds
    gone = next((e.id for e, _ in reversed(stream) if many_graph.provenance.has_event(e.id)), None)
    if gone is not None:
        ids = many.retract(many_graph, gone)
        assert gone in ids and not many_graph.provenance.has_event(gone), "retract must remove the event's entries"
        for key in many_graph.provenance.pairs():
            _check_eq5(many_graph, key)
    operator.tick(graph, n_events + 10_000)
    prov = graph.provenance
    for node, predicate in list(prov.pairs()):
        a, b = _check_eq5(graph, (node, predicate))
        p = operator.probability(graph, node, predicate)
        assert 0.0 <= p <= 1.0 and math.isclose(p, a / (a + b), rel_tol=1e-12)
    with tempfile.TemporaryDirectory() as tmp:
        graph.save(tmp)
        again = SceneGraph.load(tmp)
    for node, predicate in prov.pairs():
        assert again.provenance.alpha_beta(node, predicate) == prov.alpha_beta(node, predicate) or all(
            math.isclose(x, y, rel_tol=1e-12) for x, y in zip(again.provenance.alpha_beta(node, predicate), prov.alpha_beta(node, predicate))
        )


def _check_eq5(graph: SceneGraph, key: tuple[Any, str]) -> tuple[float, float]:
    prov = graph.provenance
    a, b = prov.alpha_beta(*key)
    assert math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0, f"belief of {key} not finite/positive"
    ra, rb = prov.reconstruct(*key)
    assert math.isclose(a, ra, rel_tol=1e-9, abs_tol=1e-9) and math.isclose(b, rb, rel_tol=1e-9, abs_tol=1e-9), (
        f"Eq. 4 violated at {key}: stored ({a}, {b}) vs log ({ra}, {rb})"
    )
    return a, b


def check_fast_matches_reference(
    name: str = "comod",
    stream: list[tuple[EvidenceEvent, dict[Any, str | None]]] | None = None,
    config: Any = None,
    *,
    vocabulary: SubsumptionTable | None = None,
    final_tick: int | None = None,
) -> None:
    """Raise AssertionError unless the fused engine of a shipped operator
    (``sgbelief.make_operator(name, ..., engine="fast")``) gives what its reference steps
    (``engine="reference"``) give on ``stream``: the same reports, beliefs, provenance (every
    entry, in order), queues, stats and, for the calibrated operators, calibration buffers.
    ``stream`` defaults to :func:`random_stream`."""
    vocab = vocabulary or _table()
    stream = random_stream() if stream is None else stream
    runs = []
    for engine in ("reference", "fast"):
        op = make_operator(name, config, vocab, engine=engine)  # type: ignore[arg-type]
        assert (getattr(op, "engine", None) is REFERENCE) == (engine == "reference"), f"{name!r} has no fast engine"
        graph = SceneGraph(create_nodes=True)
        reports = [op.update(graph, event, FrameLabels(labels)) for event, labels in stream]
        if final_tick is not None:
            op.tick(graph, final_tick)
        runs.append((op, graph, reports))
    (ref, g_ref, r_ref), (fast, g_fast, r_fast) = runs
    assert r_ref == r_fast, "the two engines must report the same outcomes"
    assert g_ref.provenance.to_dict() == g_fast.provenance.to_dict(), "provenance differs between engines"
    assert provenance_signature(g_ref) == provenance_signature(g_fast), "provenance differs between engines"
    assert ref.stats == fast.stats, (ref.stats, fast.stats)
    cal_ref, cal_fast = getattr(ref, "calibrator_", None), getattr(fast, "calibrator_", None)
    if cal_ref is not None:
        assert cal_ref.slices.keys() == cal_fast.slices.keys()
        for key, sl in cal_ref.slices.items():
            other = cal_fast.slices[key]
            assert list(sl.window_confidences) == list(other.window_confidences), key
            assert list(sl.window_labels) == list(other.window_labels), key
            # the reference engine refits scikit-learn, the fused one merges incrementally: same knots
            assert (sl.n_fit, sl.kx, sl.ky, sl.base_rate) == (other.n_fit, other.kx, other.ky, other.base_rate), key
    cons_ref, cons_fast = getattr(ref, "_consensus", {}), getattr(fast, "_consensus", {})
    assert len(cons_ref) == len(cons_fast), "the consensus is kept for different maps"
    for (_, a), (_, b) in zip(cons_ref.values(), cons_fast.values()):
        assert consensus_state(a) == consensus_state(b), "the consensus' claim tables or fits differ"
    assert sorted(g_ref.nx.nodes, key=str) == sorted(g_fast.nx.nodes, key=str)


def consensus_state(consensus: Any) -> list[Any]:
    """Everything observable of a :class:`~sgbelief.fusion.consensus.MapConsensus`, floats bit for bit:
    its claim table, the channel labels, the claim counts, the refit schedule and the fitted cells."""
    from sgbelief.calibration.agreement_shift import ShiftCalibration

    cal = consensus.calibration
    if isinstance(cal, ShiftCalibration):  # one reading per context
        fits = {repr(k): [r.fitted, r.claims, r.reads_scores, r.p_value, r.stated]
                for k, r in sorted(cal.readings_.items())}
    else:
        fits = {repr(k): [v[0], v[1], v[2], v[3]] for k, v in sorted(cal.fits_.items(), key=repr)}
    return float_bits([consensus.node, consensus.pred, consensus.ctx, list(consensus.conf), consensus.cell,
                       list(consensus.decisive), list(consensus.mass), [consensus._labels.names],
                       consensus.event, sorted(consensus.labels.items(), key=repr),
                       sorted(((repr(k), sorted(v.items())) for k, v in consensus.counts.items())),
                       consensus.n_at_fit, consensus.n_fits, fits])


def conformance_table() -> SubsumptionTable:
    """The two-predicate vocabulary :func:`random_stream` uses."""
    return _table()


# ------------------------------------------------------------------ provenance stores
#: one call on a provenance store, as a tuple (see :func:`apply_store_operations`)
StoreOperation = tuple[Any, ...]


def entry_state(entry: ProvenanceEntry) -> list[Any]:
    """Every field of an entry, floats bit for bit."""
    return float_bits([entry.event_id, entry.t, entry.d_alpha, entry.d_beta, entry.status.value, entry.stance,
                        entry.corroborated_by, entry.n_folded, entry.node, entry.predicate, entry.alive,
                        None if entry.verdict is None else int(entry.verdict), entry.confidence,
                        None if entry.summary is None else entry.summary.to_dict()])


def store_state(store: EntryLog) -> dict[str, Any]:
    """Everything observable about a provenance store, floats bit for bit and every order kept:
    beliefs and logs, the event index, the compaction timeline, the queues, each pair's pending
    entries, the compacted-id memory and the saved form. Checks on the way that the index, the
    timeline and the queues hold entry objects of the logs (or retired ones, for the lazily
    emptied queues and timeline)."""
    logs = store.logs()
    logged = {id(e) for log in logs.values() for e in log.entries}
    index = store.event_index()
    timeline = store.compaction_timeline()
    for e in (*(e for es in index.values() for e in es), *(e for e in timeline if e.alive),
              *(e for e in (*store.quarantine, *store.disagreement) if e.alive)):
        assert id(e) in logged, f"{e!r} is indexed or queued but in no log"
    return {
        "prior": float_bits([store.prior_alpha, store.prior_beta]),
        "remember_compacted": store.remember_compacted,
        "n_compacted": store.n_compacted,
        "pairs": [(key, float_bits(log.alpha), float_bits(log.beta), [entry_state(e) for e in log.entries])
                  for key, log in logs.items()],
        "event_index": [(eid, [entry_state(e) for e in es]) for eid, es in index.items()],
        "timeline": [entry_state(e) for e in timeline],
        "quarantine": [entry_state(e) for e in store.quarantine],
        "disagreement": [entry_state(e) for e in store.disagreement],
        "pending": [(key, [entry_state(e) for e in store.pending(*key)]) for key in logs if store.pending(*key)],
        "compacted_ids": store.compacted_ids(),
        "to_dict": float_bits(store.to_dict()),
    }


def apply_store_operations(store: EntryLog, operations: Sequence[StoreOperation]) -> list[Any]:
    """Run calls on a store; returns, per call, what it returned (entries as
    :func:`entry_state`, a RetractionError as its message) and every pair's belief after it
    (beliefs read without building entries). The calls:

    ``("commit", node, predicate, event_id, t, d_alpha, d_beta, stance[, verdict, confidence])``,
    ``("record", node, predicate, event_id, t, d_alpha, d_beta, status, stance[, verdict, confidence])``,
    ``("transition", k, status, scale)`` (the k-th waiting entry of the queues, modulo),
    ``("transition_held", k, status, scale)`` (the k-th live entry a ``record`` or ``read_event``
    returned so far), ``("reweigh_held", k, d_alpha, d_beta, stance)`` (new increments for the k-th
    live committed entry of those), ``("compact", before_t)``, ``("retract", event_id, cascade_window)``,
    ``("read", node, predicate)``, ``("read_event", event_id)``, ``("move", absorb, keep)``,
    ``("remove", node)``."""
    held: list[ProvenanceEntry] = []
    out: list[Any] = []
    for op in operations:
        kind = op[0]
        try:
            if kind == "commit":
                out.append(store.commit(*op[1:]))
            elif kind == "record":
                entry = store.record(*op[1:])
                held.append(entry)
                out.append(entry_state(entry))
            elif kind in ("transition", "transition_held"):
                _, k, status, scale = op
                if kind == "transition":
                    choice = [e for e in (*store.quarantine, *store.disagreement) if e.alive and e.pending]
                else:
                    choice = [e for e in held if e.alive]
                if choice:
                    store.transition(choice[k % len(choice)], status, scale=scale)
                out.append(len(choice))
            elif kind == "reweigh_held":
                _, k, d_alpha, d_beta, stance = op
                choice = [e for e in held if e.alive and e.status is EntryStatus.COMMITTED]
                if choice:
                    store.reweigh([(choice[k % len(choice)], d_alpha, d_beta, stance)])
                out.append(len(choice))
            elif kind == "compact":
                out.append(store.compact(op[1]))
            elif kind == "retract":
                out.append(store.retract(op[1], cascade_window=op[2]))
            elif kind == "read":
                out.append([entry_state(e) for e in store.entries(op[1], op[2])])
            elif kind == "read_event":
                found = store.event_entries(op[1])
                held += found
                out.append([entry_state(e) for e in found])
            elif kind == "move":
                out.append(store.move_node(op[1], op[2]))
            elif kind == "remove":
                out.append(store.remove_node(op[1]))
            else:
                raise ValueError(f"unknown store operation {kind!r}")
        except RetractionError as exc:
            out.append(f"RetractionError: {exc}")
        out.append({k: float_bits(store.alpha_beta(*k)) for k in store.pairs()})
    return out


def check_store_matches_reference(
    make_store: Callable[..., EntryLog],
    operations: Sequence[StoreOperation],
    *,
    prior: tuple[float, float] = (1.0, 1.0),
    remember_compacted: int = 100_000,
) -> None:
    """Raise AssertionError unless a store made by ``make_store(prior, remember_compacted=...)``
    behaves as the reference :class:`~sgbelief.graph.provenance.ProvenanceStore` under
    ``operations`` (:func:`apply_store_operations`): the same results and beliefs after every
    call, and the same :func:`store_state` at the end. The same exception type, if a call raises
    anything but a RetractionError."""
    runs = []
    for factory in (ProvenanceStore, make_store):
        store = factory(prior, remember_compacted=remember_compacted)
        try:
            runs.append((apply_store_operations(store, operations), store))
        except Exception as exc:  # noqa: BLE001 - compared below
            runs.append((type(exc), store))
    (ref_out, ref), (out, other) = runs
    if isinstance(ref_out, type) or isinstance(out, type):
        assert ref_out == out, f"the reference store gives {ref_out!r}, the other store {out!r}"
        return
    for i, (want, got) in enumerate(zip(ref_out, out)):
        assert want == got, f"result {i // 2} ({operations[i // 2]!r}): reference {want!r}, other store {got!r}"
    assert store_state(ref) == store_state(other), "the stores differ at the end"




def check_isotonic_matches_reference(
    outcomes: Sequence[tuple[float, int]],
    fast: IsotonicStoreFactory,
    reference: IsotonicStoreFactory = RefitIsotonic,
    *,
    capacity: int | None = None,
    batch_sizes: Iterable[int] = (1,),
    atol: float = 0.0,
) -> None:
    """Raise AssertionError unless the isotonic store ``fast`` holds and fits what ``reference``
    does after every batch of ``outcomes`` (pairs (c, y), merged in batches of the sizes
    ``batch_sizes``, cycled): the same outcomes held (count, positives, arrival order, sorted per
    label) and the same knots of p_hat.

    ``atol`` bounds the difference of the fitted values. Isotonic values are means of pooled
    blocks, so an implementation that sums a block in another order than the reference may differ
    in the last bits (relative error of order n 2^-53 for a block of n points), and the knots it
    keeps can then differ too; with ``atol > 0`` the two fits are compared as functions p_hat at
    every held confidence and knot. With ``atol = 0`` (the default) the knots must be equal, ``==``:
    what :mod:`sgbelief._fast.isotonic` guarantees, its pool-adjacent-violators running the
    reference's floating-point operations in the reference's order.
    """
    stores = fast(capacity), reference(capacity)
    sizes = list(batch_sizes) or [1]
    i = k = 0
    while i < len(outcomes):
        batch = outcomes[i : i + max(1, sizes[k % len(sizes)])]
        i += len(batch)
        k += 1
        for st in stores:
            st.merge(array("d", [c for c, _ in batch]), array("b", [1 if y else 0 for _, y in batch]))
        got, want = stores[0], stores[1]
        assert (got.n, got.n_pos) == (want.n, want.n_pos), (i, got.n, got.n_pos, want.n, want.n_pos)
        wc, wy = want.window()
        gc, gy = got.window()
        assert list(gc) == list(wc) and list(gy) == list(wy), f"held outcomes differ after {i} outcomes"
        for label in (0, 1):
            assert list(got.sorted_by_label(label)) == list(want.sorted_by_label(label)), (i, label)
        (fx, fy), (rx, ry) = got.knots(), want.knots()
        if atol == 0.0:
            assert (list(fx), list(fy)) == (list(rx), list(ry)), f"knots differ after {i} outcomes"
        elif rx:
            for c in [*wc, *rx, *fx]:
                assert abs(interpolate(fx, fy, c) - interpolate(rx, ry, c)) <= atol, (i, c)


__all__ = [
    "check_fast_matches_reference",
    "check_fusion_operator",
    "check_isotonic_matches_reference",
    "check_store_matches_reference",
    "apply_store_operations",
    "store_state",
    "conformance_table",
    "provenance_signature",
    "random_stream",
]

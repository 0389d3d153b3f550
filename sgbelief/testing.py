"""Conformance checks for FusionOperator implementations (cf. scikit-learn's ``check_estimator``).

``check_fusion_operator(op)`` runs an operator on a small seeded stream and asserts the contract
every operator must honour: it satisfies the runtime-checkable protocol; every report lists each
targeted node once with a verdict and an action; masses <= tau_T are never applied; beliefs stay
finite and positive; each belief equals prior + sum of its logged increments (Eq. 5); probability
is in [0, 1] and equals the belief mean; the graph round-trips through save/load; and, for an
operator with ``update_many`` (every :class:`~sgbelief.fusion.operators.base.BaseOperator`), a copy
taken before the stream that applies it through ``update_many`` ends with the same beliefs and
statistics.

``check_store_matches_reference(make_store, operations)`` does the same for a provenance store:
a store that builds its entries differently (a journal, deferred loading) must be observably the
reference :class:`~sgbelief.graph.provenance.ProvenanceStore` under any sequence of calls.
"""

from __future__ import annotations

import copy
import math
import random
import tempfile
from collections.abc import Callable, Sequence
from typing import Any

from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
from sgbelief.fusion.events import EvidenceEvent
from sgbelief.fusion.protocol import Action, FusionOperator, UpdateReport
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.errors import RetractionError
from sgbelief.graph.provenance import ProvenanceEntry, ProvenanceStore

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


def check_fusion_operator(operator: FusionOperator, *, n_events: int = 300, seed: int = 0) -> None:
    """Raise AssertionError when ``operator`` breaks the FusionOperator contract."""
    assert isinstance(operator, FusionOperator), f"{operator!r} does not implement FusionOperator"
    assert isinstance(operator.name, str) and operator.name, "operator.name must be a non-empty string"
    graph = SceneGraph()
    tau_t = getattr(getattr(operator, "config", None), "tau_t", 0.1)
    twin = copy.deepcopy(operator) if callable(getattr(operator, "update_many", None)) else None
    stream = random_stream(n_events, seed=seed)
    for event, labels in stream:
        report = operator.update(graph, event, FrameLabels(labels))
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
    operator.tick(graph, n_events + 10_000)
    prov = graph.provenance
    for node, predicate in list(prov.pairs()):
        a, b = prov.alpha_beta(node, predicate)
        assert math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0, f"belief of {(node, predicate)} not finite/positive"
        ra, rb = prov.reconstruct(node, predicate)
        assert math.isclose(a, ra, rel_tol=1e-9, abs_tol=1e-9) and math.isclose(b, rb, rel_tol=1e-9, abs_tol=1e-9), (
            f"Eq. 5 violated at {(node, predicate)}: stored ({a}, {b}) vs log ({ra}, {rb})"
        )
        p = operator.probability(graph, node, predicate)
        assert 0.0 <= p <= 1.0 and math.isclose(p, a / (a + b), rel_tol=1e-12)
    if twin is not None:
        batch_graph = SceneGraph()
        twin.update_many(batch_graph, [(event, FrameLabels(labels)) for event, labels in stream])
        twin.tick(batch_graph, n_events + 10_000)
        assert {k: batch_graph.provenance.alpha_beta(*k) for k in batch_graph.provenance.pairs()} == {
            k: prov.alpha_beta(*k) for k in prov.pairs()
        }, "update_many must give the beliefs update() gives on the same stream"
        assert getattr(twin, "stats", None) == getattr(operator, "stats", None), (
            "update_many must count what update() counts"
        )
    with tempfile.TemporaryDirectory() as tmp:
        graph.save(tmp)
        again = SceneGraph.load(tmp)
    for node, predicate in prov.pairs():
        assert again.provenance.alpha_beta(node, predicate) == prov.alpha_beta(node, predicate) or all(
            math.isclose(x, y, rel_tol=1e-12) for x, y in zip(again.provenance.alpha_beta(node, predicate), prov.alpha_beta(node, predicate))
        )


def check_fast_matches_reference(
    name: str = "comod",
    stream: list[tuple[EvidenceEvent, dict[Any, str | None]]] | None = None,
    config: Any = None,
    *,
    vocabulary: SubsumptionTable | None = None,
    final_tick: int | None = None,
) -> None:
    """Raise AssertionError unless the fused engine of a calibrated operator (``engine="fast"``)
    gives what its reference path (``engine="reference"``, Algorithm 1's named steps) gives on
    ``stream``: the same reports, beliefs, provenance logs (every entry, in order), queues, stats
    and calibration buffers. ``stream`` defaults to :func:`random_stream`."""
    from sgbelief.fusion.operators.calibrated import CalibratedOperator
    from sgbelief.fusion.registry import OPERATORS

    cls = OPERATORS[name]
    assert issubclass(cls, CalibratedOperator), f"{name!r} has no reference engine"
    vocab = vocabulary or _table()
    stream = random_stream() if stream is None else stream
    runs = []
    for engine in ("reference", "fast"):
        op = cls(config, vocab, engine=engine)
        graph = SceneGraph()
        reports = [op.update(graph, event, FrameLabels(labels)) for event, labels in stream]
        if final_tick is not None:
            op.tick(graph, final_tick)
        runs.append((op, graph, reports))
    (ref, g_ref, r_ref), (fast, g_fast, r_fast) = runs
    assert r_ref == r_fast, "the two engines must report the same outcomes"
    assert g_ref.provenance.to_dict() == g_fast.provenance.to_dict(), "provenance differs between engines"
    for k in g_ref.provenance.pairs():
        assert g_ref.provenance.alpha_beta(*k) == g_fast.provenance.alpha_beta(*k), k
    assert ref.stats == fast.stats, (ref.stats, fast.stats)
    assert ref.calibrator_.slices.keys() == fast.calibrator_.slices.keys()
    for key, sl in ref.calibrator_.slices.items():
        other = fast.calibrator_.slices[key]
        assert list(sl.fc) == list(other.fc) and list(sl.fy) == list(other.fy), key
    assert sorted(g_ref.nx.nodes, key=str) == sorted(g_fast.nx.nodes, key=str)


def conformance_table() -> SubsumptionTable:
    """The two-predicate vocabulary :func:`random_stream` uses."""
    return _table()


# ------------------------------------------------------------------ provenance stores
#: one call on a provenance store, as a tuple (see :func:`apply_store_operations`)
StoreOperation = tuple[Any, ...]


def _bits(x: Any) -> Any:
    """Floats as their exact hex form (tells -0.0 from 0.0), containers recursively."""
    if isinstance(x, float):
        return x.hex()
    if isinstance(x, (list, tuple)):
        return [_bits(v) for v in x]
    return x


def entry_state(entry: ProvenanceEntry) -> list[Any]:
    """Every field of an entry, floats bit for bit."""
    return _bits([entry.event_id, entry.t, entry.d_alpha, entry.d_beta, entry.status.value, entry.stance,
                  entry.corroborated_by, entry.n_folded, entry.node, entry.predicate, entry.alive])


def store_state(store: ProvenanceStore) -> dict[str, Any]:
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
        "prior": _bits([store.prior_alpha, store.prior_beta]),
        "remember_compacted": store.remember_compacted,
        "n_compacted": store.n_compacted,
        "pairs": [(key, _bits(log.alpha), _bits(log.beta), [entry_state(e) for e in log.entries])
                  for key, log in logs.items()],
        "event_index": [(eid, [entry_state(e) for e in es]) for eid, es in index.items()],
        "timeline": [entry_state(e) for e in timeline],
        "quarantine": [entry_state(e) for e in store.quarantine],
        "disagreement": [entry_state(e) for e in store.disagreement],
        "pending": [(key, [entry_state(e) for e in store.pending(*key)]) for key in logs if store.pending(*key)],
        "compacted_ids": store.compacted_ids(),
        "to_dict": _bits(store.to_dict()),
    }


def apply_store_operations(store: ProvenanceStore, operations: Sequence[StoreOperation]) -> list[Any]:
    """Run calls on a store; returns, per call, what it returned (entries as
    :func:`entry_state`, a RetractionError as its message) and every pair's belief after it
    (beliefs read without building entries). The calls:

    ``("commit", node, predicate, event_id, t, d_alpha, d_beta, stance)``,
    ``("record", node, predicate, event_id, t, d_alpha, d_beta, status, stance)``,
    ``("transition", k, status, scale)`` (the k-th waiting entry of the queues, modulo),
    ``("transition_held", k, status, scale)`` (the k-th live entry a ``record`` or ``read_event``
    returned so far), ``("compact", before_t)``, ``("retract", event_id, cascade_window)``,
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
        out.append({k: _bits(store.alpha_beta(*k)) for k in store.pairs()})
    return out


def check_store_matches_reference(
    make_store: Callable[..., ProvenanceStore],
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

"""Private: everything observable about a map, for the engines' equality tests.

Two engines are identical when they leave maps with equal signatures: beliefs, logs, queues,
event index, timeline and compacted-id memory, floats bit for bit and every order that a reader
can observe, through the store's read views; tests reach it as
:func:`sgbelief.testing.provenance_signature`.
"""

from __future__ import annotations

from typing import Any

from sgbelief.graph.provenance import ProvenanceEntry
from sgbelief.graph.scene_graph import SceneGraphModel


def float_bits(x: Any) -> Any:
    """Floats as their exact hex form (tells -0.0 from 0.0), containers recursively."""
    if isinstance(x, float):
        return x.hex()
    if isinstance(x, (list, tuple)):
        return [float_bits(v) for v in x]
    return x


def provenance_signature(graph: SceneGraphModel) -> dict[str, Any]:
    """Everything the equality tests compare, floats bit for bit and every order that is
    observable: beliefs, logs, queues, event index, timeline, compacted-id memory."""
    prov = graph.provenance
    prov.materialize()

    def entry(e: ProvenanceEntry) -> Any:
        return float_bits([e.event_id, e.t, e.d_alpha, e.d_beta, e.status.value, e.stance, e.corroborated_by,
                      e.n_folded, e.node, e.predicate, e.alive, None if e.verdict is None else int(e.verdict),
                      e.confidence, None if e.summary is None else e.summary.to_dict()])

    return {
        "nodes": [(n, dict(a)) for n, a in graph.nx.nodes(data=True)],
        "clock": graph.clock,
        "meta": dict(graph.meta),
        "pairs": [(key, float_bits(log.alpha), float_bits(log.beta), [entry(e) for e in log.entries])
                  for key, log in prov.logs().items()],
        "quarantine": [entry(e) for e in prov.quarantine],
        "disagreement": [entry(e) for e in prov.disagreement],
        "pending_by_pair": {k: [entry(e) for e in v] for k, v in prov.pending_index().items()},
        "by_event": [(k, [entry(e) for e in v]) for k, v in prov.event_index().items()],
        "timeline": [entry(e) for e in prov.compaction_timeline()],
        "compacted_order": prov.compacted_ids(),
        "compacted_memory_bound": max(prov.remember_compacted, 0),
        "n_compacted": prov.n_compacted,
        "prior": (prov.prior_alpha, prov.prior_beta, prov.remember_compacted),
    }


__all__ = ["provenance_signature"]

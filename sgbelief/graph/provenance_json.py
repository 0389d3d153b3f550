"""The provenance store's JSON form (the ``provenance`` object of graph.json), as free functions
over an :class:`~sgbelief.graph.entry_log.EntryLog`.

Per pair: node, predicate, the running (alpha, beta), the entries as rows
(:func:`~sgbelief.graph.provenance_log.entry_row`) and, for a pair with a compacted bucket, its
fold summary; then the prior, the remembered compacted ids and the compacted count. Reading
checks every row and Eq. 4 on every pair (the stored belief equals the prior plus the logged
increments) and hands the checked logs to the store's loader (``from_logs``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from sgbelief.errors import FormatError
from sgbelief.graph.compaction import FoldSummary, attach_summary, bucket_summary
from sgbelief.graph.entry_log import EntryLog, PairKey
from sgbelief.graph.provenance_log import (
    EntryStatus,
    PairLog,
    ProvenanceEntry,
    belief_from_entries,
    entry_extras,
    entry_row,
)

_STATUS_BY_VALUE = {s.value: s for s in EntryStatus}


def store_to_dict(log: EntryLog) -> dict[str, Any]:
    """A JSON-ready dict (node ids must be str or int)."""
    pairs = []
    for (node, predicate), pair_log in log.logs().items():
        pair: dict[str, Any] = {
            "node": node,
            "predicate": predicate,
            "alpha": pair_log.alpha,
            "beta": pair_log.beta,
            "entries": list(map(entry_row, pair_log.entries)),
        }
        summary = bucket_summary(pair_log.entries)
        if summary is not None:
            # optional: older readers ignore it, and files without it load with unknown counts
            pair["fold_summary"] = summary.to_dict()
        pairs.append(pair)
    return {
        "prior": [log.prior_alpha, log.prior_beta],
        "pairs": pairs,
        "compacted_ids": log.compacted_ids(),
        "n_compacted": log.n_compacted,
    }


def store_from_dict(data: dict[str, Any], from_logs: Callable[..., Any], *, where: str = "provenance") -> Any:
    """Check a :func:`store_to_dict` form and build a store of it with ``from_logs`` (a store
    class's loader, ``ProvenanceStore.from_logs`` or another store's); FormatError naming
    ``where`` and the pair / entry on bad input."""
    try:
        prior = (float(data["prior"][0]), float(data["prior"][1]))
        logs: dict[PairKey, PairLog] = {}
        for i, pair in enumerate(data["pairs"]):
            node, predicate = pair["node"], pair["predicate"]
            if not isinstance(predicate, str) or not predicate:
                raise FormatError(f"{where}.pairs[{i}].predicate must be a non-empty string")
            log = logs.setdefault((node, predicate), PairLog(*prior))
            for j, raw in enumerate(pair["entries"]):
                eid, t, da, db, status, stance, corr, n_folded = raw[:8]
                st = _STATUS_BY_VALUE.get(status)
                if st is None:
                    raise FormatError(f"{where}.pairs[{i}].entries[{j}]: unknown status {status!r}")
                if not (math.isfinite(da) and math.isfinite(db)):
                    raise FormatError(f"{where}.pairs[{i}].entries[{j}]: increments must be finite")
                verdict, confidence = entry_extras(raw, f"{where}.pairs[{i}].entries[{j}]")
                e = ProvenanceEntry(eid, int(t), float(da), float(db), st, node, predicate, int(stance),
                                    verdict, confidence)
                e.corroborated_by = list(corr) if corr else None
                e.n_folded = int(n_folded)
                log.entries.append(e)
            if pair.get("fold_summary") is not None:
                attach_summary(log.entries, FoldSummary.from_dict(pair["fold_summary"]), f"{where}.pairs[{i}]")
            rebuilt = belief_from_entries(prior, log.entries)
            for name, stored, value in zip(("alpha", "beta"), (pair["alpha"], pair["beta"]), rebuilt):
                if not math.isclose(float(stored), value, rel_tol=1e-9, abs_tol=1e-9):
                    raise FormatError(
                        f"{where}.pairs[{i}] ({node!r}, {predicate!r}): stored {name}={stored!r} does not "
                        f"equal prior + sum of logged increments ({value!r}); the file was edited or corrupted"
                    )
            if rebuilt[0] <= 0 or rebuilt[1] <= 0:
                raise FormatError(f"{where}.pairs[{i}]: belief parameters must stay > 0")
            # keep the stored running values bit-for-bit (they agree with the log to 1e-9)
            log.alpha, log.beta = float(pair["alpha"]), float(pair["beta"])
        return from_logs(
            logs,
            prior=prior,
            compacted_ids=data.get("compacted_ids", []),
            n_compacted=int(data.get("n_compacted", 0)),
        )
    except FormatError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise FormatError(f"{where}: malformed provenance data ({type(exc).__name__}: {exc})") from exc


__all__ = ["store_from_dict", "store_to_dict"]

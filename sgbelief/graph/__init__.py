"""Beliefs, provenance, the scene graph and its persistence (JSON, or the binary ``.npz`` layout of
:mod:`sgbelief.graph.binary`)."""

from __future__ import annotations

from sgbelief.graph.belief import BetaBelief, beta_kl
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance import COUNTED, PENDING, EntryStatus, ProvenanceEntry, ProvenanceStore
from sgbelief.graph.scene_graph import SceneGraph

__all__ = [
    "BetaBelief",
    "beta_kl",
    "COUNTED",
    "PENDING",
    "EntryLog",
    "EntryStatus",
    "ProvenanceEntry",
    "ProvenanceStore",
    "SceneGraph",
]

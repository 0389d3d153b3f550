"""Beliefs, provenance, the scene graph and its persistence (JSON, or the binary ``.npz`` layout of
:mod:`sgbelief.graph.binary`)."""

from __future__ import annotations

from typing import Any

from sgbelief.graph.belief import BetaBelief, beta_kl
from sgbelief.graph.entry_log import EntryLog
from sgbelief.graph.provenance import COUNTED, PENDING, EntryStatus, ProvenanceEntry, ProvenanceStore
from sgbelief.graph.scene_graph import SceneGraphModel

__all__ = [
    "BetaBelief",
    "beta_kl",
    "COUNTED",
    "PENDING",
    "EntryLog",
    "EntryStatus",
    "ProvenanceEntry",
    "ProvenanceStore",
    "SceneGraphModel",
]


def __getattr__(name: str) -> Any:
    if name == "SceneGraph":  # the model's old name (warns until 0.2.0)
        from sgbelief.graph import scene_graph

        return scene_graph.__getattr__(name)
    raise AttributeError(f"module 'sgbelief.graph' has no attribute {name!r}")

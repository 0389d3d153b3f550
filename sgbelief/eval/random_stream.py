"""Seeded random evidence streams as records, for tests, benchmarks and the executor self-test."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sgbelief.eval.formats import EventRecord


def random_records(
    seed: int,
    n_events: int,
    *,
    n_nodes: int = 50,
    predicates: Sequence[str] = ("is_car", "is_pedestrian", "is_building"),
    max_targets: int = 4,
    events_per_step: float = 3.0,
    labels: Sequence[str | None] = ("car", "person", "building", "road", None),
    mass_decimals: int = 4,
) -> list[EventRecord]:
    """A seeded random evidence stream of records (non-decreasing t) for tests and benchmarks;
    every record is a valid event (``validate_event``): masses rounded to ``mass_decimals`` sum
    to at most 1."""
    rng = np.random.default_rng(seed)
    out: list[EventRecord] = []
    t = 0
    preds = list(predicates)
    labs = list(labels)
    for i in range(n_events):
        if rng.random() < 1.0 / events_per_step:
            t += int(rng.integers(1, 4))
        k = int(rng.integers(1, max_targets + 1))
        nodes = rng.choice(n_nodes, size=min(k, n_nodes), replace=False)
        w = rng.dirichlet(np.ones(len(nodes))) * rng.uniform(0.5, 1.0)
        targets = {f"n{int(v):05d}": round(float(m), mass_decimals) for v, m in zip(nodes, w)}
        if sum(targets.values()) > 1.0:  # rounding up pushed the total over 1: round these down instead
            scale = 10.0**mass_decimals
            targets = {n: math.floor(float(m) * scale) / scale for n, m in zip(targets, w)}
        geo = {node: labs[int(rng.integers(len(labs)))] for node in targets}
        out.append(EventRecord(t=t, targets=targets, predicate=preds[int(rng.integers(len(preds)))],
                               confidence=round(float(rng.random()), 6), context="rnd", geometric=geo,
                               id=f"r{i:07d}"))
    return out


__all__ = ["random_records"]

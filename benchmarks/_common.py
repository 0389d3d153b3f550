"""Shared helpers of the benchmark scripts: machine facts, RSS, the reference loop, synthetic streams."""

from __future__ import annotations

import os
import platform
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def machine() -> dict[str, object]:
    cpu = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"nproc": os.cpu_count(), "cpu": cpu, "python": platform.python_version(), "platform": platform.platform()}


def reference_pass(events: Sequence[tuple[Any, Any]], clock: Callable[[], float]) -> float:
    """Seconds of one pass of the reference loop over ``(event, label)`` pairs: a plain Python loop
    doing one dict increment per event (the practical limit for per-event Python code)."""
    d: dict[str, int] = {}
    t0 = clock()
    for ev, _lab in events:
        k = ev.predicate
        d[k] = d.get(k, 0) + 1
    return max(clock() - t0, 1e-9)


def rss_mb() -> tuple[float, float]:
    """(current RSS, peak RSS) of this process in MB, from /proc/self/status."""
    cur = peak = 0.0
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            cur = int(line.split()[1]) / 1024
        elif line.startswith("VmHWM:"):
            peak = int(line.split()[1]) / 1024
    return cur, peak


def pair_stream(n_events: int, n_pairs: int, *, seed: int = 0, events_per_step: int = 10,
                p_decisive: float = 1.0, start: int = 0) -> Iterator[tuple[object, object]]:
    """(EvidenceEvent, FrameLabels) over ``n_pairs`` (node, predicate) pairs (3 predicates), one
    target per event, ``events_per_step`` events per time step, the geometric label decisive with
    probability ``p_decisive``. Generated lazily in numpy blocks (no event list held)."""
    import numpy as np

    from sgbelief.fusion.channel import FrameLabels
    from sgbelief.fusion.events import EvidenceEvent

    preds = ("is_car", "is_pedestrian", "is_building")
    pos_label = {"is_car": "car", "is_pedestrian": "person", "is_building": "building"}
    n_nodes = max(1, n_pairs // 3)
    nodes = [f"v{i:07d}" for i in range(n_nodes)]
    rng = np.random.default_rng(seed)
    none_labels = FrameLabels({})
    block = 65536
    trusted = EvidenceEvent.trusted
    for b0 in range(start, start + n_events, block):
        m = min(block, start + n_events - b0)
        k = rng.integers(0, n_nodes * 3, size=m)
        truth = rng.random(m) < 0.5
        conf = np.round(np.clip(np.where(truth, rng.beta(5, 2, m), rng.beta(2, 5, m)), 0, 1), 4)
        mass = np.round(rng.uniform(0.3, 1.0, m), 3)
        dec = rng.random(m) < p_decisive
        for j in range(m):
            i = b0 + j
            node = nodes[int(k[j]) // 3]
            pred = preds[int(k[j]) % 3]
            if dec[j]:
                labels = FrameLabels({node: pos_label[pred] if truth[j] else "road"})
            else:
                labels = none_labels
            yield trusted({node: float(mass[j])}, pred, float(conf[j]), "vlm", i // events_per_step, f"e{i}"), labels

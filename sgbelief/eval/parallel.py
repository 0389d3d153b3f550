"""Fan independent scenes out over processes or a Ray cluster, results in input order.

``run_scenes(fn, items, workers=1, executor="local")`` is ``[fn(x) for x in items]`` with the
work spread over ``workers`` processes (``executor="local"``, a ``ProcessPoolExecutor``) or over
a Ray cluster (``executor="ray"``, the optional extra ``sgbelief[ray]``). Results always come
back in the order of ``items``, so a parallel run is identical to the serial one as long as
``fn`` is deterministic (every sgbelief replay is: operators hold no global random state).

``fn`` and the items must be picklable (a module-level function, not a lambda). Scene-level
parallelism is the right grain: one scene's stream is inherently sequential (each update reads
the belief the previous one wrote), scenes are independent.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

T = TypeVar("T")
R = TypeVar("R")

EXECUTORS = ("local", "ray")


def default_workers() -> int:
    """Usable CPUs of this process (affinity-aware)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def run_scenes(
    fn: Callable[[T], R],
    items: Iterable[T],
    workers: int = 1,
    executor: str = "local",
    *,
    chunksize: int = 1,
    ray_address: str | None = None,
) -> list[R]:
    """``[fn(x) for x in items]``, in order, over ``workers`` processes or a Ray cluster.

    - ``executor="local"``: ``workers <= 1`` runs serially in this process (no pickling);
      ``workers > 1`` uses a process pool (``chunksize`` items per task).
    - ``executor="ray"``: one Ray task per item; connects to ``ray_address`` (or the
      ``RAY_ADDRESS`` environment variable, or starts a local Ray) when Ray is not initialised.
      ``workers`` caps the number of tasks in flight (0 = no cap).

    An exception raised by ``fn`` propagates to the caller.
    """
    seq: Sequence[T] = items if isinstance(items, Sequence) else list(items)
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {EXECUTORS}, got {executor!r}")
    if workers < 0:
        raise ValueError(f"workers must be >= 0, got {workers}")
    if executor == "ray":
        return _run_ray(fn, seq, workers, ray_address)
    if workers <= 1 or len(seq) <= 1:
        return [fn(x) for x in seq]
    from concurrent.futures import ProcessPoolExecutor
    import multiprocessing as mp

    # fork is fastest on Linux; spawn elsewhere (and when a parent already runs threads, the user
    # may set SGBELIEF_MP_START=spawn)
    method = os.environ.get("SGBELIEF_MP_START") or ("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    ctx = mp.get_context(method)
    with ProcessPoolExecutor(max_workers=min(workers, len(seq)), mp_context=ctx) as pool:
        return list(pool.map(fn, seq, chunksize=max(1, chunksize)))


def _run_ray(fn: Callable[[T], R], seq: Sequence[T], workers: int, address: str | None) -> list[R]:
    try:
        import ray
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("executor='ray' needs Ray: pip install 'sgbelief[ray]' (or pip install ray)") from exc
    if not ray.is_initialized():
        addr = address or os.environ.get("RAY_ADDRESS")
        if addr:
            ray.init(address=addr, ignore_reinit_error=True, log_to_driver=False)
        else:
            ray.init(num_cpus=max(1, workers) if workers else None, ignore_reinit_error=True,
                     include_dashboard=False, log_to_driver=False)
    remote = ray.remote(_call)
    fn_ref = ray.put(fn)
    results: list[Any] = [None] * len(seq)
    cap = workers if workers > 0 else len(seq)
    in_flight: dict[Any, int] = {}
    nxt = 0
    while nxt < len(seq) or in_flight:
        while nxt < len(seq) and len(in_flight) < cap:
            in_flight[remote.remote(fn_ref, seq[nxt])] = nxt
            nxt += 1
        done, _ = ray.wait(list(in_flight), num_returns=1)
        for ref in done:
            results[in_flight.pop(ref)] = ray.get(ref)
    return results


def random_scene_summary(seed: int, n_events: int = 150, operators: Sequence[str] = ("majority", "comod")) -> dict[str, Any]:
    """A small deterministic scene (seeded random stream through ``operators``): end beliefs and
    stats. Importable everywhere, so it serves as the executor self-test on a cluster."""
    from sgbelief.eval.random_stream import random_records
    from sgbelief.eval.replay import make_runs, replay

    runs = make_runs(list(operators), None)
    replay(random_records(seed, n_events, n_nodes=10), runs)
    return {
        "seed": seed,
        "beliefs": {
            run.name: sorted((str(k), run.graph.provenance.alpha_beta(*k)) for k in run.graph.provenance.pairs())
            for run in runs
        },
        "stats": {run.name: dict(run.operator.stats) for run in runs},
    }


def _call(fn: Callable[[T], R], item: T) -> R:
    return fn(item)


__all__ = ["run_scenes", "default_workers", "random_scene_summary", "EXECUTORS"]

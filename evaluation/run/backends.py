"""Where independent pieces of work run: a local process pool, or a Ray cluster.

A backend is a context manager yielding ``run(fn, items)``, which calls ``fn(item,
threads)`` somewhere and yields ``(item, result or exception)`` as they finish; results
travel through the backend, so remote workers need no shared file system. ``pool``:
``workers`` spawned local processes (:mod:`unitrack_env.evaluation.run.pool`); ``ray``: one
``num_cpus=1`` task per item, on a local Ray or a cluster (``address``; the ``ray`` extra).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from .pool import SupervisedPool
from .workers import worker_init

Runner = Callable[[Callable[..., Any], Iterable[Any]], Iterator[tuple[Any, Any]]]


@contextlib.contextmanager
def pool_backend(workers: int = 1) -> Iterator[Runner]:
    """Local worker processes (``workers`` <= 1: in this process)."""
    workers = max(1, int(workers))
    threads = max(1, (os.cpu_count() or 1) // workers)

    if workers == 1:
        def run_here(fn: Callable[..., Any], items: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
            for item in items:
                try:
                    yield item, fn(item, threads)
                except Exception as exc:  # reported with the item, the others go on
                    yield item, exc

        yield run_here
        return

    with SupervisedPool(workers, threads, init=worker_init()) as pool:
        def run_pool(fn: Callable[..., Any], items: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
            yield from pool.run(_call, items, lambda item: (fn, item, threads))

        yield run_pool


def _call(fn: Callable[..., Any], item: Any, threads: int, beat: Any) -> Any:
    """A pool task: ``fn(item, threads)`` (a cell keeps its own per-step watchdog)."""
    return fn(item, threads)


@contextlib.contextmanager
def ray_backend(workers: int = 1, address: str | None = None,
                gpus: float = 0.0) -> Iterator[Runner]:
    """Ray tasks on a local Ray (``address`` None) or a running cluster."""
    try:
        import ray  # lazy: optional dependency (ray)
    except ImportError:
        raise ImportError("--backend ray needs Ray: pip install 'unitrack-env[ray]'") from None
    started = not ray.is_initialized()
    if started:
        if address is None:
            ray.init(num_cpus=max(1, int(workers)), include_dashboard=False,
                     log_to_driver=False, configure_logging=False)
        else:
            ray.init(address=address, log_to_driver=False, configure_logging=False)

    def run_ray(fn: Callable[..., Any], items: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        remote = ray.remote(num_cpus=1, num_gpus=gpus, max_retries=0)(fn)
        pending = {remote.remote(item, 1): item for item in items}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                item = pending.pop(ref)
                try:
                    yield item, ray.get(ref)
                except ray.exceptions.RayTaskError as exc:
                    yield item, exc.as_instanceof_cause()
                except Exception as exc:
                    yield item, exc

    try:
        yield run_ray
    finally:
        if started:
            ray.shutdown()


def make_backend(name: str, *, workers: int = 1, address: str | None = None,
                 gpus: float = 0.0) -> contextlib.AbstractContextManager[Runner]:
    """The backend called ``name`` (``pool`` or ``ray``)."""
    if name == "pool":
        if address is not None:
            raise ValueError("--address goes with --backend ray")
        return pool_backend(workers)
    if name == "ray":
        return ray_backend(workers, address, gpus)
    raise ValueError(f"unknown backend '{name}'; valid: pool, ray")

"""One benchmark object per task: ground truth, official result files, scoring, columns.

``benchmark_for("UniTrack/MOT17-v0", root=...)`` gives the benchmark of a registered id
made with those environment arguments, without building the environment; the registration
table names each id's benchmark class (:attr:`unitrack_env.registration.Variant.scoring`).
"""

from __future__ import annotations

import inspect
from typing import Any

from unitrack_env.benchmarks.base import Benchmark
from unitrack_env.registration import Variant, variant, variants

__all__ = ["Benchmark", "benchmark_class", "benchmark_for", "task_columns"]


def benchmark_class(env_id: str | Variant) -> type[Benchmark]:
    """The benchmark class that a registered id (or its row) names."""
    row = env_id if isinstance(env_id, Variant) else variant(env_id)
    if not row.scoring:
        raise ValueError(f"'{row.env_id}' names no benchmark (its row has no scoring=)")
    cls = row.scoring_class
    if not (isinstance(cls, type) and issubclass(cls, Benchmark)):
        raise TypeError(f"scoring={row.scoring!r} does not name a Benchmark subclass")
    return cls


def benchmark_for(env_id: str | Variant, **env_kwargs: Any) -> Benchmark:
    """The benchmark of ``gym.make(env_id, **env_kwargs)``, without making the environment.

    The row's default arguments (e.g. MOT's ``benchmark=`` rule set) apply first, then
    ``env_kwargs``; the benchmark's :meth:`~Benchmark.build` takes those its signature names
    (arguments that only concern playing, such as capacities or rendering, are not).
    """
    row = env_id if isinstance(env_id, Variant) else variant(env_id)
    cls = benchmark_class(row)
    names = inspect.signature(cls.build).parameters
    return cls.build(**{k: v for k, v in {**row.kwargs, **env_kwargs}.items() if k in names})


def task_columns(task: str) -> tuple[str, ...]:
    """The result columns of a task's benchmark (empty for a task no row registers)."""
    for row in variants():
        if row.task == task and row.scoring:
            return benchmark_class(row).columns
    return ()

"""Hit statistics of the feature cache: counters, and the runs that recorded them on disk.

Each process records its :class:`CacheStats` in ``<root>/runs``; :func:`read_runs` sums
them per run, and :func:`track_cache_run` gives the caches of a block (worker processes
included) one run id.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from .cache_config import default_cache_dir, format_size

RUN_ENV: str = "UNITRACK_FEATURE_CACHE_RUN"
"""Environment variable naming the current run in the statistics (set by
:func:`track_cache_run`; inherited by worker processes)."""


@dataclass
class CacheStats:
    """Counters of one cache (in one process), or summed over processes.

    ``corrupt``: entries recomputed because unreadable; ``stored``/``evicted`` (and bytes):
    entries this process added or removed.
    """

    hits: int = 0
    misses: int = 0
    corrupt: int = 0
    stored: int = 0
    stored_bytes: int = 0
    evicted: int = 0
    evicted_bytes: int = 0

    @property
    def lookups(self) -> int:
        """Frames asked for: hits + misses + corrupt."""
        return self.hits + self.misses + self.corrupt

    @property
    def hit_rate(self) -> float:
        """Hits per lookup (NaN without lookups)."""
        return self.hits / self.lookups if self.lookups else float("nan")

    def __add__(self, other: CacheStats) -> CacheStats:
        return CacheStats(**{f.name: getattr(self, f.name) + getattr(other, f.name)
                             for f in fields(self)})

    def __sub__(self, other: CacheStats) -> CacheStats:
        return CacheStats(**{f.name: getattr(self, f.name) - getattr(other, f.name)
                             for f in fields(self)})

    def copy(self) -> CacheStats:
        """A snapshot."""
        return CacheStats(**asdict(self))

    def summary(self) -> str:
        """One line for a run's output, e.g. ``feature cache: 4/4 frames read (100%), ...``."""
        rate = f"{100 * self.hit_rate:.0f}%" if self.lookups else "-"
        text = (f"feature cache: {self.hits}/{self.lookups} frames read from the cache ({rate}), "
                f"{self.misses + self.corrupt} computed")
        if self.corrupt:
            text += f" ({self.corrupt} corrupt entries replaced)"
        if self.evicted:
            text += f", {self.evicted} old entries evicted ({format_size(self.evicted_bytes)})"
        return text


@dataclass(frozen=True)
class RunRecord:
    """Statistics of one run (the processes that shared a run id), from ``<root>/runs``."""

    run: str | None
    started: float
    updated: float
    processes: int
    stats: CacheStats
    namespaces: tuple[str, ...] = ()


def read_runs(
    root: str | os.PathLike[str], *, limit: int | None = None, run: str | None = None
) -> list[RunRecord]:
    """Run statistics recorded under ``root`` (see :meth:`FeatureCache.runs`)."""
    folder = Path(root) / "runs"
    groups: dict[str, list[dict[str, Any]]] = {}
    try:
        files = sorted(folder.glob("*.json"))
    except OSError:
        files = []
    for path in files:
        try:
            record = json.loads(path.read_text())
        except (OSError, ValueError):
            continue  # removed or being replaced: skip it
        if run is not None and record.get("run") != run:
            continue
        group = record.get("run") or f"pid:{path.stem}"
        groups.setdefault(group, []).append(record)
    names = {f.name for f in fields(CacheStats)}
    out = []
    for records in groups.values():
        stats = CacheStats()
        for record in records:
            stats = stats + CacheStats(**{k: int(v) for k, v in record.items() if k in names})
        spaces = sorted({n for r in records for n in r.get("namespaces", [])})
        out.append(RunRecord(records[0].get("run"), min(float(r["started"]) for r in records),
                             max(float(r["updated"]) for r in records), len(records), stats,
                             tuple(spaces)))
    out.sort(key=lambda r: r.started)
    return out[-limit:] if limit else out


@dataclass
class CacheRun:
    """A run's handle from :func:`track_cache_run`: its id and the cache folder (None: default)."""

    run: str
    root: Path | None = None

    def stats(self, root: str | os.PathLike[str] | None = None) -> CacheStats | None:
        """Counters summed over this run's processes (in ``root``); None if none reported."""
        folder = Path(root) if root is not None else (self.root or default_cache_dir())
        if folder is None:
            return None
        records = read_runs(folder, run=self.run)
        if not records:
            return None
        return records[0].stats

    def summary(self, root: str | os.PathLike[str] | None = None) -> str | None:
        """:meth:`CacheStats.summary` of this run, or None when no cache reported."""
        stats = self.stats(root)
        return None if stats is None else stats.summary()


@contextlib.contextmanager
def track_cache_run(root: str | os.PathLike[str] | None = None) -> Iterator[CacheRun]:
    """Give the feature caches used inside the block a run id (``$UNITRACK_FEATURE_CACHE_RUN``).

    Worker processes inherit it; read the sum afterwards with :meth:`CacheRun.summary`.

    Example:
        >>> with track_cache_run() as cache_run:                  # doctest: +SKIP
        ...     report = run("UniTrack/MOT17-v0", "unitrack", out="runs/a")
        >>> print(cache_run.summary())                            # doctest: +SKIP
        feature cache: 600/600 frames read from the cache (100%), 0 computed
    """
    run_id = f"{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}-{secrets.token_hex(4)}"
    previous = os.environ.get(RUN_ENV)
    os.environ[RUN_ENV] = run_id
    try:
        yield CacheRun(run_id, None if root is None else Path(root))
    finally:
        if previous is None:
            os.environ.pop(RUN_ENV, None)
        else:
            os.environ[RUN_ENV] = previous

"""A content-addressed, size-bounded on-disk cache of frame feature maps, on by default.

Comparing heads or hyper-parameters on the same frames should not recompute the backbone.
An entry is addressed by *what determines the features*, never by where the frame came from:

* the model identity (:meth:`ModelIdentity.key`: architecture, layer, weights digest,
  normalisation, and whatever else the model counts as its identity),
* the network input geometry ``H x W`` and the on-disk dtype, and
* a full hash of the decoded frame (:func:`content_key`: SHA-256 of every byte, its shape and
  dtype, and a tag naming the transform that turns it into the network input; 128 bits kept).

So identical frames share one entry across sequences, MOT17's detector variants
(``MOT17-02-DPM`` / ``-FRCNN`` / ``-SDP``), data sets and tasks. Layout::

    <root>/CACHEDIR.TAG                       marks the folder as a cache for backup tools
    <root>/.lock                              inter-process lock (accounting, eviction)
    <root>/usage.json                         total bytes and entries (kept under the lock)
    <root>/v2/<model key>-<H>x<W>-<dtype>/model.json          the model, readable
    <root>/v2/<model key>-<H>x<W>-<dtype>/<ab>/<content>.npy  one entry per frame
    <root>/runs/<start>-<pid>-<nonce>.json    hit statistics of recent processes

**On by default.** ``feature_cache=True`` (the heads' default) uses :func:`default_cache_dir`:
``$UNITRACK_FEATURE_CACHE``, else ``$UNITRACK_CACHE/features``, else the platform's user
cache folder (``platformdirs.user_cache_dir("unitrack-env")/features``, e.g.
``~/.cache/unitrack-env/features``). ``UNITRACK_FEATURE_CACHE=off`` turns the default off;
``feature_cache=False`` turns it off for one agent.

**Bounded.** The cap (:data:`DEFAULT_MAX_SIZE`, 10 GiB; ``$UNITRACK_FEATURE_CACHE_MAX`` or
``max_size=``) is enforced on every write: when the total exceeds it, the least recently used
entries (a hit refreshes an entry's modification time) are removed until the total is at most
:data:`EVICT_TO` of the cap.

**Safe with many writers.** An entry is written to a temporary file in its final folder and
renamed into place, so a reader sees a complete entry or none. Renames, the size accounting
and eviction happen under an exclusive lock on ``<root>/.lock`` (``fcntl.flock`` on POSIX,
``msvcrt.locking`` on Windows), so the total stays exact with any number of processes. A
corrupt entry (truncated, bad header, wrong dtype or shape) is reported once with a
:class:`FeatureCacheWarning`, recomputed and replaced; a cache that cannot be written (disk
full, read-only) is reported once and the features are used uncached.

**Same values warm or cold.** Values are stored as float16 (:data:`DEFAULT_CACHE_DTYPE`);
features served through the cache are the stored values converted back to float32 on a hit
and on a miss alike, so results do not depend on whether the cache was warm.

Use :class:`CachedAppearanceModel` (what the heads build) or :meth:`FeatureCache.get_or_compute`
for any array-producing function. Hit statistics: :attr:`FeatureCache.stats` in the process,
:func:`track_cache_run` across the worker processes of a run, and ``unitrack cache info``.

The pieces live beside this module, which re-exports their names (they were all defined here
before issue 14): settings and sizes in :mod:`.cache_config`, keys in :mod:`.cache_keys`, hit
statistics and runs in :mod:`.cache_runs`, the entry file format, atomic writes and the lock
in :mod:`.cache_files`, the folder layout, accounting and eviction in :mod:`.cache_folder`
(:class:`FeatureCache`'s base), and :class:`CachedAppearanceModel` in :mod:`.cached_model`.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitrack_env.agents.appearance.cache_config import (
    _OFF_VALUES,
    APP_NAME,
    CACHE_DIR_ENV,
    CACHE_MAX_ENV,
    DATA_ENV,
    DEFAULT_CACHE_DTYPE,
    DEFAULT_MAX_SIZE,
    default_cache_dir,
    default_max_size,
    format_size,
    parse_size,
)
from unitrack_env.agents.appearance.cache_files import (
    FeatureCacheWarning,
    _as_float32,
    _atomic_write,
    _load_entry,
    _to_stored,
)
from unitrack_env.agents.appearance.cache_folder import (
    EVICT_TO,
    LAYOUT_VERSION,
    STALE_TEMP_SECONDS,
    CacheFolder,
    CacheUsage,
    NamespaceUsage,
)
from unitrack_env.agents.appearance.cache_keys import (
    CONTENT_DIGEST_BYTES,
    CONTENT_HASH,
    CacheKey,
    content_key,
)
from unitrack_env.agents.appearance.cache_runs import (
    RUN_ENV,
    CacheRun,
    CacheStats,
    RunRecord,
    read_runs,
    track_cache_run,
)

__all__ = [  # the names this module has always offered
    "APP_NAME", "CACHE_DIR_ENV", "CACHE_MAX_ENV", "CONTENT_DIGEST_BYTES", "CONTENT_HASH",
    "DATA_ENV", "DEFAULT_CACHE_DTYPE", "DEFAULT_MAX_SIZE", "EVICT_TO", "LAYOUT_VERSION",
    "MAX_RUN_FILES", "RUN_ENV", "STALE_TEMP_SECONDS",
    "CacheKey", "CacheRun", "CacheStats", "CacheUsage", "FeatureCache", "FeatureCacheWarning",
    "NamespaceUsage", "RunRecord",
    "CachedAppearanceModel",  # noqa: F822 - imported on first use (__getattr__ below)
    "content_key", "default_cache_dir", "default_max_size", "format_size", "parse_size",
    "read_runs", "resolve_cache", "track_cache_run",
]

MAX_RUN_FILES: int = 200
"""Process statistics files kept in ``<root>/runs`` (oldest removed first)."""

_LAZY = frozenset({"CachedAppearanceModel", "AppearanceModel"})


def __getattr__(name: str) -> Any:
    """``CachedAppearanceModel`` (and the ``AppearanceModel`` it wraps), imported on first use.

    :mod:`.cached_model` builds its cache with :func:`resolve_cache`, so it imports this
    module; importing it here only when asked keeps the imports free of cycles.
    """
    if name in _LAZY:
        from unitrack_env.agents.appearance import cached_model

        return getattr(cached_model, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def resolve_cache(
    spec: FeatureCache | str | os.PathLike[str] | bool | None,
    *,
    max_size: int | str | None = None,
    dtype: type[np.floating] = DEFAULT_CACHE_DTYPE,
) -> FeatureCache | None:
    """The cache an agent option asks for.

    Args:
        spec: True: the default cache (:func:`default_cache_dir`; None when the environment
            turns it off); False or None: no cache; a folder; or a :class:`FeatureCache`.
        max_size: Cap for a cache built here (None: :func:`default_max_size`).
        dtype: On-disk dtype of a cache built here (float32: exact features, as the
            propagation heads use; entries of each dtype live apart).
    """
    if isinstance(spec, FeatureCache):
        return spec
    if spec is None or spec is False:
        return None
    if spec is True:
        root = default_cache_dir()
        return None if root is None else FeatureCache(root, max_size=max_size, dtype=dtype)
    if isinstance(spec, str) and spec.strip().lower() in _OFF_VALUES:
        return None
    return FeatureCache(spec, max_size=max_size, dtype=dtype)


# ---------------------------------------------------------------------------- the cache
class FeatureCache(CacheFolder):
    """Feature maps on disk, content-addressed and bounded (see the module docstring).

    Lookups and writes (a failure is warned about once), and this process's statistics; the
    folder itself (paths, accounting, eviction, :meth:`~CacheFolder.usage`,
    :meth:`~CacheFolder.prune`, :meth:`~CacheFolder.clear`) is the base :class:`CacheFolder`.

    Args:
        root: Cache folder (created on first write).
        max_size: Cap in bytes or as text (``"10GiB"``); None: :func:`default_max_size`.
        dtype: On-disk dtype (default float16; float32 stores the features exactly).

    Attributes:
        stats: :class:`CacheStats` of this instance (this process).
    """

    def __init__(
        self,
        root: str | os.PathLike[str],
        *,
        max_size: int | str | None = None,
        dtype: type[np.floating] = DEFAULT_CACHE_DTYPE,
    ) -> None:
        super().__init__(root, max_size=max_size, dtype=dtype)
        self._reported: set[str] = set()
        self._write_failed = False
        self._session_file: Path | None = None
        self._session_run: str | None = None
        self._session_started = 0.0
        self._session_base = CacheStats()
        self._flushed = CacheStats()

    # -- backward-compatible counters
    @property
    def hits(self) -> int:
        """Entries read from disk (``stats.hits``)."""
        return self.stats.hits

    @property
    def misses(self) -> int:
        """Entries computed because absent (``stats.misses``)."""
        return self.stats.misses

    @property
    def recomputed(self) -> int:
        """Entries recomputed because corrupt (``stats.corrupt``)."""
        return self.stats.corrupt

    # -- warnings
    def _warn(self, what: str, message: str) -> None:
        if what not in self._reported:
            self._reported.add(what)
            warnings.warn(message, FeatureCacheWarning, stacklevel=4)

    # -- reading
    def _read(
        self, key: CacheKey, expected_shape: tuple[int, ...] | None
    ) -> tuple[np.ndarray | None, bool]:
        """(array or None, whether a stored file was corrupt)."""
        path = self.path(key)
        array, problem = _load_entry(path, self.dtype, expected_shape)
        if problem:
            self._warn(str(path), f"{path}: corrupt feature-cache entry ({problem}); "
                                  "recomputing it")
            return None, True
        if array is not None:
            self._namespaces.add(path.parents[1].name)
        return array, False

    def get(
        self, key: CacheKey, expected_shape: tuple[int, ...] | None = None
    ) -> np.ndarray | None:
        """The stored array (a hit refreshes its LRU time), or None when absent or corrupt.

        Does not count in :attr:`stats`; corruption is warned about once per entry.
        """
        return self._read(key, expected_shape)[0]

    # -- writing
    def put(
        self,
        key: CacheKey,
        array: np.ndarray | torch.Tensor,
        *,
        replace: bool = False,
        model_info: dict[str, Any] | None = None,
    ) -> np.ndarray:
        """Store ``array`` (atomically, within the cap); return the stored-dtype values.

        Args:
            key: Entry identity.
            array: The features.
            replace: Overwrite an existing entry (repairing a corrupt one). Otherwise an entry
                that a concurrent writer stored first is kept (the content is the same).
            model_info: Readable description saved once per entry folder (``model.json``).

        A failed write (disk full, read-only folder) is reported once and the values are
        returned uncached.
        """
        stored = _to_stored(array, self.dtype)
        try:
            self._store(key, stored, replace, model_info)
        except FileNotFoundError:
            pass  # the folder was cleared while writing: the entry is simply not kept
        except OSError as exc:
            self._write_failed = True
            self._warn("write", f"feature cache {self.root} cannot be written "
                                f"({type(exc).__name__}: {exc}); features are computed without "
                                f"caching (set ${CACHE_DIR_ENV} elsewhere, or feature_cache=False)")
        return stored

    # -- lookups
    def get_or_compute(
        self,
        key: CacheKey,
        compute: Callable[[], np.ndarray | torch.Tensor],
        *,
        expected_shape: tuple[int, ...] | None = None,
    ) -> torch.Tensor:
        """Return the cached features for ``key``, computing and storing them if needed.

        Args:
            key: Entry identity.
            compute: Zero-argument function producing the array (called on a miss only).
            expected_shape: When given, a stored entry of another shape counts as corrupt.

        Returns:
            A float32 CPU tensor holding the stored values.
        """
        array, corrupt = self._read(key, expected_shape)
        if array is not None:
            self.stats.hits += 1
        else:
            if corrupt:
                self.stats.corrupt += 1
            else:
                self.stats.misses += 1
            array = self.put(key, compute(), replace=corrupt)
        return _as_float32(array)

    # -- statistics on disk
    def flush_stats(self) -> None:
        """Write this process's counters to ``<root>/runs``.

        Read by ``unitrack cache info`` and :func:`track_cache_run`; cheap, and a no-op when
        nothing changed.
        """
        run = os.environ.get(RUN_ENV) or None
        if self._session_file is not None and run != self._session_run:
            self._session_file = None  # a new run: a new record, counted from here
            self._session_base = self._flushed.copy()
        if self.stats == self._flushed and self._session_file is not None:
            return
        session = self.stats - self._session_base
        if session.lookups == 0 and session.stored == 0 and session.evicted == 0:
            return
        runs = self.root / "runs"
        now = time.time()
        new = self._session_file is None
        if new:
            self._session_run = run
            self._session_started = now
            self._session_file = runs / (f"{int(now * 1000):013d}-{os.getpid()}-"
                                         f"{secrets.token_hex(3)}.json")
        record = {"run": run, "pid": os.getpid(), "started": self._session_started,
                  "updated": now, "namespaces": sorted(self._namespaces), **asdict(session)}
        text = json.dumps(record).encode()
        try:
            _atomic_write(self._session_file, lambda handle: handle.write(text))
            if new:
                old = sorted(p for p in runs.iterdir() if p.suffix == ".json")
                for stale in old[:-MAX_RUN_FILES]:
                    with contextlib.suppress(OSError):
                        stale.unlink()
        except OSError as exc:
            if not self._write_failed:  # (an unwritable cache was reported already)
                self._warn("stats", f"feature cache statistics cannot be written to {runs} "
                                    f"({type(exc).__name__}: {exc})")
            return
        self._flushed = self.stats.copy()

    def runs(self, limit: int | None = None, *, run: str | None = None) -> list[RunRecord]:
        """Statistics of the most recent runs (newest last), from ``<root>/runs``.

        Args:
            limit: At most this many (the most recent).
            run: Only this run id.
        """
        return read_runs(self.root, limit=limit, run=run)

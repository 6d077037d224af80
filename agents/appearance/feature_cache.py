"""A content-addressed, size-bounded on-disk cache of frame feature maps, on by default.

Comparing heads or options on the same frames should not recompute the backbone. An entry
is addressed by what determines the features, never by where the frame came from: the
model identity (:attr:`ModelIdentity.key`), the network input ``H x W`` and on-disk dtype,
and a full hash of the decoded frame (SHA-256 of its bytes, shape, dtype and transform tag;
128 bits kept). Identical frames share one entry across sequences, MOT17's detector
variants, data sets and tasks. Layout under the root: ``CACHEDIR.TAG``, ``.lock``,
``usage.json``, ``v3/<model key>-<H>x<W>-<dtype>/{model.json, <ab>/<content>.npy}`` and
``runs/*.json`` (hit statistics of recent processes).

* On by default: ``feature_cache=True`` is ``$UNITRACK_FEATURE_CACHE``, else
  ``$UNITRACK_CACHE/features``, else the user cache folder
  (``~/.cache/unitrack-env/features``); ``UNITRACK_FEATURE_CACHE=off`` or
  ``feature_cache=False`` turn it off.
* Bounded: the cap (10 GiB, ``$UNITRACK_FEATURE_CACHE_MAX`` or ``max_size=``) is enforced on
  every write by evicting the least recently used entries down to ``EVICT_TO`` of it.
* Safe with many writers: entries are written to a temporary file and renamed; accounting
  and eviction run under an exclusive lock on ``.lock``. An unwritable cache is reported
  once and the features are used uncached.
* Checked on read: after the array (a plain ``.npy``) an entry has a 36-byte trailer (a magic
  string, the digest of its key, the array's byte count, the CRC-32 of its bytes). An entry
  swapped with another key's, damaged, cut short, without a trailer, of the wrong dtype or
  shape, or holding NaN/infinity is never served: one :class:`FeatureCacheWarning` names the
  file, and it is recomputed and replaced. Non-finite features are not stored. Layout ``v3``
  introduced the trailer; ``v2`` entries are not read (misses) and ``unitrack cache clear``
  removes them. The checks' cost per hit: ``python benchmarks/feature_cache.py --parts entry``.
* Same values warm or cold: entries are float16 and served as float32 on a hit and a miss
  alike, so results do not depend on the cache's state.

Siblings: settings in ``.cache_config``, keys in ``.cache_keys``, hit statistics in
``.cache_runs`` (``unitrack cache info``), the entry format and lock in ``.cache_files``,
layout and eviction in ``.cache_folder``, :class:`CachedAppearanceModel` in ``.cached_model``.
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

from .cache_config import (
    _OFF_VALUES,
    CACHE_DIR_ENV,
    DEFAULT_CACHE_DTYPE,
    default_cache_dir,
)
from .cache_files import (
    FeatureCacheWarning,
    _as_float32,
    _atomic_write,
    _load_entry,
    _to_stored,
    all_finite,
    key_digest,
)
from .cache_folder import CacheFolder
from .cache_keys import CacheKey
from .cache_runs import RUN_ENV, CacheStats, RunRecord, read_runs

__all__ = ["MAX_RUN_FILES", "FeatureCache", "resolve_cache"]

MAX_RUN_FILES: int = 200
"""Process statistics files kept in ``<root>/runs`` (oldest removed first)."""

def resolve_cache(
    spec: FeatureCache | str | os.PathLike[str] | bool | None,
    *,
    max_size: int | str | None = None,
    dtype: type[np.floating] = DEFAULT_CACHE_DTYPE,
) -> FeatureCache | None:
    """The cache an agent option asks for: True the default (if on), False/None none, a folder.

    A cache built here gets ``max_size`` and on-disk ``dtype`` (entries of each dtype live apart).
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

    Lookups, writes (a failure is warned about once) and this process's ``stats``; the folder
    itself (accounting, eviction, usage, prune, clear) is the base :class:`CacheFolder`.
    ``max_size`` is bytes or text (``"10GiB"``); ``dtype`` float16 by default.
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

    # -- warnings
    def _warn(self, what: str, message: str) -> None:
        if what not in self._reported:
            self._reported.add(what)
            warnings.warn(message, FeatureCacheWarning, stacklevel=4)

    # -- reading
    def _read(
        self, key: CacheKey, expected_shape: tuple[int, ...] | None
    ) -> tuple[np.ndarray | None, bool]:
        """(array or None, whether a stored file was swapped, damaged or not finite)."""
        path = self.path(key)
        digest = key_digest(self.namespace(key), key.content)
        array, problem = _load_entry(path, self.dtype, expected_shape, digest)
        if problem:
            self._warn(str(path), f"{path}: corrupt feature-cache entry ({problem}); "
                                  "not used: recomputing and replacing it")
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

        Without ``replace`` an entry a concurrent writer stored first is kept. A failed write is
        reported once and the values are returned uncached, as are values that are not all
        finite (an entry never holds NaN or infinity).
        """
        stored = _to_stored(array, self.dtype)
        if not all_finite(stored):
            return stored
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
        """The cached float32 features for ``key``, computed by ``compute()`` and stored on a miss.

        A stored entry of another shape than ``expected_shape`` counts as corrupt.
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
        """Write this process's counters to ``<root>/runs`` (no-op when nothing changed)."""
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
        """Statistics of the most recent ``limit`` runs (or of ``run``), newest last."""
        return read_runs(self.root, limit=limit, run=run)

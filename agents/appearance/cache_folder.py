"""The feature-cache folder: where entries live, the size accounting and LRU eviction.

Entries live under ``<root>/v2/<model key>-<H>x<W>-<dtype>/<ab>/``, are stored atomically
under the inter-process lock with ``usage.json`` kept exact, and the least recently used
go when the total exceeds the cap.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .cache_config import (
    DEFAULT_CACHE_DTYPE,
    default_max_size,
    parse_size,
)
from .cache_files import (
    _ENTRY_SUFFIX,
    _atomic_write,
    _Entry,
    _subdirs,
    file_lock,
)
from .cache_keys import CacheKey
from .cache_runs import CacheStats

LAYOUT_VERSION: int = 2
"""Version of the on-disk layout (the ``v2`` folder); bumped when keys or formats change."""

EVICT_TO: float = 0.9
"""Eviction removes least recently used entries until the total is at most this fraction of
the cap (so that a full cache does not evict on every write)."""

STALE_TEMP_SECONDS: float = 3600.0
"""Temporary files older than this are leftovers of killed writers; eviction removes them."""

_CACHEDIR_TAG = (
    "Signature: 8a477f597d28d172789f06886806bc55\n"
    "# This file is a cache directory tag created by unitrack-env (feature cache).\n"
    "# For information about cache directory tags see https://bford.info/cachedir/\n"
)


@dataclass
class NamespaceUsage:
    """Disk use of one entry folder ``<model key>-<H>x<W>-<dtype>`` (``last_used``: UNIX time)."""

    name: str
    entries: int = 0
    bytes: int = 0
    last_used: float = 0.0
    model: dict[str, Any] = field(default_factory=dict)


@dataclass
class CacheUsage:
    """What a cache folder holds (from a scan): entries, bytes, per-folder use, temp files."""

    root: Path
    entries: int
    bytes: int
    namespaces: list[NamespaceUsage]
    temp_files: int = 0


class CacheFolder:
    """Entries of one cache folder on disk, within a cap (the storage of a feature cache)."""

    def __init__(
        self,
        root: str | os.PathLike[str],
        *,
        max_size: int | str | None = None,
        dtype: type[np.floating] = DEFAULT_CACHE_DTYPE,
    ) -> None:
        self.root = Path(root).expanduser()
        self.max_size = default_max_size() if max_size is None else parse_size(max_size)
        self.dtype = np.dtype(dtype)
        if self.dtype.kind != "f":
            raise ValueError(f"cache dtype must be a float type, got {self.dtype}")
        self.stats = CacheStats()
        self._namespaces: set[str] = set()

    # -- paths
    @property
    def entries_dir(self) -> Path:
        """Folder of the entry folders (``<root>/v2``)."""
        return self.root / f"v{LAYOUT_VERSION}"

    def namespace(self, key: CacheKey) -> str:
        """Entry folder name of ``key``: ``<model key>-<H>x<W>-<dtype>``."""
        height, width = key.input_size
        return f"{key.model}-{int(height)}x{int(width)}-{self.dtype.name}"

    def path(self, key: CacheKey) -> Path:
        """File that holds ``key``'s entry."""
        return (self.entries_dir / self.namespace(key) / key.content[:2]
                / f"{key.content}{_ENTRY_SUFFIX}")

    def _lock(self) -> contextlib.AbstractContextManager[None]:
        return file_lock(self.root / ".lock")

    # -- writing
    def _write_identity(self, namespace: str, info: dict[str, Any]) -> None:
        target = self.entries_dir / namespace / "model.json"
        if not target.is_file():
            text = json.dumps(info, indent=2, sort_keys=True, default=str).encode()
            _atomic_write(target, lambda handle: handle.write(text))

    def _ensure_root(self) -> None:
        tag = self.root / "CACHEDIR.TAG"
        if not tag.is_file():
            _atomic_write(tag, lambda handle: handle.write(_CACHEDIR_TAG.encode()))

    def _store(self, key: CacheKey, stored: np.ndarray, replace: bool,
               model_info: dict[str, Any] | None) -> None:
        namespace = self.namespace(key)
        self._namespaces.add(namespace)
        self._ensure_root()
        self._write_identity(namespace, {
                "model_key": key.model, "input_size": list(key.input_size),
                "dtype": self.dtype.name, "layout": LAYOUT_VERSION, **(model_info or {})})
        final = self.path(key)
        final.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(dir=final.parent, prefix=f".{final.stem}.", suffix=".tmp")
        tmp = Path(tmp_name)
        try:
            with os.fdopen(fd, "wb") as handle:
                np.save(handle, stored)
                size = handle.tell()
            with self._lock():
                try:
                    old = final.stat().st_size
                except FileNotFoundError:
                    old = None
                if old is not None and not replace:  # a concurrent writer stored it first
                    tmp.unlink()
                    return
                total, entries = self._read_usage_locked()  # (before the new entry exists)
                os.replace(tmp, final)
                now = time.time_ns()
                os.utime(final, ns=(now, now))
                total += size - (old or 0)
                entries += 0 if old is not None else 1
                if total > self.max_size:
                    total, entries = self._evict_locked(int(self.max_size * EVICT_TO))
                self._write_usage_locked(total, entries)
            self.stats.stored += 1
            self.stats.stored_bytes += size
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise

    # -- accounting (callers hold the lock)
    def _usage_file(self) -> Path:
        return self.root / "usage.json"

    def _read_usage_locked(self) -> tuple[int, int]:
        try:
            data = json.loads(self._usage_file().read_text())
            return int(data["bytes"]), int(data["entries"])
        except (OSError, ValueError, KeyError, TypeError):
            entries = self._scan()
            return sum(e.size for e in entries), len(entries)

    def _write_usage_locked(self, total: int, entries: int) -> None:
        text = json.dumps({"bytes": total, "entries": entries,
                           "max_size": self.max_size}).encode()
        _atomic_write(self._usage_file(), lambda handle: handle.write(text))

    def _scan(self, *, remove_stale: bool = False) -> list[_Entry]:
        """Every entry (and, optionally, removal of stale temporary files)."""
        found: list[_Entry] = []
        stale_before = time.time() - STALE_TEMP_SECONDS
        for folder in _subdirs(self.entries_dir):
            for shard in _subdirs(folder):
                with contextlib.suppress(FileNotFoundError), os.scandir(shard) as items:
                    for item in items:
                        try:
                            info = item.stat()
                        except FileNotFoundError:
                            continue
                        if item.name.startswith("."):
                            if remove_stale and info.st_mtime < stale_before:
                                with contextlib.suppress(OSError):
                                    os.unlink(item.path)
                            continue
                        if item.name.endswith(_ENTRY_SUFFIX):
                            found.append(_Entry(Path(item.path), info.st_size, info.st_mtime_ns))
        return found

    def _evict_locked(self, target: int) -> tuple[int, int]:
        """Remove least recently used entries until at most ``target`` bytes remain."""
        entries = self._scan(remove_stale=True)
        total = sum(e.size for e in entries)
        entries.sort(key=lambda e: (e.used_ns, e.path.name))
        kept = len(entries)
        for entry in entries:
            if total <= target:
                break
            try:
                entry.path.unlink()
            except FileNotFoundError:
                pass
            except OSError:  # e.g. open by a reader on Windows: keep it
                continue
            total -= entry.size
            kept -= 1
            self.stats.evicted += 1
            self.stats.evicted_bytes += entry.size
        return total, kept

    # -- management
    def usage(self) -> CacheUsage:
        """Scan the folder: entries and bytes per entry folder (and repair ``usage.json``)."""
        per: dict[str, NamespaceUsage] = {}
        entries = self._scan()
        for entry in entries:
            name = entry.path.parents[1].name
            ns = per.setdefault(name, NamespaceUsage(name))
            ns.entries += 1
            ns.bytes += entry.size
            ns.last_used = max(ns.last_used, entry.used_ns / 1e9)
        for folder in _subdirs(self.entries_dir):
            ns = per.setdefault(folder.name, NamespaceUsage(folder.name))
            with contextlib.suppress(OSError, ValueError):
                ns.model = json.loads((folder / "model.json").read_text())
        temp = 0
        for folder in _subdirs(self.entries_dir):
            for shard in _subdirs(folder):
                with contextlib.suppress(FileNotFoundError):
                    temp += sum(1 for p in os.listdir(shard) if p.startswith("."))
        total = sum(e.size for e in entries)
        if self.root.is_dir():
            with contextlib.suppress(OSError), self._lock():
                self._write_usage_locked(*self._count_locked())
        return CacheUsage(self.root, len(entries), total,
                          sorted(per.values(), key=lambda n: (-n.bytes, n.name)), temp)

    def _count_locked(self) -> tuple[int, int]:
        entries = self._scan()
        return sum(e.size for e in entries), len(entries)

    def prune(self, max_size: int | str | None = None) -> tuple[int, int]:
        """Evict LRU entries and stale temp files down to ``max_size``; return (entries, bytes)."""
        limit = self.max_size if max_size is None else parse_size(max_size)
        if not self.root.is_dir():
            return 0, 0
        before = self.stats.copy()
        with self._lock():
            total, entries = self._evict_locked(limit)
            self._write_usage_locked(total, entries)
        after = self.stats - before
        return after.evicted, after.evicted_bytes

    def clear(self) -> tuple[int, int]:
        """Remove every entry and the run statistics. Returns (entries, bytes) removed."""
        if not self.root.is_dir():
            return 0, 0
        with self._lock():
            entries = self._scan()
            for name in (self.entries_dir, self.root / "runs"):
                shutil.rmtree(name, ignore_errors=True)
            self._write_usage_locked(0, 0)
        self._namespaces.clear()
        return len(entries), sum(e.size for e in entries)

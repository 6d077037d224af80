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
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import secrets
import shutil
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import IO, Any

import numpy as np
import torch

from unitrack_env.agents.appearance.model import AppearanceModel

DEFAULT_CACHE_DTYPE: type[np.floating] = np.float16
"""On-disk dtype of cached features (half the disk of float32, ~5e-4 relative rounding)."""

DEFAULT_MAX_SIZE: int = 10 * 2**30
"""Default cap of the cache folder: 10 GiB, about 4,600 feature maps of 1080p frames at the
default 1088 x 608 input (2.3 MB each), e.g. MOT17's 5,316 unique training frames minus the
sequence used least recently."""

CACHE_DIR_ENV: str = "UNITRACK_FEATURE_CACHE"
"""Environment variable: the cache folder, or ``off`` (also ``0``, ``false``, ``no``,
``none``) to turn the default cache off."""

CACHE_MAX_ENV: str = "UNITRACK_FEATURE_CACHE_MAX"
"""Environment variable: the cap, e.g. ``10GiB``, ``500MB`` or a number of bytes."""

RUN_ENV: str = "UNITRACK_FEATURE_CACHE_RUN"
"""Environment variable naming the current run in the statistics (set by
:func:`track_cache_run`; inherited by worker processes)."""

DATA_ENV: str = "UNITRACK_CACHE"
"""The project's cache folder (synthetic data sets); the feature cache defaults to its
``features`` sub-folder."""

APP_NAME: str = "unitrack-env"
"""Application name given to platformdirs."""

LAYOUT_VERSION: int = 2
"""Version of the on-disk layout (the ``v2`` folder); bumped when keys or formats change."""

CONTENT_HASH: str = "sha256"
"""hashlib algorithm of :func:`content_key`. SHA-256 runs on the CPU's SHA instructions through
OpenSSL (x86 since Ice Lake / Zen, ARMv8): 3.4 ms per 1080p frame here, against 6.5 ms for
BLAKE2b and 17 ms for MD5 (``benchmarks/feature_cache.py``)."""

CONTENT_DIGEST_BYTES: int = 16
"""Bytes of the content digest kept (128 bits: 32 hex digits in entry names)."""

EVICT_TO: float = 0.9
"""Eviction removes least recently used entries until the total is at most this fraction of
the cap (so that a full cache does not evict on every write)."""

STALE_TEMP_SECONDS: float = 3600.0
"""Temporary files older than this are leftovers of killed writers; eviction removes them."""

MAX_RUN_FILES: int = 200
"""Process statistics files kept in ``<root>/runs`` (oldest removed first)."""

_OFF_VALUES = frozenset({"0", "off", "false", "no", "none"})
_SIZE_UNITS = {
    "": 1, "b": 1,
    "k": 2**10, "kib": 2**10, "kb": 10**3,
    "m": 2**20, "mib": 2**20, "mb": 10**6,
    "g": 2**30, "gib": 2**30, "gb": 10**9,
    "t": 2**40, "tib": 2**40, "tb": 10**12,
}
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+)\s*([a-zA-Z]*)\s*$")
_ENTRY_SUFFIX = ".npy"
_CACHEDIR_TAG = (
    "Signature: 8a477f597d28d172789f06886806bc55\n"
    "# This file is a cache directory tag created by unitrack-env (feature cache).\n"
    "# For information about cache directory tags see https://bford.info/cachedir/\n"
)


class FeatureCacheWarning(UserWarning):
    """A cache entry was unreadable (and is recomputed), or the cache could not be written."""


# ---------------------------------------------------------------------------- configuration
def parse_size(text: str | int | float) -> int:
    """Bytes of a size such as ``"10GiB"``, ``"500MB"``, ``"1.5G"`` or ``1048576``.

    ``KiB/MiB/GiB/TiB`` and the bare ``K/M/G/T`` are powers of 1024; ``kB/MB/GB/TB`` powers
    of 1000.

    Raises:
        ValueError: not a size, or negative.
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
        unit = ""
    else:
        match = _SIZE.match(str(text))
        if match is None or match.group(2).lower() not in _SIZE_UNITS:
            raise ValueError(
                f"not a size: {text!r} (examples: 10GiB, 500MB, 1.5G, 1048576)")
        value, unit = float(match.group(1)), match.group(2).lower()
    if value < 0:
        raise ValueError(f"a size must be >= 0, got {text!r}")
    return int(value * _SIZE_UNITS[unit])


def format_size(num_bytes: float) -> str:
    """``1536`` -> ``"1.5 KiB"`` (binary units)."""
    value = float(num_bytes)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(value) < 1024 or unit == "GiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{value:.1f} TiB"  # pragma: no cover - unreachable


def default_cache_dir() -> Path | None:
    """The default cache folder, or None when ``$UNITRACK_FEATURE_CACHE`` turns it off.

    ``$UNITRACK_FEATURE_CACHE``, else ``$UNITRACK_CACHE/features``, else
    ``platformdirs.user_cache_dir("unitrack-env")/features``.
    """
    override = os.environ.get(CACHE_DIR_ENV, "").strip()
    if override:
        return None if override.lower() in _OFF_VALUES else Path(override).expanduser()
    data = os.environ.get(DATA_ENV, "").strip()
    if data:
        return Path(data).expanduser() / "features"
    import platformdirs  # lazily: only needed without an override

    return Path(platformdirs.user_cache_dir(APP_NAME)) / "features"


def default_max_size() -> int:
    """The cap: ``$UNITRACK_FEATURE_CACHE_MAX`` or :data:`DEFAULT_MAX_SIZE`."""
    text = os.environ.get(CACHE_MAX_ENV, "").strip()
    if not text:
        return DEFAULT_MAX_SIZE
    try:
        return parse_size(text)
    except ValueError as exc:
        raise ValueError(f"${CACHE_MAX_ENV}: {exc}") from None


def resolve_cache(
    spec: FeatureCache | str | os.PathLike[str] | bool | None,
    *,
    max_size: int | str | None = None,
) -> FeatureCache | None:
    """The cache an agent option asks for.

    Args:
        spec: True: the default cache (:func:`default_cache_dir`; None when the environment
            turns it off); False or None: no cache; a folder; or a :class:`FeatureCache`.
        max_size: Cap for a cache built here (None: :func:`default_max_size`).
    """
    if isinstance(spec, FeatureCache):
        return spec
    if spec is None or spec is False:
        return None
    if spec is True:
        root = default_cache_dir()
        return None if root is None else FeatureCache(root, max_size=max_size)
    if isinstance(spec, str) and spec.strip().lower() in _OFF_VALUES:
        return None
    return FeatureCache(spec, max_size=max_size)


# ---------------------------------------------------------------------------- keys
def content_key(image: np.ndarray, transform: str = "") -> str:
    """Hex digest (128 bits) of every byte of ``image``, its shape and dtype, and ``transform``.

    Args:
        image: The array to address (e.g. the decoded frame).
        transform: Names what turns ``image`` into the network input (e.g.
            ``"letterbox 1088x608 pad 128"``); empty when ``image`` is the network input. Two
            preprocessings of the same frame never share an entry.
    """
    array = np.ascontiguousarray(image)
    digest = hashlib.new(CONTENT_HASH)
    digest.update(f"{transform}|{array.dtype.str}|{array.shape}|".encode())
    digest.update(array.reshape(-1).view(np.uint8))
    return digest.hexdigest()[: 2 * CONTENT_DIGEST_BYTES]


@dataclass(frozen=True)
class CacheKey:
    """Identity of one cached feature map.

    Attributes:
        model: :meth:`ModelIdentity.key` of the appearance model.
        input_size: ``(height, width)`` of the network input.
        content: :func:`content_key` of the frame (hex).
    """

    model: str
    input_size: tuple[int, int]
    content: str

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[0-9a-f]{4,128}", self.content):
            raise ValueError(f"content must be a hex digest (content_key), got {self.content!r}")
        if not re.fullmatch(r"[A-Za-z0-9._-]+", self.model):
            raise ValueError(f"model key must be a plain identifier, got {self.model!r}")


# ---------------------------------------------------------------------------- statistics
@dataclass
class CacheStats:
    """Counters of one cache (in one process), or summed over processes.

    Attributes:
        hits: Entries read from disk.
        misses: Entries computed because they were absent.
        corrupt: Entries recomputed because the stored file was unreadable.
        stored: Entries this process added (a concurrent writer may have added one first).
        stored_bytes: Bytes of those entries.
        evicted: Entries this process removed to keep the cap.
        evicted_bytes: Bytes of those entries.
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
    """Statistics of one run (the processes that shared a run id), from ``<root>/runs``.

    Attributes:
        run: The run id (None: a process outside :func:`track_cache_run`).
        started: Earliest process start (UNIX time).
        updated: Latest statistics update (UNIX time).
        processes: Number of processes (caches) that reported.
        stats: Summed counters.
        namespaces: Entry folders used (``<model key>-<H>x<W>-<dtype>``).
    """

    run: str | None
    started: float
    updated: float
    processes: int
    stats: CacheStats
    namespaces: tuple[str, ...] = ()


# ---------------------------------------------------------------------------- locking
if os.name == "nt":  # pragma: no cover - exercised on Windows only
    import msvcrt

    def _lock_fd(fd: int) -> None:
        while True:
            try:
                msvcrt.locking(fd, msvcrt.LK_LOCK, 1)
                return
            except OSError:
                continue

    def _unlock_fd(fd: int) -> None:
        os.lseek(fd, 0, os.SEEK_SET)
        msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)
else:
    import fcntl

    def _lock_fd(fd: int) -> None:
        fcntl.flock(fd, fcntl.LOCK_EX)

    def _unlock_fd(fd: int) -> None:
        fcntl.flock(fd, fcntl.LOCK_UN)


@contextlib.contextmanager
def _file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (created if needed) across processes and threads."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        _lock_fd(fd)
        try:
            yield
        finally:
            _unlock_fd(fd)
    finally:
        os.close(fd)


def _atomic_write(path: Path, write: Callable[[IO[bytes]], None]) -> int:
    """Write a file through a temporary sibling and a rename; return its size."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            size = handle.tell()
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return size


@dataclass
class _Entry:
    path: Path
    size: int
    used_ns: int


@dataclass
class NamespaceUsage:
    """Disk use of one entry folder (one model identity, input size and dtype).

    Attributes:
        name: Folder name ``<model key>-<H>x<W>-<dtype>``.
        entries: Number of entries.
        bytes: Their total size.
        last_used: Most recent use of any entry (UNIX time; 0 without entries).
        model: The model description saved with the folder (``model.json``), or empty.
    """

    name: str
    entries: int = 0
    bytes: int = 0
    last_used: float = 0.0
    model: dict[str, Any] = field(default_factory=dict)


@dataclass
class CacheUsage:
    """What a cache folder holds (from a scan).

    Attributes:
        root: The folder.
        entries: Number of entries.
        bytes: Their total size.
        namespaces: Per entry folder, largest first.
        temp_files: Temporary files of writers in progress (or killed).
    """

    root: Path
    entries: int
    bytes: int
    namespaces: list[NamespaceUsage]
    temp_files: int = 0


# ---------------------------------------------------------------------------- the cache
class FeatureCache:
    """Feature maps on disk, content-addressed and bounded (see the module docstring).

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
        self.root = Path(root).expanduser()
        self.max_size = default_max_size() if max_size is None else parse_size(max_size)
        self.dtype = np.dtype(dtype)
        if self.dtype.kind != "f":
            raise ValueError(f"cache dtype must be a float type, got {self.dtype}")
        self.stats = CacheStats()
        self._reported: set[str] = set()
        self._write_failed = False
        self._namespaces: set[str] = set()
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
        return _file_lock(self.root / ".lock")

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
        try:
            with open(path, "rb") as handle:
                array = np.load(handle, allow_pickle=False)
        except (FileNotFoundError, NotADirectoryError):
            return None, False
        except (ValueError, OSError, EOFError) as exc:
            self._warn(str(path), f"{path}: corrupt feature-cache entry "
                                  f"({type(exc).__name__}: {exc}); recomputing it")
            return None, True
        reason = ""
        if not isinstance(array, np.ndarray) or array.dtype != self.dtype:
            reason = f"dtype {getattr(array, 'dtype', type(array).__name__)}, expected {self.dtype}"
        elif expected_shape is not None and tuple(array.shape) != tuple(expected_shape):
            reason = f"shape {array.shape}, expected {tuple(expected_shape)}"
        if reason:
            self._warn(str(path), f"{path}: corrupt feature-cache entry ({reason}); "
                                  "recomputing it")
            return None, True
        now = time.time_ns()
        with contextlib.suppress(OSError):  # least recently used = oldest modification time
            os.utime(path, ns=(now, now))
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
    def _write_identity(self, namespace: str, info: dict[str, Any]) -> None:
        target = self.entries_dir / namespace / "model.json"
        if not target.is_file():
            text = json.dumps(info, indent=2, sort_keys=True, default=str).encode()
            _atomic_write(target, lambda handle: handle.write(text))

    def _ensure_root(self) -> None:
        tag = self.root / "CACHEDIR.TAG"
        if not tag.is_file():
            _atomic_write(tag, lambda handle: handle.write(_CACHEDIR_TAG.encode()))

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
        """Evict least recently used entries down to ``max_size`` (default: the cap).

        Also removes temporary files left by killed writers. Returns (entries, bytes)
        removed.
        """
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
            for old in self.root.glob("v*"):  # layouts of older versions
                if old.is_dir() and re.fullmatch(r"v\d+", old.name):
                    shutil.rmtree(old, ignore_errors=True)
            self._write_usage_locked(0, 0)
        self._namespaces.clear()
        return len(entries), sum(e.size for e in entries)

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


def _to_stored(array: np.ndarray | torch.Tensor, dtype: np.dtype) -> np.ndarray:
    """``array`` in the on-disk dtype.

    Torch converts float32 -> float16 several times faster than numpy; both round to nearest
    even.
    """
    if isinstance(array, torch.Tensor):
        tensor = array.detach().to("cpu")
        target = torch.from_numpy(np.empty(0, dtype)).dtype
        return tensor.to(target).contiguous().numpy()
    return np.ascontiguousarray(array, dtype=dtype)


def _as_float32(array: np.ndarray) -> torch.Tensor:
    """Stored values as a float32 tensor (exact; torch converts float16 ~20x faster than numpy)."""
    if not array.flags.writeable:
        array = array.copy()
    return torch.from_numpy(array).to(torch.float32)


def _subdirs(folder: Path) -> list[Path]:
    try:
        with os.scandir(folder) as items:
            return sorted(Path(i.path) for i in items if i.is_dir() and not i.name.startswith("."))
    except (FileNotFoundError, NotADirectoryError):
        return []


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
    """A run's handle from :func:`track_cache_run`.

    Attributes:
        run: The run id every feature cache of this run (and its worker processes) records.
        root: The cache folder to read statistics from (None: :func:`default_cache_dir`).
    """

    run: str
    root: Path | None = None

    def stats(self, root: str | os.PathLike[str] | None = None) -> CacheStats | None:
        """Counters summed over the processes of this run; None when no cache reported.

        Args:
            root: Another cache folder (when the agents were given ``feature_cache=<dir>``).
        """
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

    Worker processes started inside inherit it. Caches record their counters when their agent
    resets or closes; read the sum afterwards with :meth:`CacheRun.stats` or
    :meth:`CacheRun.summary`.

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


# ---------------------------------------------------------------------------- the model
class CachedAppearanceModel:
    """An :class:`AppearanceModel` whose per-frame features go through a :class:`FeatureCache`.

    Args:
        model: The appearance model.
        cache: A cache, a folder, or True for the default cache.
        max_size: Cap of a cache built here (None: :func:`default_max_size`).

    Raises:
        ValueError: ``cache`` resolves to no cache (False, or True while
            ``$UNITRACK_FEATURE_CACHE=off``): use the model itself.

    Example:
        >>> cached = CachedAppearanceModel(AppearanceModel(), "/tmp/feats")  # doctest: +SKIP
        >>> maps = cached.features(frames)                                   # doctest: +SKIP
    """

    def __init__(
        self,
        model: AppearanceModel,
        cache: FeatureCache | str | os.PathLike[str] | bool = True,
        *,
        max_size: int | str | None = None,
    ) -> None:
        resolved = resolve_cache(cache, max_size=max_size)
        if resolved is None:
            raise ValueError(f"feature_cache={cache!r} turns the cache off "
                             f"(${CACHE_DIR_ENV}={os.environ.get(CACHE_DIR_ENV, '')!r}); "
                             "use the appearance model itself")
        self.model = model
        self.cache = resolved
        self.identity = model.identity
        self.channels = model.channels
        self.stride = model.stride
        self._model_key = model.identity.key()

    def describe(self) -> dict[str, Any]:
        """The wrapped model's description plus the cache location."""
        return {**self.model.describe(), "cache": str(self.cache.root)}

    def _info(self) -> dict[str, Any]:
        with contextlib.suppress(Exception):  # descriptive only
            return {"model": self.model.describe()}
        return {}

    def key(self, input_size: tuple[int, int], content: str) -> CacheKey:
        """The :class:`CacheKey` of a frame at ``input_size`` = (height, width)."""
        return CacheKey(self._model_key, (int(input_size[0]), int(input_size[1])), content)

    def lookup(self, input_size: tuple[int, int], content: str) -> torch.Tensor | None:
        """The cached ``(1, C, h, w)`` map of one frame, or None (nothing computed).

        Args:
            input_size: ``(height, width)`` of the network input.
            content: :func:`content_key` the entry is stored under.

        A hit counts in the statistics; a miss does not (the caller computes with
        :meth:`features` ``(..., keys=[content])``, which counts it).
        """
        array, _ = self.cache._read(self.key(input_size, content),
                                    self.model.feature_shape(*input_size))
        if array is None:
            return None
        self.cache.stats.hits += 1
        return _as_float32(array)[None]

    def features(
        self,
        images: np.ndarray | Sequence[np.ndarray],
        *,
        keys: Sequence[str] | None = None,
    ) -> torch.Tensor:
        """Feature maps ``(B, C, h, w)`` of network inputs, from the cache when possible.

        Args:
            images: uint8 RGB network inputs ``(H, W, 3)`` (one, a ``(B, H, W, 3)`` array, or
                a list), all of the same size (letterbox first).
            keys: :func:`content_key` of each frame to store the entries under (default: of
                ``images`` themselves). A caller that looks entries up before preparing its
                input (by the original frame, to skip the letterbox on a hit) passes its own.

        Returns:
            float32 CPU tensor of the stored (e.g. float16-rounded) features; the backbone
            runs once, batched, on the frames not in the cache.
        """
        batch = np.asarray(images) if not isinstance(images, np.ndarray) else images
        if batch.ndim == 3:
            batch = batch[None]
        if keys is None:
            keys = [content_key(img) for img in batch]
        if len(keys) != batch.shape[0]:
            raise ValueError(f"{batch.shape[0]} images but {len(keys)} keys")
        input_size = (int(batch.shape[1]), int(batch.shape[2]))
        expected = self.model.feature_shape(*input_size)
        found: dict[int, np.ndarray] = {}
        todo: list[tuple[int, bool]] = []
        stats = self.cache.stats
        for i, content in enumerate(keys):
            array, corrupt = self.cache._read(self.key(input_size, content), expected)
            if array is not None:
                stats.hits += 1
                found[i] = array
            else:
                todo.append((i, corrupt))
                if corrupt:
                    stats.corrupt += 1
                else:
                    stats.misses += 1
        if todo:
            computed = self.model.features(batch[[i for i, _ in todo]]).to("cpu")
            info = self._info()
            for row, (i, corrupt) in enumerate(todo):
                found[i] = self.cache.put(self.key(input_size, keys[i]), computed[row],
                                          replace=corrupt, model_info=info)
        return _as_float32(np.stack([found[i] for i in range(len(keys))]))

    def flush_stats(self) -> None:
        """Record the cache's counters on disk (see :meth:`FeatureCache.flush_stats`)."""
        self.cache.flush_stats()

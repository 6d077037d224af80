"""Files of the feature cache: the entry format, atomic writes, the lock, corrupt entries.

An entry is one ``.npy`` file written to a temporary sibling and renamed into place, so
readers see a complete file or none. After the array, a 36-byte trailer holds a magic
string, the digest of the entry's key, the array's byte count and the CRC-32 of its bytes
(``np.load`` still reads the file: it stops after the array). :func:`_load_entry` checks all
of them and that the values are finite, and names what is wrong with a swapped or damaged
entry; :func:`file_lock` is the inter-process lock (``flock`` / ``msvcrt.locking``).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import struct
import tempfile
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
import torch

_ENTRY_SUFFIX = ".npy"

_TRAILER = struct.Struct("<8s16sQI")
"""Entry trailer: magic, key digest (16 bytes), array bytes, CRC-32 of the array bytes."""

_MAGIC = b"UTFEAT1\0"

_MAX_HEADER = 1 << 16
"""Longest ``.npy`` header read (the cache writes ~128 bytes)."""


class FeatureCacheWarning(UserWarning):
    """A cache entry was unreadable (and is recomputed), or the cache could not be written."""


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
def file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (created if needed) across processes and threads."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o666)
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
    """Stored values as a float32 tensor (exact; torch converts float16 faster than numpy)."""
    if not array.flags.writeable:
        array = array.copy()
    return torch.from_numpy(array).to(torch.float32)


def _subdirs(folder: Path) -> list[Path]:
    try:
        with os.scandir(folder) as items:
            return sorted(Path(i.path) for i in items  # a link is not the cache's: not followed
                          if i.is_dir(follow_symlinks=False) and not i.name.startswith("."))
    except (FileNotFoundError, NotADirectoryError):
        return []


class _BadEntry(ValueError):
    """What is wrong with an entry file (its message is the reason shown)."""


def key_digest(namespace: str, content: str) -> bytes:
    """The 16-byte digest of an entry's key (entry folder and content key) in its trailer."""
    return hashlib.sha256(f"{namespace}/{content}".encode()).digest()[:16]


def all_finite(array: np.ndarray) -> bool:
    """Whether every value is finite.

    float16: no exponent of all ones (2.3x faster than a sum); other dtypes: a float32 sum
    first (a finite sum means finite values; a sum that overflowed is checked value by value).
    """
    if array.size == 0:
        return True
    flat = np.ascontiguousarray(array).reshape(-1)
    if flat.dtype == np.float16:
        return bool(np.bitwise_and(flat.view(np.uint16), 0x7C00).max() < 0x7C00)
    total = torch.from_numpy(flat).sum(dtype=torch.float32)
    return bool(torch.isfinite(total)) or bool(np.isfinite(flat).all())


def _write_entry(handle: IO[bytes], array: np.ndarray, key: bytes) -> None:
    """Write ``array`` as ``.npy`` followed by the trailer that ties it to ``key``."""
    np.save(handle, array)
    data = array.reshape(-1).view(np.uint8)
    handle.write(_TRAILER.pack(_MAGIC, key, data.size, zlib.crc32(data)))


def _read_bytes(path: Path) -> bytearray:
    with open(path, "rb") as handle:
        buffer = bytearray(os.fstat(handle.fileno()).st_size)
        handle.readinto(buffer)
    return buffer


def _parse_entry(buffer: bytearray, key: bytes) -> np.ndarray:
    """The array of an entry's bytes; ValueError (:class:`_BadEntry`) if not an intact entry."""
    head = io.BytesIO(bytes(buffer[:_MAX_HEADER]))
    version = np.lib.format.read_magic(head)
    read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                   else np.lib.format.read_array_header_2_0)
    shape, fortran, dtype = read_header(head, max_header_size=_MAX_HEADER)
    if fortran or dtype.hasobject:
        raise _BadEntry("not an entry the cache writes (Fortran order or objects)")
    start = head.tell()
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    expected = start + nbytes + _TRAILER.size
    if len(buffer) == start + nbytes:
        raise _BadEntry("a plain .npy without the entry trailer (not written by this cache)")
    if len(buffer) != expected:
        raise _BadEntry(f"{len(buffer)} bytes, expected {expected} (truncated or padded)")
    magic, stored_key, count, crc = _TRAILER.unpack_from(buffer, start + nbytes)
    if magic != _MAGIC or count != nbytes:
        raise _BadEntry("no valid entry trailer (damaged, or not written by the cache)")
    if stored_key != key:
        raise _BadEntry("it holds the features of another key (swapped or copied entry)")
    data = memoryview(buffer)[start:start + nbytes]
    if zlib.crc32(data) != crc:
        raise _BadEntry("checksum mismatch (damaged bytes)")
    return np.frombuffer(buffer, dtype, nbytes // max(1, dtype.itemsize), start).reshape(shape)


def _load_entry(
    path: Path, dtype: np.dtype, expected_shape: tuple[int, ...] | None, key: bytes
) -> tuple[np.ndarray | None, str]:
    """The entry at ``path`` of the key whose :func:`key_digest` is ``key``, else None and why.

    A swapped, damaged or non-finite entry gives its reason. Returns ``(array, "")``,
    ``(None, "")`` when absent, or ``(None, reason)``. Reading a valid
    entry refreshes its modification time (least recently used = oldest).
    """
    try:
        array = _parse_entry(_read_bytes(path), key)
    except (FileNotFoundError, NotADirectoryError):
        return None, ""
    except _BadEntry as exc:
        return None, str(exc)
    except (ValueError, OSError, EOFError, struct.error) as exc:
        return None, f"{type(exc).__name__}: {exc}"
    reason = ""
    if array.dtype != dtype:
        reason = f"dtype {array.dtype}, expected {dtype}"
    elif expected_shape is not None and tuple(array.shape) != tuple(expected_shape):
        reason = f"shape {array.shape}, expected {tuple(expected_shape)}"
    elif not all_finite(array):
        reason = "non-finite values (NaN or infinity)"
    if reason:
        return None, reason
    now = time.time_ns()
    with contextlib.suppress(OSError):  # least recently used = oldest modification time
        os.utime(path, ns=(now, now))
    return array, ""

"""Files of the feature cache: the entry format, atomic writes, the lock, corrupt entries.

An entry is one ``.npy`` file written to a temporary sibling and renamed into place, so
readers see a complete file or none; :func:`_load_entry` names what is wrong with a corrupt
one; :func:`file_lock` is the inter-process lock (``flock`` / ``msvcrt.locking``).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
import torch

_ENTRY_SUFFIX = ".npy"


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


def _load_entry(
    path: Path, dtype: np.dtype, expected_shape: tuple[int, ...] | None
) -> tuple[np.ndarray | None, str]:
    """The entry at ``path``, or None and (when the file is corrupt) what is wrong with it.

    Returns ``(array, "")``, ``(None, "")`` when absent, or ``(None, reason)``. Reading a valid
    entry refreshes its modification time (least recently used = oldest).
    """
    try:
        with open(path, "rb") as handle:
            array = np.load(handle, allow_pickle=False)
    except (FileNotFoundError, NotADirectoryError):
        return None, ""
    except (ValueError, OSError, EOFError) as exc:
        return None, f"{type(exc).__name__}: {exc}"
    reason = ""
    if not isinstance(array, np.ndarray) or array.dtype != dtype:
        reason = f"dtype {getattr(array, 'dtype', type(array).__name__)}, expected {dtype}"
    elif expected_shape is not None and tuple(array.shape) != tuple(expected_shape):
        reason = f"shape {array.shape}, expected {tuple(expected_shape)}"
    if reason:
        return None, reason
    now = time.time_ns()
    with contextlib.suppress(OSError):  # least recently used = oldest modification time
        os.utime(path, ns=(now, now))
    return array, ""

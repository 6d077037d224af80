"""Files written and named safely.

Atomic writes (readers see the old file or the whole new one, never half of one) that never
write through a symbolic link, and :func:`path_inside`, the check of every path read from a
file (a split list, a JSON file name, a manifest): data, never a way out of its folder.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from unitrack_env.errors import DataFormatError


class LinkRefused(OSError):
    """A link (symbolic, or a lock file's hard link) where a file is to be written: refused."""

    def __init__(self, path: str | os.PathLike, what: str = "a symbolic link") -> None:
        self.path, self.what = Path(path), what
        super().__init__(errno.ELOOP, f"{self.path} is {what}; unitrack-env never "
                                      "writes through a link (it would change the file it "
                                      "points to): remove the link, or choose another folder")

    def __str__(self) -> str:
        return str(self.strerror)

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.path, self.what))


def refuse_link(path: str | os.PathLike) -> None:
    """Raise :class:`LinkRefused` when ``path`` is a symbolic link (even a dangling one)."""
    if os.path.islink(path):
        raise LinkRefused(path)


def _name_problem(name: object) -> str | None:
    """What makes ``name`` more than a plain relative path (None: nothing)."""
    if not isinstance(name, str):
        return f"is not a name but JSON {type(name).__name__} data"
    if not name.strip():
        return "is empty"
    if "\0" in name:
        return "holds a NUL byte"
    windows = PureWindowsPath(name)
    if name.startswith(("/", "\\")) or windows.drive or windows.root:
        return "is an absolute path"
    parts = PurePosixPath(name.replace("\\", "/")).parts
    if ".." in parts:
        return "climbs out of its folder with '..'"
    if not parts:
        return "names the folder itself"
    return None


def path_inside(folder: str | os.PathLike, name: object, source: str | os.PathLike, *,
                line: int | None = None, field: str | None = None) -> Path:
    """``folder / name`` for a ``name`` read from the file ``source``, once it is checked.

    A name from a file is data: it must be a relative path (``seq``, ``seq/00001.jpg``)
    that stays inside ``folder``, with no ``..`` part and no absolute or drive path. Links
    inside ``folder`` are the owner's and are not looked at here (writes refuse them).

    Raises:
        DataFormatError: naming ``source``, its ``line`` or ``field`` and the value.
    """
    problem = _name_problem(name)
    if problem is not None:
        raise DataFormatError(source, f"{name!r} {problem}; a name read from a file must be a "
                                      f"relative path inside {folder}, so it is refused",
                              line=line, field=field)
    return Path(folder) / str(name)


def _umask() -> int:
    """The process umask (read by setting and restoring it; there is no getter)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary sibling file and ``os.replace``.

    The temporary file is created new (``O_EXCL``, never through a link) and renamed over
    ``path``; a link at ``path`` is refused (:class:`LinkRefused`), not replaced or followed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    refuse_link(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        # mkstemp creates the file 0600; give it the mode an ordinary open() would have.
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.filename is None:
            exc.filename = str(path)  # a full disk names the file it was writing
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def file_in_the_way(folder: str | os.PathLike) -> Path | None:
    """The first of ``folder`` and its parents that exists as something other than a folder.

    None when ``folder`` is a folder or can be created as one. Output options check this
    before any work, so that ``--out results.csv`` fails at once with a sentence, not after
    the first sequence with an ``[Errno 20]``.
    """
    for path in (Path(folder), *Path(folder).parents):
        if path.exists():
            return None if path.is_dir() else path
    return None

"""Who owns an output folder: one run at a time, and a manifest of what runs of ours wrote.

The lock is an exclusive ``flock`` on ``.unitrack.lock`` (the kernel drops it when its process
dies, however it dies), whose text names the holder; where ``flock`` is missing or not honoured
(some network file systems), a holder on this host whose pid runs with the recorded start time
(not a recycled pid) still refuses. ``manifest.json`` lists each file before it is written and
claims a sequence before its first file, so a killed run's half-written sequence is still ours;
``overwrite`` deletes only what it lists. For users: docs/evaluation.md.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import socket
import sys
import time
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from unitrack_env.fingerprint import sequence_files
from unitrack_env.io import LinkRefused, atomic_write_text, path_inside, refuse_link

from .episode import OutputError, SequenceRecord
from .identity import result_digest

try:  # POSIX; elsewhere the lock relies on the recorded pid alone
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

LOCK = ".unitrack.lock"
MANIFEST = "manifest.json"
#: Names of :func:`unitrack_env.io.atomic_write_bytes`'s temporary files.
TEMPORARY = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.tmp$")


class OutputInUse(RuntimeError):
    """Another process holds the output folder's lock (``holder`` says who)."""

    def __init__(self, folder: Path, holder: Holder | None) -> None:
        self.folder, self.holder = Path(folder), holder
        who = holder.describe() if holder is not None else "another process (unknown)"
        super().__init__(f"{folder} is in use by another run: {who}; wait for it to finish, "
                         f"or choose another --out (if no run is writing there, delete its "
                         f"lock file {Path(folder) / LOCK})")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.folder, self.holder))


@dataclass(frozen=True)
class Holder:
    """Who holds a lock, as written in the lock file."""

    pid: int
    host: str
    command: str
    what: str
    since: str
    started: str = ""  # the process's start time (Linux), against recycled pids

    def describe(self) -> str:
        """``pid 123 on host, `command` (what), since ...``."""
        return (f"pid {self.pid} on {self.host}, `{self.command}` ({self.what}), "
                f"since {self.since}")

    @classmethod
    def now(cls, what: str) -> Holder:
        """This process, doing ``what``."""
        command = " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else "python"
        return cls(os.getpid(), socket.gethostname(), command[:300], what,
                   time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                   _process_start(os.getpid()))

    @classmethod
    def parse(cls, text: str) -> Holder | None:
        """A holder from a lock file's text (None: empty or unreadable)."""
        try:
            data = json.loads(text)
            return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})
        except (ValueError, TypeError, KeyError):
            return None

    def running(self) -> bool | None:
        """Whether the holder still runs (None: on another host, cannot tell)."""
        if self.host != socket.gethostname():
            return None
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass  # another user's live process
        if self.started:  # a recycled pid has another start time
            return _process_start(self.pid) in ("", self.started)
        return _runs_command(self.pid, self.command) is not False


def _runs_command(pid: int, command: str) -> bool | None:
    """Whether process ``pid`` may run the program of ``command`` (None: cannot tell).

    A lock without a start time (older, or hand-made) whose pid now belongs to an unrelated
    process is stale: a process that is no Python interpreter and whose first arguments do
    not name the program the lock names (``unitrack``) cannot be a run of ours.
    """
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[:2]
    except OSError:
        return None
    names = {Path(a.decode("utf-8", "replace")).name for a in argv if a}
    return command.split(" ", 1)[0] in names or any(
        n.startswith(("python", "pypy")) for n in names)


def _process_start(pid: int) -> str:
    """The start time of process ``pid`` in clock ticks since boot (Linux), else ""."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    except OSError:
        return ""
    return fields[19] if len(fields) > 19 else ""


class FolderLock:
    """The lock of one output folder (see the module docstring); use :func:`hold_folder`."""

    def __init__(self, folder: Path, what: str) -> None:
        self.folder, self.path = Path(folder), Path(folder) / LOCK
        self.what = what
        self.fd: int | None = None

    def acquire(self) -> Holder | None:
        """Take the lock; return the dead holder it took over, if any (else None)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        for _ in range(5):
            try:  # never through a link: the lock's JSON would land in the linked file
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0),
                             0o644)
            except OSError as exc:
                if self.path.is_symlink():
                    raise LinkRefused(self.path) from exc
                raise
            try:
                if os.fstat(fd).st_nlink > 1:  # the lock's JSON would land in another name's file
                    raise LinkRefused(self.path, "a hard link (the file has other names)")
                if not self._flock(fd):
                    raise OutputInUse(self.folder, Holder.parse(_read_fd(fd)))
                if not _same_file(fd, self.path):
                    os.close(fd)  # the holder removed the file between our open and lock
                    continue
                previous = Holder.parse(_read_fd(fd))
                if previous is not None and previous.pid != os.getpid() and previous.running():
                    raise OutputInUse(self.folder, previous)  # a lock flock did not see
            except BaseException:
                with contextlib.suppress(OSError):
                    os.close(fd)
                raise
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(asdict(Holder.now(self.what))).encode(), 0)
            self.fd = fd
            return previous
        raise OutputInUse(self.folder, None)

    @staticmethod
    def _flock(fd: int) -> bool:
        if fcntl is None:
            return True
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        except OSError:  # no flock on this file system: the recorded pid decides
            return True
        return True

    def release(self) -> None:
        """Remove the lock file and drop the lock."""
        if self.fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        with contextlib.suppress(OSError):
            os.close(self.fd)
        self.fd = None


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.fstat(fd).st_ino == os.stat(path).st_ino
    except FileNotFoundError:
        return False


def _read_fd(fd: int) -> str:
    try:
        return os.pread(fd, 65536, 0).decode("utf-8", "replace")
    except OSError:
        return ""


@contextlib.contextmanager
def hold_folder(folder: str | os.PathLike, what: str) -> Iterator[FolderLock]:
    """Hold ``folder``'s lock for the block; stale temporaries are removed first.

    Raises:
        OutputInUse: another live process holds it.
    """
    lock = FolderLock(Path(folder), what)
    try:
        previous = lock.acquire()
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write to {folder}: {exc.strerror or exc}") from exc
    try:
        if previous is not None:
            warnings.warn(f"{folder}: took over the lock of a run that is no longer running "
                          f"({previous.describe()}); its finished sequences are kept",
                          UserWarning, stacklevel=3)
        remove_temporaries(Path(folder))
        yield lock
    finally:
        lock.release()


def remove_temporaries(folder: Path, below: Iterable[str] = ("data", "sequences")) -> list[Path]:
    """Remove atomic-write temporaries in ``folder`` and anywhere below its ``below`` folders.

    Other subfolders are left alone (a scorecard's cells have locks of their own).
    """
    found = [p for p in _files(folder, recursive=False) if TEMPORARY.match(p.name)]
    for sub in (s for s in below if not (folder / s).is_symlink()):  # never through a link
        found += [p for p in _files(folder / sub) if TEMPORARY.match(p.name)]
    for path in found:
        with contextlib.suppress(OSError):
            path.unlink()
    return found


def _files(folder: Path, recursive: bool = True) -> list[Path]:
    if not folder.is_dir():
        return []
    if not recursive:
        return [p for p in folder.iterdir() if p.is_file() or p.is_symlink()]
    return [Path(root) / name for root, _, names in os.walk(folder) for name in names]


@dataclass
class Manifest:
    """What runs of ours wrote in ``folder`` (relative paths) and the sequences in play."""

    folder: Path
    files: set[str] = field(default_factory=set)
    playing: set[str] = field(default_factory=set)
    found: bool = False  # read from disk (False: a folder no run of ours has written yet)

    @classmethod
    def load(cls, folder: Path) -> Manifest:
        """The folder's manifest (empty if none); ValueError if ``manifest.json`` is not ours."""
        path = Path(folder) / MANIFEST
        if not path.exists():
            return cls(Path(folder))
        try:
            data = json.loads(path.read_text())
            ours = data.get("written_by") == "unitrack-env"
            files, playing = list(data["files"]), list(data["playing"])
        except (OSError, ValueError, TypeError, AttributeError, KeyError):
            ours = False
        if ours:  # its entries are data: each must name a file inside the folder
            for key, entries, inside in (("files", files, folder),
                                         ("playing", playing, Path(folder) / "sequences")):
                for k, entry in enumerate(entries):
                    path_inside(inside, entry, path, field=f"{key}[{k}]")
            return cls(Path(folder), set(files), set(playing), True)
        raise ValueError(f"{path} is not a manifest of unitrack-env (another tool's file, or "
                         "damaged), so it cannot say which files runs of ours wrote; move it "
                         "away or choose another --out")

    def save(self) -> None:
        """Write the manifest (atomically)."""
        payload = {"format": 1, "written_by": "unitrack-env", "files": sorted(self.files),
                   "playing": sorted(self.playing)}
        atomic_write_text(self.folder / MANIFEST, json.dumps(payload, indent=1))

    def relative(self, path: Path) -> str:
        """``path`` relative to the folder, as the manifest stores it."""
        return Path(os.path.relpath(path, self.folder)).as_posix()

    def add(self, *paths: Path) -> None:
        """Record files as ours (and save), before or after they are written."""
        new = {self.relative(p) for p in paths} - self.files
        if new:
            self.files |= new
            self.save()

    def claim(self, sequences: Iterable[str]) -> None:
        """Mark ``sequences`` as in play (before any of their files is written)."""
        self.playing |= set(sequences)
        self.save()


# ------------------------------------------------------------------ a run's sequences
def sequence_outputs(out: Path, sequence: str, names: Iterable[str]) -> list[Path]:
    """The files a run writes for ``sequence``: its result files and its record."""
    data, record = out / "data", out / "sequences" / f"{sequence}.json"
    files = sequence_files(data, sequence, names, shared=False) if data.is_dir() else []
    return files + ([record] if record.is_file() else [])


def owned_files(manifest: Manifest, names: Iterable[str]) -> set[Path]:
    """Every file the manifest says is ours, with the files of the sequences in play."""
    names = list(names)
    owned = {manifest.folder / rel for rel in manifest.files}
    for sequence in manifest.playing:
        owned |= set(sequence_outputs(manifest.folder, sequence, names))
    return owned


def adopt(manifest: Manifest, names: Iterable[str], verified: Iterable[str]) -> None:
    """Record as ours what a run of ours provably wrote without listing it (verified records)."""
    out, names = manifest.folder, list(names)
    found = [p for n in verified for p in sequence_outputs(out, n, names)]
    if not manifest.found:
        try:
            run = json.loads((out / "run.json").read_text())
        except (OSError, ValueError):
            run = None
        if isinstance(run, dict) and {"env_id", "agent"} <= run.keys():
            found += [p for p in (out / "run.json", out / "metrics.json") if p.is_file()]
    if found:
        manifest.add(*found)


def in_the_way(manifest: Manifest, todo: Iterable[str], names: Iterable[str]) -> list[Path]:
    """Files that playing ``todo`` would overwrite but no run of ours wrote."""
    names, out = list(names), manifest.folder
    owned = owned_files(manifest, names)
    candidates = [out / "run.json", out / "metrics.json"]
    candidates += [p for n in todo for p in sequence_outputs(out, n, names)]
    return [p for p in candidates if p.is_file() and p not in owned]


def settle(manifest: Manifest, sequence: str, names: Iterable[str]) -> None:
    """A sequence finished (or failed): list the files it wrote, end its claim."""
    manifest.files |= {manifest.relative(p)
                       for p in sequence_outputs(manifest.folder, sequence, names)}
    manifest.playing.discard(sequence)
    manifest.save()


#: The files a run writes, by sub-folder ("": the folder itself): all ``--overwrite`` deletes.
WRITTEN = {"": ("run.json", "metrics.json"), "data": (".txt", ".json", ".png", ".mat"),
           "sequences": (".json",), "events": (".csv.gz",)}


def written_by_runs(out: Path, path: Path) -> bool:
    """Whether ``path`` is of a kind a run writes, where it writes it, in the real ``out``."""
    parts = Path(os.path.relpath(path, out)).parts
    kinds = WRITTEN.get(parts[0] if len(parts) > 1 else "", ())
    real = os.path.realpath(out)
    return (".." not in parts and parts[-1].endswith(kinds)
            and os.path.realpath(path.parent).startswith(real.rstrip(os.sep) + os.sep)
            if len(parts) > 1 else parts[0] in kinds)


def clear_ours(manifest: Manifest, names: Iterable[str]) -> list[str]:
    """Delete the listed files that :func:`written_by_runs` (``--overwrite``); return the rest."""
    out = manifest.folder
    for path in owned_files(manifest, names):
        if written_by_runs(out, path):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
    for sub in ("data", "sequences", "events"):
        for root, _, _ in sorted(os.walk(out / sub), key=lambda item: -len(item[0])):
            with contextlib.suppress(OSError):
                Path(root).rmdir()  # only empty folders go
    manifest.files, manifest.playing = set(), set()
    manifest.save()
    return sorted(manifest.relative(p) for p in _files(out)[:100_000]
                  if p.name not in (LOCK, MANIFEST))


def kept_message(out: Path, kept: list[str]) -> str:
    """The line ``--overwrite`` prints about the files it kept."""
    shown = ", ".join(kept[:5]) + (f" and {len(kept) - 5} more" if len(kept) > 5 else "")
    return (f"--overwrite kept {len(kept)} file(s) in {out} that no run of ours wrote: "
            f"{shown}")


def in_the_way_message(out: Path, files: list[Path]) -> str:
    """The refusal of a run that would overwrite files that are not ours."""
    shown = ", ".join(os.path.relpath(p, out) for p in files[:5])
    more = f" and {len(files) - 5} more" if len(files) > 5 else ""
    return (f"{out} holds files that no run of ours wrote and that this run would overwrite: "
            f"{shown}{more}; move them away or choose another --out")


def _record(out: Path, name: str) -> Path:
    return out / "sequences" / f"{name}.json"


def results_match(out: Path, names: list[str], name: str) -> bool:
    """Whether sequence ``name`` has a record whose digest matches its result files."""
    try:
        record = SequenceRecord.from_json(json.loads(_record(out, name).read_text()))
    except (OSError, ValueError, TypeError):
        return False
    return record.results == result_digest(out / "data", name, names)


def own_folder(out: Path, every: Iterable[str], names: list[str], overwrite: bool) -> Manifest:
    """The folder's manifest, after ``overwrite`` deleted our files; refuse foreign files.

    Unlisted runs of ours are adopted when their records verify. Files no run of ours wrote
    are never deleted (a warning names them) nor overwritten (OutputError).
    """
    every = list(every)
    try:
        for name in (MANIFEST, "run.json", "metrics.json", "data", "sequences", "events"):
            refuse_link(out / name)  # a link where a run writes (a folder, too) is refused
        manifest = Manifest.load(out)  # a foreign manifest.json: ValueError, a clear refusal
        listed = {manifest.folder / rel for rel in manifest.files}
        unlisted = [n for n in every if _record(out, n).is_file() and _record(out, n) not in listed]
        adopt(manifest, every, [n for n in unlisted if results_match(out, every, n)])
        if overwrite and (kept := clear_ours(manifest, every)):
            warnings.warn(kept_message(out, kept), UserWarning, stacklevel=3)
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write to {exc.filename or out}: "
                                     f"{exc.strerror or exc}") from exc
    blocked = in_the_way(manifest, names, every)
    if blocked:
        raise OutputError(in_the_way_message(out, blocked))
    return manifest


def outside(paths: list[Path], out: Path) -> list[Path]:
    """``paths`` without those inside ``out``: a run's own files are never its inputs.

    Else every file a run writes inside ``--root`` would change the fingerprints of the
    sequences it resumes.
    """
    prefixes = tuple({p.rstrip(os.sep) + os.sep
                      for p in (os.path.abspath(out), str(Path(out).resolve()))})
    return [p for p in paths if not (os.path.abspath(p) + os.sep).startswith(prefixes)]

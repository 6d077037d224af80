"""Fingerprints of a sequence's input files, so that a resumed run can tell stale results.

Text files are hashed by content; frames by name and size only (hashing every image costs
more than it is worth); the file list is covered too, so an added or removed frame counts.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

#: Suffixes hashed by name and size instead of content.
FRAME_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".webp"})
#: Suffixes of files that may hold annotations of every sequence (hashed for each sequence).
SHARED_SUFFIXES = frozenset({".json", ".txt", ".ini", ".mat", ".csv"})


def _hash_file(digest: hashlib.blake2b, path: Path) -> None:
    with path.open("rb") as handle:
        while chunk := handle.read(1 << 20):
            digest.update(chunk)


def files_fingerprint(paths: Iterable[Path], root: Path | None = None, *,
                      content: bool = False) -> str:
    """A hex digest of the files ``paths`` (names relative to ``root`` when given).

    Frames are hashed by name and size unless ``content`` is set (every byte of every file).
    """
    digest = hashlib.blake2b(digest_size=16)
    for path in sorted({Path(p) for p in paths}):
        name = str(path.relative_to(root)) if root is not None and path.is_relative_to(root) \
            else str(path)
        try:
            size = path.stat().st_size
        except OSError:
            digest.update(f"{name}\0missing\n".encode())
            continue
        digest.update(f"{name}\0{size}\n".encode())
        if content or path.suffix.lower() not in FRAME_SUFFIXES:
            _hash_file(digest, path)
    return digest.hexdigest()


def _contains(parts: tuple[str, ...], run: tuple[str, ...]) -> bool:
    """Whether ``run`` occurs as consecutive items of ``parts``."""
    n = len(run)
    return any(parts[i:i + n] == run for i in range(len(parts) - n + 1))


def sequence_files(root: Path, sequence: str, all_sequences: Iterable[str], *,
                   shared: bool = True) -> list[Path]:
    """The files under ``root`` that belong to ``sequence``, plus shared annotation files.

    A file belongs when its path names the sequence as folders (``train/MOT17-02/...``) or as
    a stem (``instances_txt/0002.txt``); annotation-like files of no sequence (a YouTube-VIS
    JSON, DAVIS's ImageSets) are shared by all, unless ``shared`` is False.
    """
    own = tuple(sequence.split("/"))
    others = [tuple(name.split("/")) for name in set(all_sequences) if name != sequence]
    out: list[Path] = []
    for folder, dirs, files in os.walk(root):
        rel = Path(folder).relative_to(root).parts
        inside = _contains(rel, own)
        if not inside and any(_contains(rel, other) for other in others):
            dirs.clear()
            continue
        for file in files:
            path = Path(folder) / file
            named = rel + (path.stem,)
            if inside or _contains(named, own):
                out.append(path)
            elif shared and path.suffix.lower() in SHARED_SUFFIXES and not any(
                    _contains(named, other) for other in others):
                out.append(path)
    return out

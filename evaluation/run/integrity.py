"""Whether a run's stored metrics still describe its files, and two runs the same data.

A sequence's record (``sequences/<name>.json``) keeps the digest of its result files
(``results``) and the fingerprint of its data files when it was played (``data``: ground
truth and annotation files by content, frames by name and size; :func:`data_fingerprint`).
``compare`` and ``report`` recompute metrics and events from those files, so they first
check them: a result file edited after scoring, or data changed since, would show numbers
that are not the run's metrics; two runs scored against different ground truth cannot be
paired. Each is refused naming the run, the sequences and what to do.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from unitrack_env.fingerprint import files_fingerprint, sequence_files

from .episode import SequenceRecord
from .identity import result_digest
from .ownership import outside

#: Sequences named in a message before abbreviating.
SHOWN: int = 5


class StaleRun(ValueError):
    """A run's result or data files no longer match what its records say was scored."""


class DifferentData(ValueError):
    """Two runs were scored against different data (ground truth) for the same sequences."""


def _names(items: list[str]) -> str:
    more = len(items) - SHOWN
    return ", ".join(items[:SHOWN]) + (f" and {more} more" if more > 0 else "")


def data_root(dataset: Any) -> Path | None:
    """The folder a data set is read from (None without one)."""
    root = getattr(dataset, "root", None) or getattr(dataset, "data_dir", None)
    return None if root is None else Path(root)


def data_fingerprint(dataset: Any, sequence: str, run: str | os.PathLike) -> str:
    """Fingerprint of ``sequence``'s data files (the run's own files inside them left out).

    "" when the data set has no folder on this machine (nothing to check).
    """
    root = data_root(dataset)
    if root is None or not root.is_dir():
        return ""
    names = getattr(dataset, "sequence_names", None) or [sequence]
    files = outside(sequence_files(root, sequence, names), Path(run))
    runs: dict[Path, bool] = {}
    return files_fingerprint([f for f in files if not _in_a_run(f, root, runs)], root)


def _in_a_run(path: Path, root: Path, runs: dict[Path, bool]) -> bool:
    """Whether ``path`` lies in a run folder (one with a ``run.json``) inside ``root``.

    Runs written inside the data folder (``--out`` inside ``--root``) are not data.
    """
    for parent in path.parents:
        if parent == root or len(parent.parts) <= len(root.parts):
            return False
        if parent not in runs:
            runs[parent] = (parent / "run.json").is_file()
        if runs[parent]:
            return True
    return False


def _record(run: Path, sequence: str) -> SequenceRecord | None:
    try:
        data = json.loads((run / "sequences" / f"{sequence}.json").read_text(encoding="utf-8"))
        return SequenceRecord.from_json(data)
    except (OSError, ValueError, TypeError):
        return None


def check_current(run: str | os.PathLike, bench: Any, sequences: Iterable[str]) -> dict[str, str]:
    """Refuse a run whose result or data files changed after scoring; return data fingerprints.

    Returns ``{sequence: data fingerprint now}`` (for :func:`check_pair`). Records without a
    digest (older runs) are not checked. Raises :class:`StaleRun`.
    """
    run = Path(run)
    edited, moved, now = [], [], {}
    for name in sequences:
        now[name] = data_fingerprint(bench.dataset, name, run)
        record = _record(run, name)
        if record is None:
            continue
        if record.results and record.results != result_digest(run / "data", name,
                                                                 bench.sequence_names):
            edited.append(name)
        if getattr(record, "data", "") and now[name] and record.data != now[name]:
            moved.append(name)
    redo = "; rerun the `unitrack evaluate` command that made it (same --out) to replay them"
    if edited:
        raise StaleRun(f"{run}: the result files of {_names(edited)} were changed after they "
                       "were scored (they no longer match the digests in sequences/*.json), "
                       f"so metrics.json does not describe them{redo}")
    if moved:
        raise StaleRun(f"{run}: the data files (ground truth, annotations) of {_names(moved)} "
                       f"under {data_root(bench.dataset)} changed after the run was scored "
                       f"(their fingerprints in sequences/*.json differ){redo}")
    return now


def check_pair(run_a: str | os.PathLike, bench_a: Any, run_b: str | os.PathLike, bench_b: Any,
               sequences: list[str]) -> None:
    """Refuse to pair two runs unless both are current and share each sequence's data.

    Raises :class:`StaleRun` or :class:`DifferentData` (naming the sequences and folders).
    """
    now_a = check_current(run_a, bench_a, sequences)
    now_b = check_current(run_b, bench_b, sequences)
    differ = [s for s in sequences if now_a[s] and now_b[s] and now_a[s] != now_b[s]]
    if differ:
        raise DifferentData(
            f"{run_a} and {run_b} were scored against different data for {_names(differ)} "
            f"(their ground-truth or annotation files differ: {data_root(bench_a.dataset)} vs "
            f"{data_root(bench_b.dataset)}); a paired comparison needs the same ground truth: "
            "score both runs on the same data")


__all__ = ["DifferentData", "StaleRun", "check_current", "check_pair", "data_fingerprint"]

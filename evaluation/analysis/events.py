"""Error events of a run, per frame: computed from its result files, stored beside them.

``<run>/events/<sequence>.csv.gz`` holds one table per scored sequence (the rows of each task:
docs/report.md). The run's benchmark computes them (``Benchmark.sequence_events``), so this
module names no task. The runner writes them while scoring and only warns when it cannot (the
scores stand); :func:`load_events` computes missing ones, replaying no agent.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import warnings
import zlib
from pathlib import Path

import pandas as pd

import unitrack_env
from unitrack_env.benchmarks import benchmark_for
from unitrack_env.benchmarks.base import Benchmark
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_bytes, path_inside
from unitrack_env.metrics.events_mot import (
    EVENT_COLUMNS,
    ID_COLUMNS,
    OPTIONAL_COLUMNS,
    EventRows,
)

#: Sub-folder of a run folder holding the event tables.
EVENTS_DIR: str = "events"


def events_path(run: str | os.PathLike, sequence: str) -> Path:
    """``<run>/events/<sequence>.csv.gz``."""
    return Path(run) / EVENTS_DIR / f"{sequence}.csv.gz"


def run_benchmark(run: str | os.PathLike) -> Benchmark:
    """The benchmark a run folder was scored with (from its ``run.json``)."""
    path = Path(run) / "run.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not a run folder of `unitrack evaluate` (no run.json)")
    spec = json.loads(path.read_text(encoding="utf-8"))
    unitrack_env.register_all()
    return benchmark_for(spec["env_id"], **spec.get("env_kwargs", {}))


def run_sequences(run: str | os.PathLike) -> list[str]:
    """The scored sequences of a run (``metrics.json``'s per-sequence rows).

    Each name becomes a file name (``events/<name>.csv.gz``) and a data set's folder: one
    that is absolute or climbs out with ``..`` is refused (DataFormatError naming it).
    """
    path = Path(run) / "metrics.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the run has no metrics (not finished or not scored)")
    names = list(json.loads(path.read_text(encoding="utf-8")).get("per_sequence", {}))
    for name in names:
        path_inside(Path(run) / EVENTS_DIR, name, path, field="per_sequence")
    return names


def sequence_events(bench: Benchmark, folder: str | os.PathLike, sequence: str) -> EventRows:
    """Events of one sequence's result files in ``folder`` (the run's ``data/``).

    The benchmark computes them (:meth:`~unitrack_env.benchmarks.base.Benchmark.sequence_events`);
    a ValueError when its task has none.
    """
    rows = bench.sequence_events(folder, sequence)
    if rows is None:
        raise ValueError(f"no per-frame events for task '{bench.task}' ({type(bench).__name__} "
                         "defines no sequence_events)")
    return rows


def to_frame(rows: EventRows) -> pd.DataFrame:
    """An event table as a DataFrame with :data:`EVENT_COLUMNS`."""
    extra = [name for name in OPTIONAL_COLUMNS if name in rows.columns]
    df = pd.DataFrame(rows.columns, columns=[*EVENT_COLUMNS, *extra])
    for col in ID_COLUMNS:
        df[col] = df[col].astype("Int64")
    return df


def write_sequence_events(run: str | os.PathLike, bench: Benchmark, sequence: str,
                          rows: EventRows | None = None) -> Path:
    """Write ``<run>/events/<sequence>.csv.gz`` atomically (``rows``, else computed).

    Returns its path.
    """
    df = to_frame(rows if rows is not None else
                  sequence_events(bench, Path(run) / "data", sequence))
    path = events_path(run, sequence)
    buffer = io.BytesIO()
    # mtime 0: the same events give the same bytes, so scoring a stored run again (a
    # committed scorecard) leaves its files untouched
    df.to_csv(buffer, index=False, compression={"method": "gzip", "mtime": 0},
              float_format="%.4f")
    atomic_write_bytes(path, buffer.getvalue())  # a new temporary file, never via a link
    return path


def write_run_events(out: str | os.PathLike, bench: Benchmark, sequences: list[str]) -> None:
    """The runner's hook: write the events of every scored sequence of a finished run.

    Never fails the run: a sequence whose events cannot be computed gets a warning (the
    results and metrics are already written). A task without events writes nothing.
    """
    for name in sequences:
        try:
            rows = bench.sequence_events(Path(out) / "data", name)
            if rows is None:
                return
            write_sequence_events(out, bench, name, rows)
        except Exception as exc:  # noqa: BLE001 - events are extra; the scores stand
            warnings.warn(f"events of {name} were not written: {exc}", stacklevel=2)


def load_events(run: str | os.PathLike, sequence: str | None = None,
                type: str | None = None) -> pd.DataFrame:  # noqa: A002 - the CLI's name
    """The error events of a run folder as a DataFrame, optionally one sequence or ``type``.

    Events missing from the folder (not written when the run was scored: the runner warned)
    are computed from the result files and the ground truth, and written for next time.
    """
    names = run_sequences(run)
    if sequence is not None:
        if sequence not in names:
            raise ValueError(f"sequence '{sequence}' is not scored in {run} "
                             f"(scored: {', '.join(names) or 'none'})")
        names = [sequence]
    bench: Benchmark | None = None
    parts = []
    for name in names:
        path = events_path(run, name)
        if not path.is_file():
            bench = bench or run_benchmark(run)
            write_sequence_events(run, bench, name)
        parts.append(read_events_file(run, path))
    df = (pd.concat(parts, ignore_index=True) if parts
          else pd.DataFrame(columns=list(EVENT_COLUMNS)))
    for col in ID_COLUMNS:
        df[col] = df[col].astype("Int64")
    if type is not None:
        df = df[df["type"] == type].reset_index(drop=True)
    return df


def read_events_file(run: str | os.PathLike, path: Path) -> pd.DataFrame:
    """One stored event table; a damaged file is a DataFormatError naming it and the cure."""
    try:
        df = pd.read_csv(path, dtype={"sequence": str, "type": str, "class": str},
                         keep_default_na=True)
        for col in ID_COLUMNS:
            if col in df:
                df[col].astype("Int64")
    except (EOFError, OSError, ValueError, TypeError, zlib.error) as exc:
        what = ("truncated gzip data" if isinstance(exc, EOFError) else
                "not gzip data" if isinstance(exc, gzip.BadGzipFile) else
                "empty" if isinstance(exc, pd.errors.EmptyDataError) else
                f"not an event table: {type(exc).__name__}")
        raise DataFormatError(path, f"damaged events file ({what}); delete it and run "
                                    f"`unitrack events {run}` to rebuild it from the run's "
                                    "result files") from exc
    return df


def event_counts(df: pd.DataFrame) -> dict[str, dict[str, int]]:
    """``{sequence: {type: count}}`` of an event table."""
    table = df.groupby(["sequence", "type"]).size()
    out: dict[str, dict[str, int]] = {}
    for (seq, kind), count in table.items():
        out.setdefault(str(seq), {})[str(kind)] = int(count)
    return out


__all__ = ["EVENTS_DIR", "event_counts", "events_path", "load_events", "run_benchmark",
           "sequence_events", "write_run_events"]

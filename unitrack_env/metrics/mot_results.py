"""MOTChallenge result rows: reading result files, checking rows, writing them for TrackEval.

A result row is ``frame, id, bb_left, bb_top, bb_width, bb_height[, conf, x, y, z]`` with
1-based frames. :func:`read_result_file` names the file, line and field of the first
malformed value; :func:`validate_tracker_rows` refuses what TrackEval would refuse or
mis-handle; :func:`write_for_trackeval` writes rows TrackEval reads back to the same doubles.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from unitrack_env.errors import DataFormatError

#: Column names of a MOTChallenge result file, used in error messages.
RESULT_FIELDS: tuple[str, ...] = (
    "frame",
    "id",
    "bb_left",
    "bb_top",
    "bb_width",
    "bb_height",
    "conf",
    "x",
    "y",
    "z",
)

#: A result row needs at least frame, id and the box.
MIN_RESULT_COLUMNS: int = 6

#: Confidence written for rows given without one (TrackEval needs the column, never uses it).
DEFAULT_CONFIDENCE: float = 1.0

#: TrackEval reads result column 8 as a class id and rejects values above this (pedestrian).
MAX_TRACKER_CLASS: int = 1


def _split_fields(line: str) -> list[str]:
    parts = line.split(",") if "," in line else line.split()
    parts = [p.strip() for p in parts]
    if len(parts) > 1 and parts[-1] == "":  # a trailing comma, which TrackEval tolerates
        parts = parts[:-1]
    return parts


def _field_name(col: int) -> str:
    return RESULT_FIELDS[col] if col < len(RESULT_FIELDS) else f"column {col + 1}"


def parse_result_file(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse a result file into ``(rows, line_numbers)``; blank lines are skipped."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataFormatError(path, "result file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, f"cannot read result file ({exc})") from None
    rows: list[list[float]] = []
    lines: list[int] = []
    width: int | None = None
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        parts = _split_fields(line)
        if len(parts) < MIN_RESULT_COLUMNS:
            raise DataFormatError(
                path,
                f"expected at least {MIN_RESULT_COLUMNS} comma-separated fields "
                f"(frame, id, bb_left, bb_top, bb_width, bb_height), got {len(parts)}",
                line=lineno,
            )
        if width is None:
            width = len(parts)
        elif len(parts) != width:
            raise DataFormatError(
                path, f"has {len(parts)} fields but earlier lines have {width}", line=lineno
            )
        values = []
        for col, part in enumerate(parts):
            try:
                value = float(part)
            except ValueError:
                raise DataFormatError(
                    path, f"{part!r} is not a number", line=lineno, field=_field_name(col)
                ) from None
            if not math.isfinite(value):
                raise DataFormatError(
                    path, f"{part!r} is not a finite number", line=lineno, field=_field_name(col)
                )
            values.append(value)
        for col, what in ((0, "frame"), (1, "id")):
            if values[col] != int(values[col]):
                raise DataFormatError(
                    path,
                    f"{what} must be an integer, got {parts[col]!r}",
                    line=lineno,
                    field=what,
                )
        if values[0] < 1:
            raise DataFormatError(
                path, f"frames are 1-based, got {parts[0]!r}", line=lineno, field="frame"
            )
        rows.append(values)
        lines.append(lineno)
    arr = np.array(rows, dtype=np.float64).reshape(len(rows), width or MIN_RESULT_COLUMNS)
    return arr, np.array(lines, dtype=np.int64)


def read_result_file(path: str | Path) -> np.ndarray:
    """Read a MOTChallenge result file into a ``(k, c)`` float64 array (``c >= 6``).

    DataFormatError names the file, line and field of the first malformed value.
    """
    return parse_result_file(Path(path))[0]


def _fail(source: Path | None, message: str, line: int | None, fld: str | None) -> Exception:
    if source is None:
        row = "" if line is None else f"row {line}: "
        col = "" if fld is None else f"column '{fld}': "
        return ValueError(f"tracker rows: {row}{col}{message}")
    return DataFormatError(source, message, line=line, field=fld)


def validate_tracker_rows(
    rows: np.ndarray, seq_length: int, source: Path | None, line_numbers: np.ndarray | None
) -> None:
    """Reject what TrackEval would reject (or mis-handle), with a precise location."""

    def where(i: int) -> int:
        return int(line_numbers[i]) if line_numbers is not None else i

    if rows.ndim != 2 or (rows.size and rows.shape[1] < MIN_RESULT_COLUMNS):
        raise _fail(source, f"expected a (k, >=6) array, got shape {rows.shape}", None, None)
    if not len(rows):
        return
    bad = np.flatnonzero(~np.isfinite(rows).all(axis=1))
    if bad.size:
        raise _fail(source, "contains NaN or infinity", where(bad[0]), None)
    for col, what in ((0, "frame"), (1, "id")):
        bad = np.flatnonzero(rows[:, col] != np.floor(rows[:, col]))
        if bad.size:
            raise _fail(source, f"{what} must be an integer", where(bad[0]), what)
    bad = np.flatnonzero(np.abs(rows[:, 1]) > 2**53)
    if bad.size:  # ids are relabelled for TrackEval, but a double holds them only to 2**53
        raise _fail(source, f"id {rows[bad[0], 1]:.0f} is out of range: result rows are read "
                            "as doubles, which hold integers exactly only up to 2**53 "
                            "(nearby ids would merge)", where(bad[0]), "id")
    bad = np.flatnonzero((rows[:, 0] < 1) | (rows[:, 0] > seq_length))
    if bad.size:
        raise _fail(
            source,
            f"frame {int(rows[bad[0], 0])} is outside the sequence (1..{seq_length})",
            where(bad[0]),
            "frame",
        )
    if rows.shape[1] > 7:
        bad = np.flatnonzero(rows[:, 7].astype(np.int64) > MAX_TRACKER_CLASS)
        if bad.size:
            raise _fail(
                source,
                f"TrackEval reads this column as a class id and accepts only <= "
                f"{MAX_TRACKER_CLASS} (pedestrian); write -1 in the x, y, z columns of 2D "
                "results, or, for results of several classes, give the data's class map "
                "(classes=, docs/evaluation.md)",
                where(bad[0]),
                "x",
            )
    keys = rows[:, 0].astype(np.int64) * (1 << 32) + np.unique(rows[:, 1], return_inverse=True)[
        1
    ].astype(np.int64)
    order = np.argsort(keys, kind="stable")
    dup = np.flatnonzero(keys[order][1:] == keys[order][:-1])
    if dup.size:
        i = int(order[dup[0] + 1])
        raise _fail(
            source,
            f"id {int(rows[i, 1])} appears more than once in frame {int(rows[i, 0])}",
            where(i),
            "id",
        )


def write_for_trackeval(rows: np.ndarray, path: Path) -> None:
    """Write rows as a result file TrackEval reads back to the same doubles."""
    out = rows.copy()
    if len(out):
        out[:, 1] = np.unique(out[:, 1], return_inverse=True)[1] + 1
    if out.shape[1] < MIN_RESULT_COLUMNS + 1:
        out = np.column_stack([out, np.full(len(out), DEFAULT_CONFIDENCE)])
    fmt = ["%d", "%d"] + ["%.17g"] * (out.shape[1] - 2)
    with path.open("w", encoding="ascii") as fh:
        if len(out):
            np.savetxt(fh, out, fmt=fmt, delimiter=",")


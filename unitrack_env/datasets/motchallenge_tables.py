"""The numeric tables of the MOTChallenge layout (``det.txt``, ``gt.txt``): parsing, checks.

:func:`parse_table` reads a comma-separated table and, on any problem, names the exact line
and field; :func:`check_rows` refuses rows that the episode or TrackEval (the official
scorer) cannot use. Both raise :class:`~unitrack_env.errors.DataFormatError`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from unitrack_env.datasets.limits import (
    MAX_FRAMES,
    MAX_TEXT_BYTES,
    MAX_TRACKS,
    check_track_count,
    check_track_total,
    read_limited,
)
from unitrack_env.errors import DataFormatError
from unitrack_env.spaces.limits import COORD_MAX, FLOAT_MAX

#: Columns of a detection row, for messages.
DET_FIELDS = ("frame", "id", "x", "y", "w", "h", "score")
#: Columns of a ground-truth row (MOT16/17/20), for messages.
GT_FIELDS = ("frame", "id", "x", "y", "w", "h", "flag", "class", "visibility")
#: Largest ground-truth id accepted: TrackEval allocates an array indexed by the largest id
#: (8 bytes per id up to it), so larger ids exhaust memory at scoring.
MAX_GT_ID = 2**24
#: TrackEval's MOTChallenge class ids (MOT16/17/20 ``gt.txt`` column 8), 1..13.
VALID_GT_CLASSES = frozenset(range(1, 14))


def parse_table(
    path: Path, min_columns: int, field_names: tuple[str, ...], *, official: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Parse a comma-separated numeric table; on any problem find the exact line and field.

    ``official`` files (``gt.txt``) are also read by TrackEval, so a byte-order mark or blank
    lines are refused at open rather than at scoring; otherwise they are skipped. Returns the
    table and each row's 1-based file line.
    """
    lines = _data_lines(path, _read_text(path, official), official)
    if official:  # ground truth: refuse 10 million ids before parsing 10 million rows
        _count_ids_early(path, lines)
    if not lines:
        return np.zeros((0, min_columns)), np.zeros(0, dtype=np.int64)
    rows = [_cells(line) for _, line in lines]
    try:
        table = np.array(rows, dtype=np.float64)
    except ValueError:
        table = None  # ragged rows or a bad value: locate it below
    if table is not None and table.ndim == 2 and table.shape[1] >= min_columns:
        bad = ~np.isfinite(table[:, :min_columns])
        if not bad.any():
            return table, np.array([lineno for lineno, _ in lines])
        row, col = np.argwhere(bad)[0]
        raise DataFormatError(
            path, f"'{rows[row][col].strip()}' is not a finite number", line=lines[row][0],
            field=field_names[col],
        )
    _locate_problem(path, lines, rows, min_columns, field_names)
    raise DataFormatError(path, "could not be parsed as a numeric table")  # pragma: no cover


def _read_text(path: Path, official: bool) -> str:
    """The file's UTF-8 text; a BOM is skipped, or refused in an ``official`` file."""
    raw = read_limited(path, MAX_TEXT_BYTES, "MOTChallenge table")
    if raw.startswith(b"\xef\xbb\xbf"):
        if official:
            raise DataFormatError(
                path, "starts with a UTF-8 byte-order mark (BOM), which TrackEval, the official "
                      "scorer, reads as part of the first number; save the file without a BOM",
                line=1)
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise DataFormatError(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})",
                              line=line) from None


def _data_lines(path: Path, text: str, official: bool) -> list[tuple[int, str]]:
    """The non-blank lines with their 1-based numbers; an ``official`` file has no blanks."""
    numbered = list(enumerate(text.splitlines(), start=1))
    if official:
        blank = [i for i, line in numbered if not line.strip()]
        if blank:
            lines_text = ", ".join(str(i) for i in blank[:5]) + (" ..." if len(blank) > 5 else "")
            raise DataFormatError(
                path, f"blank line(s) at line {lines_text}: TrackEval, the official scorer, "
                      "cannot read a file with blank lines (it fails when scoring); delete them",
                line=blank[0])
    return [(i, line) for i, line in numbered if line.strip()]


def _count_ids_early(path: Path, lines: list[tuple[int, str]]) -> None:
    """Refuse a ground-truth file at its first id beyond ``MAX_TRACKS`` distinct ones.

    A streaming pass over the id column (the second), so that a file with millions of ids
    is refused at the line that crosses the limit instead of after parsing every row (10
    million rows take minutes and gigabytes). Unparsable ids are left to the full parse.
    """
    seen: set[float] = set()
    for lineno, line in lines:
        cells = line.split(",", 2)
        if len(cells) < 3:
            continue
        try:
            seen.add(float(cells[1]))
        except ValueError:
            continue
        if len(seen) > MAX_TRACKS:
            check_track_total(len(seen), path, what="ground-truth ids up to this line",
                              field="id", line=lineno)


def _cells(line: str) -> list[str]:
    cells = line.split(",")
    if len(cells) > 1 and not cells[-1].strip():
        cells = cells[:-1]  # a trailing comma, as TrackEval accepts
    return cells


def _locate_problem(
    path: Path, lines: list[tuple[int, str]], rows: list[list[str]], min_columns: int,
    field_names: tuple[str, ...],
) -> None:
    """Raise for the first short, ragged or non-numeric line of a table numpy refused."""
    width, first = None, 0
    for (lineno, _), cells in zip(lines, rows, strict=True):
        if len(cells) < min_columns:
            raise DataFormatError(
                path,
                f"has {len(cells)} columns, expected at least {min_columns} "
                f"({','.join(field_names[:min_columns])})",
                line=lineno,
            )
        if width is not None and len(cells) != width:
            where = f"line {first} has" if first == lineno - 1 else \
                f"lines {first}-{lineno - 1} have"
            raise DataFormatError(path, f"has {len(cells)} columns where {where} {width}; every "
                                        "line needs the same columns", line=lineno)
        width, first = len(cells), first or lineno
        for col, cell in enumerate(cells):
            try:
                float(cell)
            except ValueError:
                raise DataFormatError(
                    path,
                    f"'{cell.strip()}' is not a number",
                    line=lineno,
                    field=field_names[col] if col < len(field_names) else f"column {col + 1}",
                ) from None


def check_rows(
    path: Path, table: np.ndarray, lines: np.ndarray, length: int | None, kind: str,
    *, has_class: bool = False,
) -> None:
    """Refuse rows the episode or TrackEval cannot use (``kind``: ``"det"`` or ``"gt"``)."""
    _check_frames_and_sizes(path, table, lines, length)
    if kind == "det":
        _check_detection_values(path, table, lines)
    if kind == "gt":
        _check_gt_ids(path, table, lines)
        if has_class:
            classes = table[:, 7]
            bad_cls = ~np.isin(classes, list(VALID_GT_CLASSES))
            if bad_cls.any():
                i = int(np.argmax(bad_cls))
                # MOT16/17/20 ground truth has 9 columns, MOT15's 10 (world x, y, z last).
                hint = ("; its 10 columns are MOT15's layout (world x, y, z last): read it "
                        "with UniTrack/MOT15-v0") if table.shape[1] == 10 else ""
                raise DataFormatError(
                    path, f"class {classes[i]:g} is not a MOTChallenge class id (1..13, "
                          f"TrackEval refuses others when scoring){hint}",
                    line=int(lines[i]), field="class")


def _check_frames_and_sizes(
    path: Path, table: np.ndarray, lines: np.ndarray, length: int | None
) -> None:
    """Frames are whole numbers of the sequence; box sizes are not negative."""
    frames = table[:, 0]
    bad = (frames != np.round(frames)) | (frames < 1) | (frames > MAX_FRAMES)
    if length is not None:
        bad |= frames > length
    if bad.any():
        i = int(np.argmax(bad))
        limit = (f" (the sequence has {length} frames)" if length is not None else
                 f" (at most {MAX_FRAMES:,})")
        raise DataFormatError(
            path,
            f"frame {table[i, 0]:g} is not a frame of the sequence{limit}",
            line=int(lines[i]),
            field="frame",
        )
    neg = (table[:, 4] < 0) | (table[:, 5] < 0)
    if neg.any():
        i = int(np.argmax(neg))
        name = "w" if table[i, 4] < 0 else "h"
        raise DataFormatError(
            path, f"negative box size {table[i, 4 if name == 'w' else 5]:g}",
            line=int(lines[i]), field=name,
        )


def _check_detection_values(path: Path, table: np.ndarray, lines: np.ndarray) -> None:
    """Detection boxes and scores fit the observation space."""
    outside = np.abs(table[:, 2:6]) > COORD_MAX
    if outside.any():
        i, col = (int(v) for v in np.argwhere(outside)[0])
        raise DataFormatError(
            path, f"{table[i, 2 + col]:g} is outside the observation bounds: box values "
                  f"must lie in [-{COORD_MAX:g}, {COORD_MAX:g}] pixels",
            line=int(lines[i]), field=DET_FIELDS[2 + col])
    too_big = np.abs(table[:, 6]) > FLOAT_MAX
    if too_big.any():
        i = int(np.argmax(too_big))
        raise DataFormatError(path, f"score {table[i, 6]:g} does not fit a float32",
                              line=int(lines[i]), field="score")


def _check_gt_ids(path: Path, table: np.ndarray, lines: np.ndarray) -> None:
    """Ground-truth ids are whole, in ``0..MAX_GT_ID``, at most ``MAX_TRACKS``, once per frame."""
    frames, ids = table[:, 0], table[:, 1]
    bad_ids = ids != np.round(ids)
    if bad_ids.any():
        i = int(np.argmax(bad_ids))
        raise DataFormatError(
            path, f"id {ids[i]:g} is not an integer", line=int(lines[i]), field="id"
        )
    bad_ids = (ids < 0) | (ids > MAX_GT_ID)
    if bad_ids.any():
        i = int(np.argmax(bad_ids))
        raise DataFormatError(
            path, f"id {ids[i]:g} is outside 0..{MAX_GT_ID}: TrackEval indexes an array by "
                  "ground-truth id (a negative id is scored as another object, a huge one "
                  "exhausts memory); renumber the ids",
            line=int(lines[i]), field="id")
    check_track_count(ids, path, field="id")
    key = np.stack([frames, ids], axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        seen: dict[tuple[float, float], int] = {}
        for i, pair in enumerate(map(tuple, key)):
            if pair in seen:
                raise DataFormatError(
                    path, f"id {pair[1]:g} appears twice in frame {pair[0]:g} (first on "
                          f"line {int(lines[seen[pair]])}); TrackEval refuses a ground-truth "
                          "id more than once per frame",
                    line=int(lines[i]), field="id")
            seen[pair] = i

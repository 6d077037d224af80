"""What each MOTChallenge benchmark's data look like, and data of another benchmark refused.

Every rule set (MOT15, MOT16, MOT17, MOT20, DanceTrack, SportsMOT) states its
:class:`DataSignature`: how its sequences are named, the columns and class ids of its
``gt.txt`` and the range of its detection scores. :func:`check_signature` compares a split's
sequences with it before anything is played: data that contradict the rule set (MOT17
sequences under MOT15's rules, which read every ground-truth row as a pedestrian) are
refused with one line naming the benchmark the data look like and the id to use; data that
are merely unusual (detection scores far off the declared range) give a warning. Custom
names (``SYN-01``, ``cam3``, ...) match no benchmark and are judged by their files only.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from unitrack_env.errors import DataFormatError
from unitrack_env.score_range import declared_range

#: Lines of ``gt.txt`` and ``det.txt`` read to recognise a layout (not the whole file).
SNIFF_LINES = 200
#: A 0..1 confidence never reaches this many times its declared top.
_FAR_ABOVE = 10.0


@dataclass(frozen=True)
class DataSignature:
    """What one benchmark's data look like.

    Attributes:
        benchmark: the rule set (``"MOT17"``).
        env_id: the registered id that plays it.
        sequences: regular expression of its official sequence names.
        naming: the naming in words, for messages.
        gt_columns: columns of its ``gt.txt`` (MOT15: 10, world x, y, z last).
        class_ids: the class ids of ``gt.txt`` column 8 (empty: no class column).
    """

    benchmark: str
    env_id: str
    sequences: str
    naming: str
    gt_columns: int
    class_ids: frozenset[int]

    def names_match(self, name: str) -> bool:
        """Whether ``name`` is named like one of this benchmark's sequences."""
        return re.fullmatch(self.sequences, name) is not None


_MOTCHALLENGE_CLASSES = frozenset(range(1, 14))  # TrackEval's MOTChallenge class ids

SIGNATURES: MappingProxyType[str, DataSignature] = MappingProxyType({
    "MOT15": DataSignature(
        "MOT15", "UniTrack/MOT15-v0",
        r"(ADL-Rundle-\d+|AVG-TownCentre|ETH-[A-Za-z]+\d*|KITTI-\d\d|PETS09-S2L\d|"
        r"TUD-[A-Za-z]+|Venice-\d)",
        "ADL-Rundle-6, ETH-Bahnhof, KITTI-13, PETS09-S2L1, TUD-Campus, Venice-2, ...",
        10, frozenset()),
    "MOT16": DataSignature("MOT16", "UniTrack/MOT16-v0", r"MOT16-\d\d", "MOT16-NN", 9,
                           _MOTCHALLENGE_CLASSES),
    "MOT17": DataSignature("MOT17", "UniTrack/MOT17-v0", r"MOT17-\d\d(-(DPM|FRCNN|SDP))?",
                           "MOT17-NN-{DPM,FRCNN,SDP}", 9, _MOTCHALLENGE_CLASSES),
    "MOT20": DataSignature("MOT20", "UniTrack/MOT20-v0", r"MOT20-\d\d", "MOT20-NN", 9,
                           _MOTCHALLENGE_CLASSES),
    # DanceTrack README: dancetrack0001 ...; SportsMOT README: v_-6Os86HzwCs_c001 (a YouTube
    # id and a clip number). Both write class 1 and visibility 1 in gt.txt columns 8, 9.
    "DanceTrack": DataSignature("DanceTrack", "UniTrack/DanceTrack-v0", r"dancetrack\d{4}",
                                "dancetrackNNNN", 9, _MOTCHALLENGE_CLASSES),
    "SportsMOT": DataSignature("SportsMOT", "UniTrack/SportsMOT-v0",
                               r"v_[A-Za-z0-9_-]{6,16}_c\d{3}", "v_<YouTube id>_cNNN", 9,
                               _MOTCHALLENGE_CLASSES),
})
"""Rule set -> what its data look like (read-only)."""

#: The id for custom data with the MOT16/17/20 class columns but no benchmark's names.
CUSTOM_CLASS_LAYOUT = "UniTrack/MOTChallenge-v0 with benchmark='MOT17'"


def _sniff(path: Path) -> list[list[str]]:
    """The first :data:`SNIFF_LINES` non-blank rows of a comma-separated file, as cells."""
    rows: list[list[str]] = []
    try:
        with path.open(encoding="utf-8", errors="replace") as handle:
            for line in handle:
                if line.strip():
                    rows.append([cell.strip() for cell in line.strip().rstrip(",").split(",")])
                if len(rows) >= SNIFF_LINES:
                    break
    except OSError:
        return []  # the reader names an unreadable file when it opens it
    return rows


def _numbers(rows: list[list[str]], column: int) -> list[float] | None:
    """Column ``column`` of every row as numbers (None: a row lacks it or a cell is no number)."""
    try:
        return [float(row[column]) for row in rows]
    except (IndexError, ValueError):
        return None


def gt_class_ids(gt_path: Path) -> list[int]:
    """The class ids of a ``gt.txt`` in the MOT16/17/20 layout (first lines), else [].

    The layout: exactly 9 columns, column 8 whole numbers in 1..13, column 9 (visibility) in
    0..1. MOT15's 10-column files (column 8 is a world x, -1 when unknown) are not it.
    """
    rows = _sniff(gt_path)
    if not rows or any(len(row) != 9 for row in rows):
        return []
    classes, visibility = _numbers(rows, 7), _numbers(rows, 8)
    if classes is None or visibility is None:
        return []
    if not all(c.is_integer() and c in _MOTCHALLENGE_CLASSES for c in classes):
        return []
    if not all(0.0 <= v <= 1.0 for v in visibility):
        return []
    return sorted({int(c) for c in classes})


def _named_like(name: str) -> DataSignature | None:
    return next((s for s in SIGNATURES.values() if s.names_match(name)), None)


def _refuse(path: Path, what: str, rule_set: str, looks: str, env_id: str) -> DataFormatError:
    return DataFormatError(path, f"{what}: these are {looks} data, not {rule_set}'s, and "
                                 f"{rule_set}'s rules would score them wrongly; use {env_id}")


def check_signature(benchmark: str, split_dir: Path, names: list[str]) -> None:
    """Refuse a split whose sequences are another benchmark's; warn about unusual scores.

    Reads only each sequence's name and the first lines of its ``gt/gt.txt`` and
    ``det/det.txt``.

    Raises:
        DataFormatError: a sequence is named like another benchmark's, or (under MOT15) its
            ground truth has the MOT16/17/20 class columns; the message names the id to use.
    """
    own = SIGNATURES.get(benchmark)
    if own is None:
        return
    for name in names:
        seq_dir = split_dir / name
        other = _named_like(name)
        if other is not None and other is not own:
            raise _refuse(seq_dir, f"named like a {other.benchmark} sequence ({other.naming})",
                          benchmark, other.benchmark, other.env_id)
        if not own.class_ids:
            classes = gt_class_ids(seq_dir / "gt" / "gt.txt")
            if classes:
                looks = other or _named_like_any(names)
                ids = ", ".join(map(str, classes))
                raise _refuse(seq_dir / "gt" / "gt.txt",
                              f"9 columns with class ids ({ids}) in column 8, the MOT16/17/20 "
                              f"layout ({benchmark}'s gt.txt has {own.gt_columns} columns and "
                              "no classes)", benchmark,
                              looks.benchmark if looks else "MOT16/17/20-layout",
                              looks.env_id if looks else CUSTOM_CLASS_LAYOUT)
    _warn_scores(benchmark, split_dir, names)


def _named_like_any(names: list[str]) -> DataSignature | None:
    return next((s for s in map(_named_like, names) if s is not None), None)


def _warn_scores(benchmark: str, split_dir: Path, names: list[str]) -> None:
    """Warn once when public detection scores are far above a bounded declared range."""
    declared = declared_range(benchmark)
    if not declared.bounded:
        return
    for name in names:
        path = split_dir / name / "det" / "det.txt"
        scores = _numbers(_sniff(path), 6)
        if scores and max(scores) > _FAR_ABOVE * declared.high:
            warnings.warn(
                f"{path}: detection scores reach {max(scores):g}, far above {benchmark}'s "
                f"declared {declared.low:g}..{declared.high:g}; unbounded detector scores "
                f"like these look like MOT15's (use {SIGNATURES['MOT15'].env_id}), or pass "
                "score_range= for your own data", stacklevel=4)
            return

"""Class maps of MOTChallenge-layout data: which ground-truth class ids are scored as what.

A class map names the scored classes and their ``gt.txt`` class ids (column 8), the
distractor ids (a track matched to one, IoU >= 0.5, is removed, as MOTChallenge removes
tracks on static persons and reflections) and the ignored ids (neither scored nor
removing tracks, as MOTChallenge's cars and occluders). Every class id in the ground truth
must be in exactly one of them. Given as environment arguments::

    classes={"car": [3], "pedestrian": [1, 2]}, distractors=[7], ignore=[9]

or as ``classes.json`` beside the split folders (``<root>/classes.json``), the same three
keys. Each class is scored with MOTChallenge's rules with that class as the pedestrian
class (:meth:`ClassMap.pedestrian_rows`), then combined as TrackEval combines classes.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.errors import DataFormatError

#: The file beside the split folders that declares the data's class map.
CLASS_MAP_FILE = "classes.json"
#: Names a class may not take: the combinations' and the combined row's.
RESERVED_NAMES = frozenset({"cls_comb_cls_av", "cls_comb_det_av", "COMBINED"})
#: MOTChallenge class ids a class's view is written with: the scored class (pedestrian), a
#: distractor, and any other object (occluder: neither scored nor a distractor).
VIEW_SCORED, VIEW_DISTRACTOR, VIEW_OTHER = 1, 8, 9
#: The TrackEval rule set of a class's view (its distractors include 8, not 9).
VIEW_BENCHMARK = "MOT17"


class ClassMapError(ValueError):
    """A class map is malformed; the message names the field (and the file it came from)."""


def _ids(value: Any, field: str) -> tuple[int, ...]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise ClassMapError(f"{field}: must be a list of class ids, got {value!r}")
    out = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, np.integer)) or item < 1:
            raise ClassMapError(f"{field}: class ids are integers >= 1, got {item!r}")
        out.append(int(item))
    if len(set(out)) != len(out):
        raise ClassMapError(f"{field}: repeats a class id ({sorted(out)})")
    return tuple(out)


@dataclass(frozen=True)
class ClassMap:
    """The scored classes (name: gt class ids, in order), the distractor and ignored ids."""

    classes: tuple[tuple[str, tuple[int, ...]], ...]
    distractors: tuple[int, ...] = ()
    ignore: tuple[int, ...] = ()

    @classmethod
    def parse(cls, classes: Any, distractors: Any = (), ignore: Any = ()) -> ClassMap:
        """The map of these arguments, checked: a :class:`ClassMapError` naming the field."""
        if not isinstance(classes, Mapping) or not classes:
            raise ClassMapError("classes: must map class names to lists of class ids, e.g. "
                                f'{{"car": [3], "pedestrian": [1, 2]}}, got {classes!r}')
        rows = []
        for name, ids in classes.items():
            if not isinstance(name, str) or not name.strip() or "/" in name \
                    or name in RESERVED_NAMES:
                raise ClassMapError(f"classes: {name!r} is not a usable class name (a "
                                    "non-empty text without '/', not "
                                    f"{', '.join(sorted(RESERVED_NAMES))})")
            found = _ids(ids, f"classes[{name!r}]")
            if not found:
                raise ClassMapError(f"classes[{name!r}]: lists no class id")
            rows.append((name, found))
        made = cls(tuple(rows), _ids(distractors or (), "distractors"),
                   _ids(ignore or (), "ignore"))
        made._check_overlaps()
        return made

    def _check_overlaps(self) -> None:
        seen: dict[int, str] = {}
        fields = [(f"classes[{n!r}]", ids) for n, ids in self.classes]
        for field, ids in [*fields, ("distractors", self.distractors), ("ignore", self.ignore)]:
            for ident in ids:
                if ident in seen:
                    raise ClassMapError(f"{field}: class id {ident} is also in {seen[ident]}; "
                                        "each id belongs to one class, or is a distractor, "
                                        "or is ignored")
                seen[ident] = field

    @property
    def names(self) -> tuple[str, ...]:
        """The scored classes' names, in order."""
        return tuple(name for name, _ in self.classes)

    def ids_of(self, name: str) -> tuple[int, ...]:
        """The gt class ids of the scored class ``name``."""
        return dict(self.classes)[name]

    @property
    def scored_ids(self) -> tuple[int, ...]:
        """Every id of a scored class."""
        return tuple(i for _, ids in self.classes for i in ids)

    @property
    def known_ids(self) -> frozenset[int]:
        """Every id the map names (scored, distractor or ignored)."""
        return frozenset((*self.scored_ids, *self.distractors, *self.ignore))

    def describe(self) -> str:
        """``car: 3; pedestrian: 1, 2; distractors: 7; ignore: 9`` (for messages)."""
        parts = [f"{n}: {', '.join(map(str, ids))}" for n, ids in self.classes]
        parts += [f"{label}: {', '.join(map(str, ids))}"
                  for label, ids in (("distractors", self.distractors), ("ignore", self.ignore))
                  if ids]
        return "; ".join(parts)

    def to_json(self) -> dict[str, Any]:
        """The map as ``classes.json`` holds it."""
        return {"classes": {n: list(ids) for n, ids in self.classes},
                "distractors": list(self.distractors), "ignore": list(self.ignore)}

    def check_column(self, path: Path, classes: np.ndarray, lines: np.ndarray, *,
                     scored_only: bool = False, what: str = "ground truth") -> None:
        """Refuse a class id the map does not name (``scored_only``: not a scored class).

        ``classes`` is a file's class column and ``lines`` the rows' 1-based file lines.
        """
        allowed = set(self.scored_ids) if scored_only else self.known_ids
        bad = ~np.isin(classes, list(allowed))
        if bad.any():
            i = int(np.argmax(bad))
            kind = "a scored class" if scored_only else "in the class map"
            hint = ("; -1 is no class: with a class map each row carries its class id in "
                    "column 8") if classes[i] == -1 else ""
            raise DataFormatError(path, f"{what} class {classes[i]:g} is not {kind} "
                                  f"({self.describe()}){hint}", line=int(lines[i]),
                                  field="class")

    def pedestrian_rows(self, name: str, gt: np.ndarray, tracks: np.ndarray,
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Class ``name``'s view: ground truth and result rows that MOTChallenge's rules score.

        In the gt rows (frame, id, x, y, w, h, flag, class, ...), ``name``'s ids become 1
        (pedestrian), distractor ids 8 (distractor), every other id 9 (occluder: it takes part
        in the distractor matching only); the result rows are those of ``name``'s ids, their
        class column -1. Scored under :data:`VIEW_BENCHMARK`'s rules.
        """
        gt = np.array(gt, dtype=np.float64, copy=True, ndmin=2)
        if not gt.size:
            gt = np.zeros((0, 9))
        cls = gt[:, 7].copy()
        gt[:, 7] = VIEW_OTHER
        gt[np.isin(cls, self.distractors), 7] = VIEW_DISTRACTOR
        gt[np.isin(cls, self.ids_of(name)), 7] = VIEW_SCORED
        tracks = np.asarray(tracks, dtype=np.float64)
        if not tracks.size:  # no rows (of any width)
            tracks = np.zeros((0, 10))
        mine = tracks[np.isin(tracks[:, 7], self.ids_of(name))]
        mine[:, 7] = -1  # a copy: boolean indexing
        return gt, mine


def class_map(root: str | Path | None, classes: Any = None, distractors: Any = None,
              ignore: Any = None) -> ClassMap | None:
    """The class map of the arguments, else of ``<root>/classes.json``, else None.

    The arguments win over the file. ``distractors``/``ignore`` without ``classes`` (and no
    file) are refused: they mean nothing without scored classes.
    """
    if classes is not None:
        return ClassMap.parse(classes, distractors, ignore)
    path = Path(root) / CLASS_MAP_FILE if root is not None else None
    if path is not None and path.is_file():
        if distractors is not None or ignore is not None:
            raise ClassMapError(f"distractors/ignore: given without classes, and {path} "
                                "declares the map; pass classes= too, or edit the file")
        return _read_file(path)
    if distractors is not None or ignore is not None:
        raise ClassMapError("distractors/ignore: given without classes; pass classes= "
                            '(e.g. {"pedestrian": [1]}) or a classes.json beside the data')
    return None


def _read_file(path: Path) -> ClassMap:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataFormatError(path, f"not a readable JSON file ({exc})") from None
    if not isinstance(data, dict):
        raise DataFormatError(path, 'must be a JSON object {"classes": {...}, '
                              '"distractors": [...], "ignore": [...]}')
    unknown = sorted(set(data) - {"classes", "distractors", "ignore"})
    if unknown:
        raise DataFormatError(path, "unknown key; the keys are classes, distractors, ignore",
                              field=unknown[0])
    try:
        return ClassMap.parse(data.get("classes"), data.get("distractors"), data.get("ignore"))
    except ClassMapError as exc:
        field = str(exc).split(":", 1)[0]
        raise DataFormatError(path, str(exc).split(": ", 1)[-1], field=field) from None

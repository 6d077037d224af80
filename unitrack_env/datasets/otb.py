"""Reader for the OTB-2015 layout (OTB-100, OTB-50 or any folder in that layout).

Reads ``<root>/<Seq>/img/0001.jpg ...`` with ``groundtruth_rect[.k].txt`` (docs/envs/otb.md);
LaSOT and GOT-10k are read by :mod:`unitrack_env.datasets.lasot`. :data:`OTB100_SEQUENCES` is
our own encoding of the OTB toolkit's sequence configuration (jwlim/tracker_benchmark
``matlab/util/MakeSequenceConfigVer10.m``/``Ver11.m``) and of the OTB-2015 table in
pytracking's ``pytracking/evaluation/otbdataset.py``: ``Jogging`` and ``Skating2`` hold two
targets (``.1``/``.2`` files), ``Human4`` only ``.2`` (its ``.1`` file is empty in the
release); David and BlurCar1/3/4 start later (their images are numbered from the start
frame), Football1, Freeman3 and Freeman4 have more images than annotated frames, and Tiger1's
first 5 frames are omitted (the toolkit's ``initOmit``).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.sot import (
    BOX_FIELDS,
    SOTSequence,
    numbered_images,
    read_box_file,
    read_image_size,
    select_frames,
)
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.spaces.limits import COORD_MAX

__all__ = ["OTB_GT_PATTERN", "OTBDataset", "OTBSequenceSpec", "canonical_otb_name"]


OTB_GT_PATTERN = re.compile(r"^groundtruth_rect(?:\.(\d+))?\.txt$")
"""``groundtruth_rect.txt`` or ``groundtruth_rect.<k>.txt`` (target ``k`` of the folder)."""

@dataclass(frozen=True)
class OTBSequenceSpec:
    """One OTB-2015 sequence as the toolkit configures it.

    ``start_frame``..``end_frame`` are the annotated frames (the rows of ``gt_file``);
    ``init_omit`` leading frames are skipped before tracking starts.
    """

    name: str
    folder: str
    gt_file: str
    start_frame: int
    end_frame: int
    init_omit: int = 0

    @property
    def num_frames(self) -> int:
        """Frames evaluated (after ``init_omit``)."""
        return self.end_frame - self.start_frame + 1 - self.init_omit


# name start end [init_omit]; "Name.k" means folder "Name", file groundtruth_rect.k.txt.
_OTB100_TABLE = """
Basketball 1 725; Biker 1 142; Bird1 1 408; Bird2 1 99; BlurBody 1 334; BlurCar1 247 988;
BlurCar2 1 585; BlurCar3 3 359; BlurCar4 18 397; BlurFace 1 493; BlurOwl 1 631;
Board 1 698; Bolt 1 350; Bolt2 1 293; Box 1 1161; Boy 1 602; Car1 1 1020; Car2 1 913;
Car24 1 3059; Car4 1 659; CarDark 1 393; CarScale 1 252; ClifBar 1 472; Coke 1 291;
Couple 1 140; Coupon 1 327; Crossing 1 120; Crowds 1 347; Dancer 1 225; Dancer2 1 150;
David 300 770; David2 1 537; David3 1 252; Deer 1 71; Diving 1 215; Dog 1 127;
Dog1 1 1350; Doll 1 3872; DragonBaby 1 113; Dudek 1 1145; FaceOcc1 1 892; FaceOcc2 1 812;
Fish 1 476; FleetFace 1 707; Football 1 362; Football1 1 74; Freeman1 1 326;
Freeman3 1 460; Freeman4 1 283; Girl 1 500; Girl2 1 1500; Gym 1 767; Human2 1 1128;
Human3 1 1698; Human4.2 1 667; Human5 1 713; Human6 1 792; Human7 1 250; Human8 1 128;
Human9 1 305; Ironman 1 166; Jogging.1 1 307; Jogging.2 1 307; Jump 1 122; Jumping 1 313;
KiteSurf 1 84; Lemming 1 1336; Liquor 1 1741; Man 1 134; Matrix 1 100; Mhyang 1 1490;
MotorRolling 1 164; MountainBike 1 228; Panda 1 1000; RedTeam 1 1918; Rubik 1 1997;
Shaking 1 365; Singer1 1 351; Singer2 1 366; Skater 1 160; Skater2 1 435; Skating1 1 400;
Skating2.1 1 473; Skating2.2 1 473; Skiing 1 81; Soccer 1 392; Subway 1 175; Surfer 1 376;
Suv 1 945; Sylvester 1 1345; Tiger1 1 354 5; Tiger2 1 365; Toy 1 271; Trans 1 124;
Trellis 1 569; Twinnings 1 472; Vase 1 271; Walking 1 412; Walking2 1 500; Woman 1 597
"""


def _parse_table(text: str) -> tuple[OTBSequenceSpec, ...]:
    specs = []
    for item in text.replace("\n", " ").split(";"):
        name, *numbers = item.split()
        folder, _, target = name.partition(".")
        gt_file = f"groundtruth_rect.{target}.txt" if target else "groundtruth_rect.txt"
        specs.append(OTBSequenceSpec(name, folder, gt_file, *(int(n) for n in numbers)))
    return tuple(specs)


OTB100_SEQUENCES: tuple[OTBSequenceSpec, ...] = _parse_table(_OTB100_TABLE)
"""The 100 targets of OTB-2015 (OTB-100) with their evaluated frame ranges."""


def canonical_otb_name(name: str) -> str:
    """Map ``Jogging_1`` / ``Jogging-1`` to the toolkit's ``Jogging.1``; other names unchanged.

    >>> canonical_otb_name("Skating2_2")
    'Skating2.2'
    """
    return re.sub(r"[_\-](\d+)$", r".\1", name) if re.search(r"[_\-]\d+$", name) else name


def _check_boxes(path: Path, boxes: np.ndarray, first: int) -> None:
    """Refuse ground truth the episode cannot start from or score (rows from ``first`` on).

    The first row must be finite with a positive size, every value within the observation
    bounds; later rows may be NaN or empty (the toolkit leaves those frames out).
    """
    init = boxes[first]
    if not (np.isfinite(init).all() and init[2] > 0 and init[3] > 0):
        raise DataFormatError(
            path, f"the first box {init.tolist()} is the target given to the tracker: it must "
                  "be finite with a positive width and height", line=first + 1)
    rows = boxes[first:]
    outside = np.abs(np.nan_to_num(rows)) > COORD_MAX
    if outside.any():
        i, col = (int(v) for v in np.argwhere(outside)[0])
        raise DataFormatError(
            path, f"{rows[i, col]:g} is outside the observation bounds [-{COORD_MAX:g}, "
                  f"{COORD_MAX:g}] pixels", line=first + i + 1, field=BOX_FIELDS[col])


class OTBDataset(SequenceDataset[SOTSequence]):
    """The sequences of an OTB-layout folder (OTB-2015/100, OTB-2013/50, or a subset).

    Every ``<root>/<folder>`` with an ``img/`` folder is read. Folders named in
    :data:`OTB100_SEQUENCES` yield the targets the toolkit defines for them; any other folder
    yields one sequence per non-empty ``groundtruth_rect[.k].txt`` whose frames start at the
    first numbered image.
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DataFormatError(self.root, "OTB root folder missing")
        by_folder: dict[str, list[OTBSequenceSpec]] = {}
        for spec in OTB100_SEQUENCES:
            by_folder.setdefault(spec.folder.lower(), []).append(spec)
        self._specs: dict[str, OTBSequenceSpec | tuple[Path, Path]] = {}
        for folder in sorted(p for p in self.root.iterdir() if (p / "img").is_dir()):
            known = by_folder.get(folder.name.lower())
            if known and self._add_known(folder, known):
                continue
            for gt in sorted(folder.iterdir()):
                match = OTB_GT_PATTERN.match(gt.name)
                if not match:
                    continue
                name = folder.name + (f".{match.group(1)}" if match.group(1) else "")
                if gt.stat().st_size == 0:
                    warnings.warn(f"{gt}: empty ground-truth file; sequence {name} skipped",
                                  stacklevel=2)
                    continue
                self._specs[name] = (folder, gt)
        if not self._specs:
            raise DataFormatError(
                self.root, "no sequence folders with img/ and groundtruth_rect.txt found"
            )
        self.sequence_names: list[str] = list(self._specs)
        self._lower = {n.lower(): n for n in self.sequence_names}

    def _add_known(self, folder: Path, known: list[OTBSequenceSpec]) -> bool:
        """Add the OTB-100 targets of ``folder``; False when it has none of their files.

        Ground-truth files the toolkit does not define for the folder are never dropped in
        silence: when none of its own are present the folder is read as a custom one (with
        a warning), else the extra files are named in a warning.
        """
        found = [spec for spec in known if (folder / spec.gt_file).is_file()]
        used = {spec.gt_file for spec in found}
        extra = sorted(p.name for p in folder.iterdir()
                       if OTB_GT_PATTERN.match(p.name) and p.name not in used)
        expected = ", ".join(spec.gt_file for spec in known)
        if not found:
            if extra:
                warnings.warn(
                    f"{folder}: named like the OTB-100 sequence {known[0].folder}, whose ground "
                    f"truth is {expected}, but holds {', '.join(extra)}; read as a custom "
                    "sequence (frames from the first numbered image, not the toolkit's range)",
                    stacklevel=3)
            return False
        if extra:
            warnings.warn(f"{folder}: {', '.join(extra)} ignored (the OTB toolkit defines "
                          f"{expected} for this sequence)", stacklevel=3)
        for spec in found:
            self._specs[spec.name] = spec
        return True

    def resolve(self, name: str) -> str:
        """Return the dataset's spelling of ``name`` (aliases and case are accepted)."""
        key = name.lower()
        if key not in self._lower:
            key = canonical_otb_name(name).lower()
        if key not in self._lower:
            raise UnknownSequenceError(
                f"no OTB sequence '{name}' in {self.root}; available: "
                f"{', '.join(self.sequence_names)}"
            )
        return self._lower[key]

    def load(self, name: str) -> SOTSequence:
        """Read one sequence's frames list and ground truth."""
        name = self.resolve(name)
        spec = self._specs[name]
        if isinstance(spec, OTBSequenceSpec):
            folder = self.root / next(
                p.name for p in self.root.iterdir() if p.name.lower() == spec.folder.lower()
            )
            gt_path = folder / spec.gt_file
            boxes = read_box_file(gt_path)
            expected = spec.end_frame - spec.start_frame + 1
            if len(boxes) > expected:
                raise DataFormatError(
                    gt_path,
                    f"has {len(boxes)} rows but OTB-2015 annotates frames {spec.start_frame}-"
                    f"{spec.end_frame} ({expected} rows) for {spec.name}",
                )
            if len(boxes) < expected:
                warnings.warn(
                    f"{gt_path}: {len(boxes)} of the {expected} OTB-2015 rows of {spec.name}; "
                    f"reading a trimmed copy (frames {spec.start_frame}-"
                    f"{spec.start_frame + len(boxes) - 1})",
                    stacklevel=2,
                )
            first, omit = spec.start_frame, spec.init_omit
        else:
            folder, gt_path = spec
            boxes = read_box_file(gt_path)
            first, omit = min(numbered_images(folder / "img")), 0
        if len(boxes) <= omit:
            raise DataFormatError(gt_path, f"needs more than {omit} rows")
        _check_boxes(gt_path, boxes, omit)
        boxes = boxes[omit:]
        numbers = range(first + omit, first + omit + len(boxes))
        frames = select_frames(folder / "img", numbers)
        return SOTSequence(
            name=name,
            frame_paths=frames,
            frame_numbers=tuple(numbers),
            boxes=boxes,
            image_size=read_image_size(frames[0]),
            absent=np.zeros(len(frames), dtype=bool),
            benchmark="OTB",
        )


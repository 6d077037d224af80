"""Readers for single object tracking layouts: OTB-2015 (main), LaSOT and GOT-10k.

Layouts read, exactly as the benchmarks ship them::

    OTB:     <root>/<Seq>/img/0001.jpg ...            (Board: 00001.jpg; some sets .png)
             <root>/<Seq>/groundtruth_rect.txt        (or groundtruth_rect.1.txt / .2.txt)
    LaSOT:   <root>/<class>/<class>-<n>/img/00000001.jpg ...
             <root>/<class>/<class>-<n>/groundtruth.txt, full_occlusion.txt, out_of_view.txt
    GOT-10k: <root>/<split>/<seq>/00000001.jpg ..., groundtruth.txt, absence.label
             <root>/<split>/list.txt                  (optional sequence list)

Boxes stay as written: ``(x, y, w, h)`` with the file's 1-based pixel origin (the top-left
pixel is ``(1, 1)``), so that results written back round-trip to the official files.

OTB quirks handled (facts from the OTB toolkit's sequence configuration, jwlim/
tracker_benchmark ``matlab/util/MakeSequenceConfigVer10.m``/``Ver11.m``, and the OTB-2015
table in visionml/pytracking ``pytracking/evaluation/otbdataset.py``; the table below is our
own encoding of those facts):

* Ground-truth separators: commas, tabs or spaces, mixed within a file (Crossing uses tabs);
  a last line without a newline (Human3).
* Several targets in one folder: ``Jogging.1``/``Jogging.2`` and ``Skating2.1``/
  ``Skating2.2`` read ``groundtruth_rect.1.txt``/``.2.txt``; ``Human4.2`` reads only
  ``groundtruth_rect.2.txt`` (the ``.1`` file is empty in the release). ``Jogging_1`` and
  ``Jogging-1`` are accepted as aliases of ``Jogging.1``.
* Sequences whose evaluated range is not "frame 1 to the number of images": David 300-770,
  BlurCar1 247-988, BlurCar3 3-359, BlurCar4 18-397 (their image files are numbered from the
  start frame), Football1 1-74 (81 images), Freeman3 1-460 (474 images), Freeman4 1-283
  (297 images), Diving 1-215, and Tiger1 whose first 5 frames are omitted (``initOmit``:
  tracking starts at frame 6, the first 5 ground-truth rows are dropped).

A copy whose ground truth has *fewer* rows than the table's range (a trimmed fixture, e.g.
the first 199 of Human3's 1698 frames) is read with a warning; more rows than the range is
an error.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.errors import DataFormatError, UnknownSequenceError

IMAGE_EXTENSIONS: tuple[str, ...] = (".jpg", ".jpeg", ".png", ".bmp")
"""Frame file extensions recognised in image folders."""

OTB_GT_PATTERN = re.compile(r"^groundtruth_rect(?:\.(\d+))?\.txt$")
"""``groundtruth_rect.txt`` or ``groundtruth_rect.<k>.txt`` (target ``k`` of the folder)."""

_SEPARATORS = re.compile(r"[,\s]+")
_BOX_FIELDS = ("x", "y", "w", "h")


@dataclass(frozen=True)
class OTBSequenceSpec:
    """One OTB-2015 sequence as the toolkit configures it.

    Attributes:
        name: the toolkit's sequence name (``Jogging.1``).
        folder: the folder holding ``img/`` and the ground truth.
        gt_file: ground-truth file name inside ``folder``.
        start_frame: number of the first annotated frame (first row of ``gt_file``).
        end_frame: number of the last annotated frame.
        init_omit: leading annotated frames skipped before tracking starts.
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


@dataclass(frozen=True)
class SOTSequence:
    """One single-object sequence: frames and the target's boxes.

    Attributes:
        name: sequence name (OTB: ``Jogging.1``; LaSOT: ``airplane-1``).
        frame_paths: image file of every frame, in order.
        frame_numbers: the benchmark's own number of every frame (from the file names).
        boxes: ``(num_frames, 4)`` float64 ``(x, y, w, h)`` as written in the file (1-based
            pixels). Rows with NaN have no annotation (GOT-10k test frames after the first,
            LaSOT/UAV "NaN" rows); OTB marks an absent target with a non-positive box.
        image_size: ``(width, height)`` of the first frame.
        absent: ``(num_frames,)`` bool where the benchmark flags the target as not visible
            (LaSOT full occlusion or out of view, GOT-10k ``absence.label``); all False for OTB.
        benchmark: ``"OTB"``, ``"LaSOT"`` or ``"GOT-10k"``.
    """

    name: str
    frame_paths: tuple[Path, ...]
    frame_numbers: tuple[int, ...]
    boxes: np.ndarray
    image_size: tuple[int, int]
    absent: np.ndarray
    benchmark: str

    def __post_init__(self) -> None:
        n = len(self.frame_paths)
        if self.boxes.shape != (n, 4) or self.absent.shape != (n,) or len(
            self.frame_numbers) != n:
            raise ValueError(f"{self.name}: frames, boxes and flags disagree in length")
        self.boxes.setflags(write=False)
        self.absent.setflags(write=False)

    @property
    def num_frames(self) -> int:
        """Number of frames of the sequence."""
        return len(self.frame_paths)

    @property
    def init_box(self) -> np.ndarray:
        """The target's box in the first frame (what a tracker is given)."""
        return self.boxes[0]

    @property
    def has_ground_truth(self) -> bool:
        """Whether frames after the first are annotated (False on GOT-10k test)."""
        return bool(np.isfinite(self.boxes[1:]).any()) if self.num_frames > 1 else True


def read_image_size(path: str | Path) -> tuple[int, int]:
    """Return ``(width, height)`` of an image file.

    Raises:
        DataFormatError: the file is missing or not a decodable image.
    """
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise DataFormatError(path, "missing or not a readable image")
    return int(image.shape[1]), int(image.shape[0])


def read_box_file(path: str | Path, *, allow_nan: bool = True) -> np.ndarray:
    """Read an ``x,y,w,h`` box file with comma, tab or space separators (any mix).

    Args:
        path: the ground-truth file.
        allow_nan: accept ``NaN`` entries (LaSOT/UAV write them for unannotated frames).

    Returns:
        ``(n, 4)`` float64, one row per non-empty line.

    Raises:
        DataFormatError: a line does not hold exactly four numbers, or a blank line is
            followed by more data (it would shift every later frame).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise DataFormatError(path, f"cannot read box file ({err})") from err
    rows: list[list[float]] = []
    blank_at: int | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.strip().strip(",")
        if not content:
            blank_at = blank_at or number
            continue
        if blank_at is not None:
            raise DataFormatError(path, "blank line inside the box list", line=blank_at)
        parts = _SEPARATORS.split(content)
        if len(parts) != 4:
            raise DataFormatError(
                path, f"expected 4 numbers x,y,w,h, found {len(parts)}: {content!r}", line=number
            )
        values = []
        for field_name, part in zip(_BOX_FIELDS, parts, strict=True):
            try:
                value = float(part)
            except ValueError:
                raise DataFormatError(
                    path, f"not a number: {part!r}", line=number, field=field_name
                ) from None
            if np.isinf(value) or (np.isnan(value) and not allow_nan):
                raise DataFormatError(path, f"invalid value {part!r}", line=number,
                                      field=field_name)
            values.append(value)
        rows.append(values)
    if not rows:
        raise DataFormatError(path, "contains no boxes")
    return np.asarray(rows, dtype=np.float64)


def _check_boxes(path: Path, boxes: np.ndarray, first: int) -> None:
    """Refuse ground truth the episode cannot start from or score (rows from ``first`` on).

    The first row is the target the tracker is given: it must be finite with a positive
    size; every value must fit the observation bounds. Later rows may be NaN or have a
    non-positive size: the OTB toolkit leaves such frames out of the evaluation.
    (Rows are file lines here: :func:`read_box_file` refuses blank lines inside the list.)
    """
    from unitrack_env.spaces import COORD_MAX

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
                  f"{COORD_MAX:g}] pixels", line=first + i + 1, field=_BOX_FIELDS[col])


def _read_flags(path: Path, expected: int) -> np.ndarray:
    """Read 0/1 flags written one per line or comma-separated on one line."""
    try:
        tokens = [t for t in _SEPARATORS.split(path.read_text(encoding="utf-8-sig")) if t]
    except OSError as err:
        raise DataFormatError(path, f"cannot read flag file ({err})") from err
    if len(tokens) != expected:
        raise DataFormatError(path, f"has {len(tokens)} flags, expected {expected} (one per frame)")
    try:
        values = np.array([int(float(t)) for t in tokens])
    except ValueError as err:
        raise DataFormatError(path, f"flags must be 0 or 1 ({err})") from None
    if not np.isin(values, (0, 1)).all():
        raise DataFormatError(path, "flags must be 0 or 1")
    return values.astype(bool)


def _numbered_images(folder: Path) -> dict[int, Path]:
    """Map the integer stem of every image in ``folder`` to its path."""
    if not folder.is_dir():
        raise DataFormatError(folder, "image folder missing")
    images: dict[int, Path] = {}
    for p in folder.iterdir():
        if p.suffix.lower() in IMAGE_EXTENSIONS and p.stem.isdigit():
            images.setdefault(int(p.stem), p)
    if not images:
        kinds = ", ".join(IMAGE_EXTENSIONS)
        raise DataFormatError(folder, f"contains no numbered images ({kinds})")
    return images


def _select_frames(folder: Path, numbers: range) -> tuple[Path, ...]:
    images = _numbered_images(folder)
    missing = [n for n in numbers if n not in images]
    if missing:
        raise DataFormatError(
            folder / f"{missing[0]:04d}.jpg",
            f"missing frame {missing[0]} ({len(missing)} of frames {numbers.start}-"
            f"{numbers.stop - 1} missing)",
        )
    return tuple(images[n] for n in numbers)


class OTBDataset:
    """The sequences of an OTB-layout folder (OTB-2015/100, OTB-2013/50, or a subset).

    Every ``<root>/<folder>`` with an ``img/`` folder is read. Folders named in
    :data:`OTB100_SEQUENCES` yield the targets the toolkit defines for them; any other folder
    yields one sequence per non-empty ``groundtruth_rect[.k].txt`` whose frames start at the
    first numbered image.

    Args:
        root: the folder holding the sequence folders.
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
            if known:
                for spec in known:
                    if (folder / spec.gt_file).is_file():
                        self._specs[spec.name] = spec
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

    def __len__(self) -> int:
        return len(self.sequence_names)

    def __iter__(self) -> Iterator[SOTSequence]:
        for name in self.sequence_names:
            yield self.load(name)

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
            first, omit = min(_numbered_images(folder / "img")), 0
        if len(boxes) <= omit:
            raise DataFormatError(gt_path, f"needs more than {omit} rows")
        _check_boxes(gt_path, boxes, omit)
        boxes = boxes[omit:]
        numbers = range(first + omit, first + omit + len(boxes))
        frames = _select_frames(folder / "img", numbers)
        return SOTSequence(
            name=name,
            frame_paths=frames,
            frame_numbers=tuple(numbers),
            boxes=boxes,
            image_size=read_image_size(frames[0]),
            absent=np.zeros(len(frames), dtype=bool),
            benchmark="OTB",
        )


class LaSOTDataset:
    """LaSOT: ``<root>/<class>/<class>-<n>/{img/*.jpg, groundtruth.txt, ...}``.

    ``absent`` = ``full_occlusion.txt`` OR ``out_of_view.txt`` (pytracking's
    ``target_visible`` is its negation). Frames are the sorted ``img/`` images, which must
    number exactly as many as the ground-truth rows.

    Args:
        root: the LaSOT folder holding the class folders.
        split_file: optional text file listing sequence names one per line (e.g. the
            official ``testing_set.txt``); without it every sequence found is listed.
    """

    def __init__(self, root: str | Path, split_file: str | Path | None = None) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DataFormatError(self.root, "LaSOT root folder missing")
        found = {
            seq.name: seq
            for cls in sorted(self.root.iterdir()) if cls.is_dir()
            for seq in sorted(cls.iterdir()) if (seq / "groundtruth.txt").is_file()
        }
        if split_file is not None:
            wanted = [s.strip() for s in Path(split_file).read_text().splitlines() if s.strip()]
            missing = [s for s in wanted if s not in found]
            if missing:
                raise DataFormatError(split_file, f"lists sequences not under {self.root}: "
                                      f"{', '.join(missing[:5])}")
            found = {s: found[s] for s in wanted}
        if not found:
            raise DataFormatError(self.root, "no <class>/<sequence>/groundtruth.txt found")
        self._dirs = found
        self.sequence_names: list[str] = list(found)

    def __len__(self) -> int:
        return len(self.sequence_names)

    def load(self, name: str) -> SOTSequence:
        """Read one sequence."""
        if name not in self._dirs:
            raise UnknownSequenceError(f"no LaSOT sequence '{name}' in {self.root}")
        seq = self._dirs[name]
        boxes = read_box_file(seq / "groundtruth.txt")
        images = _numbered_images(seq / "img")
        numbers = sorted(images)
        if len(numbers) != len(boxes):
            raise DataFormatError(
                seq / "groundtruth.txt",
                f"has {len(boxes)} rows but img/ holds {len(numbers)} frames",
            )
        absent = np.zeros(len(boxes), dtype=bool)
        for flag_file in ("full_occlusion.txt", "out_of_view.txt"):
            if (seq / flag_file).is_file():
                absent |= _read_flags(seq / flag_file, len(boxes))
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           absent, "LaSOT")


class GOT10kDataset:
    """GOT-10k: ``<root>/<split>/<seq>/{*.jpg, groundtruth.txt, absence.label}``.

    On the test split ``groundtruth.txt`` holds only the first frame's box; the other rows
    are NaN and :attr:`SOTSequence.has_ground_truth` is False.

    Args:
        root: the GOT-10k folder holding ``train/``, ``val/``, ``test/``.
        split: sub-folder to read.
    """

    def __init__(self, root: str | Path, split: str = "val") -> None:
        self.split_dir = Path(root) / split
        if not self.split_dir.is_dir():
            raise DataFormatError(self.split_dir, "GOT-10k split folder missing")
        listing = self.split_dir / "list.txt"
        if listing.is_file():
            names = [s.strip() for s in listing.read_text().splitlines() if s.strip()]
        else:
            names = sorted(p.name for p in self.split_dir.iterdir()
                           if (p / "groundtruth.txt").is_file())
        if not names:
            raise DataFormatError(self.split_dir, "no <seq>/groundtruth.txt found")
        self.sequence_names: list[str] = names

    def __len__(self) -> int:
        return len(self.sequence_names)

    def load(self, name: str) -> SOTSequence:
        """Read one sequence."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(f"no GOT-10k sequence '{name}' in {self.split_dir}")
        seq = self.split_dir / name
        images = _numbered_images(seq)
        numbers = sorted(images)
        boxes = read_box_file(seq / "groundtruth.txt")
        if len(boxes) == 1 and len(numbers) > 1:  # test split: first frame only
            boxes = np.vstack([boxes, np.full((len(numbers) - 1, 4), np.nan)])
        if len(boxes) != len(numbers):
            raise DataFormatError(
                seq / "groundtruth.txt",
                f"has {len(boxes)} rows but the folder holds {len(numbers)} frames",
            )
        absent = np.zeros(len(numbers), dtype=bool)
        if (seq / "absence.label").is_file():
            absent = _read_flags(seq / "absence.label", len(numbers))
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           absent, "GOT-10k")

"""LaSOT and GOT-10k readers (layouts in docs/envs/sot-protocols.md), LaSOT synthetic data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.otb import _check_boxes
from unitrack_env.datasets.sot import (
    SOTSequence,
    numbered_images,
    read_box_file,
    read_flags,
    read_image_size,
)
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.otb import render_target, write_images
from unitrack_env.datasets.synthetic.scene_model import SceneConfig
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.io import path_inside

#: LaSOT's split files at the root of the release, by ``split=`` name.
LASOT_SPLIT_FILES = {"test": "testing_set.txt", "train": "training_set.txt"}
#: ``split=`` values that read every sequence found (``"ext"``: the LaSOT extension release,
#: 150 sequences in the same layout and no split file).
LASOT_ALL = ("all", "ext")


def _split_names(root: Path, split: str | Path | None) -> tuple[Path | None, bool]:
    """The split file ``split`` names (None: every sequence) and whether it must exist."""
    if split is None:
        default = root / LASOT_SPLIT_FILES["test"]
        return (default if default.is_file() else None), False
    if split in LASOT_ALL:
        return None, False
    if split in LASOT_SPLIT_FILES:
        return root / LASOT_SPLIT_FILES[split], True
    path = Path(split)
    if not path.is_file():
        raise DataFormatError(path, "LaSOT split: give test, train, all, ext or a split file "
                                    "(one sequence name per line)")
    return path, True


class LaSOTDataset(SequenceDataset[SOTSequence]):
    """LaSOT: ``<root>/<class>/<class>-<n>/{img/%08d.jpg, groundtruth.txt, ...}``.

    ``absent`` = ``full_occlusion.txt`` OR ``out_of_view.txt`` (one line of comma-separated
    0/1 flags; pytracking's ``target_visible`` is its negation); ``nlp.txt`` is the
    sequence's ``description``. Frames are the sorted ``img/`` images, which must number
    exactly as many as the ground-truth rows. ``split``: ``"test"`` / ``"train"`` (the
    release's ``testing_set.txt`` / ``training_set.txt``), ``"all"`` or ``"ext"`` (every
    sequence found), or a split file's path; default: ``testing_set.txt`` when the root has
    one, else every sequence.
    """

    def __init__(self, root: str | Path, split: str | Path | None = None) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DataFormatError(self.root, "LaSOT root folder missing")
        found = {
            seq.name: seq
            for cls in sorted(self.root.iterdir()) if cls.is_dir()
            for seq in sorted(cls.iterdir()) if (seq / "groundtruth.txt").is_file()
        }
        split_file, required = _split_names(self.root, split)
        if split_file is not None:
            if required and not split_file.is_file():
                raise DataFormatError(split_file, f"LaSOT split '{split}' needs this file")
            wanted = [s.strip() for s in split_file.read_text().splitlines() if s.strip()]
            missing = [s for s in wanted if s not in found]
            if missing:
                raise DataFormatError(split_file, f"lists sequences not under {self.root}: "
                                      f"{', '.join(missing[:5])}")
            found = {s: found[s] for s in wanted}
        if not found:
            raise DataFormatError(self.root, "no <class>/<sequence>/groundtruth.txt found")
        self._dirs = found
        self.sequence_names: list[str] = list(found)

    def load(self, name: str) -> SOTSequence:
        """Read one sequence; DataFormatError naming the file when it cannot be played."""
        if name not in self._dirs:
            raise UnknownSequenceError(f"no LaSOT sequence '{name}' in {self.root}")
        seq = self._dirs[name]
        boxes = read_box_file(seq / "groundtruth.txt")
        _check_boxes(seq / "groundtruth.txt", boxes, 0)
        images = numbered_images(seq / "img")
        numbers = sorted(images)
        if len(numbers) != len(boxes):
            raise DataFormatError(
                seq / "groundtruth.txt",
                f"has {len(boxes)} rows but img/ holds {len(numbers)} frames",
            )
        absent = np.zeros(len(boxes), dtype=bool)
        for flag_file in ("full_occlusion.txt", "out_of_view.txt"):
            if (seq / flag_file).is_file():
                absent |= read_flags(seq / flag_file, len(boxes))
        nlp = seq / "nlp.txt"
        description = nlp.read_text(encoding="utf-8-sig").strip() if nlp.is_file() else ""
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           absent, "LaSOT", description)


#: The synthetic LaSOT default: class, sequence number, scene, split. Each target is
#: flagged fully occluded where less than a quarter of it is visible (the absent-frame rule).
_SCENE = {"num_objects": 3, "num_crossings": 1, "num_static_persons": 0, "num_occluders": 1,
          "object_height_range": (60.0, 100.0), "speed_range": (1.0, 2.5)}
SYNTHETIC_LASOT = (
    ("walker", 1, SceneConfig(width=320, height=240, num_frames=36, seed=0, **_SCENE), "test"),
    ("walker", 2, SceneConfig(width=320, height=240, num_frames=30, seed=10, **_SCENE), "test"),
    ("crosser", 1, SceneConfig(width=360, height=240, num_frames=24, seed=4, **_SCENE), "train"),
)
#: Visibility below which the synthetic target is flagged in ``full_occlusion.txt``.
OCCLUDED_BELOW = 0.25


def _flags(values: np.ndarray) -> str:
    return ",".join(str(int(v)) for v in values) + "\n"


def write_synthetic_lasot(root: Path, benchmark: str = "LaSOT") -> None:
    """Write :data:`SYNTHETIC_LASOT` in LaSOT's exact layout (split files included)."""
    splits: dict[str, list[str]] = {"test": [], "train": []}
    for cls, number, scene, split in SYNTHETIC_LASOT:
        images, boxes, visibility = render_target(scene)
        folder = Path(root) / cls / f"{cls}-{number}"
        write_images(folder / "img", images, [f"{i + 1:08d}.jpg" for i in range(len(images))])
        (folder / "groundtruth.txt").write_text(
            "".join(",".join(f"{v:.0f}" for v in row) + "\n" for row in boxes))
        occluded = visibility < OCCLUDED_BELOW
        occluded[0] = False
        (folder / "full_occlusion.txt").write_text(_flags(occluded))
        (folder / "out_of_view.txt").write_text(_flags(np.zeros(len(boxes))))
        (folder / "nlp.txt").write_text(f"synthetic person walking, the {cls} of the scene")
        splits[split].append(folder.name)
    for split, names in splits.items():
        (Path(root) / LASOT_SPLIT_FILES[split]).write_text("\n".join(names) + "\n")


def synthetic_lasot_frames(benchmark: str = "LaSOT", split: str | None = None,
                           ) -> dict[str, int]:
    """Frames of each synthetic sequence of ``split`` (default: test), known before writing."""
    wanted = split or "test"
    return {f"{cls}-{number}": scene.num_frames for cls, number, scene, s in SYNTHETIC_LASOT
            if wanted in LASOT_ALL or s == wanted}


#: LaSOT's embedded synthetic default (a generator of :mod:`~unitrack_env.datasets.synthetic`).
LASOT_SYNTHETIC = SyntheticKind("lasot", write_synthetic_lasot, ("LaSOT",),
                                synthetic_lasot_frames)


def read_cover(path: Path, expected: int) -> np.ndarray:
    """GOT-10k's ``cover.label``: one integer 0-8 per frame (the visible eighths of the target)."""
    tokens = path.read_text(encoding="utf-8-sig").split()
    if len(tokens) != expected:
        raise DataFormatError(path, f"has {len(tokens)} labels, expected {expected} (one a frame)")
    for line, token in enumerate(tokens, start=1):
        if not (token.isdigit() and int(token) <= 8):
            raise DataFormatError(path, f"cover must be an integer 0-8, not {token!r}", line=line)
    return np.array([int(t) for t in tokens])


class GOT10kDataset(SequenceDataset[SOTSequence]):
    """GOT-10k: ``<root>/<split>/list.txt`` and ``<split>/<seq>/`` with its files.

    Each sequence: ``%08d.jpg``, ``groundtruth.txt``, ``absence.label``, ``cover.label``,
    ``cut_by_image.label`` (read and checked), ``meta_info.ini`` (not read).
    ``absent`` = ``absence.label`` OR ``cover.label == 0``: the frames GOT-10k's toolkit
    leaves out (it scores frames with ``cover > 0``). On the test split ``groundtruth.txt``
    holds only the first frame's box; the other rows are NaN and
    :attr:`SOTSequence.has_ground_truth` is False.
    """

    def __init__(self, root: str | Path, split: str = "val") -> None:
        self.split_dir = Path(root) / split
        if not self.split_dir.is_dir():
            raise DataFormatError(self.split_dir, "GOT-10k split folder missing")
        listing = self.split_dir / "list.txt"
        if listing.is_file():
            lines = listing.read_text().splitlines()
            names = [s.strip() for number, s in enumerate(lines, start=1)
                     if s.strip() and path_inside(self.split_dir, s.strip(), listing, line=number)]
            missing = [n for n in names if not (self.split_dir / n).is_dir()]
            if missing:
                raise DataFormatError(listing, f"lists sequences with no folder: "
                                      f"{', '.join(missing[:5])}")
        else:
            names = sorted(p.name for p in self.split_dir.iterdir()
                           if (p / "groundtruth.txt").is_file())
        if not names:
            raise DataFormatError(self.split_dir, "no <seq>/groundtruth.txt found")
        self.sequence_names: list[str] = names

    def load(self, name: str) -> SOTSequence:
        """Read one sequence; DataFormatError naming the file when it cannot be played."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(f"no GOT-10k sequence '{name}' in {self.split_dir}")
        seq = self.split_dir / name
        images = numbered_images(seq)
        numbers = sorted(images)
        boxes = read_box_file(seq / "groundtruth.txt")
        _check_boxes(seq / "groundtruth.txt", boxes, 0)
        if len(boxes) == 1 and len(numbers) > 1:  # test split: first frame only
            boxes = np.vstack([boxes, np.full((len(numbers) - 1, 4), np.nan)])
        if len(boxes) != len(numbers):
            raise DataFormatError(
                seq / "groundtruth.txt",
                f"has {len(boxes)} rows but the folder holds {len(numbers)} frames",
            )
        absent = np.zeros(len(numbers), dtype=bool)
        if (seq / "absence.label").is_file():
            absent = read_flags(seq / "absence.label", len(numbers))
        if (seq / "cover.label").is_file():
            absent = absent | (read_cover(seq / "cover.label", len(numbers)) == 0)
        if (seq / "cut_by_image.label").is_file():
            read_flags(seq / "cut_by_image.label", len(numbers))
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           absent, "GOT-10k")


#: The synthetic GOT-10k default: split, name, scene. Cover is the visible eighths of the
#: target (0 where less than 1/16 shows, absence.label 1 there); test keeps the first box.
SYNTHETIC_GOT10K = (
    ("val", "GOT-10k_Val_000001", SceneConfig(width=320, height=240, num_frames=30, seed=10,
                                              **_SCENE)),
    ("val", "GOT-10k_Val_000002", SceneConfig(width=320, height=240, num_frames=24, seed=0,
                                              **_SCENE)),
    ("test", "GOT-10k_Test_000001", SceneConfig(width=360, height=240, num_frames=24, seed=4,
                                                **_SCENE)),
)


def write_synthetic_got10k(root: Path, benchmark: str = "GOT-10k") -> None:
    """Write :data:`SYNTHETIC_GOT10K` in GOT-10k's exact layout (``list.txt`` per split)."""
    lists: dict[str, list[str]] = {"val": [], "test": []}
    for split, name, scene in SYNTHETIC_GOT10K:
        images, boxes, visibility = render_target(scene)
        folder = Path(root) / split / name
        write_images(folder, images, [f"{i + 1:08d}.jpg" for i in range(len(images))])
        rows = [",".join(f"{v:.4f}" for v in row) for row in boxes - [1, 1, 0, 0]]
        (folder / "groundtruth.txt").write_text("\n".join(rows[:1] if split == "test" else rows)
                                               + "\n")
        lists[split].append(name)
        if split == "test":  # the release's test sequences carry no labels
            continue
        cover = np.round(visibility * 8).astype(int)
        cover[0] = max(cover[0], 1)
        (folder / "cover.label").write_text("".join(f"{c}\n" for c in cover))
        (folder / "absence.label").write_text("".join(f"{int(c == 0)}\n" for c in cover))
        (folder / "cut_by_image.label").write_text("0\n" * len(cover))
        (folder / "meta_info.ini").write_text(
            f"[METAINFO]\nobject_class: person\nresolution: ({scene.width}, {scene.height})\n")
    for split, names in lists.items():
        (Path(root) / split / "list.txt").write_text("\n".join(names) + "\n")


def synthetic_got10k_frames(benchmark: str = "GOT-10k", split: str | None = None,
                            ) -> dict[str, int]:
    """Frames of each annotated synthetic sequence (val; test has only its first box)."""
    return {name: scene.num_frames for s, name, scene in SYNTHETIC_GOT10K if s == "val"}


#: GOT-10k's embedded synthetic default.
GOT10K_SYNTHETIC = SyntheticKind("got10k", write_synthetic_got10k, ("GOT-10k",),
                                 synthetic_got10k_frames)

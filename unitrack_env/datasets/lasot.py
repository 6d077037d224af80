"""LaSOT and GOT-10k readers (layouts in :mod:`unitrack_env.datasets.otb`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.sot import (
    SOTSequence,
    numbered_images,
    read_box_file,
    read_flags,
    read_image_size,
)
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.io import path_inside


class LaSOTDataset(SequenceDataset[SOTSequence]):
    """LaSOT: ``<root>/<class>/<class>-<n>/{img/*.jpg, groundtruth.txt, ...}``.

    ``absent`` = ``full_occlusion.txt`` OR ``out_of_view.txt`` (pytracking's
    ``target_visible`` is its negation). Frames are the sorted ``img/`` images, which must
    number exactly as many as the ground-truth rows. ``split_file`` (e.g. the official
    ``testing_set.txt``) lists the sequences to read, one per line.
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

    def load(self, name: str) -> SOTSequence:
        """Read one sequence."""
        if name not in self._dirs:
            raise UnknownSequenceError(f"no LaSOT sequence '{name}' in {self.root}")
        seq = self._dirs[name]
        boxes = read_box_file(seq / "groundtruth.txt")
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
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           absent, "LaSOT")


class GOT10kDataset(SequenceDataset[SOTSequence]):
    """GOT-10k: ``<root>/<split>/<seq>/{*.jpg, groundtruth.txt, absence.label}``.

    On the test split ``groundtruth.txt`` holds only the first frame's box; the other rows
    are NaN and :attr:`SOTSequence.has_ground_truth` is False.
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
        else:
            names = sorted(p.name for p in self.split_dir.iterdir()
                           if (p / "groundtruth.txt").is_file())
        if not names:
            raise DataFormatError(self.split_dir, "no <seq>/groundtruth.txt found")
        self.sequence_names: list[str] = names

    def load(self, name: str) -> SOTSequence:
        """Read one sequence."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(f"no GOT-10k sequence '{name}' in {self.split_dir}")
        seq = self.split_dir / name
        images = numbered_images(seq)
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
            absent = read_flags(seq / "absence.label", len(numbers))
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           absent, "GOT-10k")

"""UAV123 and UAV20L reader (``data_seq/UAV123[_10fps]/<seq>/%06d.jpg``, ``anno/...``)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.otb import _check_boxes
from unitrack_env.datasets.sot import (
    SOTSequence,
    numbered_images,
    read_box_file,
    read_image_size,
    select_frames,
)
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.otb import render_target, write_images
from unitrack_env.datasets.synthetic.scene_model import SceneConfig
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: ``variant=`` -> the release's folder name under ``data_seq/`` and ``anno/``.
UAV123_VARIANTS = {"30fps": "UAV123", "10fps": "UAV123_10fps"}
#: ``split=`` values: UAV123 (123 sequences) or UAV20L (20 long ones, ``anno/UAV20L/``, frames
#: in ``data_seq/UAV123/``; no 10 fps release).
UAV123_SPLITS = ("UAV123", "UAV20L")
#: UAV123's sub-sequences ``<folder>_<k>``: the 30 fps frame range (first, last) of each part
#: of a video folder, the facts of the UAV123 toolkit's ``configSeqs.m`` as the ``got10k``
#: package's ``datasets/uav123.json`` and pytracking's ``uavdataset.py`` carry them. At 10 fps,
#: 30 fps frame ``f`` is frame ``(f - 1) // 3 + 1`` (every bound is 1 modulo 3, and the
#: UAV123_10fps lists give these numbers, e.g. person12_2 201-541, uav1_3 825-1157).
UAV123_SUBSEQUENCES: dict[str, tuple[tuple[int, int], ...]] = {
    "bird1": ((1, 253), (775, 1477), (1573, 2437)),
    "car1": ((1, 751), (751, 1627), (1627, 2629)),
    "car6": ((1, 487), (487, 1807), (1807, 2953), (2953, 3925), (3925, 4861)),
    "car8": ((1, 1357), (1357, 2575)),
    "car16": ((1, 415), (415, 1993)),
    "group1": ((1, 1333), (1333, 2515), (2515, 3925), (3925, 4873)),
    "group2": ((1, 907), (907, 1771), (1771, 2683)),
    "group3": ((1, 1567), (1567, 2827), (2827, 4369), (4369, 5527)),
    "person2": ((1, 1189), (1189, 2623)),
    "person4": ((1, 1501), (1501, 2743)),
    "person5": ((1, 877), (877, 2101)),
    "person7": ((1, 1249), (1249, 2065)),
    "person8": ((1, 1075), (1075, 1525)),
    "person12": ((1, 601), (601, 1621)),
    "person14": ((1, 847), (847, 1813), (1813, 2923)),
    "person17": ((1, 1501), (1501, 2347)),
    "person19": ((1, 1243), (1243, 2791), (2791, 4357)),
    "truck4": ((1, 577), (577, 1261)),
    "uav1": ((1, 1555), (1555, 2377), (2473, 3469)),
}
#: An annotation named like a sub-sequence (``<folder>_<k>``).
_SUBSEQUENCE = re.compile(r"^(.+)_(\d+)$")


def subsequence_range(name: str, folder: str) -> tuple[str, range] | None:
    """``(video folder, frame numbers)`` of sub-sequence ``name`` in release ``folder``.

    None when ``name`` is not one of :data:`UAV123_SUBSEQUENCES`' parts.
    """
    match = _SUBSEQUENCE.match(name)
    parts = UAV123_SUBSEQUENCES.get(match.group(1), ()) if match else ()
    if not match or not 1 <= int(match.group(2)) <= len(parts):
        return None
    first, last = parts[int(match.group(2)) - 1]
    if folder == UAV123_VARIANTS["10fps"]:
        first, last = (first - 1) // 3 + 1, (last - 1) // 3 + 1
    return match.group(1), range(first, last + 1)


class UAV123Dataset(SequenceDataset[SOTSequence]):
    """UAV123: ``<root>/data_seq/<V>/<seq>/%06d.jpg`` and ``<root>/anno/<A>/<seq>.txt``.

    ``<V>`` is ``UAV123`` (``variant="30fps"``, default) or ``UAV123_10fps`` (``"10fps"``);
    when only one of them is present it is read. ``<A>`` is ``<V>``, or ``UAV20L`` with
    ``split="UAV20L"`` (frames from ``data_seq/UAV123``). A NaN annotation row is a frame where
    the target is absent (``absent``). A sub-sequence (``person12_1``) plays its frame range
    of its video's folder (:data:`UAV123_SUBSEQUENCES`); another annotation without a frame
    folder whose name ends in ``_<k>`` is skipped with a warning.
    """

    def __init__(self, root: str | Path, variant: str | None = None,
                 split: str | None = None) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DataFormatError(self.root, "UAV123 root folder missing")
        self.split = split or "UAV123"
        if self.split not in UAV123_SPLITS:
            raise ValueError(f"UAV123 split {split!r}; valid: {', '.join(UAV123_SPLITS)}")
        if self.split == "UAV20L" and variant not in (None, "30fps"):
            raise ValueError("UAV20L has no 10 fps release; drop variant= or use split=UAV123")
        self.folder = "UAV123" if self.split == "UAV20L" else self._variant_folder(variant)
        anno = self.root / "anno" / ("UAV20L" if self.split == "UAV20L" else self.folder)
        self._files: dict[str, tuple[Path, Path, range | None]] = {}
        skipped = []
        for path in sorted(anno.glob("*.txt")):
            frames, numbers = self.root / "data_seq" / self.folder / path.stem, None
            known = subsequence_range(path.stem, self.folder)
            if known is not None:
                frames, numbers = frames.parent / known[0], known[1]
            if frames.is_dir():
                self._files[path.stem] = (path, frames, numbers)
            elif known is None and _SUBSEQUENCE.match(path.stem):
                skipped.append(path.stem)
            else:
                raise DataFormatError(path, f"no frame folder {frames}")
        if skipped:
            warnings.warn(f"{anno}: {', '.join(skipped[:5])} skipped (named like sub-sequences "
                          "but not among UAV123's, and no frame folder)", stacklevel=2)
        if not self._files:
            raise DataFormatError(anno, "no <seq>.txt annotation with a frame folder found")
        self.sequence_names: list[str] = list(self._files)

    def _variant_folder(self, variant: str | None) -> str:
        if variant is not None:
            if variant not in UAV123_VARIANTS:
                raise ValueError(f"UAV123 variant {variant!r}; valid: "
                                 f"{', '.join(UAV123_VARIANTS)}")
            return UAV123_VARIANTS[variant]
        present = [f for f in UAV123_VARIANTS.values() if (self.root / "anno" / f).is_dir()]
        if not present:
            raise DataFormatError(self.root / "anno", "no anno/UAV123 or anno/UAV123_10fps folder")
        return present[0]

    def load(self, name: str) -> SOTSequence:
        """Read one sequence; DataFormatError naming the file when it cannot be played."""
        if name not in self._files:
            raise UnknownSequenceError(f"no UAV123 sequence '{name}' in {self.root}")
        gt, folder, numbers = self._files[name]
        boxes = read_box_file(gt)
        _check_boxes(gt, boxes, 0)
        if numbers is None:
            images = numbered_images(folder)
            if len(images) != len(boxes):
                raise DataFormatError(gt, f"has {len(boxes)} rows but the frame folder holds "
                                          f"{len(images)} frames")
            numbers = sorted(images)
            frames = tuple(images[n] for n in numbers)
        else:
            if len(numbers) != len(boxes):
                raise DataFormatError(gt, f"has {len(boxes)} rows but the sub-sequence is frames "
                                          f"{numbers.start}-{numbers.stop - 1} of {folder}")
            frames = select_frames(folder, numbers)
        release = "UAV20L" if self.split == "UAV20L" else self.folder
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           np.isnan(boxes).any(axis=1), release)


_SCENE = {"num_objects": 3, "num_crossings": 1, "num_static_persons": 0, "num_occluders": 1,
          "object_height_range": (40.0, 70.0), "speed_range": (1.0, 2.5)}
#: The synthetic default: name, scene. Frames where less than a quarter of the target is
#: visible get a NaN row (UAV123's absent target); the 10 fps copy keeps every third frame.
SYNTHETIC_UAV123 = (
    ("synperson1", SceneConfig(width=360, height=240, num_frames=36, seed=0, **_SCENE)),
    ("synperson2", SceneConfig(width=320, height=240, num_frames=30, seed=10, **_SCENE)),
)
#: Visibility below which a synthetic row is written as NaN.
ABSENT_BELOW = 0.25


def write_synthetic_uav123(root: Path, benchmark: str = "UAV123") -> None:
    """Write :data:`SYNTHETIC_UAV123` in UAV123's layout, 30 fps and 10 fps (every third)."""
    for name, scene in SYNTHETIC_UAV123:
        images, boxes, visibility = render_target(scene)
        rows = [",".join(f"{v:.0f}" for v in row) for row in boxes]
        rows = ["NaN,NaN,NaN,NaN" if i and v < ABSENT_BELOW else row
                for i, (row, v) in enumerate(zip(rows, visibility, strict=True))]
        for folder, step in (("UAV123", 1), ("UAV123_10fps", 3)):
            kept = range(0, len(images), step)
            write_images(Path(root) / "data_seq" / folder / name, [images[i] for i in kept],
                         [f"{k + 1:06d}.jpg" for k in range(len(kept))])
            anno = Path(root) / "anno" / folder / f"{name}.txt"
            anno.parent.mkdir(parents=True, exist_ok=True)
            anno.write_text("".join(rows[i] + "\n" for i in kept))


def synthetic_uav123_frames(benchmark: str = "UAV123", split: str | None = None,
                            ) -> dict[str, int]:
    """Frames of each synthetic 30 fps sequence, known before writing."""
    return {name: scene.num_frames for name, scene in SYNTHETIC_UAV123}


#: UAV123's embedded synthetic default.
UAV123_SYNTHETIC = SyntheticKind("uav123", write_synthetic_uav123, ("UAV123",),
                                 synthetic_uav123_frames)

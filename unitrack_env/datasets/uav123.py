"""UAV123 reader (``data_seq/UAV123[_10fps]/<seq>/%06d.jpg``, ``anno/...``), synthetic default."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.otb import _check_boxes
from unitrack_env.datasets.sot import SOTSequence, numbered_images, read_box_file, read_image_size
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.otb import render_target, write_images
from unitrack_env.datasets.synthetic.scene_model import SceneConfig
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: ``variant=`` -> the release's folder name under ``data_seq/`` and ``anno/``.
UAV123_VARIANTS = {"30fps": "UAV123", "10fps": "UAV123_10fps"}
#: An annotation of a sub-sequence (``person12_1``): its frames are a range of the folder
#: ``person12`` that only the toolkit's ``configSeqs.m`` gives, so such files are skipped.
_SUBSEQUENCE = re.compile(r"^(.+)_(\d+)$")


class UAV123Dataset(SequenceDataset[SOTSequence]):
    """UAV123: ``<root>/data_seq/<V>/<seq>/%06d.jpg`` and ``<root>/anno/<V>/<seq>.txt``.

    ``<V>`` is ``UAV123`` (``variant="30fps"``, default) or ``UAV123_10fps`` (``"10fps"``);
    when only one of them is present it is read. A NaN annotation row is a frame where the
    target is absent (``absent``). An annotation file whose frame folder is missing and whose
    name ends in ``_<k>`` (a sub-sequence of a longer video, ``person12_1``) is skipped with a
    warning: its frame range is in the toolkit's ``configSeqs.m``, not in the release's files.
    """

    def __init__(self, root: str | Path, variant: str | None = None) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise DataFormatError(self.root, "UAV123 root folder missing")
        self.folder = self._variant_folder(variant)
        anno = self.root / "anno" / self.folder
        frames = self.root / "data_seq" / self.folder
        self._files: dict[str, Path] = {}
        skipped = []
        for path in sorted(anno.glob("*.txt")):
            if (frames / path.stem).is_dir():
                self._files[path.stem] = path
            elif _SUBSEQUENCE.match(path.stem):
                skipped.append(path.stem)
            else:
                raise DataFormatError(path, f"no frame folder {frames / path.stem}")
        if skipped:
            warnings.warn(f"{anno}: sub-sequences {', '.join(skipped[:5])} skipped (their frame "
                          "ranges are in the UAV123 toolkit's configSeqs.m)", stacklevel=2)
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
        gt = self._files[name]
        boxes = read_box_file(gt)
        _check_boxes(gt, boxes, 0)
        images = numbered_images(self.root / "data_seq" / self.folder / name)
        numbers = sorted(images)
        if len(numbers) != len(boxes):
            raise DataFormatError(gt, f"has {len(boxes)} rows but the frame folder holds "
                                      f"{len(numbers)} frames")
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           np.isnan(boxes).any(axis=1), self.folder)


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

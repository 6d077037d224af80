"""TrackingNet reader (``TRAIN_<k>/``, ``TEST/`` with ``frames/`` and ``anno/``), synthetic data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.otb import _check_boxes
from unitrack_env.datasets.sot import SOTSequence, numbered_images, read_box_file, read_image_size
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.otb import render_target, write_images
from unitrack_env.datasets.synthetic.scene_model import SceneConfig
from unitrack_env.errors import DataFormatError, UnknownSequenceError


def _chunks(root: Path, split: str) -> list[Path]:
    if split == "test":
        return [root / "TEST"]
    if split == "train":
        return sorted(p for p in root.glob("TRAIN_*") if p.is_dir())
    if split.startswith("TRAIN_"):
        return [root / split]
    raise ValueError(f"TrackingNet split {split!r}; valid: train, test, TRAIN_<k>")


class TrackingNetDataset(SequenceDataset[SOTSequence]):
    """TrackingNet: ``<chunk>/frames/<seq>/<i>.jpg`` (``i`` from 0), ``<chunk>/anno/<seq>.txt``.

    ``split``: ``"train"`` (every ``TRAIN_<k>`` chunk, default), ``"TRAIN_<k>"`` (one chunk)
    or ``"test"`` (``TEST``, whose annotation holds the first box only: the other rows are
    NaN and the sequence has no ground truth; its results are the server's ``<seq>.txt``).
    """

    def __init__(self, root: str | Path, split: str = "train") -> None:
        self.root = Path(root)
        chunks = _chunks(self.root, split)
        self._anno: dict[str, Path] = {}
        for chunk in chunks:
            if not (chunk / "anno").is_dir():
                raise DataFormatError(chunk / "anno", "TrackingNet annotation folder missing")
            for anno in sorted((chunk / "anno").glob("*.txt")):
                if not (chunk / "frames" / anno.stem).is_dir():
                    raise DataFormatError(anno, f"no frame folder {chunk / 'frames' / anno.stem}")
                self._anno[anno.stem] = anno
        if not self._anno:
            raise DataFormatError(self.root, f"no {split} sequence (<chunk>/anno/<seq>.txt)")
        self.sequence_names: list[str] = list(self._anno)

    def load(self, name: str) -> SOTSequence:
        """Read one sequence; DataFormatError naming the file when it cannot be played."""
        if name not in self._anno:
            raise UnknownSequenceError(f"no TrackingNet sequence '{name}' in {self.root}")
        anno = self._anno[name]
        boxes = read_box_file(anno)
        _check_boxes(anno, boxes, 0)
        images = numbered_images(anno.parent.parent / "frames" / name)
        numbers = sorted(images)
        if len(boxes) == 1 and len(numbers) > 1:  # TEST: first frame only
            boxes = np.vstack([boxes, np.full((len(numbers) - 1, 4), np.nan)])
        if len(boxes) != len(numbers):
            raise DataFormatError(anno, f"has {len(boxes)} rows but the frame folder holds "
                                        f"{len(numbers)} frames")
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           np.zeros(len(frames), dtype=bool), "TrackingNet")


_SCENE = {"num_objects": 3, "num_crossings": 1, "num_static_persons": 0, "num_occluders": 1,
          "object_height_range": (60.0, 100.0), "speed_range": (1.0, 2.5)}
#: The synthetic default: chunk, sequence name, scene (TEST keeps the first box only).
SYNTHETIC_TRACKINGNET = (
    ("TRAIN_0", "synwalk_0", SceneConfig(width=320, height=240, num_frames=30, seed=10, **_SCENE)),
    ("TRAIN_1", "synwalk_1", SceneConfig(width=320, height=240, num_frames=24, seed=0, **_SCENE)),
    ("TEST", "syntest_0", SceneConfig(width=360, height=240, num_frames=24, seed=4, **_SCENE)),
)


def write_synthetic_trackingnet(root: Path, benchmark: str = "TrackingNet") -> None:
    """Write :data:`SYNTHETIC_TRACKINGNET` in TrackingNet's layout (0-based boxes)."""
    for chunk, name, scene in SYNTHETIC_TRACKINGNET:
        images, boxes, _ = render_target(scene)
        write_images(Path(root) / chunk / "frames" / name, images,
                     [f"{i}.jpg" for i in range(len(images))])
        rows = [",".join(f"{v:.2f}" for v in row) for row in boxes - [1, 1, 0, 0]]
        anno = Path(root) / chunk / "anno" / f"{name}.txt"
        anno.parent.mkdir(parents=True, exist_ok=True)
        anno.write_text("\n".join(rows[:1] if chunk == "TEST" else rows) + "\n")


def synthetic_trackingnet_frames(benchmark: str = "TrackingNet", split: str | None = None,
                                 ) -> dict[str, int]:
    """Frames of each annotated (TRAIN) synthetic sequence, known before writing."""
    return {n: s.num_frames for c, n, s in SYNTHETIC_TRACKINGNET if c != "TEST"}


#: TrackingNet's embedded synthetic default.
TRACKINGNET_SYNTHETIC = SyntheticKind("trackingnet", write_synthetic_trackingnet,
                                      ("TrackingNet",), synthetic_trackingnet_frames)

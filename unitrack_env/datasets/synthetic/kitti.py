"""A synthetic KITTI tracking split in the exact layout, with detections in the result format.

Two 16-frame sequences (``0000``, ``0001``) of 480x144 PNGs: cars and pedestrians (flat
coloured boxes on a textured road) moving across, a Van (a distractor for Car), a truncated
car at the border, a DontCare region, and per-frame detections of every Car, Van and
Pedestrian with deterministic jitter and one false positive every third frame.
``training/{image_02/<seq>/%06d.png, label_02/<seq>.txt, det_02/<seq>.txt,
evaluate_tracking.seqmap.training}``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.cache import SyntheticKind

BENCHMARKS = ("KITTI",)
SEQUENCES = ("0000", "0001")
FRAMES = 16
WIDTH, HEIGHT = 480, 144
#: Objects: ``(track id, type, start x, y, w, h, dx per frame, truncated, colour)``.
_OBJECTS = (
    (0, "Car", 20.0, 60.0, 70.0, 40.0, 9.0, 0, (40, 40, 200)),
    (1, "Pedestrian", 400.0, 40.0, 18.0, 50.0, -4.0, 0, (40, 200, 40)),
    (2, "Van", 200.0, 70.0, 80.0, 45.0, 3.0, 0, (200, 160, 40)),
    (3, "Car", -30.0, 95.0, 70.0, 40.0, 0.0, 1, (120, 40, 160)),
    (4, "Pedestrian", 150.0, 30.0, 16.0, 48.0, 5.0, 0, (220, 220, 60)),
)
_DONTCARE = (300.0, 10.0, 360.0, 40.0)


def _box(obj: tuple, frame: int, shift: float) -> tuple[float, float, float, float]:
    _, _, x, y, w, h, dx, _, _ = obj
    x1 = max(0.0, x + dx * frame + shift)
    x2 = min(WIDTH - 1.0, x + dx * frame + shift + w)
    return x1, y, x2, y + h


def _row(frame: int, track: int, kind: str, truncated: int, box: tuple, score: str = "") -> str:
    x1, y1, x2, y2 = box
    occluded = -1 if kind == "DontCare" else 0
    return (f"{frame} {track} {kind} {truncated} {occluded} -10.000000 {x1:.2f} {y1:.2f} "
            f"{x2:.2f} {y2:.2f} -1000.0 -1000.0 -1000.0 -10.0 -1.0 -1.0 -1.0{score}\n")


def _sequence(folder: Path, name: str, index: int) -> None:
    rng = np.random.default_rng(40 + index)
    texture = rng.integers(70, 110, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    labels, detections = [], []
    images = folder / "image_02" / name
    images.mkdir(parents=True, exist_ok=True)
    for frame in range(FRAMES):
        image = texture.copy()
        labels.append(_row(frame, -1, "DontCare", -1, _DONTCARE))
        for obj in _OBJECTS:
            track, kind, truncated, colour = obj[0], obj[1], obj[7], obj[8]
            box = _box(obj, frame, 13.0 * index)
            if box[2] - box[0] < 4:
                continue
            x1, y1, x2, y2 = (int(round(v)) for v in box)
            cv2.rectangle(image, (x1, y1), (x2, y2), colour, thickness=-1)
            labels.append(_row(frame, track, kind, truncated, box))
            jitter = rng.normal(0.0, 1.5, 4)
            detected = tuple(float(v) for v in np.asarray(box) + jitter)
            detections.append(_row(frame, -1, "Car" if kind == "Van" else kind, 0, detected,
                                   f" {0.6 + 0.35 * rng.random():.4f}"))
        if frame % 3 == 0:
            detections.append(_row(frame, -1, "Car", 0, (10.0, 10.0, 50.0, 45.0), " 0.3500"))
        cv2.imwrite(str(images / f"{frame:06d}.png"), image)
    for sub, rows in (("label_02", labels), ("det_02", detections)):
        (folder / sub).mkdir(parents=True, exist_ok=True)
        (folder / sub / f"{name}.txt").write_text("".join(rows))


def write_kitti(root: Path, benchmark: str = "KITTI") -> None:
    """Write the synthetic split under ``root/training``."""
    folder = Path(root) / "training"
    for index, name in enumerate(SEQUENCES):
        _sequence(folder, name, index)
    (folder / "evaluate_tracking.seqmap.training").write_text(
        "".join(f"{name} empty 000000 {FRAMES:06d}\n" for name in SEQUENCES))


def annotated_frames(benchmark: str, split: str | None = None) -> dict[str, int]:
    """The frames of each annotated sequence."""
    return dict.fromkeys(SEQUENCES, FRAMES)


KIND = SyntheticKind("kitti", write_kitti, BENCHMARKS, annotated_frames)

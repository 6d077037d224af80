"""PoseTrack 2018 records: the keypoint layout, the id scheme and one video's JSON entries.

The file format these records mirror is described in :mod:`unitrack_env.datasets.posetrack`;
:mod:`unitrack_env.datasets.posetrack_json` reads and writes them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

POSETRACK_KEYPOINTS: tuple[str, ...] = (
    "nose", "head_bottom", "head_top", "left_ear", "right_ear",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
    "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
    "right_ankle",
)
"""The 17 PoseTrack 2018 keypoints in file order (categories[0]["keypoints"])."""

NUM_KEYPOINTS: int = len(POSETRACK_KEYPOINTS)

POSETRACK_SKELETON: tuple[tuple[int, int], ...] = (
    (16, 14), (14, 12), (17, 15), (15, 13), (12, 13), (6, 12), (7, 13), (6, 7), (6, 8),
    (7, 9), (8, 10), (9, 11), (2, 3), (1, 2), (1, 3), (2, 4), (3, 5), (4, 6), (5, 7),
)
"""Limbs as 1-based keypoint pairs, as in the release's ``categories[0]["skeleton"]``."""

#: The ``categories`` entry written into every file.
PERSON_CATEGORY: dict[str, Any] = {
    "supercategory": "person",
    "id": 1,
    "name": "person",
    "keypoints": list(POSETRACK_KEYPOINTS),
    "skeleton": [list(pair) for pair in POSETRACK_SKELETON],
}

#: Splits of the release; ``test`` ships images only.
SPLITS: tuple[str, ...] = ("train", "val", "test")
#: Sub-folder holding the benchmark files.
DATA_FOLDER = "posetrack_data"
#: Image id of frame ``k`` of video ``v``: ``IMAGE_ID_BASE + v * FRAMES_PER_VIDEO + k``.
IMAGE_ID_BASE = 10_000_000_000
#: Frame slots per video in the image id scheme.
FRAMES_PER_VIDEO = 10_000
#: Annotation id of person ``p`` of image ``i``: ``i * PERSONS_PER_IMAGE + p``.
PERSONS_PER_IMAGE = 100

@dataclass
class PoseTrackImage:
    """One frame entry of ``images`` (``file_name`` relative to ``posetrack_data/``).

    ``is_labeled`` is None when the entry does not say; ``nframes`` may exceed the frames
    present; ``ignore_regions`` are ``(k, 2)`` polygons (crowds) where evaluation drops
    keypoints; ``extra`` keeps every other field.
    """

    id: int
    file_name: str
    is_labeled: bool | None = None
    nframes: int | None = None
    frame_id: int | None = None
    vid_id: str | None = None
    ignore_regions: tuple[np.ndarray, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def frame_index(self) -> int:
        """The 0-based frame index from the file name (``000012.jpg`` -> 12)."""
        return int(Path(self.file_name).stem)


@dataclass
class PoseTrackPerson:
    """One person (annotation) in one frame.

    ``keypoints`` ``(17, 3)`` ``(x, y, v)`` with ``(0, 0, 0)`` absent; ``track_id`` None in
    detection files; ``scores`` None when absent (ground truth's empty list stays empty);
    ``bbox_head`` is the PCKh reference; ``extra`` keeps every other field.
    """

    image_id: int
    keypoints: np.ndarray
    track_id: int | None = None
    scores: np.ndarray | None = None
    score: float | None = None
    bbox: tuple[float, float, float, float] | None = None
    bbox_head: tuple[float, float, float, float] | None = None
    id: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def annotated(self) -> np.ndarray:
        """``(17,)`` bool: keypoints that are not ``(0, 0, 0)`` (poseval's rule)."""
        return ~np.all(self.keypoints == 0.0, axis=1)


@dataclass
class PoseTrackVideo:
    """The content of one sequence file: images, per image its people, categories, other fields."""

    images: list[PoseTrackImage]
    people: list[list[PoseTrackPerson]]
    categories: list[dict[str, Any]] = field(default_factory=lambda: [dict(PERSON_CATEGORY)])
    extra: dict[str, Any] = field(default_factory=dict)


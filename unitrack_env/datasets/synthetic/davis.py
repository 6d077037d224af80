"""Synthetic DAVIS-2017 data set: several people per sequence, segmented, crossing and occluded.

:func:`write_davis` writes the DAVIS-2017 semi-supervised layout: ``JPEGImages/480p``,
``Annotations/480p`` (palette PNGs) and ``ImageSets/2017/{train,val,test-dev}.txt``; the
folders keep DAVIS's ``480p`` name although the frames are smaller (any size is read).
The labelled objects are the first walking people visible in frame 0 by scene id, so the
pair forced to cross (which occlude each other) comes first; labels come from the instance
map after occlusion. As in DAVIS, a void band (255) may mark label borders and a test-dev
sequence ships only its first annotation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.davis import DAVIS_VOID_LABEL, write_label_png
from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneConfig

#: Benchmarks whose layout :func:`write_davis` writes.
BENCHMARKS = ("DAVIS-2017",)
#: Resolution folder of the written frames and annotations.
RESOLUTION = "480p"
#: ``ImageSets`` sub-folder.
YEAR = "2017"
#: JPEG quality of the frames.
JPEG_QUALITY = 90
#: Digits of DAVIS frame file names (``00000.jpg``).
FRAME_DIGITS = 5
#: Splits whose sequences are annotated in every frame (test-dev: first frame only).
SPLITS_WITH_GROUND_TRUTH = frozenset({"train", "val"})
#: An object must show at least this many pixels in frame 0 to be a target.
MIN_FIRST_FRAME_PIXELS = 300
#: Scene parameters shared by the default sequences.
_SCENE = {
    "width": 432,
    "height": 240,
    "num_objects": 4,
    "num_crossings": 1,
    "num_static_persons": 1,
    "num_occluders": 1,
    "object_height_range": (70.0, 120.0),
    "speed_range": (1.0, 3.0),
}


@dataclass(frozen=True)
class SyntheticDAVISSequence:
    """One synthetic DAVIS sequence (``void_border``: half-width of the void band, 0 = none)."""

    name: str
    split: str
    scene: SceneConfig
    num_objects: int = 2
    void_border: int = 0


@dataclass(frozen=True)
class DAVISSpec:
    """A synthetic DAVIS data set: its sequences."""

    sequences: tuple[SyntheticDAVISSequence, ...]


DEFAULT_SPEC = DAVISSpec(sequences=(
    SyntheticDAVISSequence("syn-crossing", "val", SceneConfig(num_frames=30, seed=1, **_SCENE),
                           num_objects=3, void_border=1),
    SyntheticDAVISSequence("syn-occluded", "val", SceneConfig(num_frames=24, seed=4, **_SCENE),
                           num_objects=3),
    SyntheticDAVISSequence("syn-walk", "train", SceneConfig(num_frames=20, seed=2, **_SCENE),
                           num_objects=2),
    SyntheticDAVISSequence("syn-test", "test-dev", SceneConfig(num_frames=12, seed=5, **_SCENE),
                           num_objects=2),
))
"""The embedded default: two val, one train and one test-dev sequence."""


def annotated_frames(benchmark: str = "DAVIS-2017", split: str | None = None,
                     spec: DAVISSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each sequence of ``split`` (None: any) annotated in every frame.

    Known without writing anything, e.g. to plan work on data not generated yet.
    """
    return {s.name: s.scene.num_frames for s in spec.sequences
            if s.split in SPLITS_WITH_GROUND_TRUTH and split in (None, s.split)}


def choose_objects(video: SyntheticVideo, count: int) -> tuple[int, ...]:
    """Return the scene ids of the ``count`` labelled objects (walkers visible in frame 0)."""
    first = video.frame(0)
    visible = [a.id for a in first.objects
               if a.role is ObjectRole.PEDESTRIAN and a.visible_pixels >= MIN_FIRST_FRAME_PIXELS]
    if len(visible) < count:
        raise ValueError(
            f"scene seed {video.config.seed}: only {len(visible)} walking people are visible in "
            f"frame 0, {count} requested"
        )
    return tuple(sorted(visible)[:count])


def label_map(instance_map: np.ndarray, objects: tuple[int, ...], void_border: int = 0
              ) -> np.ndarray:
    """Turn a scene instance map into a uint8 DAVIS label map (``objects[k]`` -> ``k + 1``)."""
    lookup = np.zeros(int(instance_map.max(initial=0)) + 1, dtype=np.uint8)
    for label, object_id in enumerate(objects, start=1):
        if object_id < len(lookup):
            lookup[object_id] = label
    labels = lookup[instance_map]
    if void_border > 0:
        kernel = np.ones((2 * void_border + 1, 2 * void_border + 1), np.uint8)
        band = cv2.dilate(labels, kernel) != cv2.erode(labels, kernel)
        labels[band] = DAVIS_VOID_LABEL
    return labels


def write_sequence(root: Path, sequence: SyntheticDAVISSequence) -> None:
    """Render one sequence's frames and annotations into the DAVIS layout under ``root``."""
    video = render_scene(sequence.scene)
    objects = choose_objects(video, sequence.num_objects)
    images = Path(root) / "JPEGImages" / RESOLUTION / sequence.name
    annotations = Path(root) / "Annotations" / RESOLUTION / sequence.name
    images.mkdir(parents=True, exist_ok=True)
    annotated = sequence.split in SPLITS_WITH_GROUND_TRUTH
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]
    for frame in video:
        stem = f"{frame.index:0{FRAME_DIGITS}d}"
        path = images / f"{stem}.jpg"
        if not cv2.imwrite(str(path), cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR), params):
            raise OSError(f"could not write {path}")
        if annotated or frame.index == 0:
            write_label_png(annotations / f"{stem}.png",
                            label_map(frame.instance_map, objects, sequence.void_border))


def write_davis(root: Path, benchmark: str = "DAVIS-2017", spec: DAVISSpec = DEFAULT_SPEC
                ) -> None:
    """Write the synthetic DAVIS data set of ``spec`` into ``root`` (``benchmark="DAVIS-2017"``)."""
    if benchmark not in BENCHMARKS:
        raise ValueError(f"write_davis writes {BENCHMARKS}, not {benchmark!r}")
    splits: dict[str, list[str]] = {}
    for sequence in spec.sequences:
        if sequence.name in {n for names in splits.values() for n in names}:
            raise ValueError(f"sequence name {sequence.name!r} is used twice")
        write_sequence(Path(root), sequence)
        splits.setdefault(sequence.split, []).append(sequence.name)
    sets = Path(root) / "ImageSets" / YEAR
    sets.mkdir(parents=True, exist_ok=True)
    for split, names in splits.items():
        (sets / f"{split}.txt").write_text("".join(f"{n}\n" for n in names))

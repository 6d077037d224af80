"""Synthetic YouTube-VIS 2019 data sets.

:func:`write_youtube_vis` writes ``train.json``/``valid.json``, frames under
``{train,valid}/JPEGImages/<video>/`` (every-5th numbering, as the 2019 release) and noisy
detections in ``detections/{train,valid}.json``. Person masks are the visible pixels of the
rendered instance map as compressed RLE; the occluder's are polygons (its visible
rectangle), so the reader's polygon path is exercised. Detections come from
:func:`~unitrack_env.datasets.synthetic.mots.simulate_frame` without overlap resolution
(VIS detections may overlap) and with class confusion, one entry per detection.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.rle import encode_masks
from unitrack_env.datasets.synthetic.motchallenge import SequenceSpec
from unitrack_env.datasets.synthetic.mots import MaskNoise, simulate_frame
from unitrack_env.datasets.synthetic.scene import render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneConfig
from unitrack_env.datasets.youtube_vis import (
    VisData,
    VisTrack,
    VisVideo,
    format_annotations,
    format_results,
    to_rle,
)

#: Benchmarks written by :func:`write_youtube_vis`.
BENCHMARKS = ("YouTube-VIS-2019",)
#: Categories of the synthetic data set.
CATEGORIES = {1: "person", 2: "occluder"}
#: Category of each role.
ROLE_CATEGORY = {ObjectRole.PEDESTRIAN: 1, ObjectRole.STATIC_PERSON: 1, ObjectRole.OCCLUDER: 2}
#: Frame file numbers step by this (the 2019 release keeps every 5th frame).
FRAME_STEP = 5
#: Seed-stream index of the detection noise.
_STREAM_DETECTIONS = 4


@dataclass(frozen=True)
class VISSpec:
    """A synthetic YouTube-VIS data set (``split``: ``"train"`` with gt, ``"test"`` -> valid)."""

    sequences: tuple[SequenceSpec, ...]
    noise: MaskNoise = field(default_factory=MaskNoise)
    class_noise: float = 0.08
    jpeg_quality: int = 90


#: The embedded default: two annotated videos and one without annotations (``valid``).
DEFAULT_SPEC = VISSpec(sequences=(
    SequenceSpec("syn-01", "train", SceneConfig(
        width=448, height=256, num_frames=24, num_objects=5, seed=21,
        object_height_range=(70.0, 110.0))),
    SequenceSpec("syn-02", "train", SceneConfig(
        width=400, height=240, num_frames=20, num_objects=4, seed=22,
        object_height_range=(65.0, 100.0))),
    SequenceSpec("syn-03", "test", SceneConfig(
        width=448, height=256, num_frames=16, num_objects=5, seed=23,
        object_height_range=(70.0, 110.0))),
))

#: The split written with annotations (the other is written as ``valid``).
ANNOTATED_SPLIT = "train"


def split_folder(split: str) -> str:
    """The folder (and reader split) a sequence of ``split`` is written to."""
    return "train" if split == ANNOTATED_SPLIT else "valid"


def annotated_frames(benchmark: str = "YouTube-VIS-2019", split: str | None = None,
                     spec: VISSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each annotated video of ``split`` (None: any; a reader's split name).

    Known without writing anything, e.g. to plan work on data not generated yet.
    """
    return {s.name: s.scene.num_frames for s in spec.sequences if s.split == ANNOTATED_SPLIT
            and split in (None, split_folder(s.split))}


def _polygon(mask: np.ndarray) -> list[list[float]]:
    """The visible rectangle of a mask as one polygon ``[x0, y0, x1, y0, x1, y1, x0, y1]``."""
    ys, xs = np.nonzero(mask)
    x0, x1, y0, y1 = float(xs.min()), float(xs.max() + 1), float(ys.min()), float(ys.max() + 1)
    return [[x0, y0, x1, y0, x1, y1, x0, y1]]


def write_youtube_vis(root: str | Path, benchmark: str = "YouTube-VIS-2019", *,
                      spec: VISSpec = DEFAULT_SPEC) -> None:
    """Render ``spec`` and write it under ``root`` in the YouTube-VIS 2019 layout."""
    if benchmark not in BENCHMARKS:
        raise ValueError(f"unknown VIS benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}")
    root = Path(root)
    splits: dict[str, tuple[list, list, list]] = {"train": ([], [], []), "valid": ([], [], [])}
    for number, seq in enumerate(spec.sequences, start=1):
        split = split_folder(seq.split)
        videos, tracks, detections = splits[split]
        scene = seq.scene
        names = tuple(f"{seq.name}/{FRAME_STEP * t:05d}.jpg" for t in range(scene.num_frames))
        video = VisVideo(number, seq.name, names, scene.height, scene.width)
        image_dir = root / split / "JPEGImages" / seq.name
        image_dir.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng([scene.seed, _STREAM_DETECTIONS])
        segs: dict[int, list] = {}
        roles: dict[int, ObjectRole] = {}
        for frame in render_scene(scene):
            path = root / split / "JPEGImages" / names[frame.index]
            if not cv2.imwrite(str(path), frame.image[:, :, ::-1],
                               [cv2.IMWRITE_JPEG_QUALITY, int(spec.jpeg_quality)]):
                raise OSError(f"{path}: cv2.imwrite failed")
            for obj in frame.objects:
                roles[obj.id] = obj.role
                mask = frame.instance_map == obj.id
                if mask.sum() < spec.noise.min_pixels:
                    continue
                seg = segs.setdefault(obj.id, [None] * scene.num_frames)
                if obj.role is ObjectRole.OCCLUDER:
                    seg[frame.index] = to_rle(_polygon(mask), scene.height, scene.width,
                                              path, "polygon")
                else:
                    seg[frame.index] = {"size": [scene.height, scene.width],
                                        "counts": encode_masks(mask[None])[0]}
            fm = simulate_frame(frame, spec.noise, rng, resolve=False,
                                class_noise=spec.class_noise)
            for counts, cls, score in zip(encode_masks(fm.det_masks), fm.det_classes,
                                          fm.det_scores, strict=True):
                det = [None] * scene.num_frames
                det[frame.index] = {"size": [scene.height, scene.width], "counts": counts}
                detections.append(VisTrack(number, int(cls), tuple(det), score=float(score)))
        videos.append(video)
        for obj_id in sorted(segs):
            tracks.append(VisTrack(number, ROLE_CATEGORY[roles[obj_id]], tuple(segs[obj_id]),
                                   id=len(tracks) + 1))
    for split, (videos, tracks, detections) in splits.items():
        data = VisData(root / f"{split}.json", tuple(videos), dict(CATEGORIES),
                       tuple(tracks) if split == "train" else None)
        (root / f"{split}.json").write_text(format_annotations(data), encoding="utf-8")
        (root / "detections").mkdir(parents=True, exist_ok=True)
        (root / "detections" / f"{split}.json").write_text(format_results(detections),
                                                           encoding="utf-8")

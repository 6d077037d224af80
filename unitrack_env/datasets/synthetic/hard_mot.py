"""Long, deliberately hard synthetic MOT sequences (30 FPS) for accuracy benchmarks.

The embedded default MOT data (:data:`~unitrack_env.datasets.synthetic.motchallenge.DEFAULT_SPEC`)
is short (64-80 frames) and easy: every person has a distinct texture and the camera stands
still. The sequences here stress what separates an association tracker from an IoU tracker
and what makes appearance *mislead* one:

* **crossings**: several pairs forced to cross with heavy overlap (scene engine);
* **occlusions**: occluders on walkers' paths, long enough to lose a track for a while;
* **look-alikes**: some people share another person's texture (same colours and pattern,
  a different pattern phase), including inside crossing pairs, so appearance alone cannot
  tell them apart and must not re-attach a lost track to the wrong one;
* **camera motion**: the camera pans (a moving crop of a wider scene, with a slow sway and
  a small vertical shake), so the whole image moves and constant-velocity predictions err;
* **30 FPS, 300 frames**: lost-track ages and confirmation rules meet real time scales.

They are written in the MOTChallenge layout by :func:`write_hard_motchallenge` (MOT17 rules:
9-column gt with classes and visibility, detections with scores in [0, 1]) and are *not*
part of the embedded default data set, so nothing that depends on the default changes.

Example:
    >>> from unitrack_env.datasets.synthetic.hard_mot import HARD_SPEC
    >>> [s.name for s in HARD_SPEC.sequences]
    ['HARD-01', 'HARD-02', 'HARD-03']
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.motchallenge import (
    DetectionNoise,
    SequenceSpec,
    write_sequence,
)
from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import (
    ObjectAnnotation,
    ObjectRole,
    SceneConfig,
    SyntheticFrame,
    Texture,
)

#: Seed-stream index of the look-alike and camera draws (the scene uses 0, 1; detections 2).
_STREAM_HARD = 3


@dataclass(frozen=True)
class CameraMotion:
    """A panning camera: the frame is a moving window on a wider scene.

    The window's left edge at frame ``t`` is ``margin / 2 + pan_amplitude * sin(2 pi t /
    pan_period + phase)`` (clipped to the scene) and its top edge ``shake_amplitude *
    sin(2 pi t / shake_period)`` below ``margin_y / 2``. The scene is rendered ``margin``
    pixels wider and ``margin_y`` pixels taller than the frame.

    Attributes:
        margin: Extra scene width in pixels.
        margin_y: Extra scene height in pixels.
        pan_amplitude: Horizontal sway in pixels.
        pan_period: Sway period in frames.
        shake_amplitude: Vertical shake in pixels.
        shake_period: Shake period in frames.
    """

    margin: int = 160
    margin_y: int = 16
    pan_amplitude: float = 70.0
    pan_period: float = 180.0
    shake_amplitude: float = 5.0
    shake_period: float = 23.0

    def offset(self, t: int, phase: float) -> tuple[int, int]:
        """``(x, y)`` of the window's top-left corner in scene pixels at frame ``t``."""
        x = self.margin / 2 + self.pan_amplitude * np.sin(2 * np.pi * t / self.pan_period + phase)
        y = self.margin_y / 2 + self.shake_amplitude * np.sin(2 * np.pi * t / self.shake_period)
        x = int(round(np.clip(x, 0, self.margin)))
        y = int(round(np.clip(y, 0, self.margin_y)))
        return x, y


@dataclass(frozen=True)
class HardSequenceSpec:
    """One hard sequence.

    Attributes:
        sequence: Name, split, frame rate and the scene (of the *frame* size; the scene is
            rendered wider when the camera moves).
        lookalikes: Number of people (after the crossing pairs' first members) who wear
            another person's texture; crossing partners are copied first.
        camera: Camera motion, or None for a static camera.
    """

    sequence: SequenceSpec
    lookalikes: int = 0
    camera: CameraMotion | None = None


@dataclass(frozen=True)
class HardMotSpec:
    """A set of hard sequences.

    Attributes:
        sequences: The sequences, in writing order.
        detection_noise: The simulated detector.
        jpeg_quality: JPEG quality of the frames.
    """

    sequences: tuple[HardSequenceSpec, ...]
    detection_noise: DetectionNoise = DetectionNoise(
        miss_rate=0.06, false_positives_per_frame=0.6, clutter_rate=0.05)
    jpeg_quality: int = 90


def _scene(width: int, height: int, seed: int, **kwargs: object) -> SceneConfig:
    return SceneConfig(width=width, height=height, num_frames=300, seed=seed, **kwargs)


HARD_SPEC = HardMotSpec(sequences=(
    # Crossings between look-alikes, a static camera, two occluders.
    HardSequenceSpec(SequenceSpec("HARD-01", "train", _scene(
        640, 360, 101, num_objects=10, num_crossings=4, num_static_persons=1,
        num_occluders=2, speed_range=(1.0, 2.6)), frame_rate=30), lookalikes=3),
    # A panning, shaking camera over a crowd with look-alikes.
    HardSequenceSpec(SequenceSpec("HARD-02", "train", _scene(
        640, 360, 102, num_objects=12, num_crossings=4, num_static_persons=2,
        num_occluders=2, speed_range=(0.8, 2.4)), frame_rate=30),
        lookalikes=4, camera=CameraMotion()),
    # Fewer, larger people; long occlusions behind wide occluders; camera sway.
    HardSequenceSpec(SequenceSpec("HARD-03", "train", _scene(
        640, 360, 103, num_objects=8, num_crossings=3, num_static_persons=1,
        num_occluders=3, object_height_range=(110.0, 170.0),
        occluder_width_range=(40.0, 70.0), occluder_height_fraction=(0.55, 0.7),
        speed_range=(1.0, 2.2)), frame_rate=30),
        lookalikes=2, camera=CameraMotion(pan_amplitude=40.0, pan_period=240.0,
                                          shake_amplitude=2.0)),
))
"""The hard sequences (3 x 300 frames, 640 x 360, 30 FPS)."""


def _lookalike_video(video: SyntheticVideo, count: int, rng: np.random.Generator
                     ) -> SyntheticVideo:
    """Give ``count`` persons another person's texture (crossing partners first)."""
    persons = [o for o in video.objects if o.role is not ObjectRole.OCCLUDER]
    crossings = video.config.num_crossings
    pairs = [(persons[2 * k], persons[2 * k + 1]) for k in range(crossings)]
    others = persons[2 * crossings:]
    copies: dict[int, Texture] = {}
    for source, target in pairs[:count]:
        copies[target.id] = source.texture
    rest = count - len(copies)
    for k in range(min(rest, len(others))):
        source = persons[int(rng.integers(len(persons)))]
        if source.id == others[k].id:
            source = persons[(persons.index(source) + 1) % len(persons)]
        copies[others[k].id] = source.texture
    objects = []
    for obj in video.objects:
        texture = copies.get(obj.id)
        if texture is not None:
            # Same colours and pattern; another seed / angle nudge, like two similar coats.
            texture = replace(texture, seed=texture.seed + 1,
                              angle=texture.angle + float(rng.uniform(-0.15, 0.15)))
            obj = replace(obj, texture=texture)
        objects.append(obj)
    return SyntheticVideo(video.config, tuple(objects), np.array(video.background))


def render_hard_sequence(spec: HardSequenceSpec) -> Iterator[SyntheticFrame]:
    """Render a hard sequence's frames (camera crop applied, annotations in frame pixels)."""
    scene = spec.sequence.scene
    camera = spec.camera
    rng = np.random.default_rng([scene.seed, _STREAM_HARD])
    wide = scene if camera is None else replace(
        scene, width=scene.width + camera.margin, height=scene.height + camera.margin_y)
    video = render_scene(wide)
    if spec.lookalikes:
        video = _lookalike_video(video, spec.lookalikes, rng)
    phase = float(rng.uniform(0, 2 * np.pi))
    for frame in video:
        if camera is None:
            yield frame
            continue
        ox, oy = camera.offset(frame.index, phase)
        image = np.ascontiguousarray(frame.image[oy:oy + scene.height, ox:ox + scene.width])
        instances = np.ascontiguousarray(
            frame.instance_map[oy:oy + scene.height, ox:ox + scene.width])
        counts = np.bincount(instances.ravel(), minlength=max(
            (o.id for o in frame.objects), default=0) + 1)
        objects = []
        for obj in frame.objects:
            x, y, w, h = obj.box
            x, y = x - ox, y - oy
            if x >= scene.width or y >= scene.height or x + w <= 0 or y + h <= 0:
                continue
            visible = int(counts[obj.id])
            objects.append(ObjectAnnotation(
                id=obj.id, role=obj.role, box=(x, y, w, h), visibility=visible / obj.area,
                visible_pixels=visible, area=obj.area, depth=obj.depth))
        yield SyntheticFrame(frame.index, image, instances, tuple(objects))


def write_hard_motchallenge(root: str | Path, benchmark: str = "MOT17", *,
                            spec: HardMotSpec = HARD_SPEC) -> None:
    """Render ``spec`` and write it under ``root`` in ``benchmark``'s MOTChallenge layout.

    Args:
        root: The data set folder (gets ``train/<SEQ>/...``).
        benchmark: ``MOT16``/``MOT17``/``MOT20`` (9-column gt) or ``MOT15``.
        spec: What to render; equal specs give identical files.
    """
    root = Path(root)
    params = [cv2.IMWRITE_JPEG_QUALITY, int(spec.jpeg_quality)]
    for hard in spec.sequences:
        seq = hard.sequence
        write_sequence(root / seq.split / seq.name, seq, render_hard_sequence(hard), benchmark,
                       spec.detection_noise, params)

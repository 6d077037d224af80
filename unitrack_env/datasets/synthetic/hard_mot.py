"""Long, deliberately hard synthetic MOT sequences (30 FPS, 300 frames) for accuracy benchmarks.

They stress what separates an association tracker from an IoU tracker: crossings with
heavy overlap, long occlusions, look-alikes (shared textures, so appearance can mislead)
and a panning, shaking camera. Written in the MOTChallenge layout by
:func:`write_hard_motchallenge`; not part of the embedded default data.

Example:
    >>> from unitrack_env.datasets.synthetic.hard_mot import HARD_SPEC
    >>> [s.sequence.name for s in HARD_SPEC.sequences]
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
    """A panning camera: the frame is a moving window on a scene ``margin``/``margin_y`` larger.

    The left edge sways by ``pan_amplitude * sin(2 pi t / pan_period + phase)`` around the
    centre (clipped to the scene); the top edge shakes by ``shake_amplitude`` likewise.
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
    """One hard sequence: the frame-size scene, ``lookalikes`` copied textures, camera or None."""

    sequence: SequenceSpec
    lookalikes: int = 0
    camera: CameraMotion | None = None


@dataclass(frozen=True)
class HardMotSpec:
    """A set of hard sequences, the simulated detector and the frames' JPEG quality."""

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
    """Render ``spec`` under ``root`` (``train/<SEQ>/...``) in ``benchmark``'s layout."""
    root = Path(root)
    params = [cv2.IMWRITE_JPEG_QUALITY, int(spec.jpeg_quality)]
    for hard in spec.sequences:
        seq = hard.sequence
        write_sequence(root / seq.split / seq.name, seq, render_hard_sequence(hard), benchmark,
                       spec.detection_noise, params)

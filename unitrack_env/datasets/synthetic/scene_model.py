"""The synthetic scene's model: configuration, objects, their motion and per-frame records.

Plain frozen records shared by the layout (:mod:`.layout`, which draws the objects of a
scene), the sprite renderer (:mod:`.sprites`) and the video (:mod:`.scene`). Conventions
(0-based frames, amodal ``(x, y, w, h)`` boxes in 0-based pixels) are those of
:mod:`unitrack_env.datasets.synthetic.scene`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np


class ObjectRole(enum.Enum):
    """What an object is; writers map roles to their benchmark's classes."""

    PEDESTRIAN = "pedestrian"
    """A walking person: the tracked class (MOTChallenge class 1)."""
    STATIC_PERSON = "static_person"
    """A person standing still (MOTChallenge class 7, a distractor class)."""
    OCCLUDER = "occluder"
    """A static non-person structure in front of everything (MOTChallenge class 9)."""


class Pattern(enum.Enum):
    """Texture pattern families; each object uses one at its own period and angle."""

    STRIPES = "stripes"
    CHECKER = "checker"
    DOTS = "dots"
    BLOBS = "blobs"


class Silhouette(enum.Enum):
    """Shape of an object's binary mask inside its box."""

    PERSON = "person"
    RECTANGLE = "rectangle"


@dataclass(frozen=True)
class Texture:
    """An object's appearance.

    Attributes:
        pattern: the pattern family.
        colour_a: first RGB colour.
        colour_b: second RGB colour (the pattern mixes ``colour_a`` and ``colour_b``).
        period: pattern period in pixels at the object's base size.
        angle: pattern orientation in radians.
        seed: seed of the random field of :attr:`Pattern.BLOBS` (unused by the others).
    """

    pattern: Pattern
    colour_a: tuple[int, int, int]
    colour_b: tuple[int, int, int]
    period: float
    angle: float
    seed: int


@dataclass(frozen=True)
class Trajectory:
    """Smooth motion: constant velocity plus a sinusoidal wobble, and a slow scale change.

    The box centre at (0-based, possibly fractional) frame ``t`` is
    ``anchor_centre + velocity * (t - anchor_frame) + wobble(t)`` with
    ``wobble(t) = amplitude * sin(2 pi t / period + phase)`` per axis; the size is the base
    size times ``1 + scale_rate * (t - anchor_frame)``.
    """

    anchor_frame: float
    anchor_centre: tuple[float, float]
    velocity: tuple[float, float]
    scale_rate: float = 0.0
    wobble_amplitude: tuple[float, float] = (0.0, 0.0)
    wobble_period: tuple[float, float] = (1.0, 1.0)
    wobble_phase: tuple[float, float] = (0.0, 0.0)

    def centre(self, t: float) -> tuple[float, float]:
        """Return the box centre ``(x, y)`` at frame ``t``."""
        dt = t - self.anchor_frame
        out = []
        for axis in (0, 1):
            wobble = self.wobble_amplitude[axis] * np.sin(
                2.0 * np.pi * t / self.wobble_period[axis] + self.wobble_phase[axis]
            )
            out.append(self.anchor_centre[axis] + self.velocity[axis] * dt + float(wobble))
        return out[0], out[1]

    def scale(self, t: float) -> float:
        """Return the size factor at frame ``t`` (never below 0.25)."""
        return max(0.25, 1.0 + self.scale_rate * (t - self.anchor_frame))


@dataclass(frozen=True)
class SceneObject:
    """One object of a scene.

    Attributes:
        id: positive object id (also its value in the instance map).
        role: what the object is.
        base_size: ``(w, h)`` in pixels at scale 1.
        depth: distance from the camera (larger is farther); ties are broken by id.
        texture: appearance.
        silhouette: mask shape.
        trajectory: motion.
    """

    id: int
    role: ObjectRole
    base_size: tuple[int, int]
    depth: float
    texture: Texture
    silhouette: Silhouette
    trajectory: Trajectory

    def size_at(self, t: int) -> tuple[int, int]:
        """Return the rendered ``(w, h)`` (before cropping to the silhouette) at frame ``t``."""
        s = self.trajectory.scale(t)
        return max(2, int(round(self.base_size[0] * s))), max(3, int(round(self.base_size[1] * s)))

    def box_at(self, t: int) -> tuple[int, int, int, int]:
        """Return the integer placement ``(x0, y0, w, h)`` of the sprite at frame ``t``."""
        w, h = self.size_at(t)
        cx, cy = self.trajectory.centre(t)
        return int(np.floor(cx - w / 2.0 + 0.5)), int(np.floor(cy - h / 2.0 + 0.5)), w, h


@dataclass(frozen=True)
class SceneConfig:
    """Parameters of one synthetic scene. Equal configs give identical scenes.

    Attributes:
        width: image width in pixels.
        height: image height in pixels.
        num_frames: number of frames.
        num_objects: number of walking pedestrians.
        num_crossings: pairs of pedestrians forced to cross each other with overlap
            (``2 * num_crossings <= num_objects``); the pairs get ids ``(1, 2)``,
            ``(3, 4)``, ... Other objects may cross by chance too.
        num_static_persons: persons standing still.
        num_occluders: static occluders, each placed on a pedestrian's path.
        seed: the only source of randomness.
        object_height_range: person height in pixels, ``(min, max)``.
        aspect_ratio_range: person width / height, ``(min, max)`` (pedestrian-like, tall).
        crossing_size_ratio: max relative height difference inside a crossing pair, so
            that box size does not tell the two apart.
        crossing_offset_range: vertical offset between a crossing pair's centres, as a
            fraction of the height, ``(min, max)``; small so that the boxes overlap.
        speed_range: horizontal walking speed in pixels per frame, ``(min, max)``.
        max_vertical_speed: largest vertical speed in pixels per frame.
        scale_rate_range: relative size change per frame, ``(min, max)``.
        wobble_amplitude: largest wobble amplitude in pixels (the "small noise").
        wobble_period_range: wobble period in frames, ``(min, max)``.
        pattern_period_range: texture period in pixels, ``(min, max)``.
        occluder_width_range: occluder width in pixels, ``(min, max)``.
        occluder_height_fraction: occluder height as a fraction of the image height,
            ``(min, max)``.
        background_colour: mean RGB colour of the background.
        background_contrast: standard deviation (grey levels) of the background's
            low-frequency texture.
        background_cell: size in pixels of the background texture's blobs.
        background_gradient: brightness change (grey levels) from top to bottom.
        background_grain: standard deviation (grey levels) of fine static grain.
    """

    width: int = 640
    height: int = 360
    num_frames: int = 70
    num_objects: int = 7
    num_crossings: int = 2
    num_static_persons: int = 1
    num_occluders: int = 1
    seed: int = 0
    object_height_range: tuple[float, float] = (85.0, 130.0)
    aspect_ratio_range: tuple[float, float] = (0.36, 0.46)
    crossing_size_ratio: float = 0.1
    crossing_offset_range: tuple[float, float] = (0.04, 0.2)
    speed_range: tuple[float, float] = (1.5, 3.5)
    max_vertical_speed: float = 0.4
    scale_rate_range: tuple[float, float] = (-0.0015, 0.0015)
    wobble_amplitude: float = 1.5
    wobble_period_range: tuple[float, float] = (12.0, 40.0)
    pattern_period_range: tuple[float, float] = (6.0, 16.0)
    occluder_width_range: tuple[float, float] = (18.0, 30.0)
    occluder_height_fraction: tuple[float, float] = (0.3, 0.45)
    background_colour: tuple[int, int, int] = (118, 122, 112)
    background_contrast: float = 14.0
    background_cell: int = 40
    background_gradient: float = -30.0
    background_grain: float = 3.0

    def __post_init__(self) -> None:
        def require(ok: bool, name: str, what: str) -> None:
            if not ok:
                raise ValueError(f"SceneConfig.{name}={getattr(self, name)!r}: {what}")

        require(self.width >= 64, "width", "must be at least 64")
        require(self.height >= 64, "height", "must be at least 64")
        require(self.num_frames >= 1, "num_frames", "must be at least 1")
        require(self.num_objects >= 0, "num_objects", "must be >= 0")
        require(
            0 <= 2 * self.num_crossings <= self.num_objects,
            "num_crossings", "needs 0 <= 2 * num_crossings <= num_objects",
        )
        require(self.num_static_persons >= 0, "num_static_persons", "must be >= 0")
        require(self.num_occluders >= 0, "num_occluders", "must be >= 0")
        require(self.seed >= 0, "seed", "must be a non-negative integer")
        for name in (
            "object_height_range", "aspect_ratio_range", "crossing_offset_range", "speed_range",
            "scale_rate_range", "wobble_period_range", "pattern_period_range",
            "occluder_width_range", "occluder_height_fraction",
        ):
            lo, hi = getattr(self, name)
            require(lo <= hi, name, "must be (min, max) with min <= max")
        require(
            self.object_height_range[0] >= 8
            and self.object_height_range[1] <= 0.8 * self.height,
            "object_height_range", "must lie within [8, 0.8 * height]",
        )
        require(self.speed_range[0] >= 0, "speed_range", "must be non-negative")
        require(self.pattern_period_range[0] > 1, "pattern_period_range", "must exceed 1 px")
        require(self.background_cell >= 2, "background_cell", "must be at least 2")


@dataclass(frozen=True)
class ObjectAnnotation:
    """One object in one frame (present when its amodal box overlaps the image).

    Attributes:
        id: object id (its value in the frame's instance map).
        role: what the object is.
        box: amodal ``(x, y, w, h)`` in 0-based pixels, tight around the full silhouette;
            may extend past the image border.
        visibility: visible fraction of the full silhouette (0..1): pixels of this id in
            the instance map divided by the silhouette's area, so both occlusion and
            truncation at the border lower it.
        visible_pixels: pixels of this object in the instance map.
        area: pixels of the full (amodal) silhouette.
        depth: the object's depth (larger is farther).
    """

    id: int
    role: ObjectRole
    box: tuple[float, float, float, float]
    visibility: float
    visible_pixels: int
    area: int
    depth: float


@dataclass(frozen=True)
class SyntheticFrame:
    """One rendered frame.

    Attributes:
        index: 0-based frame index.
        image: ``(H, W, 3)`` uint8 RGB.
        instance_map: ``(H, W)`` int32 object id per pixel after occlusion (0 = background).
        objects: annotations of the objects present, sorted by id.
    """

    index: int
    image: np.ndarray
    instance_map: np.ndarray
    objects: tuple[ObjectAnnotation, ...]


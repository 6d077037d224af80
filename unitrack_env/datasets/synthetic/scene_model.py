"""The synthetic scene's model: configuration, objects, their motion and per-frame records.

Frozen records shared by the layout, the sprite renderer and the video; 0-based frames,
amodal ``(x, y, w, h)`` boxes in 0-based pixels.
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
    """An object's appearance: a pattern mixing two RGB colours (``seed``: of the BLOBS field)."""

    pattern: Pattern
    colour_a: tuple[int, int, int]
    colour_b: tuple[int, int, int]
    period: float
    angle: float
    seed: int


@dataclass(frozen=True)
class Trajectory:
    """Smooth motion: constant velocity plus a sinusoidal wobble, and a slow scale change.

    Centre at frame ``t``: ``anchor_centre + velocity * (t - anchor_frame) + amplitude *
    sin(2 pi t / period + phase)``; size: base size times ``1 + scale_rate * (t - anchor_frame)``.
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
    """One object of a scene (``id``: its instance-map value; larger depth is farther)."""

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

    ``seed`` is the only source of randomness; ranges are ``(min, max)``, sizes in pixels,
    speeds per frame. ``num_crossings`` pairs (ids ``(1, 2)``, ``(3, 4)``, ...) are forced to
    cross with overlap, their heights within ``crossing_size_ratio`` so size does not tell them
    apart. Occluders are placed on pedestrians' paths. Background: mean colour, low-frequency
    ``background_contrast`` blobs of ``background_cell`` pixels, a vertical gradient and grain.
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

    ``box`` is amodal (may extend past the border); ``visibility`` is its instance-map pixels
    over the silhouette's ``area``, so occlusion and truncation both lower it.
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
    """One rendered frame: RGB ``image``, ``instance_map`` (0 = background), objects by id."""

    index: int
    image: np.ndarray
    instance_map: np.ndarray
    objects: tuple[ObjectAnnotation, ...]


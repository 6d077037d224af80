"""Deterministic synthetic scenes: textured people that walk, cross and occlude each other.

The scene engine is shared by every synthetic data set writer (MOTChallenge now; MOTS,
PoseTrack, VIS, OTB, DAVIS and JHMDB build on the same model). A scene is a static,
mildly textured background plus a list of :class:`SceneObject` s:

* **pedestrians** walk with constant velocity plus a small smooth wobble, and may enter or
  leave the frame. ``num_crossings`` pairs of them are *forced to cross*: the two walk in
  opposite directions through the same point at the same frame with a small vertical
  offset, so their boxes overlap heavily and the farther one is occluded. Their textures
  differ and their sizes are similar, which is what separates an appearance tracker from
  an IoU tracker.
* **static persons** stand still (MOTChallenge class 7, a distractor class).
* **occluders** are static upright structures (a pillar or sign, MOTChallenge class 9)
  nearer than everything else; one is placed on a walker's path.

Every object has a distinct texture (hue, second colour, and a stripe / checker / dot / blob
pattern at an object-specific period and orientation), a binary silhouette (a head and an
elliptic body for persons, a rectangle for occluders), and a depth. Frames are rendered far
to near, so nearer objects occlude farther ones; the rendered instance map gives each
object's visible fraction.

Conventions: frame indices are **0-based** here (writers convert to their benchmark's own
numbering); boxes are amodal ``(x, y, w, h)`` in 0-based pixel coordinates (the top-left
pixel is ``(0, 0)``), tight around the object's full silhouette, and may extend past the
image border. Images are ``uint8`` RGB.

All randomness is drawn once, in :func:`render_scene`, from :class:`numpy.random.Generator`
streams seeded by ``SceneConfig.seed``; rendering a frame is a pure function of the scene
and the frame index, so frames can be produced lazily, in any order, with identical output.

Keypoints (for the pose writers) have a reserved place: a person's joints can be defined in
the silhouette's normalised coordinates (see :func:`person_silhouette`) and mapped through
:meth:`SceneObject.box_at`; :class:`ObjectAnnotation` is where per-frame keypoints belong.
"""

from __future__ import annotations

import colorsys
import enum
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

#: Seed-stream index for object layout, textures and trajectories.
_STREAM_OBJECTS = 0
#: Seed-stream index for the background texture.
_STREAM_BACKGROUND = 1

#: Shared skin tone (RGB) of every person's head, so heads do not identify people.
HEAD_COLOUR = (206, 168, 140)
#: Head radius as a fraction of the person's height (the head touches the box top).
HEAD_RADIUS = 0.1
#: Top of the elliptic body as a fraction of the person's height (it reaches the bottom).
BODY_TOP = 0.16
#: Half-width of the gap between the legs, as a fraction of the person's width.
LEG_GAP_HALF_WIDTH = 0.07
#: Where the legs start (fraction of the height); below this the gap between them is empty.
LEG_GAP_TOP = 0.8
#: Darkening at the left/right silhouette edge (0 = flat, 1 = black edge), a cylinder shading.
EDGE_SHADING = 0.25


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


@dataclass(frozen=True)
class _Sprite:
    """An object's rendered pixels at one size, cropped to its silhouette."""

    rgb: np.ndarray  # (h, w, 3) uint8
    mask: np.ndarray  # (h, w) bool
    offset: tuple[int, int]  # (dx, dy) of the crop inside the placement box
    area: int


class SyntheticVideo:
    """A rendered-on-demand synthetic video; build it with :func:`render_scene`.

    Frames are produced lazily (``video.frame(t)`` or iterating), so only one frame is in
    memory at a time; rendered sprites are cached per object and size.

    Attributes:
        config: the scene's configuration.
        objects: every object of the scene, sorted by id.
        background: ``(H, W, 3)`` uint8 RGB static background (read-only).
    """

    def __init__(
        self, config: SceneConfig, objects: tuple[SceneObject, ...], background: np.ndarray
    ) -> None:
        self.config = config
        self.objects = objects
        background.setflags(write=False)
        self.background = background
        # Far to near, so that nearer objects are painted last and occlude.
        self._draw_order = sorted(objects, key=lambda o: (-o.depth, o.id))
        self._sprites: dict[tuple[int, int, int], _Sprite] = {}

    @property
    def num_frames(self) -> int:
        """Number of frames."""
        return self.config.num_frames

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return self.config.width

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return self.config.height

    def __len__(self) -> int:
        return self.config.num_frames

    def __iter__(self) -> Iterator[SyntheticFrame]:
        for t in range(self.config.num_frames):
            yield self.frame(t)

    def object(self, object_id: int) -> SceneObject:
        """Return the object with id ``object_id``."""
        for obj in self.objects:
            if obj.id == object_id:
                return obj
        raise KeyError(f"no object {object_id}; ids are {[o.id for o in self.objects]}")

    def frame(self, t: int) -> SyntheticFrame:
        """Render frame ``t`` (0-based)."""
        if not 0 <= t < self.config.num_frames:
            raise IndexError(f"frame {t} out of range [0, {self.config.num_frames})")
        width, height = self.config.width, self.config.height
        image = self.background.copy()
        instance_map = np.zeros((height, width), dtype=np.int32)
        placed: list[tuple[SceneObject, tuple[int, int, int, int], int]] = []
        for obj in self._draw_order:
            x0, y0, w, h = obj.box_at(t)
            sprite = self._sprite(obj, w, h)
            bx, by = x0 + sprite.offset[0], y0 + sprite.offset[1]
            sh, sw = sprite.mask.shape
            if bx >= width or by >= height or bx + sw <= 0 or by + sh <= 0:
                continue
            placed.append((obj, (bx, by, sw, sh), sprite.area))
            ix0, iy0 = max(bx, 0), max(by, 0)
            ix1, iy1 = min(bx + sw, width), min(by + sh, height)
            sub = (slice(iy0 - by, iy1 - by), slice(ix0 - bx, ix1 - bx))
            mask = sprite.mask[sub]
            image[iy0:iy1, ix0:ix1][mask] = sprite.rgb[sub][mask]
            instance_map[iy0:iy1, ix0:ix1][mask] = obj.id
        max_id = max((o.id for o in self.objects), default=0)
        counts = np.bincount(instance_map.ravel(), minlength=max_id + 1)
        annotations = tuple(
            ObjectAnnotation(
                id=obj.id,
                role=obj.role,
                box=tuple(float(v) for v in box),  # type: ignore[arg-type]
                visibility=float(counts[obj.id]) / area,
                visible_pixels=int(counts[obj.id]),
                area=area,
                depth=obj.depth,
            )
            for obj, box, area in sorted(placed, key=lambda p: p[0].id)
        )
        return SyntheticFrame(t, image, instance_map, annotations)

    def _sprite(self, obj: SceneObject, w: int, h: int) -> _Sprite:
        key = (obj.id, w, h)
        sprite = self._sprites.get(key)
        if sprite is None:
            sprite = _render_sprite(obj, w, h)
            self._sprites[key] = sprite
        return sprite


def person_silhouette(w: int, h: int) -> np.ndarray:
    """Return a ``(h, w)`` bool person mask that touches all four sides of its box.

    In normalised coordinates ``u = (x + 0.5) / w``, ``v = (y + 0.5) / h``: a round head of
    radius ``HEAD_RADIUS * h`` at the top centre, an elliptic body from ``v = BODY_TOP`` to
    the bottom spanning the full width, and a gap between the legs below ``LEG_GAP_TOP``.
    """
    u = (np.arange(w, dtype=np.float64) + 0.5) / w
    v = (np.arange(h, dtype=np.float64) + 0.5) / h
    uu, vv = np.meshgrid(u, v)
    radius = HEAD_RADIUS * h
    head = ((uu - 0.5) * w) ** 2 + ((vv - HEAD_RADIUS) * h) ** 2 <= radius**2
    half_height = (1.0 - BODY_TOP) / 2.0
    body = ((uu - 0.5) / 0.5) ** 2 + ((vv - BODY_TOP - half_height) / half_height) ** 2 <= 1.0
    legs_gap = (vv > LEG_GAP_TOP) & (np.abs(uu - 0.5) < LEG_GAP_HALF_WIDTH)
    return head | (body & ~legs_gap)


def _pattern(texture: Texture, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Return the pattern's mixing weight in [0, 1] at base-size coordinates ``(xs, ys)``."""
    c, s = np.cos(texture.angle), np.sin(texture.angle)
    along = (xs * c + ys * s) / texture.period
    across = (-xs * s + ys * c) / texture.period
    if texture.pattern is Pattern.STRIPES:
        return np.clip(0.5 + 1.5 * np.sin(2.0 * np.pi * along), 0.0, 1.0)
    if texture.pattern is Pattern.CHECKER:
        return ((np.floor(along) + np.floor(across)) % 2).astype(np.float64)
    if texture.pattern is Pattern.DOTS:
        du, dv = along - np.round(along), across - np.round(across)
        return (du**2 + dv**2 < 0.09).astype(np.float64)
    # BLOBS: a coarse random field smoothly upsampled and thresholded softly.
    cells_y = int(np.ceil((ys.max() + 1) / texture.period)) + 2
    cells_x = int(np.ceil((xs.max() + 1) / texture.period)) + 2
    field = np.random.default_rng(texture.seed).standard_normal((cells_y, cells_x))
    h, w = xs.shape
    smooth = cv2.resize(field.astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
    return np.clip(0.5 + 1.5 * smooth.astype(np.float64), 0.0, 1.0)


def _render_sprite(obj: SceneObject, w: int, h: int) -> _Sprite:
    """Render an object at size ``(w, h)``: pattern, head colour, shading; crop to the mask."""
    if obj.silhouette is Silhouette.PERSON:
        mask = person_silhouette(w, h)
    else:
        mask = np.ones((h, w), dtype=bool)
    base_w, base_h = obj.base_size
    xs, ys = np.meshgrid(
        (np.arange(w) + 0.5) * (base_w / w), (np.arange(h) + 0.5) * (base_h / h)
    )
    weight = _pattern(obj.texture, xs, ys)[..., None]
    colour_a = np.asarray(obj.texture.colour_a, dtype=np.float64)
    colour_b = np.asarray(obj.texture.colour_b, dtype=np.float64)
    rgb = colour_a * (1.0 - weight) + colour_b * weight
    if obj.silhouette is Silhouette.PERSON:
        head_rows = int(round(BODY_TOP * h))
        rgb[:head_rows] = HEAD_COLOUR
    u = (np.arange(w) + 0.5) / w
    shading = 1.0 - EDGE_SHADING * (2.0 * u - 1.0) ** 2
    rgb = np.clip(rgb * shading[None, :, None], 0, 255).astype(np.uint8)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    y0, y1, x0, x1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    mask = np.ascontiguousarray(mask[y0:y1, x0:x1])
    rgb = np.ascontiguousarray(rgb[y0:y1, x0:x1])
    mask.setflags(write=False)
    rgb.setflags(write=False)
    return _Sprite(rgb, mask, (int(x0), int(y0)), int(mask.sum()))


def _hsv_rgb(h: float, s: float, v: float) -> tuple[int, int, int]:
    r, g, b = colorsys.hsv_to_rgb(h % 1.0, s, v)
    return int(round(r * 255)), int(round(g * 255)), int(round(b * 255))


def _textures(config: SceneConfig, rng: np.random.Generator, count: int) -> list[Texture]:
    """Distinct person textures: evenly spread hues (shuffled), cycling pattern families."""
    offset = rng.uniform()
    hues = (offset + np.arange(count) / max(count, 1)) % 1.0
    hues = hues[rng.permutation(count)]
    families = list(Pattern)
    first = int(rng.integers(len(families)))
    textures = []
    for i, hue in enumerate(hues):
        colour_a = _hsv_rgb(hue, rng.uniform(0.55, 0.9), rng.uniform(0.55, 0.9))
        if rng.uniform() < 0.5:  # same hue, very different brightness
            colour_b = _hsv_rgb(hue, rng.uniform(0.2, 0.5), rng.uniform(0.15, 0.35))
        else:  # a contrasting hue
            colour_b = _hsv_rgb(hue + rng.uniform(0.35, 0.65), rng.uniform(0.3, 0.8),
                                rng.uniform(0.75, 1.0))
        textures.append(Texture(
            pattern=families[(first + i) % len(families)],
            colour_a=colour_a,
            colour_b=colour_b,
            period=float(rng.uniform(*config.pattern_period_range)),
            angle=float(rng.uniform(0.0, np.pi)),
            seed=int(rng.integers(2**31)),
        ))
    return textures


def _wobble(config: SceneConfig, rng: np.random.Generator, scale: float = 1.0) -> dict:
    amp = config.wobble_amplitude * scale
    return {
        "wobble_amplitude": (float(rng.uniform(0, amp)), float(rng.uniform(0, amp))),
        "wobble_period": (float(rng.uniform(*config.wobble_period_range)),
                          float(rng.uniform(*config.wobble_period_range))),
        "wobble_phase": (float(rng.uniform(0, 2 * np.pi)), float(rng.uniform(0, 2 * np.pi))),
    }


def _person_size(config: SceneConfig, rng: np.random.Generator, height: float | None = None
                 ) -> tuple[int, int]:
    h = float(rng.uniform(*config.object_height_range)) if height is None else height
    w = h * float(rng.uniform(*config.aspect_ratio_range))
    return int(round(w)), int(round(h))


def _centre_y(config: SceneConfig, rng: np.random.Generator, h: int) -> float:
    """A box centre height that keeps a person of height ``h`` inside the image."""
    margin = h / 2.0 + 2.0
    return float(rng.uniform(margin, max(margin, config.height - margin)))


def _build_objects(config: SceneConfig, rng: np.random.Generator) -> tuple[SceneObject, ...]:
    """Draw sizes, textures and trajectories; ids are 1.. in creation order."""
    width, frames = config.width, config.num_frames
    num_persons = config.num_objects + config.num_static_persons
    textures = _textures(config, rng, num_persons)
    specs: list[tuple[ObjectRole, tuple[int, int], Trajectory]] = []

    def walk_velocity(direction: float) -> tuple[float, float]:
        vx = direction * float(rng.uniform(*config.speed_range))
        vy = float(rng.uniform(-config.max_vertical_speed, config.max_vertical_speed))
        return vx, vy

    def scale_rate() -> float:
        return float(rng.uniform(*config.scale_rate_range))

    # Forced crossings: both walk through the same point at the same frame, opposite ways.
    for _ in range(config.num_crossings):
        size_a = _person_size(config, rng)
        ratio = 1.0 + float(rng.uniform(-config.crossing_size_ratio, config.crossing_size_ratio))
        size_b = _person_size(config, rng, height=float(np.clip(
            size_a[1] * ratio, *config.object_height_range)))
        t_cross = float(rng.uniform(0.3, 0.7)) * (frames - 1)
        cx = float(rng.uniform(0.25, 0.75)) * width
        tallest = max(size_a[1], size_b[1])
        offset = float(rng.uniform(*config.crossing_offset_range)) * tallest
        cy = _centre_y(config, rng, int(tallest + offset))
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        direction = 1.0 if rng.uniform() < 0.5 else -1.0
        for size, dy, d in ((size_a, -offset / 2, direction), (size_b, offset / 2, -direction)):
            specs.append((ObjectRole.PEDESTRIAN, size, Trajectory(
                anchor_frame=t_cross, anchor_centre=(cx, cy + sign * dy),
                velocity=walk_velocity(d), scale_rate=scale_rate(), **_wobble(config, rng),
            )))

    # Free walkers: the first enters through a side edge, the second leaves through one.
    for k in range(config.num_objects - 2 * config.num_crossings):
        size = _person_size(config, rng)
        direction = 1.0 if rng.uniform() < 0.5 else -1.0
        velocity = walk_velocity(direction)
        cy = _centre_y(config, rng, size[1])
        outside = size[0] / 2.0 + 2.0
        if k == 0:  # just outside the edge it walks in from, at an early frame
            anchor = float(rng.uniform(0.1, 0.35)) * (frames - 1)
            cx = -outside if direction > 0 else width + outside
        elif k == 1:  # just outside the edge it walks out of, at a late frame
            anchor = float(rng.uniform(0.65, 0.9)) * (frames - 1)
            cx = width + outside if direction > 0 else -outside
        else:
            anchor = float(rng.uniform(0.0, 1.0)) * (frames - 1)
            cx = float(rng.uniform(0.0, 1.0)) * width
        specs.append((ObjectRole.PEDESTRIAN, size, Trajectory(
            anchor_frame=anchor, anchor_centre=(cx, cy), velocity=velocity,
            scale_rate=scale_rate(), **_wobble(config, rng),
        )))

    for _ in range(config.num_static_persons):
        size = _person_size(config, rng)
        cx = float(rng.uniform(size[0], width - size[0]))
        specs.append((ObjectRole.STATIC_PERSON, size, Trajectory(
            anchor_frame=0.0, anchor_centre=(cx, _centre_y(config, rng, size[1])),
            velocity=(0.0, 0.0), **_wobble(config, rng, scale=0.3),
        )))

    objects: list[SceneObject] = []
    for i, (role, size, trajectory) in enumerate(specs):
        feet = trajectory.anchor_centre[1] + size[1] / 2.0
        objects.append(SceneObject(
            id=i + 1, role=role, base_size=size,
            depth=float(config.height - feet),  # lower feet = nearer (a ground plane)
            texture=textures[i], silhouette=Silhouette.PERSON, trajectory=trajectory,
        ))

    # Occluders stand on a pedestrian's path, at the frame when it is mid-image.
    walkers = [o for o in objects if o.role is ObjectRole.PEDESTRIAN]
    for _ in range(config.num_occluders):
        ow = int(round(rng.uniform(*config.occluder_width_range)))
        oh = int(round(rng.uniform(*config.occluder_height_fraction) * config.height))
        if walkers:
            target = walkers[int(rng.integers(len(walkers)))]
            t_mid = _frame_near_x(target, width / 2.0, frames)
            cx, cy = target.trajectory.centre(t_mid)
            cy += float(rng.uniform(-0.15, 0.15)) * target.base_size[1]
            cx = float(np.clip(cx, ow, width - ow))
        else:
            cx, cy = float(rng.uniform(ow, width - ow)), config.height / 2.0
        cy = float(np.clip(cy, oh / 2.0 + 1, config.height - oh / 2.0 - 1))
        grey = int(rng.integers(90, 170))
        texture = Texture(
            pattern=Pattern.STRIPES,
            colour_a=(grey, grey - 8, grey - 20),
            colour_b=(grey - 40, grey - 45, grey - 50),
            period=float(rng.uniform(10.0, 20.0)),
            angle=float(np.pi / 2),  # horizontal bands
            seed=0,
        )
        objects.append(SceneObject(
            id=len(objects) + 1, role=ObjectRole.OCCLUDER, base_size=(ow, oh),
            depth=-1.0,  # nearer than any person
            texture=texture, silhouette=Silhouette.RECTANGLE,
            trajectory=Trajectory(anchor_frame=0.0, anchor_centre=(cx, cy), velocity=(0.0, 0.0)),
        ))
    return tuple(objects)


def _frame_near_x(obj: SceneObject, x: float, frames: int) -> int:
    """The frame (within the video) at which ``obj`` is horizontally closest to ``x``."""
    distances = [abs(obj.trajectory.centre(t)[0] - x) for t in range(frames)]
    return int(np.argmin(distances))


def _background(config: SceneConfig, rng: np.random.Generator) -> np.ndarray:
    """A static, mildly textured background: coloured blobs, a vertical gradient, grain."""
    height, width = config.height, config.width
    cells = (height // config.background_cell + 2, width // config.background_cell + 2, 3)
    blobs = cv2.resize(
        rng.standard_normal(cells).astype(np.float32), (width, height),
        interpolation=cv2.INTER_CUBIC,
    )
    # Mostly luminance variation with a little colour, like pavement and walls.
    luminance = blobs.mean(axis=2, keepdims=True)
    texture = config.background_contrast * (0.8 * luminance + 0.2 * blobs)
    gradient = config.background_gradient * (np.linspace(-0.5, 0.5, height)[:, None, None])
    grain = config.background_grain * rng.standard_normal((height, width, 1))
    image = np.asarray(config.background_colour, dtype=np.float64) + texture + gradient + grain
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def render_scene(config: SceneConfig) -> SyntheticVideo:
    """Build the scene described by ``config``; frames are rendered lazily.

    Args:
        config: the scene parameters (``config.seed`` is the only randomness).

    Returns:
        The video; equal configs give identical videos.

    >>> video = render_scene(SceneConfig(num_frames=3, num_objects=2, num_crossings=1))
    >>> frame = video.frame(0)
    >>> frame.image.shape, frame.image.dtype, frame.instance_map.dtype
    ((360, 640, 3), dtype('uint8'), dtype('int32'))
    """
    objects_rng = np.random.default_rng([config.seed, _STREAM_OBJECTS])
    background_rng = np.random.default_rng([config.seed, _STREAM_BACKGROUND])
    return SyntheticVideo(
        config, _build_objects(config, objects_rng), _background(config, background_rng)
    )

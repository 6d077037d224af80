"""Deterministic synthetic scenes: textured people that walk, cross and occlude each other.

The engine every synthetic writer builds on. A scene is a static, mildly textured background
and its objects: pedestrians that walk at constant velocity with a small wobble (and may
enter or leave), standing persons (a distractor class) and occluders nearer than everything
(one on a walker's path). ``num_crossings`` pairs of pedestrians are forced to cross: they
walk opposite ways through the same point at the same frame, so their boxes overlap heavily
and the farther one is hidden. Their sizes are similar and their textures differ, which is
what separates an appearance tracker from an IoU tracker. Frames are painted far to near;
the instance map gives each object's visible fraction. Boxes are amodal and may extend past
the image border.

All randomness is drawn once, in :func:`render_scene`, from streams seeded by
``SceneConfig.seed``; a frame is a pure function of the scene and its index, so frames
render lazily, in any order, with identical output.
"""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.layout import build_objects
from unitrack_env.datasets.synthetic.scene_model import (
    ObjectAnnotation,
    SceneConfig,
    SceneObject,
    SyntheticFrame,
)
from unitrack_env.datasets.synthetic.sprites import Sprite, render_sprite

__all__ = ["SyntheticVideo", "render_scene"]

#: Seed-stream index for object layout, textures and trajectories.
_STREAM_OBJECTS = 0
#: Seed-stream index for the background texture.
_STREAM_BACKGROUND = 1


class SyntheticVideo:
    """A synthetic video rendered on demand one frame at a time (:func:`render_scene`)."""

    def __init__(
        self, config: SceneConfig, objects: tuple[SceneObject, ...], background: np.ndarray
    ) -> None:
        self.config = config
        self.objects = objects
        background.setflags(write=False)
        self.background = background
        # Far to near, so that nearer objects are painted last and occlude.
        self._draw_order = sorted(objects, key=lambda o: (-o.depth, o.id))
        self._sprites: dict[tuple[int, int, int], Sprite] = {}

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

    def _sprite(self, obj: SceneObject, w: int, h: int) -> Sprite:
        key = (obj.id, w, h)
        sprite = self._sprites.get(key)
        if sprite is None:
            sprite = render_sprite(obj, w, h)
            self._sprites[key] = sprite
        return sprite


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
    """Build the scene of ``config`` (its seed is the only randomness); frames render lazily.

    >>> video = render_scene(SceneConfig(num_frames=3, num_objects=2, num_crossings=1))
    >>> frame = video.frame(0)
    >>> frame.image.shape, frame.image.dtype, frame.instance_map.dtype
    ((360, 640, 3), dtype('uint8'), dtype('int32'))
    """
    objects_rng = np.random.default_rng([config.seed, _STREAM_OBJECTS])
    background_rng = np.random.default_rng([config.seed, _STREAM_BACKGROUND])
    return SyntheticVideo(
        config, build_objects(config, objects_rng), _background(config, background_rng)
    )

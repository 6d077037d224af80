"""Rendering one scene object: its silhouette, its texture pattern, and the cached sprite.

A sprite is an object's pixels at one size, cropped to its silhouette; the video pastes
sprites far to near (:class:`~unitrack_env.datasets.synthetic.scene.SyntheticVideo`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.scene_model import Pattern, SceneObject, Silhouette, Texture

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


@dataclass(frozen=True)
class Sprite:
    """An object's rendered pixels at one size, cropped to its silhouette."""

    rgb: np.ndarray  # (h, w, 3) uint8
    mask: np.ndarray  # (h, w) bool
    offset: tuple[int, int]  # (dx, dy) of the crop inside the placement box
    area: int


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


def render_sprite(obj: SceneObject, w: int, h: int) -> Sprite:
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
    return Sprite(rgb, mask, (int(x0), int(y0)), int(mask.sum()))


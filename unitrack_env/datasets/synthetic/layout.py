"""The layout of a synthetic scene: sizes, textures and trajectories drawn from one stream.

:func:`build_objects` draws every object of a scene (forced crossing pairs, free walkers,
static persons, occluders) from one :class:`numpy.random.Generator`. The order of the draws
is part of the data set: changing it changes every generated file (bump
``GENERATOR_VERSION`` in :mod:`unitrack_env.datasets.synthetic.cache` if you must).
"""

from __future__ import annotations

import colorsys

import numpy as np

from unitrack_env.datasets.synthetic.scene_model import (
    ObjectRole,
    Pattern,
    SceneConfig,
    SceneObject,
    Silhouette,
    Texture,
    Trajectory,
)


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


#: What the person layout draws per person: its role, base size and trajectory.
_PersonSpec = tuple[ObjectRole, tuple[int, int], Trajectory]


def _walk_velocity(
    config: SceneConfig, rng: np.random.Generator, direction: float
) -> tuple[float, float]:
    """A walking velocity ``(vx, vy)``: horizontal in ``direction``, slightly vertical."""
    vx = direction * float(rng.uniform(*config.speed_range))
    vy = float(rng.uniform(-config.max_vertical_speed, config.max_vertical_speed))
    return vx, vy


def _scale_rate(config: SceneConfig, rng: np.random.Generator) -> float:
    return float(rng.uniform(*config.scale_rate_range))


def _crossing_pair(config: SceneConfig, rng: np.random.Generator) -> list[_PersonSpec]:
    """Two pedestrians that walk through the same point at the same frame, opposite ways."""
    width, frames = config.width, config.num_frames
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
    pair: list[_PersonSpec] = []
    for size, dy, d in ((size_a, -offset / 2, direction), (size_b, offset / 2, -direction)):
        pair.append((ObjectRole.PEDESTRIAN, size, Trajectory(
            anchor_frame=t_cross, anchor_centre=(cx, cy + sign * dy),
            velocity=_walk_velocity(config, rng, d), scale_rate=_scale_rate(config, rng),
            **_wobble(config, rng),
        )))
    return pair


def _free_walker(config: SceneConfig, rng: np.random.Generator, k: int) -> _PersonSpec:
    """The ``k``-th free walker: ``k == 0`` enters through a side edge, ``k == 1`` leaves."""
    width, frames = config.width, config.num_frames
    size = _person_size(config, rng)
    direction = 1.0 if rng.uniform() < 0.5 else -1.0
    velocity = _walk_velocity(config, rng, direction)
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
    return (ObjectRole.PEDESTRIAN, size, Trajectory(
        anchor_frame=anchor, anchor_centre=(cx, cy), velocity=velocity,
        scale_rate=_scale_rate(config, rng), **_wobble(config, rng),
    ))


def _static_person(config: SceneConfig, rng: np.random.Generator) -> _PersonSpec:
    """A person standing still (a tiny wobble), fully inside the image."""
    size = _person_size(config, rng)
    cx = float(rng.uniform(size[0], config.width - size[0]))
    return (ObjectRole.STATIC_PERSON, size, Trajectory(
        anchor_frame=0.0, anchor_centre=(cx, _centre_y(config, rng, size[1])),
        velocity=(0.0, 0.0), **_wobble(config, rng, scale=0.3),
    ))


def _persons(
    config: SceneConfig, specs: list[_PersonSpec], textures: list[Texture]
) -> list[SceneObject]:
    """Turn person specs into objects with ids 1.. and ground-plane depths."""
    objects: list[SceneObject] = []
    for i, (role, size, trajectory) in enumerate(specs):
        feet = trajectory.anchor_centre[1] + size[1] / 2.0
        objects.append(SceneObject(
            id=i + 1, role=role, base_size=size,
            depth=float(config.height - feet),  # lower feet = nearer (a ground plane)
            texture=textures[i], silhouette=Silhouette.PERSON, trajectory=trajectory,
        ))
    return objects


def _occluder(
    config: SceneConfig, rng: np.random.Generator, walkers: list[SceneObject], object_id: int
) -> SceneObject:
    """A static structure on a walker's path, at the frame when that walker is mid-image."""
    width, frames = config.width, config.num_frames
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
    return SceneObject(
        id=object_id, role=ObjectRole.OCCLUDER, base_size=(ow, oh),
        depth=-1.0,  # nearer than any person
        texture=texture, silhouette=Silhouette.RECTANGLE,
        trajectory=Trajectory(anchor_frame=0.0, anchor_centre=(cx, cy), velocity=(0.0, 0.0)),
    )


def build_objects(config: SceneConfig, rng: np.random.Generator) -> tuple[SceneObject, ...]:
    """Draw sizes, textures and trajectories; ids are 1.. in creation order.

    The draws come in a fixed order: textures, forced crossing pairs, free walkers, static
    persons, then occluders (each on a walker's path).
    """
    num_persons = config.num_objects + config.num_static_persons
    textures = _textures(config, rng, num_persons)
    specs: list[_PersonSpec] = []
    for _ in range(config.num_crossings):
        specs.extend(_crossing_pair(config, rng))
    for k in range(config.num_objects - 2 * config.num_crossings):
        specs.append(_free_walker(config, rng, k))
    for _ in range(config.num_static_persons):
        specs.append(_static_person(config, rng))
    objects = _persons(config, specs, textures)
    walkers = [o for o in objects if o.role is ObjectRole.PEDESTRIAN]
    for _ in range(config.num_occluders):
        objects.append(_occluder(config, rng, walkers, len(objects) + 1))
    return tuple(objects)


def _frame_near_x(obj: SceneObject, x: float, frames: int) -> int:
    """The frame (within the video) at which ``obj`` is horizontally closest to ``x``."""
    distances = [abs(obj.trajectory.centre(t)[0] - x) for t in range(frames)]
    return int(np.argmin(distances))


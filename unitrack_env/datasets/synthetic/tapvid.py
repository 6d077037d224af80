"""Synthetic TAP-Vid data sets in the official pickle layout, with exact point tracks.

:func:`write_tapvid` renders textured-object scenes (:func:`render_scene`) and writes
``tapvid_davis.pkl`` / ``robotap_split0.pkl`` (a dict by video name) or
``tapvid_rgb_stacking.pkl`` (a list); for TAP-Vid-Kinetics, ``tapvid_kinetics.csv`` and
MPEG-4 clips written with OpenCV (:func:`write_kinetics`). A tracked point is fixed on an
object's texture (or on the static background): at frame ``t`` it is at ``x0 + u w,
y0 + v h`` of the object's placement box ``(x0, y0, w, h)``, which is exactly where the
renderer draws that texel (pixel ``i`` of the sprite shows texture coordinate
``(i + 0.5) / w``). It is occluded when the pixel under it shows another object or the
background, or lies outside the frame.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import SceneConfig, SceneObject

#: Data sets :func:`write_tapvid` writes, with their file name and container.
FILES: dict[str, tuple[str, type]] = {
    "TAPVid-DAVIS": ("tapvid_davis.pkl", dict),
    "TAPVid-RGBStacking": ("tapvid_rgb_stacking.pkl", list),
    "RoboTAP": ("robotap_split0.pkl", dict),
}
#: The Kinetics layout: annotations, and the folder (a Kinetics action label) of the clips.
KINETICS_CSV, KINETICS_LABEL = "tapvid_kinetics.csv", "synthetic_motion"
#: Annotated frames per CSV row and their rate (the official 10 s at 25 fps).
KINETICS_FRAMES, KINETICS_FPS = 250, 25
BENCHMARKS: tuple[str, ...] = (*FILES, "TAPVid-Kinetics")
#: Points per object and on the background.
POINTS_PER_OBJECT = 6
BACKGROUND_POINTS = 6
#: Pickle protocol of the written files (that of the converted real fixture).
PICKLE_PROTOCOL = 4


def _scene(seed: int, width: int, height: int, frames: int) -> SceneConfig:
    return SceneConfig(
        width=width, height=height, num_frames=frames, num_objects=3, num_crossings=1,
        num_static_persons=0, num_occluders=1, seed=seed,
        object_height_range=(0.4 * height, 0.6 * height), speed_range=(1.0, 2.5),
        occluder_height_fraction=(0.5, 0.7), background_cell=24)


@dataclass(frozen=True)
class PointVideoSpec:
    """One synthetic video: its name and scene."""

    name: str
    scene: SceneConfig


#: The videos of each data set: 16:9 frames for DAVIS and RoboTAP (the readers resize to
#: the 256 x 256 raster), 256 x 256 for RGB-Stacking (stored at that size officially).
SPECS: dict[str, tuple[PointVideoSpec, ...]] = {
    "TAPVid-DAVIS": (PointVideoSpec("syn-cross", _scene(61, 320, 180, 24)),
                     PointVideoSpec("syn-occluder", _scene(62, 320, 180, 24)),
                     PointVideoSpec("syn-fast", _scene(63, 320, 180, 20))),
    "TAPVid-RGBStacking": (PointVideoSpec("0", _scene(71, 256, 256, 20)),
                           PointVideoSpec("1", _scene(72, 256, 256, 20))),
    "RoboTAP": (PointVideoSpec("syn-robot-0", _scene(81, 320, 180, 20)),
                PointVideoSpec("syn-robot-1", _scene(82, 320, 180, 20))),
    # Clip names as Kinetics names them (youtube id, segment start and end): each clip is
    # shorter than its 10 s segment, so the reader keeps its annotations' first frames.
    "TAPVid-Kinetics": (PointVideoSpec("synkinetic0_000000_000010", _scene(91, 320, 180, 20)),
                        PointVideoSpec("synkinetic1_000010_000020", _scene(92, 320, 180, 16))),
}


def annotated_frames(benchmark: str, split: str | None = None) -> dict[str, int]:
    """Frames of each video of a synthetic data set (every video is annotated)."""
    return {spec.name: spec.scene.num_frames for spec in SPECS[benchmark]}


def _anchor_points(instance: np.ndarray, label: int, count: int,
                   rng: np.random.Generator) -> np.ndarray:
    """``count`` pixel centres (x, y) inside ``label``'s eroded region of an instance map."""
    region = cv2.erode((instance == label).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    ys, xs = np.nonzero(region)
    if len(xs) == 0:
        return np.zeros((0, 2))
    pick = rng.choice(len(xs), size=min(count, len(xs)), replace=False)
    return np.stack([xs[pick] + 0.5, ys[pick] + 0.5], axis=1)


def _object_track(obj: SceneObject, anchor_frame: int, anchor: np.ndarray,
                  frames: int) -> np.ndarray:
    """``(K, T, 2)`` positions of texture points seen at ``anchor`` in frame ``anchor_frame``."""
    x0, y0, w, h = obj.box_at(anchor_frame)
    uv = (anchor - np.array([x0, y0])) / np.array([w, h])
    boxes = np.array([obj.box_at(t) for t in range(frames)], np.float64)
    return boxes[None, :, :2] + uv[:, None, :] * boxes[None, :, 2:]


def point_tracks(video: SyntheticVideo, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The video's frames ``(T, H, W, 3)``, tracks ``(N, T, 2)`` in pixels and occlusion."""
    rendered = list(video)
    frames = np.stack([f.image for f in rendered])
    instance = np.stack([f.instance_map for f in rendered])
    rng = np.random.default_rng([seed, 7])
    tracks = [np.repeat(_anchor_points(instance[0], 0, BACKGROUND_POINTS, rng)[:, None],
                        len(frames), axis=1)]
    labels = [np.zeros(len(tracks[0]), np.int64)]
    for obj in video.objects:
        shown = (instance == obj.id).sum(axis=(1, 2))
        anchor_frame = int(np.argmax(shown))
        anchor = _anchor_points(instance[anchor_frame], obj.id, POINTS_PER_OBJECT, rng)
        tracks.append(_object_track(obj, anchor_frame, anchor, len(frames)))
        labels.append(np.full(len(anchor), obj.id, np.int64))
    xy = np.concatenate(tracks)
    label = np.concatenate(labels)
    height, width = instance.shape[1:]
    cols, rows = np.floor(xy[..., 0]).astype(int), np.floor(xy[..., 1]).astype(int)
    inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
    shown_label = np.full(inside.shape, -1, np.int64)
    t_index = np.broadcast_to(np.arange(len(frames))[None], inside.shape)
    shown_label[inside] = instance[t_index[inside], rows[inside], cols[inside]]
    return frames, xy, shown_label != label[:, None]


def video_entry(spec: PointVideoSpec) -> dict[str, np.ndarray]:
    """One video in the official layout: ``video``, ``points`` (0..1), ``occluded``."""
    frames, xy, occluded = point_tracks(render_scene(spec.scene), spec.scene.seed)
    size = np.array([spec.scene.width, spec.scene.height], np.float64)
    return {"video": frames, "points": (xy / size).astype(np.float32), "occluded": occluded}


def _csv_rows(name: str, xy: np.ndarray, occluded: np.ndarray, size: np.ndarray) -> list[str]:
    """The CSV rows of one clip: its key, then x, y, occluded for 250 frames.

    The CSV is half a pixel off the pickles (``generate_tapvid.py`` writes ``(x W - 0.5) / W``):
    the rows hold ``(x + 0.5) / W`` so that the reader gives back the exact track. Frames past
    the clip's end are occluded; a visible point whose value would leave 0..1 (in the last
    half pixel of the frame) is written occluded.
    """
    key = name.rsplit("_", 2)
    values = (xy + 0.5) / size
    occluded = occluded | ((values < 0) | (values > 1)).any(axis=-1)
    rows = []
    for track in range(len(xy)):
        cells = [key[0], str(int(key[1])), str(int(key[2]))]
        for t in range(KINETICS_FRAMES):
            if t < xy.shape[1] and not occluded[track, t]:
                cells += [repr(float(values[track, t, 0])), repr(float(values[track, t, 1])), "0"]
            else:
                cells += ["0.0", "0.0", "1"]
        rows.append(",".join(cells))
    return rows


def write_kinetics(root: str | Path) -> None:
    """Write ``tapvid_kinetics.csv`` and each clip as ``<label>/<name>.mp4`` (MPEG-4 Part 2).

    This cv2 has no H.264 encoder; MPEG-4 Part 2 (``mp4v``) is one it both writes and reads.
    """
    root = Path(root)
    (root / KINETICS_LABEL).mkdir(parents=True, exist_ok=True)
    rows = []
    for spec in SPECS["TAPVid-Kinetics"]:
        frames, xy, occluded = point_tracks(render_scene(spec.scene), spec.scene.seed)
        size = np.array([spec.scene.width, spec.scene.height], np.float64)
        rows += _csv_rows(spec.name, xy, occluded, size)
        path = root / KINETICS_LABEL / f"{spec.name}.mp4"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), KINETICS_FPS,
                                 (spec.scene.width, spec.scene.height))
        if not writer.isOpened():
            raise RuntimeError(f"OpenCV cannot write the MPEG-4 clip {path}")
        for frame in frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        writer.release()
    (root / KINETICS_CSV).write_text("\n".join(rows) + "\n")


def write_tapvid(root: str | Path, benchmark: str = "TAPVid-DAVIS") -> None:
    """Write the synthetic ``benchmark`` pickle (Kinetics: CSV and clips) under ``root``."""
    if benchmark == "TAPVid-Kinetics":
        write_kinetics(root)
        return
    if benchmark not in FILES:
        raise ValueError(f"no synthetic TAP-Vid data set {benchmark!r}; valid: "
                         f"{', '.join(BENCHMARKS)}")
    name, container = FILES[benchmark]
    entries = [(spec.name, video_entry(spec)) for spec in SPECS[benchmark]]
    data = dict(entries) if container is dict else [entry for _, entry in entries]
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    (root / name).write_bytes(pickle.dumps(data, protocol=PICKLE_PROTOCOL))

"""Synthetic OTB-2015 data set: single targets that walk, cross and get occluded.

:func:`write_otb` writes the exact OTB-2015 layout (``<Seq>/img/0001.jpg ...``,
``<Seq>/groundtruth_rect.txt`` in 1-based pixels). The target is the walker that stays in
view throughout and is the most occluded at some frame, hidden partly or wholly as it
crosses another person or passes behind the occluder; its ground truth is the amodal box,
also while hidden, as OTB annotates occluded targets. The default set exercises the OTB
quirks the reader handles: tab-separated ground truth (like Crossing), no final newline
(like Human3), grayscale frames (like Car4) and images numbered from a later frame (like
BlurCar1). Its names are not OTB-100 names, so no toolkit frame range applies.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneConfig

#: Benchmarks whose layout :func:`write_otb` writes.
BENCHMARKS = ("OTB",)
#: JPEG quality of the frames.
JPEG_QUALITY = 90
#: Digits of OTB image file names (``0001.jpg``).
IMAGE_DIGITS = 4
#: Scene parameters shared by the default sequences: few people on a small frame, slow
#: enough that the target stays in view for the whole (short) sequence.
_SCENE = {
    "num_objects": 3,
    "num_crossings": 1,
    "num_static_persons": 0,
    "num_occluders": 1,
    "object_height_range": (60.0, 100.0),
    "speed_range": (1.0, 2.5),
}


@dataclass(frozen=True)
class SyntheticOTBSequence:
    """One synthetic OTB sequence (``name`` must not be an OTB-100 name).

    ``first_frame``, ``separator``, ``grayscale`` and ``trailing_newline`` reproduce variants
    real OTB sequences have (BlurCar1 starts at 247, Crossing uses tabs).
    """

    name: str
    scene: SceneConfig
    first_frame: int = 1
    separator: str = ","
    grayscale: bool = False
    trailing_newline: bool = True


@dataclass(frozen=True)
class OTBSpec:
    """A synthetic OTB data set: its sequences."""

    sequences: tuple[SyntheticOTBSequence, ...]


DEFAULT_SPEC = OTBSpec(sequences=(
    SyntheticOTBSequence(
        "SynWalker", SceneConfig(width=320, height=240, num_frames=40, seed=0, **_SCENE)),
    SyntheticOTBSequence(
        "SynCrossing", SceneConfig(width=360, height=240, num_frames=36, seed=4, **_SCENE),
        separator="\t"),
    SyntheticOTBSequence(
        "SynLateStart", SceneConfig(width=320, height=240, num_frames=30, seed=10, **_SCENE),
        first_frame=11, grayscale=True, trailing_newline=False),
))
"""The embedded default: three short sequences (see the module docstring)."""


def annotated_frames(benchmark: str = "OTB", split: str | None = None,
                     spec: OTBSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each sequence ``spec`` writes (OTB has no splits; every one is annotated).

    Known without writing anything, e.g. to plan work on data not generated yet.
    """
    return {s.name: s.scene.num_frames for s in spec.sequences}


def choose_target(video: SyntheticVideo) -> int:
    """Return the id of the walker that stays in frame and is most occluded at some point."""
    width, height = video.width, video.height
    inside: dict[int, bool] = {o.id: True for o in video.objects
                               if o.role is ObjectRole.PEDESTRIAN}
    least_visible = dict.fromkeys(inside, 1.0)
    for frame in video:
        present = {a.id: a for a in frame.objects}
        for object_id in inside:
            annotation = present.get(object_id)
            if annotation is None:
                inside[object_id] = False
                continue
            x, y, w, h = annotation.box
            if x < 0 or y < 0 or x + w > width or y + h > height:
                inside[object_id] = False
            least_visible[object_id] = min(least_visible[object_id], annotation.visibility)
    candidates = [i for i, ok in inside.items() if ok]
    if not candidates:
        raise ValueError(
            f"no walking person stays inside the {width}x{height} image for all "
            f"{video.num_frames} frames (seed {video.config.seed}); use a slower or shorter scene"
        )
    return min(candidates, key=lambda i: (least_visible[i], i))


def target_boxes(video: SyntheticVideo, target: int) -> np.ndarray:
    """Return the target's ``(T, 4)`` boxes in OTB's 1-based pixels (as written to the file)."""
    rows = []
    for frame in video:
        box = next(a.box for a in frame.objects if a.id == target)
        rows.append([box[0] + 1.0, box[1] + 1.0, box[2], box[3]])
    return np.asarray(rows, dtype=np.float64)


def render_target(scene: SceneConfig, grayscale: bool = False,
                  ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Render ``scene`` and follow its target: BGR (or grey) frames, 1-based boxes, visibility.

    What every SOT layout's synthetic default writes (the layouts differ in file names only).
    """
    video = render_scene(scene)
    target = choose_target(video)
    code = cv2.COLOR_RGB2GRAY if grayscale else cv2.COLOR_RGB2BGR
    images = [cv2.cvtColor(frame.image, code) for frame in video]
    visibility = np.array([next(a.visibility for a in frame.objects if a.id == target)
                           for frame in video], dtype=np.float64)
    return images, target_boxes(video, target), visibility


def write_images(folder: Path, images: list[np.ndarray], names: list[str]) -> None:
    """Write ``images`` as JPEGs named ``names`` into ``folder`` (created)."""
    folder.mkdir(parents=True, exist_ok=True)
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]
    for image, name in zip(images, names, strict=True):
        if not cv2.imwrite(str(folder / name), image, params):
            raise OSError(f"could not write {folder / name}")


def write_sequence(root: Path, sequence: SyntheticOTBSequence) -> Path:
    """Render one sequence into ``root/<name>/`` (``img/`` and ``groundtruth_rect.txt``)."""
    images, boxes, _ = render_target(sequence.scene, sequence.grayscale)
    folder = Path(root) / sequence.name
    write_images(folder / "img", images, [
        f"{sequence.first_frame + i:0{IMAGE_DIGITS}d}.jpg" for i in range(len(images))])
    lines = [sequence.separator.join(f"{v:.0f}" for v in row) for row in boxes]
    text = "\n".join(lines) + ("\n" if sequence.trailing_newline else "")
    (folder / "groundtruth_rect.txt").write_text(text)
    return folder


def write_otb(root: Path, benchmark: str = "OTB", spec: OTBSpec = DEFAULT_SPEC) -> None:
    """Write the synthetic OTB data set of ``spec`` into ``root`` (``benchmark`` must be OTB)."""
    if benchmark not in BENCHMARKS:
        raise ValueError(f"write_otb writes {BENCHMARKS}, not {benchmark!r}")
    names = [s.name.lower() for s in spec.sequences]
    if len(set(names)) != len(names):
        raise ValueError(f"sequence names must be unique (case-insensitively): {names}")
    for sequence in spec.sequences:
        write_sequence(Path(root), sequence)

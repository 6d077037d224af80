"""Synthetic JHMDB data set (pose propagation), in JHMDB's exact layout.

:func:`write_jhmdb` writes ``Rename_Images/<action>/<video>/*.png`` frames,
``joint_positions/<action>/<video>/joint_positions.mat`` (``pos_img`` ``(2, 15, T)``,
1-based) and ``splits/<action>_test_split1.txt``. Each video follows one walking person
(scene object 1) whose 15 joints come from the shared stick figure of
:mod:`~unitrack_env.datasets.synthetic.poses`; a second person crosses it, in front or
behind, so the joints are briefly occluded as in a real clip. Like JHMDB, every joint is
annotated in every frame, occluded or not.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.jhmdb import MATLAB_ORIGIN, SPLIT_TEST, SPLIT_TRAIN
from unitrack_env.datasets.synthetic.poses import (
    JHMDB_FROM_SKELETON,
    select_joints,
    skeleton_pixels,
)
from unitrack_env.datasets.synthetic.scene import render_scene
from unitrack_env.datasets.synthetic.scene_model import SceneConfig

#: The tracked person of every synthetic JHMDB scene.
PUPPET_ID = 1
#: Frame size of JHMDB (width, height).
JHMDB_SIZE = (320, 240)
#: Split index of the split files written.
SPLIT_INDEX = 1


@dataclass(frozen=True)
class VideoSpec:
    """One synthetic JHMDB video (object 1 is the annotated person; split 1 train, 2 test)."""

    action: str
    video: str
    scene: SceneConfig
    split: int = 2

    @property
    def name(self) -> str:
        """``"<action>/<video>"``, the environment's sequence name."""
        return f"{self.action}/{self.video}"


def _scene(seed: int, frames: int, speed: tuple[float, float]) -> SceneConfig:
    return SceneConfig(
        width=JHMDB_SIZE[0], height=JHMDB_SIZE[1], num_frames=frames, num_objects=2,
        num_crossings=1, num_static_persons=0, num_occluders=0, seed=seed,
        object_height_range=(150.0, 185.0), speed_range=speed, max_vertical_speed=0.2,
        crossing_offset_range=(0.04, 0.12), wobble_amplitude=1.0, background_cell=24,
    )


@dataclass(frozen=True)
class JHMDBSpec:
    """A synthetic JHMDB data set: its videos in writing order."""

    videos: tuple[VideoSpec, ...]

    def __post_init__(self) -> None:
        names = [v.name for v in self.videos]
        if len(set(names)) != len(names):
            raise ValueError(f"JHMDBSpec.videos: duplicate action/video in {names}")


#: The embedded default: three short clips of two actions (JHMDB clips are 15-40 frames).
#: As in JHMDB, the annotated person is in full view in the first frame (the propagation
#: tasks start from it); in ``le_med_2`` and ``ri_med_1`` it then walks behind the other
#: person (down to 20% and 24% visible) and comes out again.
DEFAULT_SPEC = JHMDBSpec(videos=(
    VideoSpec("walk", "SYN_walk_f_cm_np1_fr_med_1", _scene(31, 40, (0.8, 1.6)), split=2),
    VideoSpec("walk", "SYN_walk_f_cm_np1_le_med_2", _scene(32, 40, (1.5, 2.2)), split=1),
    VideoSpec("run", "SYN_run_f_cm_np1_ri_med_1", _scene(33, 36, (2.0, 3.0)), split=2),
))


def annotated_frames(benchmark: str = "JHMDB", split: str | None = None,
                     spec: JHMDBSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each video of ``split`` (None: any; ``train``/``test`` of split set 1).

    Every video is annotated. Known without writing anything, e.g. to plan work on data not
    generated yet.
    """
    wanted = {None: None, "train": SPLIT_TRAIN, "test": SPLIT_TEST}[split]
    return {v.name: v.scene.num_frames for v in spec.videos if wanted in (None, v.split)}


def puppet_joints(spec: VideoSpec) -> np.ndarray:
    """Return the ``(T, 15, 2)`` 0-based JHMDB joints of a video's annotated person."""
    video = render_scene(spec.scene)
    puppet = video.object(PUPPET_ID)
    return np.stack([select_joints(skeleton_pixels(puppet, t), JHMDB_FROM_SKELETON)
                     for t in range(video.num_frames)])


MAT_HEADER: bytes = b"MATLAB 5.0 MAT-file, written by unitrack-env".ljust(116)
"""The text header of the MAT files we write (MATLAB 5: 116 bytes of free text)."""


def joint_positions_mat(joints: np.ndarray) -> bytes:
    """The bytes of a ``joint_positions.mat`` (``pos_img``, 1-based) for ``(T, 15, 2)`` joints."""
    # lazy: start-up cost (scipy.io)
    from scipy.io import savemat

    pos = (np.asarray(joints, dtype=np.float64) + MATLAB_ORIGIN).transpose(2, 1, 0)
    buffer = io.BytesIO()
    savemat(buffer, {"pos_img": np.ascontiguousarray(pos)}, do_compression=False)
    # scipy writes the time to the second into the 116-byte text header; a fixed text makes
    # the same joints the same bytes (result digests, byte-equal comparisons).
    return MAT_HEADER + buffer.getvalue()[len(MAT_HEADER):]


def write_jhmdb(root: str | Path, benchmark: str = "JHMDB", *,
                spec: JHMDBSpec = DEFAULT_SPEC) -> None:
    """Render ``spec`` under ``root`` in JHMDB's layout (``benchmark="JHMDB"``)."""
    if benchmark != "JHMDB":
        raise ValueError(f"write_jhmdb writes JHMDB only, not {benchmark!r}")
    root = Path(root)
    splits: dict[str, list[str]] = {}
    for spec_video in spec.videos:
        frame_dir = root / "Rename_Images" / spec_video.action / spec_video.video
        frame_dir.mkdir(parents=True, exist_ok=True)
        video = render_scene(spec_video.scene)
        puppet = video.object(PUPPET_ID)
        joints = []
        for frame in video:
            path = frame_dir / f"{frame.index + 1:05d}.png"
            if not cv2.imwrite(str(path), frame.image[:, :, ::-1]):
                raise OSError(f"{path}: cv2.imwrite failed to write the PNG frame")
            joints.append(select_joints(skeleton_pixels(puppet, frame.index),
                                        JHMDB_FROM_SKELETON))
        mat_dir = root / "joint_positions" / spec_video.action / spec_video.video
        mat_dir.mkdir(parents=True, exist_ok=True)
        (mat_dir / "joint_positions.mat").write_bytes(joint_positions_mat(np.stack(joints)))
        splits.setdefault(spec_video.action, []).append(
            f"{spec_video.video}.avi {spec_video.split}")
    split_dir = root / "splits"
    split_dir.mkdir(parents=True, exist_ok=True)
    for action, lines in splits.items():
        (split_dir / f"{action}_test_split{SPLIT_INDEX}.txt").write_text(
            "".join(line + " \n" for line in lines), encoding="ascii")

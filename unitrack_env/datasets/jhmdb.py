"""Reader for JHMDB pose propagation (frames + ``joint_positions.mat``).

Reads ``Rename_Images/<action>/<video>/*.png``,
``joint_positions/<action>/<video>/joint_positions.mat`` and optional
``splits/<action>_test_split<k>.txt`` (HMDB51 format: 1 = train, 2 = test).
``pos_img`` ``(2, 15, T)`` holds sub-pixel joints in MATLAB's 1-based convention (the
top-left pixel's centre is ``(1, 1)``). They are returned 0-based (``pos_img - 1``), as the
UniTrack/CRW/TimeCycle loaders and evaluation script use them (``lbls_coord = pos_img - 1``)
and as an agent samples feature maps; PCK depends only on differences, so scores do not
change. JHMDB annotates occluded joints too, so every joint counts as visible.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.sot import read_image_size
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.spaces.limits import COORD_MAX

JHMDB_JOINT_NAMES: tuple[str, ...] = (
    "neck",
    "belly",
    "face",
    "right_shoulder",
    "left_shoulder",
    "right_hip",
    "left_hip",
    "right_elbow",
    "left_elbow",
    "right_knee",
    "left_knee",
    "right_wrist",
    "left_wrist",
    "right_ankle",
    "left_ankle",
)
"""The 15 JHMDB puppet joints in ``pos_img`` order (JHMDB README; mmpose's ``jhmdb`` dataset
info lists the same order, calling the third joint "head")."""

NUM_JOINTS: int = len(JHMDB_JOINT_NAMES)

JHMDB_SKELETON: tuple[tuple[int, int], ...] = (
    (13, 9), (9, 5), (5, 1), (1, 6), (6, 10), (10, 14),  # legs through the belly
    (1, 0), (0, 2),  # belly - neck - face
    (0, 3), (3, 7), (7, 11),  # right arm
    (0, 4), (4, 8), (8, 12),  # left arm
)
"""Limbs as joint-index pairs, for drawing."""

MATLAB_ORIGIN: float = 1.0
"""Subtracted from ``pos_img`` to get 0-based pixel coordinates."""

SPLIT_TRAIN: int = 1
SPLIT_TEST: int = 2
_SPLIT_LABELS = {"train": SPLIT_TRAIN, "test": SPLIT_TEST}
_SPLIT_FILE = re.compile(r"^(?P<action>.+)_test_split(?P<k>\d+)\.txt$")


def read_joint_positions(path: str | Path, *, zero_based: bool = True) -> np.ndarray:
    """Read ``pos_img`` ``(2, 15, T)`` of a ``joint_positions.mat`` as ``(T, 15, 2)`` ``(x, y)``.

    ``zero_based`` subtracts MATLAB's 1; a bad file or shape raises DataFormatError.
    """
    # lazy: start-up cost (scipy.io; keeps ``import unitrack_env`` fast)
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        mat = loadmat(str(path))
    except (OSError, ValueError, NotImplementedError, MatReadError) as err:
        raise DataFormatError(path, f"cannot read MATLAB file ({err})") from err
    if "pos_img" not in mat:
        raise DataFormatError(path, "has no 'pos_img' variable", field="pos_img")
    try:
        pos = np.asarray(mat["pos_img"], dtype=np.float64)
    except (TypeError, ValueError):
        raise DataFormatError(path, f"pos_img must be a numeric array, got MATLAB class "
                                    f"{mat['pos_img'].dtype}", field="pos_img") from None
    if pos.ndim == 2 and pos.shape == (2, NUM_JOINTS):  # a one-frame video loses its last axis
        pos = pos[:, :, None]
    if pos.ndim != 3 or pos.shape[:2] != (2, NUM_JOINTS):
        raise DataFormatError(
            path, f"pos_img has shape {pos.shape}, expected (2, {NUM_JOINTS}, T)", field="pos_img"
        )
    keypoints = pos.transpose(2, 1, 0).copy()
    if not np.isfinite(keypoints).all():
        frame, joint, _ = (int(v) for v in np.argwhere(~np.isfinite(keypoints))[0])
        raise DataFormatError(
            path, f"joint {joint} ({JHMDB_JOINT_NAMES[joint]}) of frame {frame + 1} is "
                  f"{keypoints[frame, joint].tolist()}; every JHMDB joint is annotated with "
                  "finite coordinates", field="pos_img")
    if np.abs(keypoints).max() > COORD_MAX:
        frame, joint, _ = (int(v) for v in np.argwhere(np.abs(keypoints) > COORD_MAX)[0])
        raise DataFormatError(
            path, f"joint {joint} ({JHMDB_JOINT_NAMES[joint]}) of frame {frame + 1} is "
                  f"{keypoints[frame, joint].tolist()}, outside the observation bounds "
                  f"[-{COORD_MAX:g}, {COORD_MAX:g}] pixels", field="pos_img")
    if zero_based:
        keypoints -= MATLAB_ORIGIN
    return keypoints


@dataclass(frozen=True)
class PoseSequence:
    """One JHMDB video: ``"<action>/<video>"``, its PNGs, ``(T, 15, 2)`` 0-based joints, size."""

    name: str
    frame_paths: tuple[Path, ...]
    keypoints: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        if self.keypoints.shape != (len(self.frame_paths), NUM_JOINTS, 2):
            raise ValueError(f"{self.name}: keypoints and frames disagree")
        self.keypoints.setflags(write=False)

    @property
    def action(self) -> str:
        """The action class folder."""
        return self.name.split("/", 1)[0]

    @property
    def video(self) -> str:
        """The video folder."""
        return self.name.split("/", 1)[1]

    @property
    def num_frames(self) -> int:
        """Number of frames."""
        return len(self.frame_paths)

    @property
    def init_keypoints(self) -> np.ndarray:
        """The first frame's joints (what a propagation agent is given)."""
        return self.keypoints[0]


def read_split_files(split_dir: str | Path, split_index: int = 1) -> dict[str, int]:
    """Read ``<action>_test_split<k>.txt`` files into ``{"<action>/<video>": 1 or 2}``."""
    split_dir = Path(split_dir)
    membership: dict[str, int] = {}
    files = sorted(split_dir.glob(f"*_test_split{split_index}.txt"))
    if not files:
        raise DataFormatError(split_dir, f"no *_test_split{split_index}.txt files")
    for path in files:
        action = _SPLIT_FILE.match(path.name).group("action")  # type: ignore[union-attr]
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if not line.strip():
                continue
            parts = line.split()
            if len(parts) != 2 or parts[1] not in ("0", "1", "2"):
                raise DataFormatError(path, f"expected '<video>.avi <1|2>', got {line!r}",
                                      line=number)
            membership[f"{action}/{Path(parts[0]).stem}"] = int(parts[1])
    return membership


class JHMDBDataset(SequenceDataset[PoseSequence]):
    """The annotated videos of a JHMDB folder.

    ``split`` None lists every annotated video; ``"train"``/``"test"`` reads split file set
    ``split_index`` (1-3) from ``split_dir`` (default ``<root>/splits``).
    """

    def __init__(
        self,
        root: str | Path,
        split: str | None = None,
        split_index: int = 1,
        split_dir: str | Path | None = None,
    ) -> None:
        self.root = Path(root)
        self.frame_dir = self.root / "Rename_Images"
        self.joint_dir = self.root / "joint_positions"
        for folder in (self.frame_dir, self.joint_dir):
            if not folder.is_dir():
                raise DataFormatError(
                    folder, "missing; root= must hold Rename_Images/ and joint_positions/"
                )
        names = sorted(
            f"{mat.parent.parent.name}/{mat.parent.name}"
            for mat in self.joint_dir.glob("*/*/joint_positions.mat")
        )
        if split is not None:
            if split not in _SPLIT_LABELS:
                raise ValueError(f"split must be None, 'train' or 'test'; got {split!r}")
            membership = read_split_files(
                Path(split_dir) if split_dir is not None else self.root / "splits", split_index
            )
            names = [n for n in names if membership.get(n) == _SPLIT_LABELS[split]]
        if not names:
            raise DataFormatError(self.joint_dir, "no <action>/<video>/joint_positions.mat")
        self.sequence_names: list[str] = names

    def load(self, name: str) -> PoseSequence:
        """Read one video's frame list and joints."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(
                f"no JHMDB video '{name}' in {self.root} (names are '<action>/<video>'); "
                f"{len(self.sequence_names)} available, e.g. {self.sequence_names[0]}"
            )
        mat = self.joint_dir / name / "joint_positions.mat"
        keypoints = read_joint_positions(mat)
        frame_folder = self.frame_dir / name
        if not frame_folder.is_dir():
            raise DataFormatError(frame_folder, f"frames of '{name}' missing")
        frames = tuple(sorted(p for p in frame_folder.iterdir() if p.suffix.lower() == ".png"))
        if len(frames) < len(keypoints):
            raise DataFormatError(
                mat, f"annotates {len(keypoints)} frames but {frame_folder} has {len(frames)}"
            )
        frames = frames[: len(keypoints)]
        return PoseSequence(name, frames, keypoints, read_image_size(frames[0]))

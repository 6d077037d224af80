"""Pose propagation on JHMDB (frames + ``joint_positions.mat``, 15 puppet joints)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.jhmdb import JHMDBBenchmark
from unitrack_env.datasets.jhmdb import JHMDB_SKELETON, NUM_JOINTS, PoseSequence
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import InvalidActionError
from unitrack_env.metrics.pose import PAPER_PCK_THRESHOLDS, frame_pck
from unitrack_env.render import draw_skeleton

#: PCK threshold of the per-step reward.
REWARD_ALPHA = 0.1


class JHMDBEnv(SequenceEnv[PoseSequence]):
    """Pose propagation: follow one person's 15 joints through a JHMDB video.

    ## Description
    Each episode is one JHMDB video (``"<action>/<video>"``). The agent is given the first
    frame's 15 joints (neck, belly, face, shoulders, hips, elbows, knees, wrists, ankles, in
    ``joint_positions.mat`` order) and must predict them in every frame, as in the UniTrack
    paper's pose propagation (appendix, JHMDB table; the propagation itself is Gaussian
    belief maps carried by the appearance model's affinities). The final metrics are
    PCK@0.1 and PCK@0.2.

    With no ``root`` (and no ``UNITRACK_DATA``), the environment reads a small deterministic
    synthetic data set in JHMDB's exact layout (320x240 PNG frames, ``pos_img`` in
    ``joint_positions.mat``; a walking person crossed by another one), generated once into
    the user cache.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, the frame as uint8 RGB at its native
      size (320x240 in JHMDB).
    - ``init_keypoints``: ``Box((15, 2), float32)``: the first frame's joints ``(x, y)`` in
      0-based pixels (``pos_img - 1``; the top-left pixel's centre is ``(0, 0)``). This is
      the task's input; it is the same in every step of an episode. No other ground truth
      is observed.

    ## Action space
    ``Box((15, 2), float32)``: the predicted joints of the current frame, same coordinates
    and joint order as ``init_keypoints``. Wrong shapes, non-numbers and NaN/infinite
    values raise ``InvalidActionError`` before anything is recorded.

    ## Rewards
    PCK@0.1 of the frame (:func:`unitrack_env.metrics.pose.frame_pck`): the fraction of the
    15 joints within ``0.1 x`` the normaliser of the ground truth. The default normaliser
    is ``0.6 x`` the diagonal of the box spanned by the frame's ground-truth joints, the one
    of the authors' evaluation script (CRW/TimeCycle ``eval_pck``), which produced every
    number of the paper's JHMDB table. The first frame is the given input and scores 0
    (it is never scored).

    ## Starting state
    ``reset`` returns the first frame and ``init_keypoints``; the agent answers that frame
    too (echoing ``init_keypoints`` is fine: frame 1 is not scored), so an episode has one
    step per frame. ``info`` holds ``sequence``, ``frame_index`` (1-based), ``seq_length``,
    ``frame_rate`` (30, JHMDB's clips are 30 fps), ``image_size`` ``(height, width)`` and
    ``synthetic``.

    ## Episode end
    ``terminated=True`` after the last frame. ``info["metrics"]`` holds ``PCK@0.1`` and
    ``PCK@0.2`` of the video (frames 2..T, per joint, then averaged over the 15 joints, as
    the authors' script does) as fractions. Results are written per video as
    ``<folder>/<action>/<video>/joint_positions.mat`` with ``pos_img`` ``(2, 15, T)`` in
    JHMDB's own 1-based convention (the predicted frame 1 included), readable by the same
    reader; :meth:`score_folder` pools the joints of all videos before averaging, like
    the script.

    ## Arguments
    - ``root``: the JHMDB folder holding ``Rename_Images/`` and ``joint_positions/``
      (default: ``$UNITRACK_DATA/JHMDB`` if that variable is set, else the synthetic data).
    - ``split``: None (every annotated video), ``"train"`` or ``"test"`` of the split files.
    - ``split_index``: 1, 2 or 3 (JHMDB's splits); ``split_dir`` where they are.
    - ``sequences``: restrict to these ``"<action>/<video>"`` names.
    - ``normaliser``: ``"box_diagonal"`` (default, the paper's) or ``"box_max_side"``.
    - ``thresholds``: PCK thresholds of the final metrics (default ``(0.1, 0.2)``).
    - ``max_frame_size``: bound of the frame space ``(height, width)``.
    - ``decode_frames``: when False, ``frame`` is a 1x1 black placeholder.
    - ``shuffle``: visit sequences in a seeded random order.
    - ``render_mode``: ``"rgb_array"`` draws the predicted skeleton, one colour per joint.

    ## Version history
    - v0: initial version.
    """

    frame_size_source = "the video's first frame"

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        split: str | None = None,
        split_index: int = 1,
        split_dir: str | os.PathLike | None = None,
        sequences: list[str] | tuple[str, ...] | None = None,
        normaliser: str = "box_diagonal",
        thresholds: tuple[float, ...] = PAPER_PCK_THRESHOLDS,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        bench = JHMDBBenchmark.build(root, split, split_index, split_dir, normaliser, thresholds)
        self._use_benchmark(bench, sequences, bench.dataset.root)
        self.normaliser = normaliser
        self.thresholds = tuple(float(t) for t in thresholds)
        joints = spaces.Box(-ut_spaces.COORD_MAX, ut_spaces.COORD_MAX, (NUM_JOINTS, 2),
                            np.float32)
        self.observation_space = spaces.Dict(
            {"frame": ut_spaces.Image(*self.max_frame_size), "init_keypoints": joints})
        self.action_space = spaces.Box(-ut_spaces.COORD_MAX, ut_spaces.COORD_MAX,
                                       (NUM_JOINTS, 2), np.float32)
        self._predictions: list[np.ndarray] = []

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name)
        width, height = sequence.image_size
        self._check_frame_size(name, width, height, axes=False)
        self._sequence = sequence
        self._predictions = []
        return dict(seq_length=sequence.num_frames, frame_rate=30, image_size=(height, width),
                    synthetic=self.synthetic, has_ground_truth=True)

    def _observe(self, t: int) -> dict[str, Any]:
        image = self._read_frame(t)
        return {"frame": image, "init_keypoints": self._sequence.init_keypoints.astype(np.float32)}

    def _frame_info(self, t: int) -> dict[str, Any]:
        return {"frame_index": t + 1}

    def _record(self, action: Any, t: int) -> tuple[float, dict[str, Any]]:
        """Record frame ``t``'s joints; the reward is PCK@0.1 (frame 1 is not scored)."""
        pred = _validate_joints(action)
        self._predictions.append(pred)
        self._answer = pred
        if t == 0:
            return 0.0, {}
        reward = frame_pck(pred, self._sequence.keypoints[t], REWARD_ALPHA, self.normaliser)
        return reward, {"pck": reward}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> np.ndarray:
        """Return the ``(steps, 15, 2)`` joints recorded so far (0-based pixels)."""
        if not self._predictions:
            return np.zeros((0, NUM_JOINTS, 2))
        return np.stack(self._predictions)

    def episode_metrics(self) -> dict[str, float]:
        """PCK at every threshold of the recorded video (frame 1 not scored)."""
        pred = self.episode_results()
        return self.scoring.counts(pred, self._sequence.keypoints[: len(pred)]).as_dict()

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the frame with the last predicted skeleton (``init_keypoints`` at reset)."""
        canvas = np.ascontiguousarray(self._frame).copy()
        pose = self._answer if self._answer is not None else self._sequence.keypoints[0]
        draw_skeleton(canvas, pose, JHMDB_SKELETON)
        return canvas


def _validate_joints(action: Any) -> np.ndarray:
    """Return the action as ``(15, 2)`` float64, or raise InvalidActionError."""
    arr = np.asarray(action)
    if arr.shape != (NUM_JOINTS, 2):
        raise InvalidActionError(
            f"action must be the ({NUM_JOINTS}, 2) predicted joints (x, y); got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InvalidActionError(f"action must hold numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        joint = int(np.argwhere(~np.isfinite(arr))[0, 0])
        raise InvalidActionError(f"joint {joint} is NaN or infinite: {arr[joint].tolist()}")
    if np.abs(arr).max() > ut_spaces.COORD_MAX:
        joint = int(np.argwhere(np.abs(arr) > ut_spaces.COORD_MAX)[0, 0])
        raise InvalidActionError(
            f"joint {joint} {arr[joint].tolist()} is outside the action space: x and y must lie "
            f"in [-{ut_spaces.COORD_MAX:g}, {ut_spaces.COORD_MAX:g}] pixels")
    return arr

"""Single object tracking (box propagation) on OTB-2015 data."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.otb import OTBBenchmark, format_box_value
from unitrack_env.datasets.sot import SOTSequence
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import DataFormatError, InvalidActionError
from unitrack_env.metrics.sot import frame_iou
from unitrack_env.render import draw_boxes

#: Colour of the agent's box in renderings (RGB).
ACTION_COLOUR = (0, 255, 0)
#: Colour of the initial box drawn before the first step (RGB).
INIT_COLOUR = (255, 200, 0)


def _canonical(box: np.ndarray) -> np.ndarray:
    """Round each number to its shortest float32 decimal, so the result file reads back exactly.

    The recorded box is what :meth:`OTBEnv.write_episode` writes and what the episode's
    metrics are computed from; reading the file back gives the very same float64 numbers,
    so ``score_folder`` reproduces ``info["metrics"]`` exactly.
    """
    return np.array([float(format_box_value(v)) for v in box], dtype=np.float64)


def validate_box(action: Any) -> np.ndarray:
    """Check a box action and return it as ``(4,)`` float64 ``(x, y, w, h)``.

    Raises:
        InvalidActionError: not 4 numbers, NaN or infinite values, or a negative size.
    """
    try:
        box = np.asarray(action)
    except (TypeError, ValueError) as err:
        raise InvalidActionError(f"action must be 4 numbers (x, y, w, h): {err}") from None
    if box.shape != (4,):
        raise InvalidActionError(
            f"action must have shape (4,) as (x, y, w, h) in the ground truth's 1-based pixels; "
            f"got shape {box.shape}"
        )
    if not (np.issubdtype(box.dtype, np.floating) or np.issubdtype(box.dtype, np.integer)):
        raise InvalidActionError(f"action must hold numbers, got dtype {box.dtype}")
    box = box.astype(np.float64)
    if not np.isfinite(box).all():
        raise InvalidActionError(f"action has a non-finite number: {box.tolist()}")
    if box[2] < 0 or box[3] < 0:
        raise InvalidActionError(f"action has a negative width or height: {box.tolist()}")
    if np.abs(box).max() > ut_spaces.COORD_MAX:
        raise InvalidActionError(
            f"action exceeds the coordinate bound {ut_spaces.COORD_MAX:g}: {box.tolist()}"
        )
    return box


class OTBEnv(SequenceEnv[SOTSequence]):
    """Single object tracking by box propagation on an OTB-2015-layout data set.

    ## Description
    Each episode is one video sequence of OTB-2015 (OTB-100, OTB-50, or any folder in the
    OTB layout). The agent is given the target's box in the first frame and answers with
    its box in every frame, like the OTB toolkit's one-pass evaluation (OPE). The
    environment scores every answer against the ground truth and, at the end of the
    episode, reports the toolkit's success AUC and precision at 20 pixels.

    The layout read is ``<root>/<Seq>/img/0001.jpg ...`` and ``groundtruth_rect.txt``
    (commas, tabs or spaces; ``groundtruth_rect.<k>.txt`` for the folders with two
    targets), with the toolkit's frame ranges for the sequences that do not start at
    frame 1 (David 300-770, BlurCar1 247-988, Tiger1 without its first 5 frames, ...; see
    :mod:`unitrack_env.datasets.otb`). A copy whose ground truth is shorter than the
    toolkit's range (a trimmed fixture, e.g. 199 of Human3's 1698 frames) is played over
    its annotated frames only, with a warning from the reader.

    With no ``root`` (and no ``UNITRACK_DATA``), the environment reads a small
    deterministic synthetic data set in the exact OTB layout (three sequences of a walking
    person who crosses another one and passes behind an occluder; one ground truth file
    tab-separated, one grayscale sequence whose images start at ``0011.jpg``), generated
    once into the user cache, so it works offline.

    ``UniTrack/LaSOT-v0`` reads LaSOT (``<class>/<class>-<n>/img/%08d.jpg``,
    ``groundtruth.txt``, ``full_occlusion.txt`` and ``out_of_view.txt`` as one line of
    comma-separated flags, ``nlp.txt`` given as ``info["nlp"]``; ``split=`` as above, default
    the root's ``testing_set.txt``). It scores by the LaSOT toolkit's rules: a frame where the
    target is absent (either flag) is removed before scoring but the rates stay divided by all
    frames, so it fails both plots; ``NormPrecision`` is the normalized precision plot (centre
    error over the true box's width and height) at 0.2. ``UniTrack/UAV123-v0`` reads UAV123
    (``data_seq/UAV123[_10fps]/<seq>/%06d.jpg``, ``anno/UAV123[_10fps]/<seq>.txt``, a NaN row
    = target absent, scored by the OTB toolkit's rule for invalid ground truth;
    ``variant="10fps"``; a sub-sequence such as ``person12_1`` plays its frame range of its
    video's folder, from the toolkit's ``configSeqs.m``; ``split="UAV20L"`` reads UAV20L's
    whole videos). ``UniTrack/NfS-v0`` reads NfS (``<seq>/<fps>/<seq>/%05d.jpg`` and
    ``<seq>/<fps>/<seq>.txt`` VATIC rows, ``variant="30"`` or ``"240"``; a 30 fps file holding
    the 240 fps rows keeps every eighth) scored by the OTB rules. All three have a
    synthetic default in their own layout; LaSOT and UAV123 add ``NormPrecision``.
    ``UniTrack/GOT10k-v0`` reads GOT-10k (``<split>/list.txt``, ``<seq>/%08d.jpg``,
    ``groundtruth.txt``, ``absence.label``, ``cover.label``, ``cut_by_image.label``;
    ``split="val"`` by default, ``"test"`` has the first box only) and reports its AO, SR0.5
    and SR0.75 over the frames after the first with ``cover > 0``, boxes clipped to the
    image, frames pooled over sequences; results are written in the evaluation server's
    layout ``<seq>/<seq>_001.txt`` (a run adds ``<seq>_time.txt`` and, with ``--repeats``,
    ``<seq>_002.txt`` ...). No real GOT-10k sample is in the project's fixtures: it
    is tested on its synthetic default only. ``UniTrack/TrackingNet-v0`` reads TrackingNet
    (``TRAIN_<k>/`` and ``TEST/``, each with ``frames/<seq>/<i>.jpg`` and
    ``anno/<seq>.txt``; ``split="train"`` by default, ``"TRAIN_<k>"`` or ``"test"``, whose
    annotation is the first box only) with the columns of LaSOT; its results are the
    server's flat ``<seq>.txt`` files. No real TrackingNet sample is in the fixtures either.
    More in docs/envs/sot-protocols.md.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, the frame as uint8 RGB at its native
      size (grayscale OTB sequences are given as RGB with three equal channels).
    - ``init_box``: ``Box((4,), float32)``: the target's box in the first frame,
      ``(x, y, w, h)`` in the ground truth file's 1-based pixels (the top-left pixel is
      ``(1, 1)``), the same at every step of the episode. It is the task's input; the
      ground truth of later frames never appears in observations.

    ## Action space
    ``Box((4,), float32)``: the target's box ``(x, y, w, h)`` in the current frame, in the
    same 1-based pixels (finite, ``w, h >= 0``; any numeric dtype of shape ``(4,)`` is
    accepted). NaN or infinite numbers, negative sizes and other shapes raise
    ``InvalidActionError`` before anything is recorded. A zero-size box is allowed and is
    scored as the OTB toolkit scores it (replaced by the previous frame's box).

    ## Rewards
    The IoU of the box the OTB toolkit scores for this frame with the frame's ground truth:
    on the first frame the toolkit scores the given box (so the reward is 1), on later
    frames the agent's box (a zero-size box is replaced by the previous frame's scored
    box). Frames whose ground truth is not a valid box (NaN, ``w <= 0`` or ``h <= 0``)
    give 0. The episode return divided by the number of frames with valid ground truth is
    ``AverageOverlap`` (divided by all frames when every frame is valid);
    ``info["iou"]`` repeats the reward.

    ## Starting state
    ``reset`` returns the first evaluated frame of the chosen sequence (frame 1 for most
    sequences; David starts at 300) and the initial box. The first step answers that same
    frame, so an episode has as many steps as the sequence has frames. ``info`` holds
    ``sequence``, ``frame_index`` (the benchmark's own 1-based frame number), ``seq_length``,
    ``frame_rate`` (OTB has none; 30), ``image_size`` ``(height, width)``, ``benchmark``,
    ``has_ground_truth`` and ``synthetic``.

    ## Episode end
    ``terminated=True`` after the agent has answered the last frame (there is no
    truncation). The final ``info["metrics"]`` holds the sequence's OTB scores, computed
    with the toolkit's rules (first frame = ground truth, degenerate boxes repaired, 21
    overlap thresholds ``0:0.05:1``, strictly greater, 51 precision thresholds; a frame
    with invalid ground truth stays in the denominators and fails every success threshold
    but passes every precision threshold): ``AUC`` (mean success rate; a perfect tracker
    scores 20/21), ``Precision@20px`` and ``AverageOverlap``. :meth:`write_episode` writes
    ``<Seq>.txt``, one ``x,y,w,h`` line per frame (the usual OTB result file), and
    :meth:`score_folder` scores such files with the same functions.

    ## Arguments
    - ``root``: the OTB folder holding the sequence folders (default: ``$UNITRACK_DATA/OTB``
      if that variable is set, else the synthetic default).
    - ``sequences``: restrict to these sequence names (default: every sequence found).
    - ``data_format``: the layout of ``root``, a key of
      :data:`unitrack_env.benchmarks.otb.SOT_FORMATS` (default ``"otb"``; a registered id of
      another SOT data set passes its own).
    - ``split``, ``variant``: passed to the format's reader (LaSOT: ``"test"``, ``"train"``,
      ``"all"``, ``"ext"`` or a split file; UAV123: ``variant="10fps"``, ``split="UAV20L"``;
      NfS: ``variant="30"`` or ``"240"``).
    - ``max_frame_size``: bound ``(height, width)`` of the frame space.
    - ``decode_frames``: when False, ``frame`` is a 1x1 black placeholder (for agents that
      never look at pixels; saves the decode time).
    - ``prefetch``: decode the next frame on a background thread.
    - ``shuffle``: visit sequences in a seeded random order.
    - ``render_mode``: ``"rgb_array"`` draws the agent's last box on the frame it answered.

    ## Version history
    - v0: initial version.
    """

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        sequences: list[str] | tuple[str, ...] | None = None,
        data_format: str = "otb",
        split: str | None = None,
        variant: str | None = None,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        self.scoring = OTBBenchmark.build(root, data_format, split, variant)
        self.dataset = self.scoring.dataset
        if sequences is not None:
            self.sequence_names = [self.dataset.resolve(s) for s in sequences]
        else:
            self.sequence_names = list(self.dataset.sequence_names)
        box_low = np.array([-ut_spaces.COORD_MAX, -ut_spaces.COORD_MAX, 0.0, 0.0], np.float32)
        box_high = np.float32(ut_spaces.COORD_MAX)
        self.observation_space = spaces.Dict({
            "frame": ut_spaces.Image(*self.max_frame_size),
            "init_box": spaces.Box(box_low, box_high, (4,), np.float32),
        })
        self.action_space = spaces.Box(box_low, box_high, (4,), np.float32)

        self._results: list[np.ndarray] = []
        self._scored: np.ndarray | None = None

    # ------------------------------------------------------------------ data
    @staticmethod
    def _gt_path(sequence: SOTSequence) -> Path:
        """The ground-truth file of a sequence (``groundtruth_rect.<k>.txt`` for ``Name.k``)."""
        folder = sequence.frame_paths[0].parent.parent
        suffix = sequence.name[len(folder.name):]
        if not (suffix[1:].isdigit() and suffix.startswith(".")):
            suffix = ""
        return folder / f"groundtruth_rect{suffix}.txt"

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.scoring.load(name)
        init = sequence.init_box
        if not (np.isfinite(init).all() and init[2] > 0 and init[3] > 0):
            raise DataFormatError(
                self._gt_path(sequence),
                f"{name}: the first box {init.tolist()} is not a valid target (finite, w, h > 0)",
                line=1,
            )
        width, height = sequence.image_size
        self._check_frame_size(name, width, height)
        self._sequence = sequence
        self._results = []
        self._scored = None
        info = dict(seq_length=sequence.num_frames, frame_rate=30.0,
                    image_size=(height, width), benchmark=self.scoring.name,
                    has_ground_truth=sequence.has_ground_truth, synthetic=self.synthetic)
        if sequence.description:  # LaSOT's nlp.txt
            info["nlp"] = sequence.description
        return info

    def _observe(self, t: int) -> dict[str, Any]:
        image = self._read_frame(t)
        return {"frame": image, "init_box": self._sequence.init_box.astype(np.float32)}

    def _frame_info(self, t: int) -> dict[str, Any]:
        return {"frame_index": self._sequence.frame_numbers[t]}

    def _record(self, action: Any, t: int) -> tuple[float, dict[str, Any]]:
        """Record frame ``t``'s box; the reward is the IoU of the box the toolkit scores."""
        box = _canonical(validate_box(action))
        self._results.append(box)
        gt = self._sequence.boxes[t]
        # The box the OTB toolkit scores (metrics.sot.repair_predictions, frame by frame).
        if t == 0:
            scored = gt.copy()
        elif (box[2] <= 0 or box[3] <= 0) and not np.isnan(gt).any():
            scored = self._scored
        else:
            scored = box
        self._scored = scored
        reward = frame_iou(scored, gt)
        self._answer = box
        return reward, {"iou": reward}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> np.ndarray:
        """Return the boxes recorded so far, ``(frames, 4)`` float64 (one row per frame)."""
        if not self._results:
            return np.zeros((0, 4))
        return np.stack(self._results)

    def episode_metrics(self) -> dict[str, float]:
        """Score the recorded boxes of the finished episode with the OTB toolkit's rules.

        Raises:
            ValueError: the episode is not finished.
        """
        sequence = self._sequence
        if sequence is None or len(self._results) != sequence.num_frames:
            raise ValueError("the episode is not finished; play every frame first")
        return self.scoring.score_sequence(sequence.name, self.episode_results())

    def write_episode(self, folder: Path) -> None:
        """Write ``<folder>/<sequence>.txt``: one ``x,y,w,h`` line per frame, atomically."""
        self._require_episode(played=bool(self._results))
        super().write_episode(folder)

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the frame with the agent's last box (or the initial box before any step)."""
        if self._answer is None:
            return draw_boxes(self._frame, self._sequence.init_box[None], colour=INIT_COLOUR)
        return draw_boxes(self._answer_frame, self._answer[None], colour=ACTION_COLOUR)

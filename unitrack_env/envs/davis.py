"""Semi-supervised video object segmentation (mask propagation) on DAVIS-2017 data."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.davis import BENCHMARK, DAVISBenchmark
from unitrack_env.datasets.davis import DAVIS_VOID_LABEL, VOSSequence
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import DataFormatError, InvalidActionError
from unitrack_env.metrics.vos import VOSScores, frame_scores, scores_from_frames

# Drawing lives in unitrack_env.render; the old names stay importable from here.
from unitrack_env.render import overlay_labels

#: Largest object label: labels are uint8 and 255 is void.
MAX_OBJECTS = 254
#: Default bound of the frame space (height, width): DAVIS Full-Resolution reaches 4096 wide.
DEFAULT_MAX_FRAME_SIZE = (2160, 4096)
#: DAVIS videos run at 24 frames per second.
DAVIS_FRAME_RATE = 24.0


def validate_labels(action: Any, shape: tuple[int, int], object_ids: tuple[int, ...]
                    ) -> np.ndarray:
    """Check a label-map action and return it as a fresh ``(H, W)`` uint8 array.

    Args:
        action: the agent's label map.
        shape: the frame's ``(height, width)``.
        object_ids: the sequence's object labels (0 = background is always allowed).

    Raises:
        InvalidActionError: not a 2-D integer map of the frame's size, or a label that is
            neither 0 nor an object of the sequence (255 = void is not a prediction).
    """
    labels = np.asarray(action)
    if labels.ndim != 2 or labels.shape != tuple(shape):
        raise InvalidActionError(
            f"action must be a label map of the frame's size, shape (height, width) = "
            f"{tuple(shape)}; got shape {labels.shape}"
        )
    if labels.dtype == np.bool_ or not np.issubdtype(labels.dtype, np.integer):
        raise InvalidActionError(
            f"action must be an integer label map (uint8; 0 = background, k = object k); got "
            f"dtype {labels.dtype}; convert it with .astype(np.uint8)"
        )
    if labels.dtype != np.uint8:
        low, high = int(labels.min(initial=0)), int(labels.max(initial=0))
        if low < 0 or high > MAX_OBJECTS:
            raise InvalidActionError(
                f"action labels must lie in 0..{max(object_ids, default=0)}; got {low}..{high}"
            )
    labels = labels.astype(np.uint8, copy=True)
    present = np.flatnonzero(np.bincount(labels.ravel(), minlength=256))
    extra = sorted(set(present.tolist()) - {0, *object_ids})
    if extra:
        hint = (" (255 is DAVIS's void label, used only in the ground truth; predict 0 or an "
                "object there)" if DAVIS_VOID_LABEL in extra else "")
        raise InvalidActionError(
            f"action contains labels {extra} that are not objects of this sequence; allowed: 0 "
            f"(background) and {list(object_ids)}{hint}"
        )
    return labels


class DAVISEnv(SequenceEnv[VOSSequence]):
    """Semi-supervised video object segmentation by mask propagation on DAVIS-2017 data.

    ## Description
    Each episode is one video sequence of DAVIS-2017 (or any data in its layout). The
    agent is given the first frame's label map (which pixels belong to which object) and
    answers with a label map for every frame. The environment scores every answer with
    the region similarity J and, at the end of the episode, reports the official DAVIS-2017
    semi-supervised scores of the sequence: J, F and J&F.

    The layout read is ``<root>/JPEGImages/480p/<seq>/00000.jpg ...``,
    ``<root>/Annotations/480p/<seq>/00000.png ...`` (palette PNGs whose indices are labels:
    0 background, ``k`` object ``k``, 255 void) and ``<root>/ImageSets/2017/<split>.txt``.
    DAVIS frames are 854x480, but any size works, and sizes may differ between sequences.

    With no ``root`` (and no ``UNITRACK_DATA``), the environment reads a small
    deterministic synthetic data set in the exact DAVIS-2017 layout (two ``val``, one
    ``train`` and one ``test-dev`` sequence, 432x240, with 2-3 people each who cross and
    occlude one another; one sequence has void borders), generated once into the user
    cache, so it works offline.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, the frame as uint8 RGB at its native
      size.
    - ``init_labels``: :class:`~unitrack_env.spaces.LabelMap` ``(H, W)`` uint8, the first
      frame's annotation as the benchmark ships it (0 background, ``k`` object ``k``, 255
      void), the same at every step. It is the task's input; the annotations of later
      frames never appear in observations.
    - ``num_objects``: ``Discrete(255)``, the number of objects. Their labels are the values
      of ``init_labels`` other than 0 and 255 (``1..num_objects`` in DAVIS).

    ## Action space
    :class:`~unitrack_env.spaces.LabelMap` ``(H, W)``: the label map of the current frame,
    of the frame's size, each pixel 0 (background) or an object label. Any integer dtype
    is accepted (``argmax`` output need not be cast); other shapes, float or bool dtypes,
    255 (void) and labels that are not objects of the sequence raise
    ``InvalidActionError`` before anything is recorded. ``action_space.sample()`` draws a
    valid map for the current episode (the space is narrowed at every reset). A vector
    environment's batched ``action_space`` was copied before any reset and does not know
    each copy's frame size, so its samples are not valid actions: give each copy a map of
    the size of its own ``observation["frame"]``.

    ## Rewards
    The frame's contribution to the official J-Mean: the mean J (region IoU outside void
    pixels, 1 for an object that is absent and not predicted) over the sequence's objects
    on the frames the DAVIS evaluation scores, and 0 on the first frame (it is given) and
    on the last frame (the official evaluation drops it). So the episode return divided by
    ``seq_length - 2`` is exactly the sequence's ``J-Mean``. ``info["j"]`` holds the
    per-object J of every annotated frame, scored or not. Sequences without annotations
    (test-dev) give reward 0.

    ## Starting state
    ``reset`` returns the first frame of the chosen sequence and its label map. The first
    step answers that same frame (the official results include ``00000.png``), so an
    episode has as many steps as the sequence has frames. ``info`` holds ``sequence``,
    ``frame_index`` (0-based, the frame file's number), ``seq_length``, ``frame_rate`` (24),
    ``image_size`` ``(height, width)``, ``benchmark``, ``has_ground_truth``, ``object_ids``
    and ``synthetic``.

    ## Episode end
    ``terminated=True`` after the agent has answered the last frame (there is no
    truncation). The final ``info["metrics"]`` holds the sequence's DAVIS-2017
    semi-supervised scores (first and last frames excluded, void pixels ignored, objects
    compared by label): ``J-Mean``, ``J-Recall``, ``J-Decay``, ``F-Mean``, ``F-Recall``,
    ``F-Decay`` and ``J&F-Mean``, as fractions (NaN for a sequence of 2 frames or fewer,
    which has no scored frame). :meth:`write_episode` writes the official result format,
    ``<folder>/<seq>/<frame>.png`` palette PNGs with the DAVIS palette, and
    :meth:`score_folder` scores such folders with the same functions (over all objects of
    all sequences for the combined row, as the DAVIS table does).

    ## Arguments
    - ``root``: the DAVIS folder holding ``JPEGImages``, ``Annotations`` and ``ImageSets``
      (default: ``$UNITRACK_DATA/DAVIS`` if that variable is set, else the synthetic
      default).
    - ``split``: ``"val"`` (the benchmark's), ``"train"``, ``"test-dev"`` (first frame
      annotated only: no reward, no metrics), or None for every sequence folder.
    - ``sequences``: restrict to these sequence names (default: all of the split).
    - ``resolution``: ``"480p"`` or ``"Full-Resolution"``.
    - ``year``: ``ImageSets`` sub-folder (``"2017"``).
    - ``max_frame_size``: bound ``(height, width)`` of the frame and label-map spaces.
    - ``decode_frames``: when False, ``frame`` is a 1x1 black placeholder (for agents that
      never look at pixels; the label maps keep the frame's size).
    - ``prefetch``: decode the next frame on a background thread.
    - ``shuffle``: visit sequences in a seeded random order.
    - ``render_mode``: ``"rgb_array"`` overlays the agent's last label map on the frame it
      answered (id-coloured translucent masks with outlines).

    ## Version history
    - v0: initial version.
    """

    default_max_frame_size = DEFAULT_MAX_FRAME_SIZE

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        split: str | None = "val",
        sequences: list[str] | tuple[str, ...] | None = None,
        resolution: str = "480p",
        year: str = "2017",
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        bench = DAVISBenchmark.build(root, split, resolution, year)
        self._use_benchmark(bench, sequences, f"split {split!r} of {bench.dataset.root}")
        self.observation_space = spaces.Dict({
            "frame": ut_spaces.Image(*self.max_frame_size),
            "init_labels": ut_spaces.LabelMap(*self.max_frame_size, max_label=255),
            "num_objects": spaces.Discrete(MAX_OBJECTS + 1),
        })
        self.action_space: ut_spaces.LabelMap = ut_spaces.LabelMap(
            *self.max_frame_size, max_label=MAX_OBJECTS
        )

        self._init_labels: np.ndarray | None = None
        self._results: list[np.ndarray] = []
        self._j: list[np.ndarray] = []
        self._f: list[np.ndarray] = []

    # ------------------------------------------------------------------ data
    @property
    def _shape(self) -> tuple[int, int]:
        width, height = self._sequence.image_size
        return height, width

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.scoring.load(name)
        width, height = sequence.image_size
        self._check_frame_size(name, width, height)
        if max(sequence.object_ids) > MAX_OBJECTS:  # pragma: no cover - 255 is void
            raise DataFormatError(sequence.annotation_paths[0], "object label above 254")
        self._sequence = sequence
        self._init_labels = sequence.read_annotation(0)
        self._init_labels.setflags(write=False)
        self.action_space.narrow(height, width, (0, *sequence.object_ids))
        self._results, self._j, self._f = [], [], []
        return dict(seq_length=sequence.num_frames, frame_rate=DAVIS_FRAME_RATE,
                    image_size=self._shape, benchmark=BENCHMARK,
                    has_ground_truth=sequence.has_ground_truth,
                    object_ids=sequence.object_ids, synthetic=self.synthetic)

    def _observe(self, t: int) -> dict[str, Any]:
        return {
            "frame": self._read_frame(t),
            "init_labels": self._init_labels.copy(),
            "num_objects": len(self._sequence.object_ids),
        }

    def _frame_info(self, t: int) -> dict[str, Any]:
        stem = self._sequence.frame_names[t]
        return {"frame_index": int(stem) if stem.isdigit() else t}

    def _record(self, action: Any, t: int) -> tuple[float, dict[str, Any]]:
        """Record frame ``t``'s label map; score J on the frames DAVIS evaluates."""
        sequence = self._sequence
        labels = validate_labels(action, self._shape, sequence.object_ids)
        self._results.append(labels)
        self._answer = labels
        if sequence.annotation_paths[t] is None:
            return 0.0, {}
        gt = sequence.read_annotation(t)
        scored = sequence.has_ground_truth and 0 < t < sequence.num_frames - 1
        j, f = frame_scores(gt, labels, sequence.object_ids, with_f=scored)
        reward = 0.0
        if scored:
            self._j.append(j)
            self._f.append(f)
            reward = float(j.mean())
        return reward, {"j": j}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> list[np.ndarray]:
        """Return the label maps recorded so far (one ``(H, W)`` uint8 array per frame)."""
        return [labels.copy() for labels in self._results]

    def episode_scores(self) -> VOSScores:
        """Return the DAVIS scores of the finished episode (per object and summary).

        Raises:
            ValueError: the episode is not finished or the sequence has no annotations.
        """
        sequence = self._sequence
        if sequence is None or len(self._results) != sequence.num_frames:
            raise ValueError("the episode is not finished; play every frame first")
        if not sequence.has_ground_truth:
            raise ValueError(f"sequence '{sequence.name}' has no annotations to score against")
        n = len(sequence.object_ids)
        j = np.stack(self._j, axis=1) if self._j else np.zeros((n, 0))
        f = np.stack(self._f, axis=1) if self._f else np.zeros((n, 0))
        return scores_from_frames(j, f, sequence.object_ids, sequence.name)

    def episode_metrics(self) -> dict[str, float]:
        """Return the DAVIS summary of the finished episode (``J-Mean``, ..., ``J&F-Mean``)."""
        return dict(self.episode_scores().summary)

    def write_episode(self, folder: Path) -> None:
        """Write ``<folder>/<seq>/<frame>.png`` palette PNGs (the official result format)."""
        self._require_episode(played=bool(self._results))
        super().write_episode(folder)

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the frame with the agent's last label map (or the first-frame labels)."""
        if self._answer is None:
            return overlay_labels(self._frame, self._init_labels)
        return overlay_labels(self._answer_frame, self._answer)

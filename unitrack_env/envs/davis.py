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

    Spaces, rewards, metrics and arguments: docs/envs/davis.md.
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

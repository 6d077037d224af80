"""Video instance segmentation on YouTube-VIS 2019 data."""

from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.vis import BENCHMARK, VISBenchmark
from unitrack_env.datasets.rle import decode_masks
from unitrack_env.datasets.youtube_vis import FRAME_RATE, VisTrack, VisVideo
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.metrics.mots import MaskClearStream
from unitrack_env.render import draw_masks
from unitrack_env.score_range import declared_range

#: Default capacity of the detection arrays.
DEFAULT_MAX_DETECTIONS = 128


class VISEnv(SequenceEnv[VisVideo]):
    """Video instance segmentation by associating per-frame detection masks.

    ## Description
    Each episode is one video of YouTube-VIS 2019. At every step the agent sees one frame
    and that frame's detections (mask, class, score) and answers with a track id per
    detection (UniTrack's association step for VIS). The environment assembles the tracks
    (a track's mask per frame, its category and score) and at the end of the episode reports
    the official track mAP (TrackEval's YouTube-VIS evaluation). Results are written in the
    official results JSON format ``[{video_id, category_id, segmentations, score}]``.

    With no ``root`` (and no ``UNITRACK_DATA``), the environment reads a small deterministic
    synthetic data set in the exact YouTube-VIS 2019 layout (``train.json``, ``valid.json``,
    ``<split>/JPEGImages/<video>/00000.jpg``), generated once into the user cache: people
    (category ``person``) walking, crossing and occluding each other, a static ``occluder``
    object, and noisy overlapping detections with class confusion.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, uint8 RGB at the video's size.
    - ``masks``: :class:`~unitrack_env.spaces.MaskStack` ``(num_detections, H, W)`` bool: the
      detection masks. A stack, not a label map, because VIS detections may overlap.
    - ``boxes``: ``Box((max_detections, 4), float32)``, each mask's tight ``(x, y, w, h)`` in
      0-based pixels; rows past ``num_detections`` are 0.
    - ``scores``: ``Box((max_detections,), float32)``.
    - ``classes``: ``Box(0, max category id, (max_detections,), int64)``: category ids (0 =
      padding); names are in ``env.unwrapped.categories``.
    - ``num_detections``: ``Discrete(max_detections + 1)``.

    ## Action space
    ``{"ids": Box(0, 2**31 - 1, (max_detections,), int64)}``: the track id of each detection
    (``i < num_detections``), 0 = not reported; entries past ``num_detections`` are ignored;
    the unpadded ``(num_detections,)`` form is accepted. Invalid actions (wrong length or
    dtype, negative ids, one id on two detections) raise ``InvalidActionError`` before
    anything is recorded. A track's category is the most frequent class of its detections
    (ties: the larger summed score), its score the mean score of its detections.

    ## Rewards
    ``TP - FP - IDSW`` of the frame under CLEAR matching at mask IoU >= 0.5 against every
    ground-truth mask of the frame, class-agnostic (a dense association signal; the official
    measure, track mAP, is only defined per video and comes at the end). ``info["clear"]``
    has the counts. Splits without annotations give reward 0.

    ## Starting state
    ``reset`` returns the first frame and its detections; ``info`` holds ``sequence`` (video
    name), ``video_id``, ``frame_index`` (0-based position in ``file_names``), ``seq_length``,
    ``frame_rate`` (6: every 5th frame of 30 fps video), ``image_size``,
    ``has_ground_truth`` and
    ``detection_scores`` (the range of the detection scores, ``{"low", "high", "bounded",
    "source"}``: 0..1, see :mod:`unitrack_env.score_range`).

    ## Episode end
    ``terminated=True`` after the last frame. The final ``info["metrics"]`` holds the video's
    track mAP fields: ``AP`` (mean over IoU 0.50:0.05:0.95), ``AP50``, ``AP75``, ``AR``, and
    TrackEval's ``AP_all``, ``AR_all`` and area ranges (-1 where undefined).

    ## Arguments
    - ``root``: the benchmark folder, holding ``<split>.json`` and the frames
      ``<split>/JPEGImages/<file_name>`` (default ``$UNITRACK_DATA/YouTube-VIS-2019`` if set,
      else the synthetic default).
    - ``split``: ``"train"``, ``"valid"`` or ``"test"``; ``annotation_file`` overrides
      ``<root>/<split>.json``.
    - ``sequences``: restrict to these videos (names).
    - ``detections``: ``"public"`` (``<root>/detections/<split>.json``; the benchmark ships
      none), ``"gt"`` (the ground truth, score 1) or a results-format JSON file: every
      non-null segmentation of an entry is one detection of that frame with the entry's
      ``category_id`` and ``score`` (a per-frame detector writes one entry per detection,
      non-null on one frame).
    - ``min_score``: drop detections scored below this (the one place that filters
      detections by score).
    - ``max_detections``, ``max_frame_size``, ``decode_frames``, ``prefetch``, ``shuffle``,
      ``render_mode`` as in the other environments.

    ## Version history
    - v0: initial version.
    """

    requires = ("trackeval",)

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        split: str = "train",
        sequences: list[str] | tuple[str, ...] | None = None,
        detections: str | os.PathLike = "public",
        annotation_file: str | os.PathLike | None = None,
        min_score: float | None = None,
        max_detections: int = DEFAULT_MAX_DETECTIONS,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        bench = VISBenchmark.build(root, split, detections, annotation_file)
        self._use_benchmark(bench, sequences, bench.dataset.annotation_path)
        self.categories = dict(self.dataset.data.categories)
        self.min_score = min_score
        self.max_detections = int(max_detections)
        self.observation_space = ut_spaces.mask_observation_space(
            self.max_detections, self.max_frame_size,
            num_classes=max(self.categories, default=1))
        self.action_space: spaces.Dict = ut_spaces.mask_id_action_space(self.max_detections)

        self._gt: list[VisTrack] | None = None
        self._dets: list[list[tuple[dict, int, float]]] = []
        self._clear = MaskClearStream()
        self._tracks: dict[int, dict[int, tuple[dict, int, float]]] = {}
        self._current: dict[str, Any] = {}

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        video = self.dataset.video(name)
        self._check_frame_size(name, video.width, video.height, axes=False, hint="one")
        per_frame: list[list[tuple[dict, int, float]]] = [[] for _ in range(video.length)]
        for det in self.dataset.detections_of(video):
            if self.min_score is not None and det.score < self.min_score:
                continue
            for t, seg in enumerate(det.segmentations):
                if seg is not None:
                    per_frame[t].append((seg, det.category_id, det.score))
        most = max((len(f) for f in per_frame), default=0)
        if most > self.max_detections:
            raise ValueError(f"{self.dataset.detection_path()}: a frame of {name} has {most} "
                             f"detections, more than max_detections={self.max_detections}")
        self._sequence = video
        self._gt = self.dataset.data.tracks_of(video.id) if self.dataset.has_annotations else None
        self._dets = per_frame
        self._clear.reset()
        self._tracks = {}
        return dict(video_id=video.id, seq_length=video.length, frame_rate=FRAME_RATE,
                    image_size=(video.height, video.width), benchmark=BENCHMARK,
                    has_ground_truth=self._gt is not None, synthetic=self.synthetic,
                    detection_scores=declared_range(BENCHMARK).info())

    def _length(self) -> int:
        return self._sequence.length

    def _frame_path(self, t: int) -> Path:
        return self.dataset.frame_path(self._sequence, t)

    def _frame_size(self) -> tuple[int, int]:
        return self._sequence.width, self._sequence.height

    def _observe(self, t: int) -> dict[str, Any]:
        video = self._sequence
        image = self._read_frame(t)
        dets = self._dets[t]
        masks = decode_masks([d[0]["counts"] for d in dets], video.height, video.width)
        self._current = {"masks": masks, "dets": dets}
        n = len(dets)
        boxes = np.zeros((self.max_detections, 4), dtype=np.float32)
        scores = np.zeros(self.max_detections, dtype=np.float32)
        classes = np.zeros(self.max_detections, dtype=np.int64)
        boxes[:n] = ut_spaces.mask_boxes(masks)
        scores[:n] = [d[2] for d in dets]
        classes[:n] = [d[1] for d in dets]
        return {"frame": image, "masks": masks, "boxes": boxes, "scores": scores,
                "classes": classes, "num_detections": n}

    def _record(self, action: dict[str, Any], t: int) -> tuple[float, dict[str, Any]]:
        """Record the ids given to frame ``t``'s detections and score them, class-agnostic."""
        dets = self._current["dets"]
        ids = ut_spaces.unpack_mask_ids(action, len(dets), self.max_detections)
        reported = np.flatnonzero(ids > 0)
        for i in reported:
            self._tracks.setdefault(int(ids[i]), {})[t] = dets[i]
        keep = ids > 0
        self._answer = (self._current["masks"][keep], ids[keep])
        if self._gt is None:
            return 0.0, {}
        present = [(i, track.segmentations[t]) for i, track in enumerate(self._gt)
                   if track.segmentations[t] is not None and not track.iscrowd]
        counts = self._clear.update(np.asarray([i for i, _ in present], np.int64),
                                    [s for _, s in present], [], ids[reported],
                                    [dets[i][0] for i in reported])
        clear = {"tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "idsw": counts.idsw}
        return float(counts.tp - counts.fp - counts.idsw), {"clear": clear}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> list[VisTrack]:
        """The tracks recorded so far in the results format, ordered by track id."""
        if self._sequence is None:
            return []
        out = []
        for track_id in sorted(self._tracks):
            frames = self._tracks[track_id]
            votes: dict[int, list[float]] = defaultdict(list)
            for _, cls, score in frames.values():
                votes[cls].append(score)
            category = max(votes, key=lambda c: (len(votes[c]), sum(votes[c]), -c))
            length = self._sequence.length
            segs = tuple(frames[k][0] if k in frames else None for k in range(length))
            score = float(np.mean([s for _, _, s in frames.values()]))
            out.append(VisTrack(self._sequence.id, category, segs, score=score))
        return out

    def episode_metrics(self) -> dict[str, float]:
        """Track mAP of the recorded episode on its video (needs annotations)."""
        if self._gt is None:
            raise ValueError("this video has no annotations to score against")
        return super().episode_metrics()

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """The frame with id-coloured masks (after a step) or grey detections (at reset)."""
        if self._answer is None:
            return draw_masks(self._frame, self._current["masks"])
        return draw_masks(self._answer_frame, *self._answer)

"""Video instance segmentation on YouTube-VIS 2019 data."""

from __future__ import annotations

import functools
import hashlib
import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from unitrack_env import spaces as ut_spaces
from unitrack_env.datasets.mots import decode_masks
from unitrack_env.datasets.youtube_vis import (
    FRAME_RATE,
    VisTrack,
    VisVideo,
    YouTubeVISDataset,
    format_results,
    parse_vis_results,
)
from unitrack_env.envs.base import SequenceEnv
from unitrack_env.envs.mots import draw_masks
from unitrack_env.errors import DataFormatError
from unitrack_env.frames import FramePrefetcher
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.mots import MaskClearStream
from unitrack_env.metrics.report import ScoreReport

#: Default capacity of the detection arrays.
DEFAULT_MAX_DETECTIONS = 128
#: Default bound of the frame space (height, width).
DEFAULT_MAX_FRAME_SIZE = (2160, 3840)
#: Benchmark name (and folder under ``$UNITRACK_DATA``).
BENCHMARK = "YouTube-VIS-2019"


class VISEnv(SequenceEnv[VisVideo], task="vis"):
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
    ``frame_rate`` (6: every 5th frame of 30 fps video), ``image_size`` and
    ``has_ground_truth``.

    ## Episode end
    ``terminated=True`` after the last frame. The final ``info["metrics"]`` holds the video's
    track mAP fields: ``AP`` (mean over IoU 0.50:0.05:0.95), ``AP50``, ``AP75``, ``AR``, and
    TrackEval's ``AP_all``, ``AR_all`` and area ranges (-1 where undefined).

    ## Arguments
    - ``root``: the benchmark folder (default ``$UNITRACK_DATA/YouTube-VIS-2019`` if set, else
      the synthetic default).
    - ``split``: ``"train"``, ``"valid"`` or ``"test"``; ``annotation_file`` overrides
      ``<root>/<split>.json``.
    - ``sequences``: restrict to these videos (names).
    - ``detections``: ``"public"`` (``<root>/detections/<split>.json``), ``"gt"`` or a
      results-format JSON file.
    - ``min_score``: drop detections scored below this.
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
        max_frame_size: tuple[int, int] = DEFAULT_MAX_FRAME_SIZE,
        decode_frames: bool = True,
        prefetch: bool = True,
        shuffle: bool = False,
        render_mode: str | None = None,
    ) -> None:
        super().__init__(shuffle=shuffle, render_mode=render_mode)
        data_root = self._data_root(root, BENCHMARK, BENCHMARK, kind="youtube_vis")
        self.dataset = YouTubeVISDataset(data_root, split, detections, annotation_file)
        self.sequence_names = self._select_sequences(
            sequences, self.dataset.sequence_names, self.dataset.annotation_path
        )
        self.categories = dict(self.dataset.data.categories)
        self.min_score = min_score
        self.max_detections = int(max_detections)
        self.max_frame_size = (int(max_frame_size[0]), int(max_frame_size[1]))
        self.decode_frames = decode_frames
        self.prefetch = prefetch
        self.observation_space = ut_spaces.mask_observation_space(
            self.max_detections, self.max_frame_size,
            num_classes=max(self.categories, default=1))
        self.action_space: spaces.Dict = ut_spaces.mask_id_action_space(self.max_detections)

        self._sequence: VisVideo | None = None
        self._gt: list[VisTrack] | None = None
        self._dets: list[list[tuple[dict, int, float]]] = []
        self._frames: FramePrefetcher | None = None
        self._k = 0
        self._done = True
        self._clear = MaskClearStream()
        self._tracks: dict[int, dict[int, tuple[dict, int, float]]] = {}
        self._current: dict[str, Any] = {}
        self._render_state: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    # ------------------------------------------------------------------ episode control
    def _start_episode(self, name: str) -> tuple[dict[str, Any], dict[str, Any]]:
        if self._frames is not None:
            self._frames.close()
        video = self.dataset.video(name)
        if video.height > self.max_frame_size[0] or video.width > self.max_frame_size[1]:
            raise ValueError(f"{name}: frames are {video.width}x{video.height}, larger than "
                             f"max_frame_size={self.max_frame_size}; pass a larger one")
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
        self._frames = self._open_frames(functools.partial(self.dataset.frame_path, video),
                                         range(video.length), prefetch=self.prefetch)
        self._k = 0
        self._done = False
        self._clear.reset()
        self._tracks = {}
        self._render_state = None
        return self._observe(), self._info(reset=True)

    def _observe(self) -> dict[str, Any]:
        video, k = self._sequence, self._k
        image = self._decode(k, next_key=k + 1 if k + 1 < video.length else None,
                             size=(video.width, video.height),
                             path=self.dataset.frame_path(video, k), source="the JSON")
        dets = self._dets[k]
        masks = decode_masks([d[0]["counts"] for d in dets], video.height, video.width)
        self._current = {"image": image, "masks": masks, "dets": dets}
        return self._pack(image, masks, dets)

    def _pack(self, image: np.ndarray, masks: np.ndarray, dets: list) -> dict[str, Any]:
        n = len(dets)
        boxes = np.zeros((self.max_detections, 4), dtype=np.float32)
        scores = np.zeros(self.max_detections, dtype=np.float32)
        classes = np.zeros(self.max_detections, dtype=np.int64)
        boxes[:n] = ut_spaces.mask_boxes(masks)
        scores[:n] = [d[2] for d in dets]
        classes[:n] = [d[1] for d in dets]
        return {"frame": image, "masks": masks, "boxes": boxes, "scores": scores,
                "classes": classes, "num_detections": n}

    def _info(self, *, reset: bool = False) -> dict[str, Any]:
        video = self._sequence
        out: dict[str, Any] = {"sequence": video.name, "frame_index": self._k}
        if reset:
            out.update(video_id=video.id, seq_length=video.length, frame_rate=FRAME_RATE,
                       image_size=(video.height, video.width), benchmark=BENCHMARK,
                       has_ground_truth=self._gt is not None, synthetic=self.synthetic)
        return out

    def step(self, action: dict[str, Any]
             ) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Record the ids given to this frame's detections, score them, and move on."""
        if self._done or self._sequence is None:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        dets = self._current["dets"]
        ids = ut_spaces.unpack_mask_ids(action, len(dets), self.max_detections)
        reported = np.flatnonzero(ids > 0)
        for i in reported:
            self._tracks.setdefault(int(ids[i]), {})[self._k] = dets[i]
        reward, clear = self._score_frame(ids[reported], [dets[i][0] for i in reported])
        keep = ids > 0
        self._render_state = (self._current["image"], self._current["masks"][keep], ids[keep])
        extra: dict[str, Any] = {"clear": clear} if clear is not None else {}
        if self._k + 1 >= self._sequence.length:
            self._done = True
            observation = self._pack(self._fresh(self._current["image"]),
                                     self._fresh(self._current["masks"]), dets)
            info = self._info() | extra
            if self._gt is not None:
                info["metrics"] = self.episode_metrics()
            self._frames.close()
            return observation, reward, True, False, info
        self._k += 1
        return self._observe(), reward, False, False, self._info() | extra

    def _score_frame(self, ids: np.ndarray, rles: list[dict]
                     ) -> tuple[float, dict[str, int] | None]:
        if self._gt is None:
            return 0.0, None
        present = [(i, t.segmentations[self._k]) for i, t in enumerate(self._gt)
                   if t.segmentations[self._k] is not None and not t.iscrowd]
        counts = self._clear.update(np.asarray([i for i, _ in present], np.int64),
                                    [s for _, s in present], [], ids, rles)
        clear = {"tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "idsw": counts.idsw}
        return float(counts.tp - counts.fp - counts.idsw), clear

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

    def episode_digest(self) -> str:
        """SHA-256 of the episode's results JSON."""
        return hashlib.sha256(format_results(self.episode_results()).encode()).hexdigest()

    def episode_metrics(self) -> dict[str, float]:
        """Track mAP of the recorded episode on its video (needs annotations)."""
        from unitrack_env.metrics.vis import score_videos

        if self._gt is None:
            raise ValueError("this video has no annotations to score against")
        report = score_videos(self.dataset.data, self.episode_results(), [self._sequence])
        return report.per_sequence[self._sequence.name]

    def sequence_length(self, name: str) -> int:
        """Number of frames of video ``name``."""
        return self.dataset.video(name).length

    def has_ground_truth(self, name: str) -> bool:
        """Whether the split has annotations."""
        return self.dataset.has_annotations

    def write_episode(self, folder: Path) -> None:
        """Write ``<folder>/<video>.json``: this video's entries of the official results JSON.

        ``unitrack_env.metrics.vis.merge_result_files(folder)`` concatenates them into the
        challenge's ``results.json``.
        """
        if self._sequence is None:
            raise RuntimeError("no episode to write; call reset() and play it first")
        atomic_write_text(Path(folder) / f"{self._sequence.name}.json",
                          format_results(self.episode_results()))

    def score_folder(self, folder: Path, sequences: list[str]) -> ScoreReport:
        """Track mAP of ``<folder>/<video>.json`` files, per video and combined."""
        from unitrack_env.metrics.vis import score_videos

        videos = [self.dataset.video(name) for name in dict.fromkeys(sequences)]
        results: list[VisTrack] = []
        for video in videos:
            path = Path(folder) / f"{video.name}.json"
            if not path.is_file():
                raise DataFormatError(path, f"result file for video '{video.name}' is missing")
            results += parse_vis_results(path, {video.id: video})
        return score_videos(self.dataset.data, results, videos, source=Path(folder))

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """The frame with id-coloured masks (after a step) or grey detections (at reset)."""
        if self._render_state is None:
            return draw_masks(self._current["image"], self._current["masks"])
        return draw_masks(*self._render_state)


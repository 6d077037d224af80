"""Multi-object tracking and segmentation on MOTS Challenge (MOTS20) and KITTI MOTS data."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.mots import MOTSBenchmark
from unitrack_env.datasets.mots import MOTSSequenceInfo
from unitrack_env.datasets.mots_format import CLASS_IDS, CLASS_IGNORE, MaskAnnotations
from unitrack_env.datasets.rle import encode_masks, resolve_overlaps
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.metrics.mots import MaskClearStream

# Drawing lives in unitrack_env.render; the old names stay importable from here.
from unitrack_env.render import draw_masks
from unitrack_env.score_range import declared_range

#: Default capacity of the detection arrays.
DEFAULT_MAX_DETECTIONS = 128


class MOTSEnv(SequenceEnv[MOTSSequenceInfo]):
    """Multi-object tracking and segmentation by associating detection masks.

    ## Description
    Each episode is one video sequence of MOTS Challenge (``MOTS20``) or KITTI MOTS. At every
    step the agent sees one frame and that frame's detection masks, and answers with a track
    id for each mask (the association step of UniTrack's MOTS head). The environment records
    the reported masks with their ids, scores them against the ground truth with TrackEval's
    MOTS rules, and at the end of the episode reports the official metrics (HOTA, sMOTSA,
    MOTSA, IDF1, IDSW, ...). The recorded episode is written in the official MOTS txt result
    format (``time_frame id class_id img_height img_width rle``).

    With no ``root`` (and no ``UNITRACK_DATA``), the environment reads a small deterministic
    synthetic data set in the exact MOTS20 (or KITTI MOTS) layout, generated once into the
    user cache: textured people walking, crossing and occluding each other, an occluder
    annotated as an ignore region, and noisy detection masks (dilated/eroded, shifted,
    missed, false positives, scores).

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, the frame as uint8 RGB at its native size.
    - ``masks``: :class:`~unitrack_env.spaces.MaskStack`, ``(num_detections, H, W)`` bool:
      the detection masks at the frame's size. A stack of masks rather than a label map, so
      that the mask tasks (MOTS and VIS, where masks may overlap) share one representation;
      rather than padding, because a padded ``(max_detections, H, W)`` array is megabytes
      per frame. MOTS masks never overlap: where detection masks of the input file overlap,
      the pixel goes to the higher-scored detection (MOTS results must be disjoint).
    - ``boxes``: ``Box((max_detections, 4), float32)``: each mask's tight box ``(x, y, w,
      h)`` in 0-based pixels (``pycocotools`` ``toBbox`` convention); rows past
      ``num_detections`` are 0.
    - ``scores``: ``Box((max_detections,), float32)``: detection scores.
    - ``num_detections``: ``Discrete(max_detections + 1)``.

    Ground truth never appears in observations.

    ## Action space
    ``{"ids": Box(0, 2**31 - 1, (max_detections,), int64)}``: ``ids[i]`` is the track id of
    detection ``i`` for ``i < num_detections``, 0 = not reported; entries past
    ``num_detections`` are ignored. The unpadded ``{"ids": (num_detections,)}`` is accepted
    too; ``unitrack_env.spaces.pack_mask_ids`` builds the padded form. Wrong lengths or
    dtypes, negative ids, and one id given to two masks raise ``InvalidActionError`` before
    anything is recorded. Reported masks keep the detection's pixels, so results are
    disjoint, as the MOTS format requires.

    ## Rewards
    ``TP - FP - IDSW`` of the frame under TrackEval's MOTS evaluation: reported masks that are
    unmatched and lie more than half inside the ignore regions are dropped, then CLEAR's
    matching at mask IoU >= 0.5. The episode return divided by the number of ground-truth
    masks is TrackEval's MOTSA. ``info["clear"]`` has the frame's ``tp``, ``fp``, ``fn`` and
    ``idsw``. Splits without ground truth give reward 0.

    ## Starting state
    ``reset`` returns the first frame and its detections. ``info`` holds ``sequence``,
    ``frame_index`` (the benchmark's own numbering: MOTS20 1-based, KITTI 0-based),
    ``seq_length``, ``frame_rate``, ``image_size`` ``(height, width)``, ``benchmark``,
    ``has_ground_truth`` and
    ``detection_scores`` (the range of the detection scores, ``{"low", "high", "bounded",
    "source"}``: 0..1, see :mod:`unitrack_env.score_range`).

    ## Episode end
    ``terminated=True`` after the last frame is answered. The final ``info["metrics"]`` holds
    the sequence's TrackEval metrics (``HOTA``, ``DetA``, ``AssA``, ``sMOTSA``, ``MOTSA``,
    ``MOTSP``, ``IDF1``, ``IDSW``, ``CLR_FP``, ``CLR_FN``, ... as fractions; ``MOTA``/``MOTP``/
    ``sMOTA`` are TrackEval's names of the same numbers).

    ## Arguments
    - ``benchmark``: ``"MOTS20"`` (MOTS Challenge layout) or ``"KITTI-MOTS"``.
    - ``root``: the benchmark folder (default: ``$UNITRACK_DATA/<benchmark>`` if that
      variable is set, else the synthetic default). MOTS20: ``<split>/<seq>/seqinfo.ini``,
      ``img1/000001.jpg`` ..., ``gt/gt.txt``. KITTI MOTS: ``<split>/image_02/<seq>/000000.png``
      ... (KITTI tracking's ``training``/``testing`` folders) and ground truth
      ``instances_txt/<seq>.txt`` or ``instances/<seq>/000000.png`` ... (16-bit maps of
      object ids).
    - ``split``: MOTS20 ``"train"``/``"test"``; KITTI ``"training"``/``"testing"``.
    - ``sequences``: restrict to these sequences.
    - ``detections``: ``"public"`` (``<seq>/det/det.txt``; KITTI ``<split>/det_02/<seq>.txt``),
      ``"gt"`` (ground-truth masks of the tracked class, score 1) or a folder of
      ``<seq>.txt`` files, in the MOTS txt format with an optional 7th score field (1 when
      absent; the ``id`` field is ignored). Neither benchmark ships mask detections.
    - ``object_class``: ``"pedestrian"`` or (KITTI) ``"car"``: the class tracked and scored.
    - ``min_score``: drop detections scored below this (the one place that filters
      detections by score).
    - ``max_detections``, ``max_frame_size``: space capacities.
    - ``decode_frames``: when False, ``frame`` is a 1x1 black placeholder.
    - ``prefetch``: decode the next frame on a background thread.
    - ``shuffle``: visit sequences in a seeded random order.
    - ``render_mode``: ``"rgb_array"`` draws id-coloured masks and boxes.

    ## Version history
    - v0: initial version.
    """

    requires = ("trackeval",)

    def __init__(
        self,
        benchmark: str = "MOTS20",
        root: str | os.PathLike | None = None,
        split: str | None = None,
        sequences: list[str] | tuple[str, ...] | None = None,
        detections: str | os.PathLike = "public",
        object_class: str = "pedestrian",
        min_score: float | None = None,
        max_detections: int = DEFAULT_MAX_DETECTIONS,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        bench = MOTSBenchmark.build(benchmark, root, split, detections, object_class)
        self._use_benchmark(bench, sequences, bench.dataset.split_dir)
        self.benchmark, self.object_class = benchmark, object_class
        self.class_id = CLASS_IDS[object_class]
        self.min_score = min_score
        self.max_detections = int(max_detections)
        self.observation_space = ut_spaces.mask_observation_space(
            self.max_detections, self.max_frame_size)
        self.action_space: spaces.Dict = ut_spaces.mask_id_action_space(self.max_detections)

        self._gt: MaskAnnotations | None = None
        self._dets: MaskAnnotations | None = None
        self._clear = MaskClearStream()
        self._results: list[tuple[int, np.ndarray, list[bytes]]] = []
        self._current: dict[str, Any] = {}

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        info = self.dataset.info(name)
        self._check_frame_size(name, info.width, info.height, axes=False, hint="one")
        dets = self.dataset.load_detections(name, self.class_id)
        if self.min_score is not None:
            dets = dets.select(dets.scores >= self.min_score)
        counts = np.bincount(dets.frames - info.first_frame, minlength=1) if len(dets) else [0]
        if len(dets) and (dets.frames.min() < info.first_frame
                          or dets.frames.max() >= info.first_frame + info.length):
            bad = int(np.argmax((dets.frames < info.first_frame)
                                | (dets.frames >= info.first_frame + info.length)))
            raise dets._error(bad, f"time_frame {dets.frames[bad]} is outside the sequence "
                              f"({info.first_frame}..{info.first_frame + info.length - 1})",
                              "time_frame")
        if max(counts) > self.max_detections:
            raise ValueError(f"{self.dataset.detection_path(name)}: a frame has {max(counts)} "
                             f"detections, more than max_detections={self.max_detections}")
        self._sequence = info
        self._gt = self.dataset.ground_truth(name)
        self._dets = dets
        self._clear.reset()
        self._results = []
        return dict(seq_length=info.length, frame_rate=info.frame_rate,
                    image_size=(info.height, info.width), benchmark=self.benchmark,
                    has_ground_truth=self._gt is not None, synthetic=self.synthetic,
                    detection_scores=declared_range(self.benchmark).info())

    def _first_step(self) -> int:
        return self._sequence.first_frame  # the benchmark's numbering: MOTS20 1, KITTI 0

    def _length(self) -> int:
        return self._sequence.length

    def _frame_path(self, t: int) -> Path:
        return self._sequence.frame_path(t)

    def _frame_size(self) -> tuple[int, int]:
        return self._sequence.width, self._sequence.height

    def _observe(self, t: int) -> dict[str, Any]:
        info = self._sequence
        image = self._read_frame(t)
        rows = self._dets.rows(t)
        masks = self._dets.decode(rows, info.height, info.width)
        scores = self._dets.scores[rows]
        counts = [self._dets.counts[i] for i in rows]
        if len(masks) > 1 and (masks.sum(axis=0) > 1).any():
            masks = resolve_overlaps(masks, scores)
            counts = encode_masks(masks)
        n = len(rows)
        boxes = np.zeros((self.max_detections, 4), dtype=np.float32)
        padded_scores = np.zeros(self.max_detections, dtype=np.float32)
        boxes[:n] = ut_spaces.mask_boxes(masks)
        padded_scores[:n] = scores
        self._current = {"masks": masks, "counts": counts}
        return {"frame": image, "masks": masks, "boxes": boxes, "scores": padded_scores,
                "num_detections": n}

    def _record(self, action: dict[str, Any], t: int) -> tuple[float, dict[str, Any]]:
        """Record the ids given to frame ``t``'s masks and score them (``info["clear"]``)."""
        counts = self._current["counts"]
        ids = ut_spaces.unpack_mask_ids(action, len(counts), self.max_detections)
        reported = np.flatnonzero(ids > 0)
        reported_counts = [counts[i] for i in reported]
        self._results.append((t, ids[reported], reported_counts))
        keep = ids > 0
        self._answer = (self._current["masks"][keep], ids[keep])
        if self._gt is None:
            return 0.0, {}
        info = self._sequence
        rows = self._gt.rows(t)
        cls = self._gt.classes[rows]
        gt_rows, ignore_rows = rows[cls == self.class_id], rows[cls == CLASS_IGNORE]
        size = [info.height, info.width]
        frame = self._clear.update(
            self._gt.ids[gt_rows], self._gt.rles(gt_rows), self._gt.rles(ignore_rows),
            ids[reported], [{"size": size, "counts": c} for c in reported_counts])
        clear = {"tp": frame.tp, "fp": frame.fp, "fn": frame.fn, "idsw": frame.idsw}
        return float(frame.tp - frame.fp - frame.idsw), {"clear": clear}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> MaskAnnotations:
        """The masks reported so far with their ids, as MOTS result records."""
        info = self._sequence
        frames, ids, counts = [], [], []
        for t, frame_ids, frame_counts in self._results:
            frames += [t] * len(frame_ids)
            ids += frame_ids.tolist()
            counts += frame_counts
        k = len(frames)
        height = info.height if info is not None else 0
        width = info.width if info is not None else 0
        return MaskAnnotations(
            np.asarray(frames, np.int64), np.asarray(ids, np.int64),
            np.full(k, self.class_id, np.int64), np.full(k, height, np.int64),
            np.full(k, width, np.int64), tuple(counts), np.ones(k), np.zeros(k, np.int64))

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """The frame with id-coloured masks (after a step) or grey detections (at reset)."""
        if self._answer is None:
            return draw_masks(self._frame, self._current["masks"])
        return draw_masks(self._answer_frame, *self._answer)

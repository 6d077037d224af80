"""Multi-object tracking on MOTChallenge-layout data (MOT15/16/17/20, DanceTrack, SportsMOT)."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.motchallenge import MOTChallengeBenchmark, result_rows
from unitrack_env.datasets.motchallenge import (
    Annotations,
    MOTSequence,
)
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.envs.track_classes import track_classes
from unitrack_env.metrics.clear_stream import StreamingClear
from unitrack_env.metrics.mot_classes import class_frame
from unitrack_env.metrics.mot_preprocess import preprocess_frame
from unitrack_env.render import draw_boxes
from unitrack_env.score_range import UNIT, ScoreRange, check_mode, declared_range

#: Default capacity of the padded detection arrays (MOT20 public detections reach ~250).
DEFAULT_MAX_DETECTIONS = 512
#: Default capacity of the padded track arrays.
DEFAULT_MAX_TRACKS = 512


class MOTChallengeEnv(SequenceEnv[MOTSequence]):
    """Multi-object tracking by association on a MOTChallenge-layout data set.

    ## Description
    Each episode is one video sequence of a MOTChallenge benchmark (MOT15, MOT16, MOT17,
    MOT20, DanceTrack, SportsMOT, or custom data in that layout). At every step the agent
    sees one frame and that frame's detections (the benchmark's public detections, or a
    user-given detection folder), and answers with its tracks for that frame: an id and a
    box per tracked object. The environment scores the answer against the ground truth with
    the official MOTChallenge rules and, at the end of the episode, reports the official TrackEval
    metrics (HOTA, CLEAR, Identity) of the whole sequence.

    With no ``root`` (and no ``UNITRACK_DATA``), the environment reads a small
    deterministic synthetic data set in the exact MOTChallenge layout, generated once into
    the user cache, so it works offline. For MOT15/16/17/20 it holds ``train`` sequences
    ``SYN-01`` (72 frames, 640x360) and ``SYN-02`` (64 frames, 576x324, 25 fps) and ``test``
    sequence ``SYN-03`` (80 frames) of textured people who walk and cross (two forced
    crossings each), one standing person and one occluder (classes 7 and 9 in MOT16/17/20;
    MOT15's ground truth lists the persons only), with simulated public detections (MOT15:
    scored 0-100). The names carry no detector suffix, even under MOT17: there is one
    detection set, not MOT17's three.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, the frame as uint8 RGB at its native
      size.
    - ``boxes``: ``Box((max_detections, 4), float32)``, finite, ``w, h >= 0``: detections
      ``(x, y, w, h)`` in 1-based pixels as in ``det.txt``; rows past ``num_detections``
      are 0.
    - ``scores``: ``Box((max_detections,), float32)``, finite: detection scores as in the
      file (MOT15's are unbounded), or on 0..1 with ``detection_scores="unit"``.
    - ``num_detections``: ``Discrete(max_detections + 1)``, the number of valid rows.
    - ``classes`` (with a class map only): ``Box((max_detections,), int64)``, each
      detection's class id (``det.txt`` column 8); only the scored classes' detections are
      observed.

    Ground truth never appears in observations. ``unitrack_env.spaces.unpack_detections``
    returns the valid rows.

    ## Action space
    A ``Dict`` of padded arrays: ``ids`` ``(max_tracks,) int64`` (ids >= 1), ``boxes``
    ``(max_tracks, 4) float32`` (same coordinates as the detections) and ``num_tracks``
    ``Discrete(max_tracks + 1)``. Build it with ``unitrack_env.spaces.pack_tracks(ids,
    boxes, max_tracks)``; the unpadded form ``{"ids": (k,), "boxes": (k, 4)}`` is accepted
    too. Invalid actions (wrong shapes or dtypes, NaN or infinite boxes, negative sizes,
    ids < 1, duplicate ids) raise ``InvalidActionError`` before anything is recorded.
    With a class map, each track takes the class of the detection it overlaps most in the
    frame (IoU > 0), else the class it had last, else the first scored id (as KITTI's
    tracks); the result rows carry it in column 8.

    ## Rewards
    ``TP - FP - IDSW`` of the frame under TrackEval's CLEAR matching (IoU >= 0.5, with
    MOTChallenge preprocessing: tracks matching distractor classes are dropped, only
    pedestrians with a non-zero flag count). The episode return divided by the number of
    evaluated ground-truth boxes is exactly TrackEval's MOTA. ``info["clear"]`` has the
    frame's ``tp``, ``fp``, ``fn`` and ``idsw``. Splits without ground truth give reward 0.
    With a class map, the sum over the classes, each scored on its own (the return divided
    by the evaluated boxes is the detection-averaged MOTA).

    ## Starting state
    ``reset`` returns the first frame of the chosen sequence and its detections.
    ``info`` holds ``sequence``, ``frame_index`` (1-based), ``seq_length``, ``frame_rate``,
    ``image_size`` ``(height, width)``, ``benchmark``, ``has_ground_truth`` and
    ``detection_scores``: the range of the observed scores, ``{"low", "high", "bounded",
    "source"}`` (see below), so that an agent can state its thresholds on 0..1.

    ## Episode end
    ``terminated=True`` after the agent has answered the last frame of the sequence (there
    is no truncation). The final ``info["metrics"]`` holds the sequence's official
    TrackEval metrics with TrackEval's names (``HOTA``, ``DetA``, ``AssA``, ``MOTA``,
    ``MOTP``, ``IDF1``, ``IDSW``, ``CLR_FP``, ``CLR_FN``, ``MT``, ``ML``, ...), as fractions.
    With a class map: per class (``car/HOTA``, ...) and combined as TrackEval combines
    classes (``cls_comb_cls_av/HOTA``, the class average; ``cls_comb_det_av/HOTA``, the
    detection average, also unprefixed: ``HOTA``).
    The recorded tracks are available in the official result format via
    :meth:`episode_results`.

    ## Arguments
    - ``benchmark``: rule set, one of ``MOT15``, ``MOT16``, ``MOT17``, ``MOT20``,
      ``DanceTrack``, ``SportsMOT``. DanceTrack and SportsMOT are scored by TrackEval's
      MOTChallenge code under their own names (MOT17's rules), as their official kits do.
    - ``root``: the benchmark folder holding ``train/`` and ``test/`` (DanceTrack: the
      ``dancetrack`` folder with ``{train,val,test}/`` and ``*_seqmap.txt``; SportsMOT: the
      folder with ``dataset/`` and ``splits_txt/``; the split's sequences are its seqmap's
      when it has one) (default:
      ``$UNITRACK_DATA/<benchmark>`` if that variable is set, else the synthetic default).
      Data of another benchmark (sequences named like its own, or MOT16/17/20 class columns
      under MOT15) are refused before the first frame, naming the id to use
      (``unitrack_env.datasets.mot_signatures``).
    - ``split``: sub-folder to read (``"train"`` or ``"test"``; DanceTrack and SportsMOT
      also ``"val"``, their ids' default). The test split has no ground truth: its results
      are written for the test server (DanceTrack: in a ``tracker/`` folder to zip).
    - ``sequences``: restrict to these sequence names (default: all of the split).
    - ``detections``: ``"public"`` or a folder of ``<sequence>.txt`` files in det format
      (``frame,-1,x,y,w,h,score``, optionally ``,-1,-1,-1``; rows in any order).
      DanceTrack and SportsMOT ship no public detections: give your detector's folder, or
      put it at ``<root>/detections/<split>/``; otherwise the env refuses at ``make``,
      naming that path. Their embedded defaults ship simulated detections there.
    - ``detection_scores``: ``"raw"`` (default) passes the file's scores through;
      ``"unit"`` maps the benchmark's declared range to 0..1 (``(score - low) / (high -
      low)``, clipped), for trackers whose thresholds assume confidences in 0..1. Declared
      ranges (:data:`unitrack_env.score_range.DETECTION_SCORES`): MOT15 0..100, unbounded
      (PETS09-S2L1's scores run from -0.48 to 138.92); MOT16, MOT17, MOT20 0..1.
    - ``score_range``: ``(low, high)`` of your own data's scores, instead of the
      benchmark's declared range.
    - ``min_score``: drop detections whose score (as observed, i.e. after
      ``detection_scores``) is below this value (the one place that filters detections
      by score).
    - ``max_detections``, ``max_tracks``, ``max_frame_size``: space capacities.
    - ``decode_frames``: when False, ``frame`` is a 1x1 black placeholder (for agents that
      never look at pixels; saves the decode time).
    - ``prefetch``: decode the next frame on a background thread.
    - ``shuffle``: visit sequences in a seeded random order.
    - ``render_mode``: ``"rgb_array"`` draws id-coloured track boxes on the frame.
    - ``classes``, ``distractors``, ``ignore``: a class map for data of other classes than
      pedestrians (``unitrack_env.datasets.mot_classes``), e.g.
      ``classes={"car": [3], "pedestrian": [1, 2]}, distractors=[7], ignore=[9]``: the
      ``gt.txt`` class ids (column 8) scored as each class, those whose matched tracks are
      removed (as MOTChallenge's static persons), those neither scored nor removing. Each
      class is scored with MOTChallenge's rules as if it were the pedestrians. Every class id
      of the ground truth and detections must be in the map (refused at ``reset``, naming the
      file, line and field); detections carry their class id in column 8. Without
      ``classes``, ``<root>/classes.json`` (the same three keys) when present, else
      pedestrians under ``benchmark``'s rules, as before.

    ## Version history
    - v0: initial version (DanceTrack and SportsMOT added in v0, issue 40).
    """

    requires = ("trackeval",)
    frame_size_source = "seqinfo.ini"

    def __init__(
        self,
        benchmark: str = "MOT17",
        root: str | os.PathLike | None = None,
        split: str = "train",
        sequences: list[str] | tuple[str, ...] | None = None,
        detections: str | os.PathLike | None = "public",
        min_score: float | None = None,
        detection_scores: str = "raw",
        score_range: tuple[float, float] | None = None,
        max_detections: int = DEFAULT_MAX_DETECTIONS,
        max_tracks: int = DEFAULT_MAX_TRACKS,
        classes: dict[str, list[int]] | None = None,
        distractors: list[int] | None = None,
        ignore: list[int] | None = None,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        self.benchmark = benchmark
        bench = MOTChallengeBenchmark.build(benchmark, root, split, detections, classes,
                                            distractors, ignore)
        self._use_benchmark(bench, sequences, bench.dataset.split_dir)
        #: The data's class map (None: pedestrians under the rule set).
        self.class_map = bench.class_map
        self.min_score = min_score
        self.detection_scores = check_mode(detection_scores)
        #: The declared range of the file's scores (``score_range``, else the benchmark's).
        self.score_range: ScoreRange = ScoreRange.of(score_range) if score_range is not None \
            else declared_range(self.benchmark)
        self.max_detections = int(max_detections)
        self.max_tracks = int(max_tracks)
        self.observation_space = ut_spaces.detection_observation_space(
            self.max_detections, self.max_frame_size
        )
        if self.class_map is not None:
            self.observation_space.spaces["classes"] = spaces.Box(
                0, max(self.class_map.scored_ids), (self.max_detections,), np.int64)
        self.action_space: spaces.Dict = ut_spaces.track_action_space(self.max_tracks)
        self._track_class: dict[int, int] = {}

        self._detections: Annotations | None = None
        self._clear = StreamingClear()
        self._results: list[np.ndarray] = []

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name, check_frames=self.decode_frames)
        info = sequence.info
        self._check_frame_size(name, info.width, info.height)
        detections = sequence.detections
        if self.detection_scores == "unit":
            detections = dataclasses.replace(
                detections, scores=self.score_range.to_unit(detections.scores))
        if self.min_score is not None:
            detections = detections.filter(detections.scores >= self.min_score)
        if self.class_map is not None:  # agents see the scored classes' detections only
            detections = detections.filter(np.isin(detections.classes,
                                                   self.class_map.scored_ids))
        most = int(detections.count_per_frame(info.length).max(initial=0))
        if most > self.max_detections:
            raise ValueError(
                f"{self.dataset.detection_path(name)}: a frame has {most} detections, more than "
                f"max_detections={self.max_detections}; pass a larger max_detections"
            )
        self._sequence = sequence
        self._detections = detections
        self._clear.reset()
        self._results = []
        self._track_class = {}
        return dict(seq_length=info.length, frame_rate=info.frame_rate,
                    image_size=(info.height, info.width), benchmark=self.benchmark,
                    has_ground_truth=sequence.ground_truth is not None,
                    synthetic=self.synthetic, detection_scores=self.observed_scores().info())

    def observed_scores(self) -> ScoreRange:
        """The range of the scores in the observations (0..1 with ``detection_scores="unit"``)."""
        if self.detection_scores == "raw":
            return self.score_range
        return dataclasses.replace(UNIT, source=f"{self.score_range.low:g}.."
                                   f"{self.score_range.high:g} mapped to 0..1, clipped "
                                   f"(detection_scores='unit'); {self.score_range.source}")

    def _first_step(self) -> int:
        return 1  # MOTChallenge frames are numbered from 1

    def _length(self) -> int:
        return self._sequence.info.length

    def _frame_path(self, t: int) -> Path:
        return self._sequence.info.frame_path(t)

    def _frame_size(self) -> tuple[int, int]:
        return self._sequence.info.width, self._sequence.info.height

    def _observe(self, t: int) -> dict[str, Any]:
        image = self._read_frame(t)
        rows = self._detections.rows(t)
        n = rows.stop - rows.start
        boxes = np.zeros((self.max_detections, 4), dtype=np.float32)
        scores = np.zeros(self.max_detections, dtype=np.float32)
        boxes[:n] = self._detections.boxes[rows]
        scores[:n] = self._detections.scores[rows]
        out = {"frame": image, "boxes": boxes, "scores": scores, "num_detections": n}
        if self.class_map is not None:
            out["classes"] = np.zeros(self.max_detections, dtype=np.int64)
            out["classes"][:n] = self._detections.classes[rows]
        return out

    def _record(self, action: dict[str, Any], t: int) -> tuple[float, dict[str, Any]]:
        """Record the tracks of frame ``t`` and score them (``info["clear"]``)."""
        ids, boxes = ut_spaces.unpack_tracks(action, self.max_tracks)
        results = result_rows(t, ids, boxes)
        if self.class_map is not None:
            rows = self._detections.rows(t)
            results[:, 7] = track_classes(ids, boxes, self._detections.boxes[rows],
                                          self._detections.classes[rows], self._track_class,
                                          self.class_map.scored_ids[0])
        self._results.append(results)
        self._answer = (ids, boxes)
        gt = self._sequence.ground_truth
        if gt is None:
            return 0.0, {}
        rows = gt.rows(t)
        if self.class_map is not None:
            frame = class_frame(self.class_map, t, gt.ids[rows], gt.boxes[rows],
                                gt.scores[rows], gt.classes[rows], results)
        else:
            frame = preprocess_frame(
                gt.ids[rows], gt.boxes[rows], gt.classes[rows],
                gt.scores[rows].astype(np.int64), ids, boxes, self.benchmark,
            )
        counts = self._clear.update(
            frame.gt_ids, frame.gt_boxes, frame.tracker_ids, frame.tracker_boxes, iou=frame.iou
        )
        clear = {"tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "idsw": counts.idsw}
        return float(counts.tp - counts.fp - counts.idsw), {"clear": clear}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> np.ndarray:
        """Return the tracks recorded so far as MOTChallenge result rows.

        Columns: ``frame, id, x, y, w, h, conf, -1, -1, -1`` (``conf`` = 1), the official
        result format; with a class map the 8th holds the track's class id. Write them with
        ``np.savetxt(..., delimiter=",")``.
        """
        if not self._results:
            return np.zeros((0, 10))
        return np.concatenate(self._results)

    def sequence_inputs(self, name: str) -> list[Path]:
        """The sequence's folder and its detection file (which may live elsewhere)."""
        return [*super().sequence_inputs(name), self.dataset.detection_path(name)]

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the current frame with id-coloured tracks (``rgb_array``), else None."""
        if self._answer is None:
            rows = self._detections.rows(self._t)
            return draw_boxes(self._frame, self._detections.boxes[rows])
        ids, boxes = self._answer
        return draw_boxes(self._answer_frame, boxes, ids)

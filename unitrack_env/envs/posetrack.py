"""Multi-person pose tracking on PoseTrack 2018 (per-sequence JSON, 17 keypoints)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.posetrack import PoseTrackBenchmark
from unitrack_env.datasets.posetrack import PoseTrackSequence
from unitrack_env.datasets.posetrack_json import read_posetrack_json
from unitrack_env.datasets.posetrack_records import (
    NUM_KEYPOINTS,
    PERSON_CATEGORY,
    POSETRACK_SKELETON,
    PoseTrackPerson,
    PoseTrackVideo,
)
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import DataFormatError
from unitrack_env.metrics.posetrack import PosevalSequence, evaluated_frames, summarise
from unitrack_env.metrics.posetrack_frames import (
    POSEVAL_DROPS_LAST_FRAME,
    PoseFrame,
    remove_ignored,
)
from unitrack_env.render import draw_poses
from unitrack_env.score_range import declared_range

#: Default capacity of the padded pose arrays (PoseTrack frames hold up to ~30 people).
DEFAULT_MAX_PEOPLE = 100
#: Default capacity of the padded track arrays.
DEFAULT_MAX_TRACKS = 100
#: Frame rate reported in ``info`` (PoseTrack files do not declare one; its videos are
#: 25-30 fps).
FRAME_RATE = 30
#: ``detections=`` value: the annotated poses without their ids.
ORACLE = "oracle"
_LIMBS = tuple((a - 1, b - 1) for a, b in POSETRACK_SKELETON)


class PoseTrackEnv(SequenceEnv[PoseTrackSequence]):
    """Multi-person pose tracking by association on PoseTrack 2018 data.

    ## Description
    Each episode is one PoseTrack video. At every step the agent sees a frame and that
    frame's person poses (17 keypoints each, without identities) and answers with a track
    id per pose it keeps. The environment scores the answer with poseval's per-keypoint
    CLEAR MOT rules (head-normalised distance <= 0.5, see
    :mod:`unitrack_env.metrics.posetrack`) and reports poseval's MOTA, the IDF1 and ID
    switches the UniTrack paper adds, precision and recall at the end of the episode.

    **Observations (pose detections).** ``detections=`` names a folder of
    ``<sequence>.json`` files in the PoseTrack result format (``images`` + ``annotations``
    with ``keypoints``, per-keypoint ``scores`` and a pose ``score``; ``track_id`` is
    ignored). The UniTrack paper uses the pose estimates of LightTrack, which are not
    available offline, so on real data without ``detections=`` the environment falls back
    to **oracle detections**: the annotated poses of the labelled frames with their ids
    removed, sorted left to right, score 1 (``info["oracle_detections"]`` is True). Oracle
    detections make MOTA an identity-only score; report them as such. The synthetic data
    set (one ``train``, two ``val`` and one ``test`` video of 40-56 frames, every 4th frame
    labelled plus a dense block of 16 in the middle; a standing person in each is an ignore
    region) ships simulated pose-estimator detections (misses, jitter, hallucinated occluded
    joints, false poses), used by default. A split without annotation files and without
    ``detections=`` runs with no poses.

    **Frames.** An episode visits the frames listed in the sequence file's ``images`` (all
    frames of a release video; ``nframes`` is reported as ``info["nframes_declared"]``).
    The bundled real fixture (mmpose's trimmed copy) lists one labelled frame of a
    149-frame video, so its episodes have one step; poseval drops the last evaluated frame
    of every sequence, so with the default ``drop_last_frame=True`` such a one-frame
    sequence has no evaluated frame and its metrics are NaN. A test split (frames only) is
    read from ``images/test/<sequence>/``.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, uint8 RGB at native size.
    - ``keypoints``: ``Box((max_people, 17, 3), float32)``: ``(x, y, score)`` per keypoint
      in the file's pixels and PoseTrack's keypoint order (nose, head_bottom, head_top,
      left/right ear, shoulders, elbows, wrists, hips, knees, ankles); score in ``[0, 1]``,
      0 for a keypoint the detector did not find (coordinates then 0). Rows past
      ``num_people`` are 0.
    - ``scores``: ``Box((max_people,), float32)``: pose scores.
    - ``num_people``: ``Discrete(max_people + 1)``.

    ``unitrack_env.spaces.unpack_poses`` returns the valid rows. Ground truth never appears
    in observations (oracle detections carry no ids).

    ## Action space
    A ``Dict`` of padded arrays, mirroring the MOT action: ``ids`` ``(max_tracks,) int64``
    (>= 1), ``keypoints`` ``(max_tracks, 17, 3) float32`` (the tracked poses, usually the
    observed ones echoed; a keypoint with score 0 is not predicted) and ``num_tracks``
    ``Discrete(max_tracks + 1)``. Build it with ``unitrack_env.spaces.pack_pose_tracks``;
    the unpadded ``{"ids": (k,), "keypoints": (k, 17, 3)}`` is accepted. Wrong shapes or
    dtypes, NaN/inf, scores outside ``[0, 1]``, ids < 1 or duplicate ids raise
    ``InvalidActionError`` before anything is recorded.

    ## Rewards
    On every frame poseval evaluates (labelled frames with people, except the last one
    when ``drop_last_frame``): ``sum over the 15 poseval joints of (TP - FP - IDSW)``
    (``TP`` = matched keypoints incl. switches). Other frames give 0. The episode return
    divided by the number of ground-truth keypoints (``info["metrics"]["num_objects"]``)
    is the keypoint-pooled MOTA; the reported MOTA averages the per-joint MOTAs instead.
    ``info["clear"]`` has the frame's ``tp``, ``fp``, ``fn``, ``idsw`` summed over joints.
    Splits without ground truth give 0.

    ## Starting state
    ``reset`` returns the first frame and its poses. ``info`` holds ``sequence``,
    ``frame_index`` (0-based frame number of the file name, PoseTrack's own),
    ``image_id``, ``is_labeled``, ``seq_length``, ``frame_rate`` (30; not in the files),
    ``image_size`` ``(height, width)``, ``nframes_declared``, ``has_ground_truth``,
    ``detections`` (``"synthetic"``, ``"oracle"``, ``"folder"`` or ``"none"``),
    ``oracle_detections``, ``synthetic`` and
    ``detection_scores`` (the range of the detection scores, ``{"low", "high", "bounded",
    "source"}``: 0..1, see :mod:`unitrack_env.score_range`).

    ## Episode end
    ``terminated=True`` after the last frame. ``info["metrics"]`` holds poseval's metrics
    as fractions: ``MOTA``, ``IDF1`` (means over joints), ``IDSW`` (sum over joints),
    ``MOTP``, ``Precision``, ``Recall``, ``MOTA/<body part>`` (poseval's columns),
    ``<metric>/<joint>`` per joint, and counts. Results are written as the official
    PoseTrack 2018 result JSON ``<folder>/<sequence>.json`` (the ground truth's ``images``,
    one annotation per track with ``track_id``, ``keypoints`` ``(x, y, 1)`` or
    ``(0, 0, 0)``, ``scores`` and ``score``), which :meth:`score_folder` re-reads.

    ## Arguments
    - ``root``: folder holding ``posetrack_data/`` (default: ``$UNITRACK_DATA/PoseTrack2018``
      if that variable is set, else the synthetic data).
    - ``split``: ``"train"``, ``"val"`` (default, the paper's) or ``"test"``.
    - ``sequences``: restrict to these sequence names.
    - ``detections``: a folder of ``<sequence>.json`` pose detections, ``"oracle"``, or
      None (synthetic: its simulated detections; real: oracle, or none for test).
    - ``min_score``: drop detected poses scored below this (the one place that filters
      detections by score).
    - ``max_people``, ``max_tracks``, ``max_frame_size``: space capacities.
    - ``drop_last_frame``: leave out the last evaluated frame per sequence like poseval.
    - ``decode_frames``, ``prefetch``, ``shuffle``: as in the other environments.
    - ``render_mode``: ``"rgb_array"`` draws the tracked skeletons coloured by id.

    ## Version history
    - v0: initial version.
    """

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        split: str = "val",
        sequences: list[str] | tuple[str, ...] | None = None,
        detections: str | os.PathLike | None = None,
        min_score: float | None = None,
        max_people: int = DEFAULT_MAX_PEOPLE,
        max_tracks: int = DEFAULT_MAX_TRACKS,
        drop_last_frame: bool = POSEVAL_DROPS_LAST_FRAME,
        **options: Unpack[EpisodeOptions],
    ) -> None:
        super().__init__(**options)
        bench = PoseTrackBenchmark.build(root, split, drop_last_frame)
        self._use_benchmark(bench, sequences, f"{bench.dataset.data_dir} ({split})")
        self.detection_source, self.detection_dir = self._detection_source(
            self.dataset.data_dir.parent, detections)
        self.min_score = min_score
        self.max_people = int(max_people)
        self.max_tracks = int(max_tracks)
        self.drop_last_frame = bool(drop_last_frame)
        self.observation_space = spaces.Dict({
            "frame": ut_spaces.Image(*self.max_frame_size),
            "keypoints": ut_spaces.keypoint_array_space(self.max_people, NUM_KEYPOINTS),
            "scores": spaces.Box(0.0, ut_spaces.FLOAT_MAX, (self.max_people,), np.float32),
            "num_people": spaces.Discrete(self.max_people + 1),
        })
        self.action_space = ut_spaces.pose_track_action_space(self.max_tracks, NUM_KEYPOINTS)
        self._poses: list[tuple[np.ndarray, np.ndarray]] = []
        self._evaluated: set[int] = set()
        self._poseval = PosevalSequence()
        self._results: list[list[PoseTrackPerson]] = []

    def _detection_source(self, data_root: Path, detections: str | os.PathLike | None
                          ) -> tuple[str, Path | None]:
        if detections is None:
            if self.synthetic:
                # lazy: start-up cost (unitrack_env.datasets.synthetic, every generator)
                from unitrack_env.datasets.synthetic.posetrack import DETECTIONS_FOLDER

                return "synthetic", Path(data_root) / DETECTIONS_FOLDER / self.dataset.split
            return (ORACLE if self.dataset.annotated else "none"), None
        if str(detections) == ORACLE:
            if not self.dataset.annotated:
                raise ValueError(f"detections='oracle' needs annotations, and split "
                                 f"'{self.dataset.split}' has none; pass a detection folder")
            return ORACLE, None
        folder = Path(detections).expanduser()
        if not folder.is_dir():
            raise DataFormatError(folder, "detections= is not a folder of <sequence>.json files")
        return "folder", folder

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        sequence = self.dataset.load(name)
        width, height = sequence.image_size
        self._check_frame_size(name, width, height, hint="one")
        self._poses = self._load_poses(sequence)
        most = max((len(s) for s, _ in self._poses), default=0)
        if most > self.max_people:
            raise ValueError(f"{name}: a frame has {most} poses, more than max_people="
                             f"{self.max_people}; pass a larger max_people")
        self._sequence = sequence
        self._evaluated = (set(evaluated_frames(sequence.ground_truth,
                                                drop_last_frame=self.drop_last_frame))
                           if sequence.ground_truth is not None else set())
        _check_head_boxes(sequence, self._evaluated)
        self._poseval = PosevalSequence()
        self._results = []
        first = sequence.images[0]
        return dict(
            seq_length=sequence.length, frame_rate=FRAME_RATE, image_size=(height, width),
            nframes_declared=first.nframes if first.nframes is not None else sequence.length,
            has_ground_truth=sequence.ground_truth is not None,
            detections=self.detection_source,
            oracle_detections=self.detection_source == ORACLE,
            synthetic=self.synthetic,
            detection_scores=declared_range("PoseTrack2018").info(),
        )

    @property
    def _k(self) -> int:
        """The current step (the cursor :attr:`_t`; kept for code that reads ``_k``)."""
        return self._t

    def _load_poses(self, sequence: PoseTrackSequence) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per frame ``(scores (n,), keypoints (n, 17, 3))`` from the detection source."""
        empty = (np.zeros(0, np.float32), np.zeros((0, NUM_KEYPOINTS, 3), np.float32))
        if self.detection_source == "none":
            return [empty] * sequence.length
        if self.detection_source == ORACLE:
            per_image = sequence.ground_truth.people
            out = []
            for people in per_image:
                poses = [_observed_pose(p, oracle=True) for p in people]
                poses.sort(key=lambda sp: _leftmost(sp[1]))  # no file (= track id) order
                out.append(_stack(poses) if poses else empty)
            return out
        path = self.detection_dir / f"{sequence.name}.json"
        video = read_posetrack_json(path)
        position = {image.id: k for k, image in enumerate(sequence.images)}
        lists: list[list[tuple[float, np.ndarray]]] = [[] for _ in sequence.images]
        for image, people in zip(video.images, video.people, strict=True):
            if image.id not in position:
                if people:
                    raise DataFormatError(path, f"has poses on image {image.id}, which sequence "
                                                f"'{sequence.name}' does not list", field="images")
                continue
            for person in people:
                lists[position[image.id]].append(_observed_pose(person, oracle=False))
        out = []
        for poses in lists:
            if self.min_score is not None:
                poses = [sp for sp in poses if sp[0] >= self.min_score]
            out.append(_stack(poses) if poses else empty)
        return out

    def _observe(self, t: int) -> dict[str, Any]:
        image = self._read_frame(t)
        scores, poses = self._poses[t]
        n = len(scores)
        keypoints = np.zeros((self.max_people, NUM_KEYPOINTS, 3), dtype=np.float32)
        pose_scores = np.zeros(self.max_people, dtype=np.float32)
        keypoints[:n] = poses
        pose_scores[:n] = scores
        return {"frame": image, "keypoints": keypoints, "scores": pose_scores, "num_people": n}

    def _frame_info(self, t: int) -> dict[str, Any]:
        image = self._sequence.images[t]
        return {"frame_index": image.frame_index, "image_id": image.id,
                "is_labeled": bool(image.is_labeled)}

    def _record(self, action: dict[str, Any], t: int) -> tuple[float, dict[str, Any]]:
        """Record the pose tracks of frame ``t``; score the frames poseval evaluates."""
        ids, keypoints = ut_spaces.unpack_pose_tracks(action, self.max_tracks, NUM_KEYPOINTS)
        image = self._sequence.images[t]
        people = [_result_person(image.id, int(i), kp) for i, kp in zip(ids, keypoints,
                                                                          strict=True)]
        self._results.append(people)
        self._answer = (ids, keypoints)
        if t not in self._evaluated:
            return 0.0, {}
        counts = self._poseval.update(PoseFrame.from_people(self._sequence.ground_truth.people[t]),
                                      PoseFrame.from_people(people), image.ignore_regions)
        clear = {"tp": int(counts.detections.sum()), "fp": int(counts.false_positives.sum()),
                 "fn": int(counts.misses.sum()), "idsw": int(counts.switches.sum())}
        return float(counts.mota_numerator), {"clear": clear}

    def episode_metrics(self) -> dict[str, float]:
        """Poseval's metrics of the recorded episode (needs ground truth)."""
        if self._sequence is None or self._sequence.ground_truth is None:
            raise ValueError("this sequence has no ground truth to score against")
        return summarise([self._poseval.counts()])

    # ------------------------------------------------------------------ results
    def episode_results(self) -> PoseTrackVideo:
        """Return the recorded tracks as a PoseTrack 2018 result (the sequence's images)."""
        if self._sequence is None:
            raise RuntimeError("no episode; call reset() first")
        people = self._results + [[] for _ in range(self._sequence.length - len(self._results))]
        return PoseTrackVideo(list(self._sequence.images), people, [dict(PERSON_CATEGORY)])

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """Return the frame with the tracked skeletons coloured by id (detections at reset)."""
        if self._answer is None:
            return draw_poses(self._frame, self._poses[self._t][1], _LIMBS)
        ids, keypoints = self._answer
        return draw_poses(self._answer_frame, keypoints, _LIMBS, ids)


def _check_head_boxes(sequence: PoseTrackSequence, evaluated: set[int]) -> None:
    """Refuse, at reset, a scored ground-truth person without ``bbox_head``.

    Poseval normalises joint distances by the head box and would fail on that frame
    mid-episode.
    """
    for t in sorted(evaluated):
        image = sequence.images[t]
        frame = PoseFrame.from_people(sequence.ground_truth.people[t])
        if image.ignore_regions:
            frame = remove_ignored(frame, image.ignore_regions)
        missing = frame.present.any(axis=1) & ~np.isfinite(frame.head_size)
        if missing.any():
            raise DataFormatError(
                sequence.annotation_path or sequence.name,
                f"person with track_id {int(frame.ids[missing][0])} on image {image.id} "
                f"({image.file_name}) has keypoints but no bbox_head; poseval needs the head "
                "box to normalise joint distances", field="bbox_head")


def _observed_pose(person: PoseTrackPerson, *, oracle: bool) -> tuple[float, np.ndarray]:
    """A person as ``(pose score, (17, 3) float32 (x, y, keypoint score))``."""
    present = person.annotated
    if oracle or person.scores is None or person.scores.size == 0:
        joint_scores = present.astype(np.float64)
    else:
        joint_scores = np.where(present, np.clip(person.scores, 0.0, 1.0), 0.0)
    pose = np.zeros((NUM_KEYPOINTS, 3), dtype=np.float32)
    pose[present, :2] = person.keypoints[present, :2]
    pose[:, 2] = joint_scores
    if oracle:
        score = 1.0
    elif person.score is not None:
        score = person.score
    else:
        score = float(joint_scores[present].mean()) if present.any() else 0.0
    return max(0.0, float(score)), pose


def _leftmost(pose: np.ndarray) -> float:
    present = pose[:, 2] > 0
    return float(pose[present, 0].min()) if present.any() else float("inf")


def _stack(poses: list[tuple[float, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([s for s, _ in poses], dtype=np.float32),
            np.stack([p for _, p in poses]).astype(np.float32))


def _result_person(image_id: int, track_id: int, keypoints: np.ndarray) -> PoseTrackPerson:
    """One tracked pose in the result format: ``(x, y, 1)`` if its score > 0 else ``(0, 0, 0)``."""
    present = keypoints[:, 2] > 0
    out = np.zeros((NUM_KEYPOINTS, 3))
    out[present, :2] = keypoints[present, :2]
    out[present, 2] = 1.0
    scores = np.where(present, keypoints[:, 2], 0.0)
    score = float(scores[present].mean()) if present.any() else 0.0
    return PoseTrackPerson(image_id=image_id, keypoints=out, track_id=track_id, scores=scores,
                           score=score, extra={"category_id": 1})

"""PoseTrack multi-person pose tracking metrics: poseval's per-keypoint CLEAR MOT (our code).

Restated from poseval (leonid-pishchulin/poseval, ``py/eval_helpers.py`` ``assignGTmulti``,
``py/evaluateTracking.py`` ``computeMetrics``; UniTrack's copy, ``eval/poseval`` of
Zhongdao/UniTrack @ 5efab37, adds IDF1 and the ID-switch sum) and py-motmetrics'
``MOTAccumulator.update``, which poseval calls. Nothing is imported from them;
``tests/unitrack_env/test_posetrack.py`` cross-checks the counts with motmetrics 1.4.0.

* Joints: poseval's 15, read by name from the 17 PoseTrack 2018 keypoints (``convert.py``; the
  ears are ignored). A keypoint exists unless it is ``(0, 0, 0)``, on both sides.
* Frames: ground-truth frames with a person (``cleanupData``), predictions paired by position,
  the last frame dropped. Keypoints strictly inside an ignore polygon are removed on both
  sides, then persons left without keypoints (``removeIgnoredPoints``).
* Matching, per joint and frame, by py-motmetrics' rule among candidates (both joints exist,
  head-normalised distance <= 0.5): a ground truth keeps the hypothesis it last matched if
  still a candidate; the rest go by minimum-distance assignment, a match whose ground truth
  last matched another hypothesis being a switch; the rest are misses and false positives. A
  frame with nobody on one side scores one dummy miss and false positive per joint (poseval's
  ``trackidxGT = trackidxPr = [0]``, distance NaN); our dummy ids cannot collide with real
  ones, while poseval's 0 can equal a real track 0 in the first sequence it globs (moving
  only IDF1 there).
* Scores: counts summed over sequences per joint. ``MOTP = 1 - sum(matched d) / detections``
  is 0 for a joint without detections and averaged as such, as poseval does (so a sequence
  may score below the pooled set); poseval with py-motmetrics >= 1.2 also sums unmatched
  candidate pairs (``events['D']`` then holds RAW rows), we keep the matched distances.
  Per-joint IDF1 (py-motmetrics' global identity assignment, ``2 IDTP / (objects +
  predictions)``) is averaged over sequences (UniTrack's ``idf1 / nSeq``). Totals are means
  over the joints with a defined value, ``IDSW`` their sum (the UniTrack paper: "averaged for
  IDF-1 and MOTA, and summed for ID-switch, over 15 key points").
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from unitrack_env.datasets.posetrack_records import PoseTrackVideo
from unitrack_env.metrics.posetrack_frames import (
    BODY_PARTS,
    DIST_THRESHOLD,
    DUMMY_GT_ID,
    DUMMY_PRED_ID,
    NUM_JOINTS,
    POSEVAL_DROPS_LAST_FRAME,
    POSEVAL_JOINTS,
    PoseFrame,
    joint_distances,
    remove_ignored,
)
from unitrack_env.metrics.posetrack_joint import ClearAccumulator

__all__ = [
    "FrameCounts",
    "PosevalSequence",
    "SequenceCounts",
    "evaluate_video",
    "evaluated_frames",
    "summarise",
]


@dataclass(frozen=True)
class FrameCounts:
    """Per-joint CLEAR events of one frame (each field ``(15,)`` int)."""

    matches: np.ndarray
    switches: np.ndarray
    misses: np.ndarray
    false_positives: np.ndarray

    @property
    def detections(self) -> np.ndarray:
        """``matches + switches`` per joint."""
        return self.matches + self.switches

    @property
    def mota_numerator(self) -> int:
        """The frame's MOTA numerator summed over joints (the environment's reward).

        ``sum_j (detections_j - false_positives_j - switches_j)``.
        """
        return int((self.detections - self.false_positives - self.switches).sum())

    @classmethod
    def zeros(cls) -> FrameCounts:
        """A frame that is not evaluated."""
        z = np.zeros(NUM_JOINTS, np.int64)
        return cls(z, z.copy(), z.copy(), z.copy())


class PosevalSequence:
    """poseval's tracking evaluation of one sequence, fed one frame at a time."""

    def __init__(self) -> None:
        self.joints = [ClearAccumulator() for _ in range(NUM_JOINTS)]
        self.frames = 0
        #: The last frame's persons after ignore regions, and per joint the matched pairs
        #: ``(gt person, predicted person, switched, distance)``, missed gt persons and
        #: unmatched predicted persons; ``None`` when poseval scored it against dummies
        #: (no person on one side: one miss and one false positive per joint).
        self.last_frame: tuple[PoseFrame, PoseFrame, list | None] | None = None

    def update(
        self,
        gt: PoseFrame,
        pred: PoseFrame,
        ignore_regions: Sequence[np.ndarray] = (),
    ) -> FrameCounts:
        """Evaluate one frame (only frames poseval evaluates, see :func:`evaluated_frames`)."""
        if ignore_regions:
            gt = remove_ignored(gt, ignore_regions)
            pred = remove_ignored(pred, ignore_regions)
        self.frames += 1
        out = [np.zeros(NUM_JOINTS, np.int64) for _ in range(4)]
        if len(gt) == 0 or len(pred) == 0:
            for j, acc in enumerate(self.joints):
                counts = acc.update(np.array([DUMMY_GT_ID]), np.array([DUMMY_PRED_ID]),
                                    np.full((1, 1), np.nan))
                out[2][j], out[3][j] = counts.misses, counts.false_positives
            self.last_frame = (gt, pred, None)
            return FrameCounts(*out)
        if np.any(~np.isfinite(gt.head_size[gt.present.any(axis=1)])):
            raise ValueError("a ground-truth person with keypoints has no bbox_head (poseval "
                             "needs the head box to normalise distances)")
        dist = joint_distances(gt, pred)
        joints = []
        for j, acc in enumerate(self.joints):
            g = np.nonzero(gt.present[:, j])[0]
            p = np.nonzero(pred.present[:, j])[0]
            d = dist[np.ix_(g, p, [j])][..., 0]
            d = np.where(d <= DIST_THRESHOLD, d, np.nan)
            counts = acc.update(gt.ids[g], pred.ids[p], d)
            out[0][j], out[1][j] = counts.matches, counts.switches
            out[2][j], out[3][j] = counts.misses, counts.false_positives
            pairs, missed, false = acc.last_pairs
            joints.append(([(int(g[a]), int(p[b]), sw, dd) for a, b, sw, dd in pairs],
                           g[missed], p[false]))
        self.last_frame = (gt, pred, joints)
        return FrameCounts(*out)

    def counts(self) -> SequenceCounts:
        """Return the sequence's per-joint totals."""
        arr = lambda name: np.array([getattr(a, name) for a in self.joints])  # noqa: E731
        return SequenceCounts(
            matches=arr("matches"), switches=arr("switches"), misses=arr("misses"),
            false_positives=arr("false_positives"), distance=arr("distance"),
            idf1=np.array([a.idf1() for a in self.joints]), frames=self.frames,
        )


@dataclass(frozen=True)
class SequenceCounts:
    """Per-joint totals of one sequence (each array ``(15,)``)."""

    matches: np.ndarray
    switches: np.ndarray
    misses: np.ndarray
    false_positives: np.ndarray
    distance: np.ndarray
    idf1: np.ndarray
    frames: int

    @property
    def detections(self) -> np.ndarray:
        """``matches + switches``."""
        return self.matches + self.switches

    @property
    def objects(self) -> np.ndarray:
        """Ground-truth joint occurrences."""
        return self.detections + self.misses


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    num = np.asarray(num, np.float64)
    den = np.asarray(den, np.float64)
    out = np.full(num.shape, np.nan)
    np.divide(num, den, out=out, where=den > 0)
    return out


def _mean_defined(values: np.ndarray) -> float:
    defined = values[~np.isnan(values)]
    return float(defined.mean()) if defined.size else float("nan")


def summarise(sequences: Iterable[SequenceCounts]) -> dict[str, float]:
    """Combine sequences into poseval's metrics (fractions; see the module docstring).

    A flat dict: ``MOTA``, ``IDF1``, ``IDSW`` (summed), ``MOTP``, ``Precision``, ``Recall``
    (means over joints), ``MOTA/<part>``, ``<metric>/<joint>`` and pooled ``num_*`` counts;
    NaN without evaluated frames.
    """
    seqs = list(sequences)
    zero = np.zeros(NUM_JOINTS)
    total = {name: sum((getattr(s, name) for s in seqs), zero.copy())
             for name in ("matches", "switches", "misses", "false_positives", "distance")}
    detections = total["matches"] + total["switches"]
    objects = detections + total["misses"]
    mota = 1.0 - _ratio(total["misses"] + total["switches"] + total["false_positives"], objects)
    motp = np.where(detections > 0, 1.0 - _ratio(total["distance"], detections), 0.0)
    precision = _ratio(detections, detections + total["false_positives"])
    recall = _ratio(detections, objects)
    idf1 = (np.sum([s.idf1 for s in seqs], axis=0) / len(seqs)) if seqs else zero + np.nan
    out: dict[str, float] = {
        "MOTA": _mean_defined(mota),
        "IDF1": _mean_defined(idf1),
        "IDSW": float(total["switches"].sum()),
        "MOTP": _mean_defined(motp),
        "Precision": _mean_defined(precision),
        "Recall": _mean_defined(recall),
    }
    index = {name: j for j, name in enumerate(POSEVAL_JOINTS)}
    for part, names in BODY_PARTS.items():
        out[f"MOTA/{part}"] = float(np.mean([mota[index[n]] for n in names]))
    for j, name in enumerate(POSEVAL_JOINTS):
        out[f"MOTA/{name}"] = float(mota[j])
        out[f"IDF1/{name}"] = float(idf1[j])
        out[f"IDSW/{name}"] = float(total["switches"][j])
        out[f"Precision/{name}"] = float(precision[j])
        out[f"Recall/{name}"] = float(recall[j])
    out["num_objects"] = float(objects.sum())
    out["num_misses"] = float(total["misses"].sum())
    out["num_false_positives"] = float(total["false_positives"].sum())
    out["num_frames"] = float(sum(s.frames for s in seqs))
    out["num_sequences"] = float(len(seqs))
    return out


# --------------------------------------------------------------------------- files
def evaluated_frames(gt: PoseTrackVideo, *, drop_last_frame: bool = POSEVAL_DROPS_LAST_FRAME
                     ) -> list[int]:
    """Return the positions of the frames poseval evaluates in a ground-truth file.

    Frames with at least one annotated person, in file order, without the last one when
    ``drop_last_frame`` (poseval's behaviour).
    """
    frames = [k for k, people in enumerate(gt.people) if people]
    return frames[:-1] if drop_last_frame else frames


def evaluate_video(
    gt: PoseTrackVideo,
    pred: PoseTrackVideo,
    *,
    drop_last_frame: bool = POSEVAL_DROPS_LAST_FRAME,
) -> SequenceCounts:
    """Evaluate one sequence's result file against its ground-truth file.

    Raises ValueError when the result lists other images than the ground truth (poseval
    pairs frames by position).
    """
    if [im.id for im in pred.images] != [im.id for im in gt.images]:
        raise ValueError(
            f"the result lists {len(pred.images)} images, the ground truth {len(gt.images)} "
            "(or in another order); poseval pairs frames by position, so copy the ground "
            "truth's 'images' list")
    seq = PosevalSequence()
    for k in evaluated_frames(gt, drop_last_frame=drop_last_frame):
        seq.update(PoseFrame.from_people(gt.people[k]), PoseFrame.from_people(pred.people[k]),
                   gt.images[k].ignore_regions)
    return seq.counts()

"""PoseTrack multi-person pose tracking metrics: poseval's per-keypoint CLEAR MOT (our code).

Definitions restated from poseval (leonid-pishchulin/poseval, ``py/eval_helpers.py``
``assignGTmulti`` and ``py/evaluateTracking.py`` ``computeMetrics``; the copy UniTrack ships in
``eval/poseval`` (Zhongdao/UniTrack @ 5efab37) adds IDF1 and the ID-switch sum) and from
py-motmetrics' ``MOTAccumulator.update`` (the library poseval calls). Nothing is imported from
them; ``tests/unitrack_env/test_posetrack.py`` cross-checks the counts with motmetrics 1.4.0.

**Joints.** poseval scores 15 joints (:data:`POSEVAL_JOINTS`, its ``Joint`` order), read from
the 17 PoseTrack 2018 keypoints by name (``convert.py``: ``head_bottom``, ``nose``,
``head_top``, shoulders ... ankles; the ear slots are ignored). A keypoint exists unless it is
``(0, 0, 0)``; the same rule applies to ground truth and predictions.

**Frames.** Only ground-truth frames with at least one person are evaluated (poseval's
``cleanupData``); predictions are paired with them by position. poseval then drops the
**last** of those frames in every sequence (``imgidxs = imgidxs[:-1]``); we reproduce it
(:data:`POSEVAL_DROPS_LAST_FRAME`, switchable). Where a frame has ignore regions, keypoints
strictly inside a polygon are removed from ground truth and predictions, and persons left
without keypoints are removed (``removeIgnoredPoints``).

**Matching, per joint and frame.** ``d = ||gt - pred|| / head_size`` with
``head_size = 0.6 * ||(x2, y2) - (x1, y1)||`` of the ground-truth ``bbox_head``
(``getHeadSize``); a pair is a candidate when both joints exist and ``d <= 0.5``
(``distThresh``). Ground-truth persons with the joint are the objects, predicted persons with
the joint the hypotheses, and py-motmetrics' rule assigns them: (1) a ground truth keeps the
hypothesis it was last matched to if that hypothesis is present and a candidate; (2) the rest
are assigned by a minimum-distance linear assignment (non-candidates excluded); a match whose
ground truth was last matched to another hypothesis is an ID switch; (3) unmatched ground
truths are misses, unmatched hypotheses false positives. When a frame has no predicted or no
ground-truth person at all, poseval records one dummy miss and one dummy false positive per
joint (``trackidxGT = trackidxPr = [0]``, distance NaN); we do the same with dummy ids that
cannot collide with real ones (poseval's ``0`` can coincide with a real track 0 in the first
sequence it globs, which only affects IDF1 there, by design-free accident).

**Scores.** Per joint, counts are summed over sequences, then
``MOTA = 1 - (misses + switches + false_positives) / objects``,
``MOTP = 1 - sum(matched d) / detections`` (``detections = matches + switches``; 0, not
undefined, for a joint without detections, and averaged over the joints as such, as poseval
does: a sequence may therefore score below the pooled set),
``precision = detections / (detections + false_positives)``,
``recall = detections / objects``; per joint ``IDF1`` (py-motmetrics' global min-cost identity
assignment, ``2 IDTP / (objects + predictions)``) is computed per sequence and **averaged over
sequences** (UniTrack's ``idf1 / nSeq``). The reported totals are the means over the joints
whose value is defined, and ``IDSW`` is the **sum** over joints (the UniTrack paper: "averaged
for IDF-1 and MOTA, and summed for ID-switch, over 15 key points"). poseval prints percent;
we return fractions. poseval's MOTP with py-motmetrics >= 1.2 also sums the distances of
unmatched candidate pairs (``events['D']`` then holds RAW rows); we keep its original meaning,
the matched distances.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from unitrack_env.datasets.posetrack import (
    POSETRACK_KEYPOINTS,
    PoseTrackPerson,
    PoseTrackVideo,
)

POSEVAL_JOINTS: tuple[str, ...] = (
    "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle",
    "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow",
    "left_wrist", "head_bottom", "nose", "head_top",
)
"""poseval's 15 joints in its ``Joint`` order (``head_bottom`` is poseval's ``neck``)."""

NUM_JOINTS: int = len(POSEVAL_JOINTS)

#: Column of each poseval joint in the 17 PoseTrack keypoints.
KEYPOINT_OF_JOINT: tuple[int, ...] = tuple(POSETRACK_KEYPOINTS.index(n) for n in POSEVAL_JOINTS)

#: poseval's body-part columns (``getCum``): joints averaged into each printed column.
BODY_PARTS: MappingProxyType[str, tuple[str, ...]] = MappingProxyType({
    "Head": ("head_top", "head_bottom", "nose"),
    "Shou": ("right_shoulder", "left_shoulder"),
    "Elb": ("right_elbow", "left_elbow"),
    "Wri": ("right_wrist", "left_wrist"),
    "Hip": ("right_hip", "left_hip"),
    "Knee": ("right_knee", "left_knee"),
    "Ankl": ("right_ankle", "left_ankle"),
})

#: Match threshold on the head-normalised distance (poseval's ``distThresh``).
DIST_THRESHOLD: float = 0.5
#: Head size = this factor x the diagonal of the head box (poseval's ``getHeadSize``).
HEAD_SIZE_FACTOR: float = 0.6
#: poseval leaves out the last evaluated frame of every sequence (``imgidxs[:-1]``).
POSEVAL_DROPS_LAST_FRAME: bool = True
#: Ids of poseval's dummy miss / false positive in frames without GT or predictions.
DUMMY_GT_ID: int = -(2**62)
DUMMY_PRED_ID: int = -(2**62)


# --------------------------------------------------------------------------- frames
@dataclass(frozen=True)
class PoseFrame:
    """The persons of one frame, reduced to poseval's 15 joints.

    Attributes:
        ids: ``(n,)`` int64 track ids.
        xy: ``(n, 15, 2)`` float64 joint coordinates.
        present: ``(n, 15)`` bool, joints that exist.
        head_size: ``(n,)`` float64 PCKh reference (ground truth only; NaN if unknown).
    """

    ids: np.ndarray
    xy: np.ndarray
    present: np.ndarray
    head_size: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def empty(cls) -> PoseFrame:
        """A frame without persons."""
        return cls(np.zeros(0, np.int64), np.zeros((0, NUM_JOINTS, 2)),
                   np.zeros((0, NUM_JOINTS), bool), np.zeros(0))

    @classmethod
    def from_keypoints(
        cls,
        ids: Sequence[int] | np.ndarray,
        keypoints: np.ndarray,
        bbox_head: np.ndarray | None = None,
    ) -> PoseFrame:
        """Build a frame from ``(n, 17, 3)`` PoseTrack keypoints.

        Args:
            ids: track id of each person.
            keypoints: ``(n, 17, 3)`` ``(x, y, v)``; ``(0, 0, 0)`` is an absent keypoint.
            bbox_head: optional ``(n, 4)`` head boxes ``(x, y, w, h)`` (ground truth).
        """
        kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, len(POSETRACK_KEYPOINTS), 3)
        ids_arr = np.asarray(ids, dtype=np.int64).reshape(-1)
        if len(ids_arr) != len(kp):
            raise ValueError(f"{len(ids_arr)} ids but {len(kp)} poses")
        cols = list(KEYPOINT_OF_JOINT)
        xy = kp[:, cols, :2].copy()
        present = ~np.all(kp[:, cols, :] == 0.0, axis=2)
        return cls(ids_arr, xy, present, head_sizes(bbox_head, len(kp)))

    @classmethod
    def from_people(cls, people: Sequence[PoseTrackPerson], *, dummy_id: int = -1) -> PoseFrame:
        """Build a frame from parsed persons (missing track ids become ``dummy_id``)."""
        if not people:
            return cls.empty()
        ids = [p.track_id if p.track_id is not None else dummy_id for p in people]
        keypoints = np.stack([p.keypoints for p in people])
        heads = np.array([p.bbox_head if p.bbox_head is not None else (np.nan,) * 4
                          for p in people], dtype=np.float64)
        return cls.from_keypoints(ids, keypoints, heads)

    def subset(self, keep: np.ndarray) -> PoseFrame:
        """The persons selected by a boolean or index array."""
        return PoseFrame(self.ids[keep], self.xy[keep], self.present[keep], self.head_size[keep])


def head_sizes(bbox_head: np.ndarray | None, count: int) -> np.ndarray:
    """Return ``0.6 x`` the head-box diagonal of each person (NaN without a head box)."""
    if bbox_head is None:
        return np.full(count, np.nan)
    boxes = np.asarray(bbox_head, dtype=np.float64).reshape(-1, 4)
    return HEAD_SIZE_FACTOR * np.hypot(boxes[:, 2], boxes[:, 3])


def remove_ignored(frame: PoseFrame, regions: Sequence[np.ndarray]) -> PoseFrame:
    """Drop joints strictly inside any ignore polygon, then persons left without joints.

    Mirrors poseval's ``removeIgnoredPointsRects``, which runs only on frames that have
    ignore regions: a person with no joint left (or none to begin with) is removed.
    Polygons with fewer than 3 vertices contain nothing.
    """
    if not regions:
        return frame
    polygons = [np.asarray(p, np.float32).reshape(-1, 2) for p in regions]
    polygons = [p for p in polygons if len(p) >= 3]
    present = frame.present.copy()
    for poly in polygons:
        contour = poly.reshape(-1, 1, 2)
        for n, j in zip(*np.nonzero(present), strict=True):
            x, y = frame.xy[n, j]
            if cv2.pointPolygonTest(contour, (float(x), float(y)), False) > 0:
                present[n, j] = False
    keep = present.any(axis=1)
    return PoseFrame(frame.ids[keep], frame.xy[keep], present[keep], frame.head_size[keep])


def joint_distances(gt: PoseFrame, pred: PoseFrame) -> np.ndarray:
    """Return ``(len(gt), len(pred), 15)`` head-normalised joint distances.

    Entries are ``inf`` where the joint is missing on either side.
    """
    diff = gt.xy[:, None] - pred.xy[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        dist = np.hypot(diff[..., 0], diff[..., 1]) / gt.head_size[:, None, None]
    both = gt.present[:, None, :] & pred.present[None, :, :]
    return np.where(both, dist, np.inf)


# --------------------------------------------------------------------------- one joint
def _assignment(costs: np.ndarray) -> list[tuple[int, int]]:
    """Minimum-cost assignment ignoring non-finite entries (py-motmetrics' scipy path).

    Non-finite costs are replaced by ``2 r c + 1`` (``c`` = largest finite magnitude + 1,
    ``r`` = the smaller side), a cost that no optimal solution pays unless forced, and such
    pairs are dropped from the result.
    """
    if costs.size == 0:
        return []
    valid = np.isfinite(costs)
    if not valid.any():
        return []
    finite = costs.copy()
    if not valid.all():
        c = np.abs(costs[valid]).max() + 1.0
        finite = np.where(valid, costs, 2.0 * min(costs.shape) * c + 1.0)
    rows, cols = linear_sum_assignment(finite)
    return [(int(i), int(j)) for i, j in zip(rows, cols, strict=True) if valid[i, j]]


@dataclass(frozen=True)
class JointFrameCounts:
    """CLEAR events of one joint in one frame."""

    matches: int
    switches: int
    misses: int
    false_positives: int
    distance: float

    @property
    def detections(self) -> int:
        """``matches + switches`` (py-motmetrics' ``num_detections``)."""
        return self.matches + self.switches


@dataclass
class ClearAccumulator:
    """py-motmetrics' ``MOTAccumulator`` event rules for one joint of one sequence.

    Keeps the CLEAR totals and the per-identity frame counts IDF1 needs; all state is on the
    instance.
    """

    matches: int = 0
    switches: int = 0
    misses: int = 0
    false_positives: int = 0
    distance: float = 0.0
    last_match: dict[int, int] = field(default_factory=dict)
    candidate_frames: Counter = field(default_factory=Counter)

    def update(self, oids: np.ndarray, hids: np.ndarray, dist: np.ndarray) -> JointFrameCounts:
        """Add one frame: ``dist`` is ``(len(oids), len(hids))`` with NaN for non-candidates."""
        oids = np.asarray(oids, dtype=np.int64).reshape(-1)
        hids = np.asarray(hids, dtype=np.int64).reshape(-1)
        d = np.asarray(dist, dtype=np.float64).reshape(len(oids), len(hids)).copy()
        pairs = {(int(oids[i]), int(hids[j])) for i, j in zip(*np.nonzero(np.isfinite(d)),
                                                               strict=True)}
        self.candidate_frames.update(pairs)
        o_done = np.zeros(len(oids), bool)
        h_done = np.zeros(len(hids), bool)
        matches = switches = 0
        total = 0.0
        if len(oids) and len(hids):
            for i, o in enumerate(oids.tolist()):  # 1. keep last frame's partner if a candidate
                if o not in self.last_match:
                    continue
                js = np.nonzero(~h_done & (hids == self.last_match[o]))[0]
                if len(js) and np.isfinite(d[i, js[0]]):
                    o_done[i] = h_done[js[0]] = True
                    matches += 1
                    total += d[i, js[0]]
            d[o_done, :] = np.nan
            d[:, h_done] = np.nan
            for i, j in _assignment(d):  # 2. assign the rest
                o, h = int(oids[i]), int(hids[j])
                if o in self.last_match and self.last_match[o] != h:
                    switches += 1
                else:
                    matches += 1
                total += d[i, j]
                o_done[i] = h_done[j] = True
                self.last_match[o] = h
        frame = JointFrameCounts(matches, switches, int((~o_done).sum()), int((~h_done).sum()),
                                 float(total))
        self.matches += frame.matches
        self.switches += frame.switches
        self.misses += frame.misses
        self.false_positives += frame.false_positives
        self.distance += frame.distance
        return frame

    @property
    def objects(self) -> int:
        """Ground-truth occurrences (``num_objects``)."""
        return self.matches + self.switches + self.misses

    @property
    def predictions(self) -> int:
        """Hypothesis occurrences (``num_predictions``)."""
        return self.matches + self.switches + self.false_positives

    def idtp(self) -> int:
        """Identity true positives of the best one-to-one id mapping (py-motmetrics ``idtp``).

        py-motmetrics minimises ``IDFP + IDFN`` over mappings between ground-truth and
        hypothesis ids; with per-pair candidate frame counts ``c(o, h)`` that is the same as
        maximising ``sum c(o, h)`` over the mapped pairs.
        """
        if not self.candidate_frames:
            return 0
        oids = sorted({o for o, _ in self.candidate_frames})
        hids = sorted({h for _, h in self.candidate_frames})
        weight = np.zeros((len(oids), len(hids)))
        o_index = {o: i for i, o in enumerate(oids)}
        h_index = {h: j for j, h in enumerate(hids)}
        for (o, h), count in self.candidate_frames.items():
            weight[o_index[o], h_index[h]] = count
        rows, cols = linear_sum_assignment(weight, maximize=True)
        return int(weight[rows, cols].sum())

    def idf1(self) -> float:
        """``2 IDTP / (objects + predictions)`` (NaN when both are 0, as 0/0 in numpy)."""
        denominator = self.objects + self.predictions
        return 2.0 * self.idtp() / denominator if denominator else float("nan")


# --------------------------------------------------------------------------- sequences
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

    def update(
        self,
        gt: PoseFrame,
        pred: PoseFrame,
        ignore_regions: Sequence[np.ndarray] = (),
    ) -> FrameCounts:
        """Evaluate one frame (only frames poseval evaluates, see :func:`evaluated_frames`).

        Args:
            gt: ground-truth persons (with head sizes).
            pred: predicted persons.
            ignore_regions: the frame's ignore polygons.
        """
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
            return FrameCounts(*out)
        if np.any(~np.isfinite(gt.head_size[gt.present.any(axis=1)])):
            raise ValueError("a ground-truth person with keypoints has no bbox_head (poseval "
                             "needs the head box to normalise distances)")
        dist = joint_distances(gt, pred)
        for j, acc in enumerate(self.joints):
            g = np.nonzero(gt.present[:, j])[0]
            p = np.nonzero(pred.present[:, j])[0]
            d = dist[np.ix_(g, p, [j])][..., 0]
            d = np.where(d <= DIST_THRESHOLD, d, np.nan)
            counts = acc.update(gt.ids[g], pred.ids[p], d)
            out[0][j], out[1][j] = counts.matches, counts.switches
            out[2][j], out[3][j] = counts.misses, counts.false_positives
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

    Returns:
        Flat dict: ``MOTA``, ``IDF1``, ``IDSW`` (sum over joints), ``MOTP``, ``Precision``,
        ``Recall`` (means over joints), ``MOTA/<part>`` for poseval's body-part columns,
        ``<metric>/<joint>`` for every joint, and the pooled counts ``num_objects``,
        ``num_misses``, ``num_false_positives``, ``num_frames``, ``num_sequences``.
        Metrics of a set without evaluated frames are NaN.
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

    Raises:
        ValueError: the result lists other images than the ground truth (poseval pairs
            frames by position, so both must list the same images in the same order).
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

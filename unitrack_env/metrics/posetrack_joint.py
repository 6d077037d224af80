"""One joint's CLEAR MOT accumulator, with py-motmetrics' matching rule (our code).

:class:`ClearAccumulator` keeps a ground truth on the hypothesis it last matched while that
pair stays a candidate, assigns the rest by minimum distance, and counts matches, switches,
misses, false positives and the identity assignment (IDF1). Definitions in
:mod:`unitrack_env.metrics.posetrack`.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment


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
    #: The last :meth:`update`'s pairs ``(row, column, switched, distance)`` and its
    #: unmatched rows and columns (indices into its inputs), for per-frame error events.
    last_pairs: tuple[list[tuple[int, int, bool, float]], np.ndarray, np.ndarray] = field(
        default_factory=lambda: ([], np.zeros(0, np.int64), np.zeros(0, np.int64)), repr=False)

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
        pairs: list[tuple[int, int, bool, float]] = []
        if len(oids) and len(hids):
            for i, o in enumerate(oids.tolist()):  # 1. keep last frame's partner if a candidate
                if o not in self.last_match:
                    continue
                js = np.nonzero(~h_done & (hids == self.last_match[o]))[0]
                if len(js) and np.isfinite(d[i, js[0]]):
                    o_done[i] = h_done[js[0]] = True
                    matches += 1
                    total += d[i, js[0]]
                    pairs.append((i, int(js[0]), False, float(d[i, js[0]])))
            d[o_done, :] = np.nan
            d[:, h_done] = np.nan
            for i, j in _assignment(d):  # 2. assign the rest
                o, h = int(oids[i]), int(hids[j])
                switched = o in self.last_match and self.last_match[o] != h
                switches += switched
                matches += not switched
                pairs.append((i, j, switched, float(d[i, j])))
                total += d[i, j]
                o_done[i] = h_done[j] = True
                self.last_match[o] = h
        self.last_pairs = (pairs, np.flatnonzero(~o_done), np.flatnonzero(~h_done))
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


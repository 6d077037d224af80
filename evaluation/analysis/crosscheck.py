"""Cross-check of MOTChallenge scores with py-motmetrics, and where and why the two differ.

py-motmetrics (C. Heindl, J. Valmadre et al., https://github.com/cheind/py-motmetrics, MIT
licence) independently implements CLEAR MOT and the ID measures; it is fed exactly the frames
TrackEval scores, with distances ``1 - IoU`` (NaN below 0.5). The two count alike but match
differently: motmetrics keeps each object's *last-ever* match where TrackEval favours only the
previous frame's (:data:`CONTINUATION`, the usual cause: fewer ID switches after a gap), and
it maximises the number of matches, then minimises their summed ``1 - IoU``, where TrackEval
maximises the summed IoU. TrackEval stays the official scorer; measurements in
docs/design-decisions.md, "Cross-check with py-motmetrics". motmetrics 1.4.0's ``iou_matrix``
(``np.asfarray``, gone in NumPy 2) and ``merge_event_dataframes`` (broken on pandas 2) are not
called, so no NumPy patch is needed.
"""

from __future__ import annotations

import argparse
import configparser
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import motmetrics
import numpy as np

from unitrack_env.metrics.clear_stream import StreamingClear
from unitrack_env.metrics.mot_preprocess import (
    EPS,
    MATCH_IOU_THRESHOLD,
    GtFrame,
    TrackerFrame,
    gt_frames_from_rows,
    preprocess,
    tracker_frames_from_rows,
)
from unitrack_env.metrics.motchallenge import score_sequence

#: motmetrics metric names we compute, and the TrackEval-style keys we return them under.
MOTMETRICS_FIELDS: dict[str, str] = {
    "mota": "MOTA",
    "motp": "MOTP_distance",
    "idf1": "IDF1",
    "idp": "IDP",
    "idr": "IDR",
    "num_switches": "IDSW",
    "num_false_positives": "CLR_FP",
    "num_misses": "CLR_FN",
    "num_detections": "CLR_TP",
    "num_objects": "GT_Dets",
    "num_predictions": "Dets",
    "idtp": "IDTP",
    "idfp": "IDFP",
    "idfn": "IDFN",
}

#: Metrics both libraries compute under the same name (fractions or counts).
COMPARED: tuple[str, ...] = ("MOTA", "IDF1", "IDSW", "CLR_TP", "CLR_FP", "CLR_FN",
                             "IDTP", "IDFP", "IDFN")

CONTINUATION = "continuation"
"""Rule of a pair motmetrics matched because it was the object's last-ever match."""
DISPLACED = "displaced"
"""Rule of a pair whose TrackEval tracker motmetrics gave to another object it continued."""
OTHER = "assignment"
"""Any other difference: the assignment objective, or a knock-on of an earlier difference."""
RULES: tuple[str, ...] = (CONTINUATION, DISPLACED, OTHER)


def iou_distance(iou: np.ndarray, threshold: float = MATCH_IOU_THRESHOLD) -> np.ndarray:
    """Return motmetrics distances ``1 - IoU``, NaN where ``IoU < threshold - eps`` (not pairable).

    >>> iou_distance(np.array([[0.75, 0.2]]))
    array([[0.25,  nan]])
    """
    iou = np.asarray(iou, dtype=np.float64)
    dist = 1.0 - iou
    dist[iou < threshold - EPS] = np.nan
    return dist


@dataclass(frozen=True)
class PairDifference:
    """One ground-truth object matched differently by the two libraries in one frame.

    ``trackeval`` / ``motmetrics``: each library's tracker id (None: missed); ``rule``:
    :data:`CONTINUATION`, :data:`DISPLACED` or :data:`OTHER`; ``last_frame``: motmetrics'
    frame of the continued match.
    """

    frame: int
    gt_id: int
    trackeval: int | None
    motmetrics: int | None
    rule: str
    last_frame: int | None = None

    def describe(self) -> str:
        """One line: what each library matched and why they differ."""
        te = "missed" if self.trackeval is None else f"tracker {self.trackeval}"
        mm = "missed" if self.motmetrics is None else f"tracker {self.motmetrics}"
        why = {CONTINUATION: f"motmetrics continued its last match, from frame "
                             f"{self.last_frame}; TrackEval only continues the previous frame's",
               DISPLACED: "motmetrics gave TrackEval's tracker to an object it continued",
               OTHER: "assignment objective or a knock-on of an earlier difference"}[self.rule]
        return f"frame {self.frame} gt {self.gt_id}: TrackEval {te}, motmetrics {mm} ({why})"


@dataclass(frozen=True)
class Crosscheck:
    """TrackEval's and motmetrics' metrics of one sequence, and the pairs they match differently."""

    trackeval: dict[str, float]
    motmetrics: dict[str, float]
    pairs: list[PairDifference] = field(default_factory=list)

    def differences(self) -> dict[str, tuple[float, float]]:
        """``{metric: (TrackEval, motmetrics)}`` of the :data:`COMPARED` metrics that differ."""
        return {k: (self.trackeval[k], self.motmetrics[k]) for k in COMPARED
                if abs(self.trackeval[k] - self.motmetrics[k]) > 1e-9}

    def rule_counts(self) -> dict[str, int]:
        """How many differently matched pairs each rule explains."""
        return {rule: sum(p.rule == rule for p in self.pairs) for rule in RULES}

    def report(self, name: str = "sequence", examples: int = 5) -> str:
        """A few lines: the metrics that differ, the rules behind the pairs, first examples."""
        diff = self.differences()
        if not diff and not self.pairs:
            return f"{name}: TrackEval and py-motmetrics agree exactly on {', '.join(COMPARED)}"
        cells = [f"{k} {te:.4f} vs {mm:.4f}" if k in ("MOTA", "IDF1")
                 else f"{k} {te:g} vs {mm:g}" for k, (te, mm) in diff.items()]
        counts = self.rule_counts()
        lines = [f"{name}: TrackEval vs py-motmetrics: " + ("; ".join(cells) or "metrics agree"),
                 f"  {len(self.pairs)} object-frames matched differently: "
                 f"{counts[CONTINUATION]} by the continuation rule (motmetrics keeps an object's "
                 f"last-ever match, TrackEval only the previous frame's), {counts[DISPLACED]} "
                 f"displaced by such a continuation, {counts[OTHER]} by the assignment "
                 "objective or as knock-ons"]
        lines += [f"  {p.describe()}" for p in self.pairs[:examples]]
        return "\n".join(lines)


def _matched_pairs(acc: Any) -> dict[int, dict[int, int]]:
    """Motmetrics' matches per frame, ``{frame: {gt id: tracker id}}``."""
    events = acc.mot_events
    kept = events[events.Type.isin(["MATCH", "SWITCH"])]
    out: dict[int, dict[int, int]] = {}
    for (frame, _), row in kept.iterrows():
        out.setdefault(int(frame), {})[int(row.OId)] = int(row.HId)
    return out


def _accumulate(gt_frames: Sequence[GtFrame], tracker_frames: Sequence[TrackerFrame],
                benchmark: str) -> tuple[Any, list[dict[int, int] | None]]:
    """The motmetrics accumulator and TrackEval's matches per frame.

    A frame without ground truth or without tracker boxes gets None: it leaves TrackEval's
    previous-frame record untouched.
    """
    if len(gt_frames) != len(tracker_frames):
        raise ValueError(
            f"{len(gt_frames)} ground-truth frames but {len(tracker_frames)} tracker frames"
        )
    acc = motmetrics.MOTAccumulator(auto_id=False)
    clear = StreamingClear()
    trackeval: list[dict[int, int] | None] = []
    for t, (gt, trk) in enumerate(zip(gt_frames, tracker_frames, strict=True), start=1):
        frame = preprocess(gt, trk, benchmark)
        acc.update(frame.gt_ids.tolist(), frame.tracker_ids.tolist(), iou_distance(frame.iou),
                   frameid=t)
        clear.update(frame.gt_ids, frame.gt_boxes, frame.tracker_ids, frame.tracker_boxes,
                     iou=frame.iou)
        active = len(frame.gt_ids) > 0 and len(frame.tracker_ids) > 0
        trackeval.append(dict(clear.frame_matches) if active else None)
    return acc, trackeval


def _summary(acc: Any) -> dict[str, float]:
    host = motmetrics.metrics.create()
    summary = host.compute(acc, metrics=list(MOTMETRICS_FIELDS), return_dataframe=False)
    return {key: float(summary[name]) for name, key in MOTMETRICS_FIELDS.items()}


def motmetrics_summary(
    gt_frames: Sequence[GtFrame],
    tracker_frames: Sequence[TrackerFrame],
    *,
    benchmark: str,
) -> dict[str, float]:
    """Score a sequence with py-motmetrics after ``benchmark``'s MOTChallenge preprocessing.

    Returns TrackEval-named fractions (MOTA, IDF1, IDP, IDR, IDSW, CLR_TP/FP/FN, GT_Dets, Dets,
    IDTP/FP/FN) and ``MOTP_distance``, motmetrics' mean ``1 - IoU``.
    """
    acc, _ = _accumulate(gt_frames, tracker_frames, benchmark)
    return _summary(acc)


def _differing_pairs(motmetrics: dict[int, dict[int, int]],
                     trackeval: list[dict[int, int] | None]) -> list[PairDifference]:
    """Every object matched differently, with the rule that explains it."""
    last: dict[int, tuple[int, int]] = {}  # motmetrics: gt -> (tracker, frame), last-ever
    previous: dict[int, int] = {}  # TrackEval: the previous frame's record
    out = []
    for t, te_frame in enumerate(trackeval, start=1):
        te = te_frame or {}
        mm = motmetrics.get(t, {})
        frame = []
        for g in sorted(set(te) | set(mm)):
            if te.get(g) == mm.get(g):
                continue
            h, (kept, since) = mm.get(g), last.get(g, (None, None))
            continued = h is not None and h == kept and previous.get(g) != h
            frame.append(PairDifference(t, g, te.get(g), h, CONTINUATION if continued else OTHER,
                                        since if continued else None))
        taken = {p.motmetrics for p in frame if p.rule == CONTINUATION}
        out += [replace(p, rule=DISPLACED) if p.rule == OTHER and p.trackeval in taken else p
                for p in frame]
        last.update({g: (h, t) for g, h in mm.items()})
        if te_frame is not None:
            previous = te_frame
    return out


def crosscheck_frames(gt_frames: Sequence[GtFrame], tracker_frames: Sequence[TrackerFrame],
                      trackeval: dict[str, float], *, benchmark: str) -> Crosscheck:
    """Compare TrackEval's metrics of a sequence with motmetrics' on the same frames."""
    acc, te_matches = _accumulate(gt_frames, tracker_frames, benchmark)
    return Crosscheck(dict(trackeval), _summary(acc),
                      _differing_pairs(_matched_pairs(acc), te_matches))


def crosscheck_sequence(seq_dir: Path, results: Path | np.ndarray, *, benchmark: str,
                        seq_length: int | None = None) -> Crosscheck:
    """Score ``results`` with TrackEval and with motmetrics, and compare them.

    ``results`` is a MOTChallenge result file or its rows; ``seq_dir`` the sequence folder
    (``gt/gt.txt``, ``seqinfo.ini``).
    """
    seq_dir = Path(seq_dir)
    rows = results if isinstance(results, np.ndarray) else \
        np.loadtxt(results, delimiter=",", ndmin=2)
    # TrackEval first: it refuses a missing or bad gt.txt / seqinfo.ini with the file named.
    te = score_sequence(seq_dir, rows, benchmark=benchmark, seq_length=seq_length)
    if seq_length is None:
        ini = configparser.ConfigParser()
        ini.read(seq_dir / "seqinfo.ini", encoding="utf-8")
        seq_length = int(ini["Sequence"]["seqLength"])
    n = int(seq_length)
    gt_rows = np.loadtxt(seq_dir / "gt" / "gt.txt", delimiter=",", ndmin=2)
    return crosscheck_frames(gt_frames_from_rows(gt_rows, n, benchmark=benchmark),
                             tracker_frames_from_rows(rows[:, :6], n), dict(te),
                             benchmark=benchmark)


def main(argv: Sequence[str] | None = None) -> int:
    """Print where TrackEval and py-motmetrics differ on one result file."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("sequence", type=Path, help="sequence folder with gt/gt.txt")
    parser.add_argument("results", type=Path, help="MOTChallenge result file of the sequence")
    parser.add_argument("--benchmark", default="MOT17", help="rule set (default MOT17)")
    parser.add_argument("--examples", type=int, default=5, help="pairs to list (default 5)")
    args = parser.parse_args(argv)
    check = crosscheck_sequence(args.sequence, args.results, benchmark=args.benchmark)
    print(check.report(args.sequence.name, args.examples))
    return 0


if __name__ == "__main__":
    sys.exit(main())

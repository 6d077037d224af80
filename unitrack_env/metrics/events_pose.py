"""Per-frame error events of PoseTrack, from poseval's per-joint CLEAR matching.

poseval scores every joint separately (a CLEAR MOT accumulator per joint), so the events are
per joint and person: ``tp`` (a matched joint, with its head-normalised ``distance``),
``idsw`` (a match to another track than that ground truth's last one; its ``tp`` row is listed
as well), ``fn`` and ``fp``. Summed over a sequence they give poseval's counts exactly:
``tp`` = matches + switches, ``idsw`` = switches, ``fn`` = misses, ``fp`` = false positives.
In a frame with no person on one side (after ignore regions) poseval counts one miss and one
false positive per joint against dummies; those rows have no ids.
"""

from __future__ import annotations

from unitrack_env.datasets.posetrack_records import PoseTrackVideo
from unitrack_env.metrics.events_mot import EventRows
from unitrack_env.metrics.posetrack import PosevalSequence, evaluated_frames
from unitrack_env.metrics.posetrack_frames import (
    NUM_JOINTS,
    POSEVAL_DROPS_LAST_FRAME,
    PoseFrame,
)


def _point(frame: PoseFrame, person: int, joint: int, prefix: str = "") -> dict[str, float]:
    x, y = frame.xy[person, joint]
    return {f"{prefix}x": float(x), f"{prefix}y": float(y)}


def posetrack_sequence_events(sequence: str, gt: PoseTrackVideo, pred: PoseTrackVideo, *,
                              drop_last_frame: bool = POSEVAL_DROPS_LAST_FRAME) -> EventRows:
    """Events of one sequence's result file against its ground truth (module docstring).

    ``frame`` is the 1-based position of the image in the annotation file.
    """
    if [im.id for im in pred.images] != [im.id for im in gt.images]:
        raise ValueError("the result lists other images than the ground truth (poseval pairs "
                         "frames by position)")
    seq = PosevalSequence()
    rows = EventRows(sequence)
    last: list[dict[int, int]] = [{} for _ in range(NUM_JOINTS)]
    for k in evaluated_frames(gt, drop_last_frame=drop_last_frame):
        seq.update(PoseFrame.from_people(gt.people[k]), PoseFrame.from_people(pred.people[k]),
                   gt.images[k].ignore_regions)
        g, p, joints = seq.last_frame
        if joints is None:
            for j in range(NUM_JOINTS):
                rows.add(k + 1, "fn", joint=j)
                rows.add(k + 1, "fp", joint=j)
            continue
        for j, (pairs, missed, false) in enumerate(joints):
            for a, b, switched, dist in pairs:
                gid, tid = int(g.ids[a]), int(p.ids[b])
                common = {"gt_id": gid, "track_id": tid, "joint": j, "distance": dist,
                          **_point(g, a, j), **_point(p, b, j, "t")}
                rows.add(k + 1, "tp", **common)
                if switched:
                    rows.add(k + 1, "idsw", prev_track_id=last[j][gid], **common)
                last[j][gid] = tid
            for a in missed.tolist():
                rows.add(k + 1, "fn", gt_id=int(g.ids[a]), joint=j, **_point(g, a, j))
            for b in false.tolist():
                rows.add(k + 1, "fp", track_id=int(p.ids[b]), joint=j, **_point(p, b, j, "t"))
    return rows

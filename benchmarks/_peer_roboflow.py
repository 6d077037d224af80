"""Run one roboflow `trackers` tracker on MOTChallenge public detections (peer benchmark).

Executed by benchmarks/mot_agent.py (accuracy, peers) inside a separate virtual environment with the
PyPI package `trackers` (it requires opencv-python, which must not enter unitrack-env's own
environment). Reads det.txt with plain numpy, writes a MOTChallenge result file, and prints
a JSON line with the time per frame.

Usage: python _peer_roboflow.py {sort,bytetrack} DET_TXT SEQ_LENGTH FRAME_RATE OUT_TXT
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import supervision as sv
from trackers import ByteTrackTracker, SORTTracker


def main() -> None:
    name, det_path, length, frame_rate, out_path = sys.argv[1:6]
    length, frame_rate = int(length), float(frame_rate)
    det = np.loadtxt(det_path, delimiter=",", ndmin=2)
    tracker = {"sort": SORTTracker, "bytetrack": ByteTrackTracker}[name](frame_rate=frame_rate)
    rows, spent, counts = [], 0.0, []
    for t in range(1, length + 1):
        d = det[det[:, 0] == t]
        xyxy = np.column_stack([d[:, 2], d[:, 3], d[:, 2] + d[:, 4], d[:, 3] + d[:, 5]])
        detections = sv.Detections(xyxy=xyxy.astype(np.float32),
                                   confidence=d[:, 6].astype(np.float32),
                                   class_id=np.zeros(len(d), dtype=int))
        start = time.perf_counter()
        out = tracker.update(detections)
        spent += time.perf_counter() - start
        counts.append(len(d))
        for (x1, y1, x2, y2), tid in zip(out.xyxy, out.tracker_id, strict=True):
            if tid is not None and tid >= 0:
                rows.append(f"{t},{int(tid) + 1},{x1:.3f},{y1:.3f},{x2 - x1:.3f},{y2 - y1:.3f},"
                            "1,-1,-1,-1")
    with open(out_path, "w") as handle:
        handle.write("\n".join(rows) + "\n")
    print(json.dumps({"ms_per_frame": 1e3 * spent / length,
                      "mean_detections": float(np.mean(counts))}))


if __name__ == "__main__":
    main()

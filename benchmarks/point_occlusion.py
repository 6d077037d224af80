"""The confidence ``unitrack-points`` decides occlusion from, on visible and occluded points.

Usage (from the repository root)::

    PYTHONPATH=. python benchmarks/point_occlusion.py [--root ../shared/data/TAPVid]

Plays ``unitrack-points`` (default model, "first" queries, forward pass) over every video
of the data set (default: the synthetic TAPVid-DAVIS videos) and, for every query and frame
after its query frame, records its confidence (``agent.confidence``: the propagated belief
map's peak over the query frame's peak), split by the ground truth's occlusion flag. Prints
the 10th, 50th and 90th percentiles of both groups, and the occlusion accuracy each
threshold would give beside that of always answering "visible"; and the median position error
of visible points by the frames elapsed since their query frame (1-5, 6-15, 16 or more).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent

THRESHOLDS = (0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5)


def main() -> int:
    """Collect the confidences and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=None, help="TAP-Vid folder (default: synthetic)")
    args = parser.parse_args()
    env = gym.make("UniTrack/TAPVid-DAVIS-v0", root=args.root).unwrapped
    agent = make_agent("unitrack-points", feature_cache=False)
    confidence, occluded, error, age = [], [], [], []
    for name in env.sequence_names:
        observation, info = env.reset(options={"sequence": name})
        agent.reset(observation, info)
        truth = env.scoring.queries(name)
        terminated = False
        while not terminated:
            frame = info["frame_index"]
            action = agent.act(observation)
            later = np.flatnonzero(truth.query_frames < frame)
            confidence.extend(agent.confidence[later].tolist())
            occluded.extend(truth.occluded[later, frame].tolist())
            error.extend(np.linalg.norm(action["tracks"][later] - truth.tracks[later, frame],
                                        axis=1).tolist())
            age.extend((frame - truth.query_frames[later]).tolist())
            observation, _, terminated, _, info = env.step(action)
    confidence, occluded = np.array(confidence), np.array(occluded, bool)
    error, age = np.array(error)[~occluded], np.array(age)[~occluded]
    print(f"{env.scoring.name}: {len(confidence)} (query, frame) pairs, "
          f"{occluded.mean():.1%} occluded")
    for label, group in (("visible", confidence[~occluded]), ("occluded", confidence[occluded])):
        if len(group):
            low, mid, high = np.percentile(group, [10, 50, 90])
            print(f"  {label:9s} confidence p10 {low:.2f}  median {mid:.2f}  p90 {high:.2f}")
    print(f"  occlusion accuracy answering always visible: {(~occluded).mean():.3f}")
    for threshold in THRESHOLDS:
        accuracy = ((confidence < threshold) == occluded).mean()
        print(f"  occluded below {threshold:.2f}: occlusion accuracy {accuracy:.3f}")
    for low, high in ((1, 5), (6, 15), (16, None)):
        chosen = (age >= low) & (age <= (high or age.max()))
        if chosen.any():
            print(f"  median error of visible points {low}-{high or ''} frames after the "
                  f"query: {np.median(error[chosen]):.1f} px")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Time per frame of the point head beside one backbone pass and the pose head, side by side.

Usage (from the repository root)::

    PYTHONPATH=. python benchmarks/point_head.py [--root ../shared/data/TAPVid]
        [--video blackswan] [--mode first] [--frames 32] [--threads 2]

One shared appearance model (the default weights), no feature cache. For each frame of a
TAP-Vid video at the 256 x 256 raster, interleaved: one backbone pass on the frame
(``AppearanceModel.features``), ``unitrack-points`` answering its queries (its backbone pass
included) and ``unitrack-pose`` propagating 15 of the same points as joints (its default
320 x 320 input; its backbone pass included). Prints milliseconds per frame (mean and
median) and the point head's query count.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import AppearanceModel


def _timed(fn, *args):
    start = time.perf_counter()
    out = fn(*args)
    return out, 1000.0 * (time.perf_counter() - start)


def main() -> int:
    """Run the side-by-side timing and print it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=None, help="TAP-Vid folder (default: synthetic)")
    parser.add_argument("--video", default=None, help="video name (default: the first)")
    parser.add_argument("--mode", default="first", choices=("first", "strided"))
    parser.add_argument("--frames", type=int, default=32)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()

    env = gym.make("UniTrack/TAPVid-DAVIS-v0", root=args.root, query_mode=args.mode).unwrapped
    video = args.video or env.sequence_names[0]
    model = AppearanceModel(num_threads=args.threads)
    points = make_agent("unitrack-points", appearance_model=model, feature_cache=False,
                        num_threads=args.threads)
    pose = make_agent("unitrack-pose", appearance_model=model, feature_cache=False,
                      num_threads=args.threads)
    observation, info = env.reset(options={"sequence": video})
    points.reset(observation, info)
    joints = np.resize(env.scoring.queries(video).query_points[:, [2, 1]], (15, 2))
    pose.reset({"frame": observation["frame"], "init_keypoints": joints}, {})
    times: dict[str, list[float]] = {"backbone 256x256": [], "unitrack-points": [],
                                     "unitrack-pose (320x320)": []}
    for _ in range(min(args.frames, info["num_frames"])):
        frame = observation["frame"]
        times["backbone 256x256"].append(_timed(model.features, frame)[1])
        action, ms = _timed(points.act, observation)
        times["unitrack-points"].append(ms)
        times["unitrack-pose (320x320)"].append(_timed(pose.act, {"frame": frame,
                                                                   "init_keypoints": joints})[1])
        observation, _, terminated, _, _ = env.step(action)
        if terminated:
            break
    print(f"{video} ({args.mode}, {info['num_queries']} queries), {args.threads} threads, "
          f"{len(times['unitrack-points'])} frames; milliseconds per frame:")
    for name, values in times.items():
        print(f"  {name:26s} mean {statistics.fmean(values):8.1f}   "
              f"median {statistics.median(values):8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Environment speed: step overhead without decode, and no-op throughput vs raw cv2.imread.

Prints:
  1. the environment's own cost per step (action validation, CLEAR scoring, observation
     building) with 50 detections and 50 tracks per frame, frames not decoded
     (goal < 1 ms);
  2. a no-op agent's frames per second through the environment on the real MOT17 frames,
     relative to a plain loop of ``cv2.imread`` over the same files (goal >= 0.9).

Usage: python benchmarks/env_speed.py [--mot17 ../shared/data/MOT17] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.spaces import pack_tracks

REPO = Path(__file__).resolve().parents[1]


def make_dense_sequence(root: Path, frames: int = 300, objects: int = 50) -> None:
    """A MOTChallenge sequence with `objects` gt boxes and detections in every frame."""
    rng = np.random.default_rng(0)
    seq = root / "train" / "DENSE"
    (seq / "img1").mkdir(parents=True)
    (seq / "gt").mkdir()
    (seq / "det").mkdir()
    (seq / "seqinfo.ini").write_text(
        "[Sequence]\nname=DENSE\nimDir=img1\nframeRate=30\n"
        f"seqLength={frames}\nimWidth=1920\nimHeight=1080\nimExt=.jpg\n")
    start = rng.uniform([0, 0], [1800, 900], (objects, 2))
    speed = rng.normal(0, 2, (objects, 2))
    gt, det = [], []
    for t in range(1, frames + 1):
        xy = start + speed * t
        for i in range(objects):
            gt.append(f"{t},{i + 1},{xy[i, 0]:.2f},{xy[i, 1]:.2f},40,100,1,1,1.0")
            jitter = rng.normal(0, 2, 2)
            det.append(f"{t},-1,{xy[i, 0] + jitter[0]:.2f},{xy[i, 1] + jitter[1]:.2f},40,100,0.9")
    (seq / "gt" / "gt.txt").write_text("\n".join(gt) + "\n")
    (seq / "det" / "det.txt").write_text("\n".join(det) + "\n")


def step_overhead(repeats: int) -> tuple[float, float]:
    with tempfile.TemporaryDirectory() as tmp:
        make_dense_sequence(Path(tmp))
        env = gym.make("UniTrack/MOTChallenge-v0", root=tmp, decode_frames=False).unwrapped
        ids = np.arange(1, 51)
        per_step, final = [], []
        for _ in range(repeats):
            obs, _ = env.reset(options={"sequence": "DENSE"})
            steps, spent, done = 0, 0.0, False
            while not done:
                action = pack_tracks(ids, obs["boxes"][: obs["num_detections"]], env.max_tracks)
                t0 = time.perf_counter()
                obs, _, done, _, info = env.step(action)
                elapsed = time.perf_counter() - t0
                if done:  # the last step also runs the end-of-episode TrackEval scoring
                    final.append(elapsed)
                else:
                    spent += elapsed
                    steps += 1
            per_step.append(spent / steps)
        env.close()
        return statistics.median(per_step), statistics.median(final)


def noop_throughput(root: Path, repeats: int) -> tuple[float, float]:
    env = gym.make("UniTrack/MOT17-v0", root=root)
    base = env.unwrapped
    files = [base.dataset.split_dir / name / "img1" / f"{t:06d}.jpg"
             for name in base.sequence_names for t in range(1, base.sequence_length(name) + 1)]
    empty = {"ids": np.zeros(0, np.int64), "boxes": np.zeros((0, 4))}
    env_fps, raw_fps = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for f in files:
            cv2.imread(str(f))
        raw_fps.append(len(files) / (time.perf_counter() - t0))
        t0 = time.perf_counter()
        frames = 0
        for name in base.sequence_names:
            obs, _ = env.reset(options={"sequence": name})
            done = False
            while not done:
                obs, _, done, _, _ = env.step(empty)
                frames += 1
        env_fps.append(frames / (time.perf_counter() - t0))
    env.close()
    return statistics.median(env_fps), statistics.median(raw_fps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mot17", type=Path, default=REPO / ".." / "shared" / "data" / "MOT17")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    overhead, final = step_overhead(args.repeats)
    print(f"env step overhead, 50 detections + 50 tracks, no decode: {overhead * 1e3:.3f} ms/step "
          f"(goal < 1 ms: {'met' if overhead < 1e-3 else 'NOT met'})")
    print(f"last step incl. TrackEval end-of-episode scoring of 300 frames x 50 boxes: "
          f"{final * 1e3:.1f} ms")
    if args.mot17.is_dir():
        env_fps, raw_fps = noop_throughput(args.mot17, args.repeats)
        ratio = env_fps / raw_fps
        print(f"no-op agent through the env on real MOT17 frames: {env_fps:.1f} FPS; raw "
              f"cv2.imread loop: {raw_fps:.1f} FPS; ratio {ratio:.2f} "
              f"(goal >= 0.9: {'met' if ratio >= 0.9 else 'NOT met'}; includes reset, "
              "end-of-episode TrackEval scoring and decode to RGB)")
    else:
        print(f"skipped the MOT17 throughput: {args.mot17} not found")


if __name__ == "__main__":
    main()

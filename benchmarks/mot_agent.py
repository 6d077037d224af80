"""Speed and accuracy of the `unitrack` MOT agent (issue: appearance model + MOT agent).

Parts (run all, or pick with --parts):
  stages       per-frame split on the real MOT17 frames: decode / backbone / association / env,
               and end-to-end time relative to a backbone-only loop (goal <= 1.15x)
  association  one association step at 30 tracks x 30 detections with RSM vs one backbone pass
               at 1088x608 (goal >= 10x faster)
  cache        second run with the feature cache vs the first (goal >= 20x faster)
  accuracy     HOTA / IDF1 / MOTA / IDSW of iou vs unitrack (rsm/cf/gf/gpf, motion on/off) with
               the offline default and random weights, on the synthetic set, PETS09-S2L1 and
               the MOT17 clips (the backbone runs once per weights thanks to the feature cache)
  peers        roboflow `trackers` SORT and ByteTrack on the same detections (run in a separate
               virtual environment: `trackers` needs opencv-python, which must not enter ours),
               accuracy on PETS09-S2L1 and time per frame at 30 detections, vs iou and unitrack

Usage: python benchmarks/mot_agent.py [--parts stages,association,...] [--threads 2]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import AppearanceModel, letterbox
from unitrack_env.agents.primitives.association import Associator
from unitrack_env.agents.primitives.similarity import SIMILARITIES
from unitrack_env.evaluation.runner import run
from unitrack_env.frames import read_rgb

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO / ".." / "shared" / "data"
#: PETS09-S2L1 detection scores are 0-100+; trackers built for [0, 1] scores get them / 100.
PETS_SCORE_SCALE = 100.0


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def stages(threads: int) -> None:
    root = SHARED / "MOT17"
    env = gym.make("UniTrack/MOT17-v0", root=root)
    agent = make_agent("unitrack", num_threads=threads)
    model = agent.appearance
    base = env.unwrapped
    paths = [base.dataset.split_dir / n / "img1" / f"{t:06d}.jpg"
             for n in base.sequence_names for t in range(1, base.sequence_length(n) + 1)]
    frames = [read_rgb(p) for p in paths]
    model.features(letterbox(frames[0]).image)  # warm-up

    decode = _median_time(lambda: [read_rgb(p) for p in paths], 3) / len(paths)
    torch.set_num_threads(threads)

    def backbone_only():
        for frame in frames:
            model.features(letterbox(frame).image)

    backbone = _median_time(backbone_only, 2) / len(frames)

    spent = {"backbone": 0.0, "act": 0.0}
    original = model.features

    def timed_features(images):
        start = time.perf_counter()
        out = original(images)
        spent["backbone"] += time.perf_counter() - start
        return out

    model.features = timed_features
    start = time.perf_counter()
    steps = 0
    for name in base.sequence_names:
        obs, info = env.reset(options={"sequence": name})
        agent.reset(obs, info)
        done = False
        while not done:
            t0 = time.perf_counter()
            action = agent.act(obs)
            spent["act"] += time.perf_counter() - t0
            obs, _, done, _, _ = env.step(action)
            steps += 1
    total = (time.perf_counter() - start) / steps
    model.features = original
    in_backbone = spent["backbone"] / steps
    association = (spent["act"] - spent["backbone"]) / steps
    env_time = total - spent["act"] / steps
    print(f"[stages] real MOT17 clips, {steps} frames (1920x1080 and 640x480), "
          f"{threads} threads, input 1088x608, model {model.identity.arch}/{model.identity.layer}")
    print(f"  decode (cv2, RGB)       {decode * 1e3:8.1f} ms/frame (overlapped by prefetching)")
    print(f"  backbone (in the agent) {in_backbone * 1e3:8.1f} ms/frame")
    print(f"  association (RoIAlign + RSM + Kalman/Hungarian) {association * 1e3:8.1f} ms/frame")
    print(f"  env (step, scoring, waiting for frames) {env_time * 1e3:8.1f} ms/frame")
    print(f"  end-to-end {total * 1e3:.1f} ms/frame vs backbone-only loop {backbone * 1e3:.1f} "
          f"ms/frame: ratio {total / backbone:.2f} (goal <= 1.15)")
    env.close()


def association_step(threads: int) -> None:
    torch.set_num_threads(threads)
    model = AppearanceModel()
    image = np.random.default_rng(0).integers(0, 256, (608, 1088, 3), dtype=np.uint8)
    model.features(image)
    backbone = _median_time(lambda: model.features(image), 5)
    rng = np.random.default_rng(1)
    n, locations = 30, 40
    start = rng.uniform([0, 0], [1800, 900], (n, 2))
    velocity = rng.normal(0, 3, (n, 2))
    codes = torch.nn.functional.normalize(torch.randn(n, locations, model.channels), dim=-1)

    def frame(t: int):
        boxes = np.column_stack([start + velocity * t, np.full((n, 2), (40.0, 100.0))])
        noise = 0.1 * torch.randn(n, locations, model.channels)
        payloads = [torch.nn.functional.normalize(codes[i] + noise[i], dim=-1) for i in range(n)]
        return boxes, np.full(n, 0.9), payloads

    frames = [frame(t) for t in range(40)]
    associator = Associator(SIMILARITIES["rsm"])
    for boxes, scores, payloads in frames[:10]:
        associator.step(boxes, scores, payloads)  # tracks exist and are confirmed
    times = []
    for boxes, scores, payloads in frames[10:]:
        t0 = time.perf_counter()
        associator.step(boxes, scores, payloads)
        times.append(time.perf_counter() - t0)
    step = statistics.median(times)
    print(f"[association] {n} tracks x {n} detections, RSM over {locations} locations x "
          f"{model.channels} channels, {threads} threads: {step * 1e3:.2f} ms/step; backbone "
          f"pass at 1088x608: {backbone * 1e3:.0f} ms; ratio {backbone / step:.1f}x "
          "(goal >= 10x)")


def cache(threads: int) -> None:
    root = SHARED / "MOT17"
    with tempfile.TemporaryDirectory() as tmp:
        times = []
        for attempt in range(2):
            out = Path(tmp) / f"run{attempt}"
            start = time.perf_counter()
            run("UniTrack/MOT17-v0", "unitrack", out=out, progress=False,
                env_kwargs={"root": str(root)},
                agent_kwargs={"feature_cache": str(Path(tmp) / "features"),
                              "num_threads": threads})
            times.append(time.perf_counter() - start)
            # the agent part only: the env also decodes frames and TrackEval scores each run
        # Same comparison for the agent alone (what the cache saves), on the same frames:
        agent_times = []
        env = gym.make("UniTrack/MOT17-v0", root=root, decode_frames=True)
        base = env.unwrapped
        observations = []
        for name in base.sequence_names:
            obs, info = env.reset(options={"sequence": name})
            seq = [(obs, info)]
            done = False
            while not done:
                obs, _, done, _, step_info = env.step({"ids": np.zeros(0, int),
                                                       "boxes": np.zeros((0, 4))})
                if not done:
                    seq.append((obs, step_info))
            observations.append(seq)
        for _attempt in range(2):
            agent = make_agent("unitrack", num_threads=threads,
                               feature_cache=str(Path(tmp) / "agent-features"))
            start = time.perf_counter()
            for seq in observations:
                agent.reset(seq[0][0], seq[0][1])
                for obs, _ in seq:
                    agent.act(obs)
            agent_times.append(time.perf_counter() - start)
    print(f"[cache] whole evaluation of the MOT17 clips (env + agent + TrackEval): first "
          f"{times[0]:.2f} s, second {times[1]:.2f} s, speed-up {times[0] / times[1]:.1f}x")
    print(f"[cache] agent alone (backbone vs cached features): first {agent_times[0]:.2f} s, "
          f"second {agent_times[1]:.3f} s, speed-up {agent_times[0] / agent_times[1]:.1f}x "
          "(goal >= 20x)")


def _datasets() -> list[tuple[str, str, dict]]:
    sets = [("synthetic MOT16", "UniTrack/MOT16-v0", {})]
    if (SHARED / "MOT15").is_dir():
        sets.append(("PETS09-S2L1", "UniTrack/MOT15-v0", {"root": str(SHARED / "MOT15")}))
    if (SHARED / "MOT17").is_dir():
        sets.append(("MOT17 clips", "UniTrack/MOT17-v0", {"root": str(SHARED / "MOT17")}))
    return sets


def _agent_kwargs(env_id: str) -> dict:
    # PETS scores are 0-100+: the paper's new-track threshold 0.5 means 50 on that scale.
    return {"new_track_score": 0.5 * PETS_SCORE_SCALE} if env_id.endswith("MOT15-v0") else {}


def accuracy(threads: int) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, env_id, env_kwargs in _datasets():
            report = run(env_id, "iou", out=Path(tmp) / f"iou-{env_id[9:]}", progress=False,
                         env_kwargs=env_kwargs)
            rows.append((label, "iou", "-", report.combined))
            for weights in ("imagenet-lite0", "random"):
                for similarity in ("rsm", "cf", "gf", "gpf"):
                    for motion in (True, False):
                        kwargs = {"weights": weights, "similarity": similarity,
                                  "use_motion": motion, "num_threads": threads,
                                  "feature_cache": str(Path(tmp) / "features"),
                                  **_agent_kwargs(env_id)}
                        out = Path(tmp) / f"{env_id[9:]}-{weights}-{similarity}-{motion}"
                        report = run(env_id, "unitrack", out=out, progress=False,
                                     env_kwargs=env_kwargs, agent_kwargs=kwargs)
                        config = f"{similarity}{'' if motion else ' w/o motion'}"
                        rows.append((label, f"unitrack {config}", weights, report.combined))
                        print(f"  {label:16s} {config:18s} {weights:15s} "
                              f"HOTA {100 * report.combined['HOTA']:5.1f}", flush=True)
    print("\n[accuracy] combined metrics per data set (percent; IDSW count)")
    print("| data | agent | weights | HOTA | IDF1 | MOTA | IDSW |")
    print("|---|---|---|---|---|---|---|")
    for label, agent, weights, m in rows:
        print(f"| {label} | {agent} | {weights} | {100 * m['HOTA']:.1f} | {100 * m['IDF1']:.1f} "
              f"| {100 * m['MOTA']:.1f} | {m['IDSW']:.0f} |")


def _peer_python() -> Path:
    venv = Path(os.environ.get("UNITRACK_PEER_VENV", REPO / "benchmarks" / ".peer-venv"))
    python = venv / "bin" / "python"
    if not python.exists():
        print(f"[peers] creating {venv} with the PyPI package `trackers` (one-off)...", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "trackers==2.6.1"],
                       check=True)
    return python


def _dense_det_file(path: Path, frames: int = 300, n: int = 30) -> None:
    rng = np.random.default_rng(0)
    start = rng.uniform([0, 0], [1800, 900], (n, 2))
    velocity = rng.normal(0, 3, (n, 2))
    lines = []
    for t in range(1, frames + 1):
        xy = start + velocity * t + rng.normal(0, 1, (n, 2))
        lines += [f"{t},-1,{x:.2f},{y:.2f},40,100,0.9" for x, y in xy]
    path.write_text("\n".join(lines) + "\n")


def peers(threads: int) -> None:
    from unitrack_env.metrics.motchallenge import score_sequence

    python = _peer_python()
    script = REPO / "benchmarks" / "_peer_roboflow.py"
    seq = SHARED / "MOT15" / "train" / "PETS09-S2L1"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        det = np.loadtxt(seq / "det" / "det.txt", delimiter=",")
        det[:, 6] = np.clip(det[:, 6] / PETS_SCORE_SCALE, 0, 1)
        scaled = Path(tmp) / "det.txt"
        np.savetxt(scaled, det, delimiter=",", fmt="%.4f")
        dense = Path(tmp) / "dense.txt"
        _dense_det_file(dense)
        for name in ("sort", "bytetrack"):
            out = Path(tmp) / f"{name}.txt"
            subprocess.run([str(python), str(script), name, str(scaled), "400", "7", str(out)],
                           check=True, capture_output=True, text=True)
            metrics = score_sequence(seq, out, benchmark="MOT15")
            timing = subprocess.run(
                [str(python), str(script), name, str(dense), "300", "30",
                 str(Path(tmp) / "dense-out.txt")], check=True, capture_output=True, text=True)
            ms = json.loads(timing.stdout.strip().splitlines()[-1])["ms_per_frame"]
            rows.append((f"roboflow {name}", metrics, ms))
        for agent, kwargs in (("iou", {}), ("unitrack", {"num_threads": threads,
                                                         **_agent_kwargs("MOT15-v0")})):
            report = run("UniTrack/MOT15-v0", agent, out=Path(tmp) / agent, progress=False,
                         env_kwargs={"root": str(SHARED / "MOT15")}, agent_kwargs=kwargs)
            rows.append((agent, report.combined, _agent_ms_at_30(agent) if agent == "iou"
                         else float("nan")))
    print("\n[peers] PETS09-S2L1 frames 1-400, public detections, TrackEval; time per frame of "
          "the tracker alone at 30 detections (unitrack: see [stages]/[association])")
    print("| tracker | HOTA | IDF1 | MOTA | IDSW | ms/frame @30 dets |")
    print("|---|---|---|---|---|---|")
    for name, m, ms in rows:
        print(f"| {name} | {100 * m['HOTA']:.1f} | {100 * m['IDF1']:.1f} | {100 * m['MOTA']:.1f} "
              f"| {m['IDSW']:.0f} | {ms:.2f} |")


def _agent_ms_at_30(name: str) -> float:
    rng = np.random.default_rng(0)
    agent = make_agent(name)
    agent.reset(None, {"frame_rate": 30})
    start = rng.uniform(0, 1800, (30, 2))
    velocity = rng.normal(0, 3, (30, 2))
    observations = []
    for t in range(300):
        boxes = np.zeros((512, 4), np.float32)
        boxes[:30, :2] = start + velocity * t + rng.normal(0, 1, (30, 2))
        boxes[:30, 2:] = (40, 100)
        scores = np.zeros(512, np.float32)
        scores[:30] = 0.9
        observations.append({"frame": np.zeros((1, 1, 3), np.uint8), "boxes": boxes,
                             "scores": scores, "num_detections": 30})
    t0 = time.perf_counter()
    for obs in observations:
        agent.act(obs)
    return (time.perf_counter() - t0) / len(observations) * 1e3


PARTS = {"stages": stages, "association": association_step, "cache": cache,
         "accuracy": accuracy, "peers": peers}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--parts", default=",".join(PARTS))
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    for part in args.parts.split(","):
        if part in {"stages", "cache", "peers"} and not SHARED.is_dir():
            print(f"[{part}] skipped: {SHARED} not found")
            continue
        PARTS[part](args.threads)


if __name__ == "__main__":
    main()

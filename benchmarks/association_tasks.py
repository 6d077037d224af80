"""Speed and accuracy of the `unitrack` association head on MOT, MOTS, VIS and PoseTrack.

Parts (run all, or pick with --parts):
  speed     frames per second of `unitrack` on CPU per environment (synthetic defaults, first
            --frames frames of the first sequence), agent-only and end to end, and the share
            of the agent's time spent in the backbone (appearance model forward pass)
  rsm       cost of RSM as a function of the number of locations n per object (3 tracks x 3
            detections of n locations each, n = 50..2000), and the fitted exponent of
            time ~ n^k (the paper argues O(n^2))
  accuracy  unitrack vs iou on the synthetic sets of MOTS, VIS and PoseTrack (every sequence)
            and on the real PoseTrack 2018 frames in ../shared/data (one labelled frame per
            sequence with oracle poses, scored with drop_last_frame=False: a smoke check)

Usage: python benchmarks/association_tasks.py [--parts speed,rsm,accuracy] [--frames 20]
       [--input-size 1088x608] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from _timing import Timed, timed_acts  # a sibling file (the script's folder)

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import MOT_INPUT_SIZE, AppearanceModel
from unitrack_env.agents.primitives.similarity import rsm

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO / ".." / "shared" / "data"

#: Environments of the speed part (synthetic defaults).
SPEED_ENVS = ("UniTrack/MOT16-v0", "UniTrack/MOTS-v0", "UniTrack/VIS-v0",
              "UniTrack/PoseTrack-v0")
#: Headline metrics printed per environment in the accuracy part.
ACCURACY_METRICS = {
    "UniTrack/MOTS-v0": ("HOTA", "sMOTSA", "IDF1", "IDSW"),
    "UniTrack/VIS-v0": ("AP", "AP50", "AP75", "AR"),
    "UniTrack/PoseTrack-v0": ("MOTA", "IDF1", "IDSW", "Precision", "Recall"),
}
#: Locations per object in the RSM timing.
RSM_SIZES = (50, 100, 200, 300, 500, 700, 1000, 1500, 2000)
#: The exponent is fitted on sizes from here on (small sizes are dominated by overheads).
RSM_FIT_FROM = 200
#: Objects per side in the RSM timing (tracks = detections).
RSM_OBJECTS = 3
#: Channels of the default appearance model's stride-8 map (EfficientNet-Lite0 stage5).
RSM_CHANNELS = 112


@dataclass(frozen=True)
class Options:
    """Command-line options of the benchmark."""

    parts: tuple[str, ...]
    frames: int
    input_size: tuple[int, int]
    threads: int


def _parse() -> Options:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="speed,rsm,accuracy")
    parser.add_argument("--frames", type=int, default=20, help="frames per env (speed part)")
    parser.add_argument("--input-size", default=f"{MOT_INPUT_SIZE[0]}x{MOT_INPUT_SIZE[1]}",
                        help="network input WIDTHxHEIGHT")
    parser.add_argument("--threads", type=int, default=2, help="torch threads")
    args = parser.parse_args()
    width, height = (int(v) for v in args.input_size.lower().split("x"))
    return Options(tuple(p.strip() for p in args.parts.split(",") if p.strip()), args.frames,
                   (width, height), args.threads)


def speed(options: Options, model: AppearanceModel) -> None:
    """Agent FPS per environment and the backbone's share of the agent's time."""
    print(f"\n== speed: unitrack on CPU, input {options.input_size[0]}x{options.input_size[1]}, "
          f"{options.threads} torch threads, first {options.frames} frames ==")
    print(f"{'environment':<24}{'frame':>10}{'dets/fr':>9}{'agent FPS':>11}{'e2e FPS':>9}"
          f"{'backbone':>10}{'features':>10}{'assoc.':>9}")
    for env_id in SPEED_ENVS:
        env = gym.make(env_id)
        agent = make_agent("unitrack", appearance_model=model, input_size=options.input_size,
                           feature_cache=False)  # time the backbone, not cache hits
        backbone = Timed(model.features)
        model.features = backbone  # type: ignore[method-assign]
        try:
            obs, info = env.reset(options={"sequence": env.unwrapped.sequence_names[0]})
            agent.reset(obs, info)
            assoc = Timed(agent.associator.step)
            agent.associator.step = assoc  # type: ignore[method-assign]
            counts: list[int] = []
            start = time.perf_counter()
            agent_time, frames, obs = timed_acts(
                env, agent, obs, options.frames,
                lambda o, sink=counts: sink.append(
                    int(o.get("num_detections", o.get("num_people", 0)))))
            total = time.perf_counter() - start
            detections = sum(counts)
        finally:
            del model.features  # back to the class method
        h, w = obs["frame"].shape[:2]
        features = agent_time - backbone.seconds - assoc.seconds
        print(f"{env_id:<24}{f'{w}x{h}':>10}{detections / frames:>9.1f}"
              f"{frames / agent_time:>11.2f}{frames / total:>9.2f}"
              f"{backbone.seconds / agent_time:>10.0%}{features / agent_time:>10.0%}"
              f"{assoc.seconds / agent_time:>9.0%}")
    print("(backbone = appearance-model forward pass incl. normalisation; features = letterbox,"
          " RoIAlign / mask or pose rasterisation and pooling; assoc. = Kalman, RSM, matching)")


def rsm_cost() -> None:
    """Time RSM for n locations per object and fit time ~ n^k."""
    print(f"\n== rsm: {RSM_OBJECTS} tracks x {RSM_OBJECTS} detections, n locations each, "
          f"C = {RSM_CHANNELS}, float32, {torch.get_num_threads()} threads ==")
    gen = torch.Generator().manual_seed(0)
    sizes, times = [], []
    print(f"{'n':>6}{'median ms':>11}{'affinity':>12}")
    for n in RSM_SIZES:
        tracks = [torch.randn(n, RSM_CHANNELS, generator=gen) for _ in range(RSM_OBJECTS)]
        dets = [torch.randn(n, RSM_CHANNELS, generator=gen) for _ in range(RSM_OBJECTS)]
        rsm(tracks, dets)  # warm-up
        repeats = 7 if n <= 500 else 3
        samples = []
        for _ in range(repeats):
            start = time.perf_counter()
            rsm(tracks, dets)
            samples.append(time.perf_counter() - start)
        sizes.append(n)
        times.append(statistics.median(samples))
        side = RSM_OBJECTS * n
        print(f"{n:>6}{times[-1] * 1e3:>11.2f}{f'{side}x{side}':>12}")
    fit = [(s, t) for s, t in zip(sizes, times, strict=True) if s >= RSM_FIT_FROM]
    k, _ = np.polyfit(np.log([s for s, _ in fit]), np.log([t for _, t in fit]), 1)
    k_all, _ = np.polyfit(np.log(sizes), np.log(times), 1)
    print(f"fitted exponent k (time ~ n^k): {k:.2f} for n >= {RSM_FIT_FROM}, "
          f"{k_all:.2f} over all n")


def _play(env: gym.Env, agent: Any, sequence: str) -> dict[str, float]:
    obs, info = env.reset(options={"sequence": sequence})
    agent.reset(obs, info)
    while True:
        obs, _, terminated, truncated, info = env.step(agent.act(obs))
        if terminated or truncated:
            return info.get("metrics", {})


def accuracy(options: Options, model: AppearanceModel) -> None:
    """unitrack vs iou on the synthetic sets and the real PoseTrack frames."""
    with tempfile.TemporaryDirectory(prefix="unitrack-assoc-bench-") as cache:
        _accuracy(options, model, cache)


def _accuracy(options: Options, model: AppearanceModel, cache: str) -> None:
    print(f"\n== accuracy: unitrack (input {options.input_size[0]}x{options.input_size[1]}) "
          "vs iou ==")
    runs: list[tuple[str, dict[str, Any]]] = [(env_id, {}) for env_id in ACCURACY_METRICS]
    real = SHARED / "PoseTrack2018"
    if real.is_dir():
        # One labelled frame per sequence: keep poseval's dropped last frame so that it is
        # scored (oracle poses, so this only checks that every person is reported).
        runs.append(("UniTrack/PoseTrack-v0", {"root": str(real), "drop_last_frame": False}))
    for env_id, env_kwargs in runs:
        env = gym.make(env_id, **env_kwargs)
        keys = ACCURACY_METRICS[env_id]
        label = env_id + (" (real)" if env_kwargs else " (synthetic)")
        print(f"\n{label}")
        print(f"{'sequence':<26}{'agent':<10}" + "".join(f"{k:>10}" for k in keys))
        for sequence in env.unwrapped.sequence_names:
            if not env.unwrapped.has_ground_truth(sequence):
                continue
            for name in ("iou", "unitrack"):
                kwargs = {} if name == "iou" else {
                    "appearance_model": model, "input_size": options.input_size,
                    "feature_cache": cache}
                metrics = _play(env, make_agent(name, **kwargs), sequence)
                print(f"{sequence:<26}{name:<10}"
                      + "".join(f"{metrics.get(k, float('nan')):>10.3f}" for k in keys))


def main() -> None:
    """Run the chosen parts."""
    options = _parse()
    torch.set_num_threads(options.threads)
    os.environ.setdefault("UNITRACK_CACHE", str(Path(tempfile.gettempdir()) / "unitrack-bench"))
    model = AppearanceModel()
    print(f"appearance model: {model}")
    if "speed" in options.parts:
        speed(options, model)
    if "rsm" in options.parts:
        rsm_cost()
    if "accuracy" in options.parts:
        accuracy(options, model)


if __name__ == "__main__":
    main()

"""Speed, memory and accuracy of the UniTrack propagation heads (SOT, VOS, pose) on CPU.

Usage (from the repository root)::

    PYTHONPATH=. python benchmarks/propagation.py --parts speed,memory,accuracy --threads 2

Parts:

* ``speed``: frames per second of each head on the real fixtures (first ``--frames`` frames
  of OTB Crossing, DAVIS blackswan at 480p, the JHMDB catch clip) and the share of the time
  spent in the backbone (``AppearanceModel.features``, timed by a wrapper).
* ``memory``: peak resident memory (``resource.getrusage`` ``ru_maxrss``; torch CPU tensors
  are not seen by tracemalloc) of a VOS run at 480p with M = 6, in a fresh subprocess.
* ``accuracy``: heads vs the repeat baselines vs OpenCV's ``TrackerMIL`` (a classical SOT
  peer, used only here), offline default weights vs ``weights="random"`` vs the default
  weights read out as the ``stage3+stage5`` hypercolumn, on the real
  fixtures (OTB Crossing + Human3, DAVIS blackswan + dog, JHMDB catch). DAVIS J is given
  under the official rules (first and last frames excluded) and with the last frame.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import unitrack_env  # noqa: F401
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import AppearanceModel
from unitrack_env.agents.base import Agent

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import timed_acts  # noqa: E402  (a sibling file of this script)

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


@dataclass
class Config:
    parts: tuple[str, ...] = ("speed", "memory", "accuracy")
    threads: int = 2
    frames: int = 20


class TimedModel:
    """Wraps an AppearanceModel and adds up the time spent in ``features``."""

    def __init__(self, model: AppearanceModel) -> None:
        self.model = model
        self.stride = model.stride
        self.seconds = 0.0

    def features(self, images: Any) -> torch.Tensor:
        start = time.perf_counter()
        out = self.model.features(images)
        self.seconds += time.perf_counter() - start
        return out


class MILAgent(Agent):
    """OpenCV's TrackerMIL as a SOT peer (benchmark only; boxes in OTB 1-based pixels)."""

    def __init__(self) -> None:
        import cv2

        self._cv2 = cv2
        self.tracker: Any = None
        self.box = np.zeros(4, np.float32)
        self.first = True

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self.box = np.asarray(observation["init_box"], np.float32).copy()
        x, y, w, h = self.box
        self.tracker = self._cv2.TrackerMIL_create()
        frame = self._cv2.cvtColor(observation["frame"], self._cv2.COLOR_RGB2BGR)
        self.tracker.init(frame, (int(round(x - 1)), int(round(y - 1)), int(round(w)),
                                  int(round(h))))
        self.first = True

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        if self.first:
            self.first = False
            return self.box.copy()
        frame = self._cv2.cvtColor(observation["frame"], self._cv2.COLOR_RGB2BGR)
        ok, rect = self.tracker.update(frame)
        if ok:
            x, y, w, h = rect
            self.box = np.array([x + 1, y + 1, w, h], np.float32)
        return self.box.copy()


def play(env: gym.Env, agent: Any, sequence: str,
         max_frames: int | None = None) -> tuple[dict[str, float], int, float, list[Any]]:
    """Play (part of) an episode; return metrics, frames, seconds and the step infos."""
    obs, info = env.reset(options={"sequence": sequence})
    start = time.perf_counter()
    agent.reset(obs, info)
    frames, infos = 0, []
    while True:
        action = agent.act(obs)
        frames += 1
        obs, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        if terminated or truncated or (max_frames is not None and frames >= max_frames):
            return info.get("metrics", {}), frames, time.perf_counter() - start, infos


TASKS = {
    "sot-dcf": ("UniTrack/OTB-v0", "OTB", "unitrack-dcf", "repeat-box", ["Crossing", "Human3"]),
    "sot-xcorr": ("UniTrack/OTB-v0", "OTB", "unitrack-xcorr", "repeat-box",
                  ["Crossing", "Human3"]),
    "vos": ("UniTrack/DAVIS-v0", "DAVIS", "unitrack-vos", "repeat-mask", ["blackswan", "dog"]),
    "pose": ("UniTrack/JHMDB-v0", "JHMDB", "unitrack-pose", "repeat-pose", None),
}


def speed(cfg: Config) -> None:
    print(f"\n== speed (CPU, {cfg.threads} threads, first {cfg.frames} frames) ==")
    print("reset: the first frame's features and memory; per frame: each later frame's act()"
          " (the env's decode and scoring excluded); backbone: share of the per-frame time")
    print(f"{'task':<10} {'sequence':<46} {'reset s':>8} {'s/frame':>8} {'FPS':>6} "
          f"{'backbone':>9}")
    model = AppearanceModel()
    for task, (env_id, folder, agent_name, _, seqs) in TASKS.items():
        env = gym.make(env_id, root=str(DATA / folder))
        sequence = (seqs or env.unwrapped.sequence_names)[0]
        timed = TimedModel(model)
        agent = make_agent(agent_name, appearance_model=timed)
        obs, info = env.reset(options={"sequence": sequence})
        start = time.perf_counter()
        agent.reset(obs, info)
        reset_seconds = time.perf_counter() - start
        obs, *_ = env.step(agent.act(obs))  # the first answer is the given target
        timed.seconds = 0.0
        seconds, frames, _ = timed_acts(env, agent, obs, max(1, cfg.frames - 1))
        per_frame = seconds / frames
        print(f"{task:<10} {sequence:<46} {reset_seconds:8.3f} {per_frame:8.3f} "
              f"{1 / per_frame:6.2f} {timed.seconds / seconds:9.0%}")


def memory(cfg: Config) -> None:
    print("\n== memory (VOS, DAVIS blackswan 480p, M = 6, fresh process) ==")
    code = (
        "import resource, torch, gymnasium as gym, unitrack_env\n"
        "from unitrack_env.agents import make_agent\n"
        f"torch.set_num_threads({cfg.threads})\n"
        f"env = gym.make('UniTrack/DAVIS-v0', root={str(DATA / 'DAVIS')!r})\n"
        "agent = make_agent('unitrack-vos')\n"
        "obs, info = env.reset(options={'sequence': 'blackswan'})\n"
        "base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "agent.reset(obs, info)\n"
        f"for _ in range({max(cfg.frames, 8)}):\n"
        "    obs, *_ = env.step(agent.act(obs))\n"
        "peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "print(base / 2**20, peak / 2**20)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1])
    before, peak = (float(v) for v in out.stdout.split())
    print(f"peak RSS {peak:.2f} GiB (before the agent's first frame: {before:.2f} GiB; "
          f"goal < 4 GiB)")


def accuracy(cfg: Config) -> None:
    print("\n== accuracy on the real fixtures ==")
    rows: list[tuple[str, str, str, str]] = []
    models = {"imagenet-lite0": AppearanceModel(), "random": AppearanceModel("random"),
              "imagenet-lite0 stage3+stage5": AppearanceModel(layer="stage3+stage5")}
    for task, (env_id, folder, agent_name, baseline, seqs) in TASKS.items():
        env = gym.make(env_id, root=str(DATA / folder))
        for sequence in seqs or env.unwrapped.sequence_names:
            candidates: dict[str, Any] = {baseline: make_agent(baseline)}
            if task == "sot-dcf":
                candidates["opencv-mil"] = MILAgent()
            for weights, model in models.items():
                candidates[f"{agent_name} [{weights}]"] = make_agent(
                    agent_name, appearance_model=model)
            for label, agent in candidates.items():
                if task == "sot-xcorr" and label == baseline:
                    continue
                metrics, _, _, infos = play(env, agent, sequence)
                text = ", ".join(f"{k} {v:.3f}" for k, v in metrics.items()
                                 if k in ("AUC", "Precision@20px", "J-Mean", "F-Mean",
                                          "PCK@0.1", "PCK@0.2"))
                if task == "vos":
                    per_frame = [np.mean(list(i["j"].values())) if isinstance(i["j"], dict)
                                 else float(np.mean(i["j"])) for i in infos[1:]]
                    text += f", J with last frame {np.mean(per_frame):.3f}"
                rows.append((task, sequence, label, text))
                print(f"{task:<10} {sequence:<46} {label:<32} {text}", flush=True)
    print(f"{len(rows)} rows")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="speed,memory,accuracy")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--frames", type=int, default=20)
    args = parser.parse_args()
    cfg = Config(tuple(args.parts.split(",")), args.threads, args.frames)
    torch.set_num_threads(cfg.threads)
    print(f"torch {torch.__version__}, {cfg.threads} threads; peak RSS so far "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    for part in cfg.parts:
        {"speed": speed, "memory": memory, "accuracy": accuracy}[part](cfg)


if __name__ == "__main__":
    main()

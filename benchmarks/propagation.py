"""Speed, memory and accuracy of the UniTrack propagation heads (SOT, VOS, pose) on CPU.

Usage (from the repository root)::

    PYTHONPATH=. python benchmarks/propagation.py --parts stages,heads --threads 2

Parts:

* ``stages``: label propagation, the formulation the heads use (window ring, grouped top-k,
  first frame above a floor) against the one it replaced (``LabelPropagator(reference=True)``:
  keys gathered at every step, plain top-k), side by side and interleaved, on features of
  the real DAVIS frames at 854x480 (default model, computed once): milliseconds per step
  and per stage (``torch.profiler`` labels of ``agents.primitives.label_propagation.stage``:
  normalize, gather, affinity, top-k, labels, weights, memory; "matmul" is the time in
  ``aten::mm``/``aten::bmm`` inside them, the floor of any float32 formulation that computes
  the same affinities), and the largest label difference over the recurrent run.
* ``precision``: label propagation in float32 (the default) against
  ``propagation_precision="bf16"`` with several candidate counts, interleaved step by step on
  the DAVIS features at 854x480: milliseconds per step, and how far the labels of the
  recurrent runs drift from float32's (CPUs with native bfloat16 only).
* ``heads``: seconds per frame of the whole ``unitrack-vos`` head at 854x480 (DAVIS) and of
  ``unitrack-pose`` (JHMDB, 320x320) with either propagator, interleaved frame by frame on
  one shared model, split into backbone, propagation and the rest (upsampling + argmax for
  VOS, map decoding for pose); the metrics of both full runs (J, F, J&F / PCK).
* ``speed``: frames per second of each head on the real fixtures (first ``--frames`` frames
  of OTB Crossing, DAVIS blackswan at 480p, the JHMDB catch clip) and the share of the time
  spent in the backbone (``AppearanceModel.features``, timed by a wrapper).
* ``memory``: peak resident memory (``VmHWM`` of the child; torch CPU tensors are not seen
  by tracemalloc) of a VOS run at 480p with M = 6, in a fresh subprocess.
* ``accuracy``: heads vs the repeat baselines vs OpenCV's ``TrackerMIL`` (a classical SOT
  peer, used only here), offline default weights vs ``weights="random"`` vs the default
  weights read out as the ``stage3+stage5`` hypercolumn, on the real
  fixtures (OTB Crossing + Human3, DAVIS blackswan + dog, JHMDB catch). DAVIS J is given
  under the official rules (first and last frames excluded) and with the last frame.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import torch.nn.functional as F
from _timing import PEAK_RSS_GIB, Timed, timed_acts  # a sibling file (the script's folder)
from torch.profiler import ProfilerActivity, profile

import unitrack_env  # noqa: F401
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import AppearanceModel
from unitrack_env.agents.base import Agent
from unitrack_env.agents.heads.vos import VOID_LABEL, labels_to_onehot
from unitrack_env.agents.primitives import label_propagation
from unitrack_env.agents.primitives.label_propagation import (
    CANDIDATE_FACTOR,
    STAGE_PREFIX,
    LabelPropagationConfig,
    LabelPropagator,
)

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


@dataclass
class Config:
    parts: tuple[str, ...] = ("stages", "precision", "heads", "speed", "memory", "accuracy")
    threads: int = 2
    frames: int = 20
    sequences: tuple[str, ...] = ("blackswan", "dog")
    runtime: str = "auto"


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


# ---------------------------------------------------------------------- label propagation
#: Propagator formulations compared: name -> ``LabelPropagator(reference=...)``.
FORMULATIONS: dict[str, bool] = {"old": True, "new": False}
#: Reported stages: the ``stage`` labels, "matmul" (aten::mm + aten::bmm inside them) and
#: "other" (the step's time outside every label).
STAGES = ("normalize", "gather", "affinity", "matmul", "top-k", "rescore", "labels", "weights",
          "memory", "other")


def davis_features(model: AppearanceModel, sequence: str,
                   frames: int) -> tuple[list[torch.Tensor], torch.Tensor]:
    """The first ``frames`` feature maps of a DAVIS sequence (full 854x480 frames) and the
    first frame's soft labels on the feature grid (as ``unitrack-vos`` builds them)."""
    env = gym.make("UniTrack/DAVIS-v0", root=str(DATA / "DAVIS"))
    obs, _ = env.reset(options={"sequence": sequence})
    labels = np.asarray(obs["init_labels"])
    ids = tuple(sorted(int(v) for v in np.unique(labels) if v not in (0, VOID_LABEL)))
    feats: list[torch.Tensor] = []
    with torch.inference_mode():
        while len(feats) < frames:
            feats.append(model.features(obs["frame"])[0].clone())
            obs, _, terminated, truncated, _ = env.step(labels)
            if terminated or truncated:
                break
    onehot = labels_to_onehot(labels, ids)
    small = F.interpolate(onehot[None], size=feats[0].shape[1:], mode="bilinear",
                          align_corners=False, antialias=True)[0]
    return feats, small


def profiled_step(prop: LabelPropagator, feats: torch.Tensor) -> dict[str, float]:
    """Seconds of one ``prop.step`` per stage (under ``torch.profiler``)."""
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        start = time.perf_counter()
        prop.step(feats)
        wall = time.perf_counter() - start
    times = dict.fromkeys(STAGES, 0.0)
    for event in prof.key_averages():
        if event.key.startswith(STAGE_PREFIX):
            times[event.key[len(STAGE_PREFIX):]] += event.cpu_time_total / 1e6
        elif event.key in ("aten::mm", "aten::bmm"):
            times["matmul"] += event.self_cpu_time_total / 1e6
    times["other"] = wall - sum(v for k, v in times.items() if k != "matmul")
    times["step (profiled)"] = wall
    return times


def run_formulations(feats: list[torch.Tensor], labels: torch.Tensor, profiled: bool,
                     props: dict[str, LabelPropagator] | None = None
                     ) -> tuple[dict[str, dict[str, list[float]]], float]:
    """Propagators (default: ``FORMULATIONS``) over the same frames, rotating the order.

    Returns:
        Per formulation, seconds per step (and per stage when ``profiled``), warm-up steps
        (the memory filling up) left out; the largest label difference between the first
        two.
    """
    if props is None:
        props = {name: LabelPropagator(reference=ref) for name, ref in FORMULATIONS.items()}
    first, second = list(props)[:2]
    for prop in props.values():
        prop.reset(feats[0], labels)
    times: dict[str, dict[str, list[float]]] = {name: defaultdict(list) for name in props}
    diff = 0.0
    for t, frame in enumerate(feats[1:], 1):
        outs = {}
        for name in list(props)[t % len(props):] + list(props)[:t % len(props)]:
            if profiled:
                for stage_name, seconds in profiled_step(props[name], frame).items():
                    times[name][stage_name].append(seconds)
                continue
            start = time.perf_counter()
            outs[name] = props[name].step(frame)
            times[name]["step (wall)"].append(time.perf_counter() - start)
        if outs:
            diff = max(diff, float((outs[first] - outs[second]).abs().max()))
    warm = min(5, len(feats) // 3)
    return {n: {k: v[warm:] for k, v in d.items()} for n, d in times.items()}, diff


def stages(cfg: Config) -> None:
    print(f"\n== label propagation per stage: old (reference=True) vs new, interleaved, "
          f"{cfg.threads} threads ==")
    model = AppearanceModel(runtime=cfg.runtime)
    for sequence in cfg.sequences:
        feats, labels = davis_features(model, sequence, cfg.frames + 1)
        c, h, w = feats[0].shape
        walls, diff = run_formulations(feats, labels, profiled=False)
        per_stage, _ = run_formulations(feats, labels, profiled=True)
        steps = len(walls["old"]["step (wall)"])
        print(f"DAVIS {sequence}: 854x480 frames, features {c} x {h} x {w}, {labels.shape[0]} "
              f"labels; M = 6, radius 12, top-10; median of {steps} steps after the memory "
              f"filled")
        print(f"{'stage':<18} {'old ms':>9} {'new ms':>9} {'old/new':>8}")
        table = [(row, per_stage) for row in (*STAGES, "step (profiled)")]
        for row, source in [*table, ("step (wall)", walls)]:
            old, new = (statistics.median(source[n][row]) * 1e3 for n in FORMULATIONS)
            ratio = f"{old / new:7.2f}x" if new > 0.05 else ""
            print(f"{row:<18} {old:9.1f} {new:9.1f} {ratio:>8}")
        print(f"max |labels old - new| over {len(feats) - 1} recurrent steps: {diff:.1e}")


#: ``precision`` part: bf16 candidates per query, in multiples of ``topk``, measured.
CANDIDATE_FACTORS = (1, 2, 3)


def precision(cfg: Config) -> None:
    print(f"\n== label propagation precision: float32 vs bf16 (k' = factor * top-k "
          f"candidates by bfloat16 affinity, scored again in float32), interleaved step by "
          f"step, {cfg.threads} threads ==")
    flags = label_propagation.cpu_flags() or set()
    print(f"CPU flags: {', '.join(sorted(flags & {'avx512_bf16', 'amx_bf16', 'avx512f'}))}")
    model = AppearanceModel(runtime=cfg.runtime)
    for sequence in cfg.sequences:
        feats, labels = davis_features(model, sequence, cfg.frames + 1)
        props = {"float32": LabelPropagator()}
        for factor in CANDIDATE_FACTORS:  # the factor is read when a propagator is made
            label_propagation.CANDIDATE_FACTOR = factor
            props[f"bf16 x{factor}"] = LabelPropagator(
                LabelPropagationConfig(propagation_precision="bf16"))
        label_propagation.CANDIDATE_FACTOR = CANDIDATE_FACTOR
        for prop in props.values():
            prop.reset(feats[0], labels)
        seconds: dict[str, list[float]] = defaultdict(list)
        diff: dict[str, list[torch.Tensor]] = defaultdict(list)
        for t, frame in enumerate(feats[1:], 1):
            outs = {}
            for name in list(props)[t % len(props):] + list(props)[:t % len(props)]:
                start = time.perf_counter()
                outs[name] = props[name].step(frame)
                seconds[name].append(time.perf_counter() - start)
            for name in props:
                diff[name].append((outs[name] - outs["float32"]).abs().amax(0).flatten())
        c, h, w = feats[0].shape
        warm = min(5, len(feats) // 3)
        print(f"DAVIS {sequence}: 854x480 frames, features {c} x {h} x {w}, "
              f"{labels.shape[0]} labels; M = 6, radius 12, top-10; median of "
              f"{len(feats) - 1 - warm} steps after the memory filled; label differences "
              f"over all {len(feats) - 1} recurrent steps")
        print(f"{'precision':<12} {'ms/step':>8} {'speed-up':>9} {'max |diff|':>11} "
              f"{'locations > 1e-4':>17}")
        base = statistics.median(seconds["float32"][warm:])
        for name in props:
            ms = statistics.median(seconds[name][warm:])
            d = torch.cat(diff[name])
            print(f"{name:<12} {ms * 1e3:8.1f} {base / ms:8.2f}x {float(d.max()):11.1e} "
                  f"{float((d > 1e-4).float().mean()):17.2%}")


def _lockstep(envs: dict[str, gym.Env], agents: dict[str, Any], sequence: str,
              timers: dict[str, tuple[TimedModel, Timed]]) -> dict[str, Any]:
    """Play one episode per formulation, frame by frame in turn; per-frame seconds."""
    obs = {}
    for name, env in envs.items():
        obs[name], info = env.reset(options={"sequence": sequence})
        agents[name].reset(obs[name], info)
    seconds: dict[str, dict[str, list[float]]] = {n: defaultdict(list) for n in envs}
    metrics: dict[str, dict[str, float]] = {}
    frame = 0
    while len(metrics) < len(envs):
        for name in list(envs)[::1 if frame % 2 else -1]:
            model, step = timers[name]
            before = (model.seconds, step.seconds)
            start = time.perf_counter()
            action = agents[name].act(obs[name])
            total = time.perf_counter() - start
            if frame >= 3:  # the first answer is the given one; then the memory fills
                seconds[name]["head"].append(total)
                seconds[name]["backbone"].append(model.seconds - before[0])
                seconds[name]["propagation"].append(step.seconds - before[1])
                seconds[name]["rest"].append(total - seconds[name]["backbone"][-1]
                                             - seconds[name]["propagation"][-1])
            obs[name], _, terminated, truncated, info = envs[name].step(action)
            if terminated or truncated:
                metrics[name] = info.get("metrics", {})
        frame += 1
    return {"seconds": seconds, "metrics": metrics, "frames": frame}


#: Head -> (env id, data folder, metrics reported).
HEADS = {
    "unitrack-vos": ("UniTrack/DAVIS-v0", "DAVIS", ("J-Mean", "F-Mean", "J&F-Mean")),
    "unitrack-pose": ("UniTrack/JHMDB-v0", "JHMDB", ("PCK@0.1", "PCK@0.2")),
}


def heads(cfg: Config) -> None:
    print(f"\n== whole heads per frame, old vs new propagator, interleaved frame by frame "
          f"(backbone runtime {cfg.runtime!r}, {cfg.threads} threads) ==")
    model = AppearanceModel(runtime=cfg.runtime)
    print(f"backbone runtime: {model.runtime}; 'rest': upsampling + argmax (VOS), map "
          f"decoding (pose); medians over the frames after the memory filled")
    for agent_name, (env_id, folder, keys) in HEADS.items():
        env0 = gym.make(env_id, root=str(DATA / folder))
        sequences = (cfg.sequences if agent_name == "unitrack-vos"
                     else env0.unwrapped.sequence_names[:1])
        for sequence in sequences:
            envs = {name: gym.make(env_id, root=str(DATA / folder)) for name in FORMULATIONS}
            agents, timers = {}, {}
            for name, reference in FORMULATIONS.items():
                timed = TimedModel(model)
                agent = make_agent(agent_name, appearance_model=timed)
                agent.propagator = LabelPropagator(agent.propagator.config, reference=reference)
                step = Timed(agent.propagator.step)
                agent.propagator.step = step
                agents[name], timers[name] = agent, (timed, step)
            run = _lockstep(envs, agents, sequence, timers)
            print(f"{agent_name} {sequence} ({run['frames']} frames)")
            print(f"  {'':<4} {'s/frame':>8} {'backbone':>9} {'propag.':>8} {'rest':>7}  "
                  + "  ".join(f"{k:>8}" for k in keys))
            med = {n: {k: statistics.median(v) for k, v in run["seconds"][n].items()}
                   for n in FORMULATIONS}
            for name in FORMULATIONS:
                m = med[name]
                print(f"  {name:<4} {m['head']:8.3f} {m['backbone']:9.3f} "
                      f"{m['propagation']:8.3f} {m['rest']:7.3f}  "
                      + "  ".join(f"{run['metrics'][name].get(k, float('nan')):8.4f}"
                                  for k in keys))
            diffs = ", ".join(f"{k} {run['metrics']['new'][k] - run['metrics']['old'][k]:+.1e}"
                              for k in keys)
            print(f"  old/new: head {med['old']['head'] / med['new']['head']:.2f}x, "
                  f"propagation {med['old']['propagation'] / med['new']['propagation']:.2f}x;"
                  f" new - old: {diffs}")


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
        PEAK_RSS_GIB
        + "import torch, gymnasium as gym, unitrack_env\n"
        "from unitrack_env.agents import make_agent\n"
        f"torch.set_num_threads({cfg.threads})\n"
        f"env = gym.make('UniTrack/DAVIS-v0', root={str(DATA / 'DAVIS')!r})\n"
        "agent = make_agent('unitrack-vos')\n"
        "obs, info = env.reset(options={'sequence': 'blackswan'})\n"
        "base = peak_rss_gib()\n"
        "agent.reset(obs, info)\n"
        f"for _ in range({max(cfg.frames, 8)}):\n"
        "    obs, *_ = env.step(agent.act(obs))\n"
        "print(base, peak_rss_gib())\n"
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
    parser.add_argument("--parts", default=",".join(Config.parts))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--sequences", default=",".join(Config.sequences),
                        help="DAVIS sequences of the stages and heads parts")
    parser.add_argument("--runtime", default="auto",
                        help="backbone runtime of the stages and heads parts")
    args = parser.parse_args()
    cfg = Config(tuple(args.parts.split(",")), args.threads, args.frames,
                 tuple(args.sequences.split(",")), args.runtime)
    torch.set_num_threads(cfg.threads)
    print(f"torch {torch.__version__}, {cfg.threads} threads; peak RSS so far "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    parts = {"stages": stages, "precision": precision, "heads": heads, "speed": speed,
             "memory": memory, "accuracy": accuracy}
    for part in cfg.parts:
        parts[part](cfg)


if __name__ == "__main__":
    main()

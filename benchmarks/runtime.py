"""CPU inference at the hardware's pace: backbone runtimes, label propagation, heads end to end.

Usage (from the repository root; OpenVINO / ONNX Runtime rows need the extras)::

    .venv/bin/python benchmarks/runtime.py --parts backbone,propagation,heads,memory \
        --threads 2 --before f786a63

Every comparison is measured side by side in one run: the candidates take turns (round
robin, ``--repeats`` rounds) and each row reports the fastest round (min) and the median, so
that load from other processes on a shared machine hits all candidates alike; read the
ratios, not the absolute times.

Parts:

* ``backbone``: ``AppearanceModel.features`` per runtime (torch eager, OpenVINO, ONNX Runtime)
  at the paper's input sizes (MOT 1088 x 608, DAVIS 854 x 480, SOT 3 crops of 520 x 520):
  ms, GFLOP/s (FLOPs counted once with torch's ``FlopCounterMode``), speed-up over torch
  and the features' cosine similarity / max abs difference to torch on a real frame.
* ``propagation``: ``LabelPropagator`` now vs the version at git revision ``--before``
  (loaded from git history), on real DAVIS blackswan features at 480p (60 x 107 x 112,
  memory of 6 frames): per stage (first-frame search, local search, whole step), the
  largest difference of the outputs, and J&F of ``unitrack-vos`` on blackswan and dog with
  either propagator.
* ``heads``: end-to-end s/frame (``agent.act``; MOT also the env's decode and scoring) per
  head, "before" (torch runtime, label and box propagation of ``--before``) vs "after"
  (``runtime="auto"``, current code): VOS 854 x 480, SOT XCorr / DCF (520 crops), pose
  (JHMDB), MOT on the 1080p MOT17 frames, with the per-stage share of the backbone.
* ``memory``: peak RSS of a VOS run (480p, M = 6) per runtime, each in a fresh process.
"""

from __future__ import annotations

import argparse
import functools
import os
import resource
import statistics
import subprocess
import sys
import time
import types
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym
import numpy as np
import torch
from _timing import PEAK_RSS_GIB  # a sibling file (the script's folder)

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import AppearanceModel, letterbox
from unitrack_env.agents.appearance.runtime import available_runtimes
from unitrack_env.agents.primitives import label_propagation as current_lp
from unitrack_env.agents.primitives.label_propagation import normalize_features

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / ".." / "shared" / "data"
BEFORE = "f786a63"
"""Revision whose label and box propagation are the "before": the tree before issue 13."""


@dataclass
class Config:
    parts: tuple[str, ...] = ("backbone", "propagation", "heads", "memory")
    threads: int = 2
    repeats: int = 5
    frames: int = 12
    before: str = BEFORE


def module_at(revision: str, path: str, name: str) -> types.ModuleType:
    """A module as it was at a git revision (for before/after rows in one run)."""
    source = subprocess.run(["git", "show", f"{revision}:{path}"], capture_output=True,
                            text=True, check=True, cwd=REPO).stdout
    module = types.ModuleType(name)
    module.__file__ = f"{revision}:{path}"
    sys.modules[name] = module  # dataclasses resolve their module by name
    exec(compile(source, module.__file__, "exec"), module.__dict__)  # noqa: S102 (our repo)
    return module


def round_robin(candidates: dict[str, Callable[[], Any]], repeats: int) -> dict[str, list[float]]:
    """Run each candidate once per round, ``repeats`` rounds; seconds per call."""
    times: dict[str, list[float]] = {name: [] for name in candidates}
    for _ in range(repeats):
        for name, fn in candidates.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return times


def rgb(path: Path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)


def cosine(a: torch.Tensor, b: torch.Tensor) -> float:
    a, b = a.double().flatten(), b.double().flatten()
    return float(a @ b / (a.norm() * b.norm()))


# ---------------------------------------------------------------------- backbone
def backbone(cfg: Config) -> None:
    from torch.utils.flop_counter import FlopCounterMode

    runtimes = available_runtimes()
    print(f"\n== backbone: AppearanceModel.features per runtime ({cfg.threads} threads; "
          f"installed: {', '.join(runtimes)}) ==")
    models = {name: AppearanceModel(runtime=name, num_threads=cfg.threads) for name in runtimes}
    mot = letterbox(rgb(DATA / "MOT17" / "train" / "MOT17-02-FRCNN" / "img1" / "000001.jpg"))
    davis = rgb(DATA / "DAVIS" / "JPEGImages" / "480p" / "blackswan" / "00000.jpg")
    crops = np.stack([cv2.resize(davis[:, 100:580], (520, 520))] * 3)
    inputs = {"MOT 1088x608": mot.image, "DAVIS 854x480": davis, "SOT 3x520x520": crops}
    print(f"{'input':<15} {'runtime':<12} {'GFLOP':>6} {'min ms':>8} {'med ms':>8} "
          f"{'GFLOP/s':>8} {'speed-up':>8} {'cosine':>10} {'max|d|':>8}")
    for label, image in inputs.items():
        with FlopCounterMode(display=False) as counter, torch.inference_mode():
            models["torch"]._network(models["torch"].preprocess(image))
        gflop = counter.get_total_flops() / 1e9
        reference = models["torch"].features(image)
        outputs = {name: model.features(image) for name, model in models.items()}  # warm
        times = round_robin({name: functools.partial(model.features, image)
                             for name, model in models.items()}, cfg.repeats)
        base = min(times["torch"])
        for name, seconds in times.items():
            best = min(seconds)
            diff = float((outputs[name] - reference).abs().max())
            print(f"{label:<15} {name:<12} {gflop:6.1f} {best * 1e3:8.1f} "
                  f"{statistics.median(seconds) * 1e3:8.1f} {gflop / best:8.1f} "
                  f"{base / best:7.2f}x {cosine(outputs[name], reference):10.7f} {diff:8.1e}")


# ---------------------------------------------------------------------- propagation
def _davis_features(model: AppearanceModel, sequence: str, count: int) -> list[torch.Tensor]:
    files = sorted((DATA / "DAVIS" / "JPEGImages" / "480p" / sequence).glob("*.jpg"))[:count]
    return [model.features(rgb(f))[0] for f in files]


def propagation(cfg: Config) -> None:
    print(f"\n== label propagation: now vs {cfg.before} (DAVIS blackswan 480p, M = 6, "
          f"{cfg.threads} threads) ==")
    old = module_at(cfg.before, "agents/primitives/label_propagation.py", "_lp_before")
    model = AppearanceModel(runtime="auto", num_threads=cfg.threads)
    feats = _davis_features(model, "blackswan", 8)
    c, h, w = feats[0].shape
    labels = torch.zeros(2, h, w)
    labels[0] = 1.0
    labels[:, h // 3:2 * h // 3, w // 3:2 * w // 3] = torch.tensor([0.0, 1.0]).view(2, 1, 1)
    props = {"before": old.LabelPropagator(), "now": current_lp.LabelPropagator()}
    for prop in props.values():
        prop.reset(feats[0], labels)
        for f in feats[1:6]:
            prop.step(f)
    query = feats[6]
    outs = {name: prop.propagate(query) for name, prop in props.items()}
    print(f"features {c} x {h} x {w}; outputs max |now - before| "
          f"{float((outs['now'] - outs['before']).abs().max()):.2e}")
    q = normalize_features(query)
    flat = q.reshape(c, -1).t().contiguous()
    stages: dict[str, Callable[[], Any]] = {}
    for name, prop in props.items():
        stages[f"first frame [{name}]"] = lambda p=prop: p._search_first(flat, *p._first, h, w)
        stages[f"local [{name}]"] = lambda p=prop: p._search_local(q, h, w)
        stages[f"step [{name}]"] = lambda p=prop: p.propagate(query)
    with torch.inference_mode():  # the propagators' step buffers are inference tensors
        times = round_robin(stages, cfg.repeats)
    for stage in ("first frame", "local", "step"):
        before, now = min(times[f"{stage} [before]"]), min(times[f"{stage} [now]"])
        medians = [statistics.median(times[f"{stage} [{n}]"]) * 1e3 for n in ("before", "now")]
        print(f"{stage:<12} before {before * 1e3:7.1f} ms  now {now * 1e3:7.1f} ms  "
              f"speed-up {before / now:5.2f}x  (medians {medians[0]:.1f} / {medians[1]:.1f} ms)")
    env = gym.make("UniTrack/DAVIS-v0", root=str(DATA / "DAVIS"))
    for sequence in ("blackswan", "dog"):
        metrics = {}
        for name, cls in (("before", old.LabelPropagator), ("now", current_lp.LabelPropagator)):
            agent = make_agent("unitrack-vos", appearance_model=model)
            agent.propagator = cls()
            metrics[name] = _play(env, agent, sequence)
        dj = metrics["now"]["J-Mean"] - metrics["before"]["J-Mean"]
        df = metrics["now"]["F-Mean"] - metrics["before"]["F-Mean"]
        print(f"unitrack-vos {sequence:<10} J {metrics['now']['J-Mean']:.4f} (diff {dj:+.1e}) "
              f"F {metrics['now']['F-Mean']:.4f} (diff {df:+.1e})")


def _play(env: gym.Env, agent: Any, sequence: str) -> dict[str, float]:
    obs, info = env.reset(options={"sequence": sequence})
    agent.reset(obs, info)
    while True:
        obs, _, terminated, truncated, info = env.step(agent.act(obs))
        if terminated or truncated:
            return info.get("metrics", {})


# ---------------------------------------------------------------------- heads
class TimedFeatures:
    """Replaces a model's ``features`` by a timed call (the backbone's share of a step)."""

    def __init__(self, model: AppearanceModel) -> None:
        self.inner = model.features
        self.seconds = 0.0
        model.features = self  # type: ignore[method-assign]

    def __call__(self, images: Any) -> torch.Tensor:
        start = time.perf_counter()
        out = self.inner(images)
        self.seconds += time.perf_counter() - start
        return out


HEADS = {
    "vos": ("UniTrack/DAVIS-v0", "DAVIS", "unitrack-vos", "blackswan"),
    "sot-xcorr": ("UniTrack/OTB-v0", "OTB", "unitrack-xcorr", "Crossing"),
    "sot-dcf": ("UniTrack/OTB-v0", "OTB", "unitrack-dcf", "Crossing"),
    "pose": ("UniTrack/JHMDB-v0", "JHMDB", "unitrack-pose", None),
    "mot": ("UniTrack/MOT17-v0", "MOT17", "unitrack", "MOT17-02-FRCNN"),
}


def _argmax_decode(agent: Any, soft: torch.Tensor) -> np.ndarray:
    """The VOS head's label decoding before issue 13 (``argmax(0)``, not ``max(0).indices``)."""
    full = torch.nn.functional.interpolate(soft[None], size=agent._size, mode="bilinear",
                                           align_corners=False)[0]
    return agent._lookup[full.argmax(0).numpy().astype(np.intp)]


def _make_head(agent_name: str, model: AppearanceModel,
               before: dict[str, types.ModuleType] | None) -> Any:
    options = {"feature_cache": False} if agent_name == "unitrack" else {}
    agent = make_agent(agent_name, appearance_model=model, **options)
    if before is None:
        return agent
    if agent_name in ("unitrack-vos", "unitrack-pose"):
        agent.propagator = before["lp"].LabelPropagator(agent.propagator.config)
        if agent_name == "unitrack-vos":
            agent.decode = types.MethodType(_argmax_decode, agent)
    elif agent_name in ("unitrack-xcorr", "unitrack-dcf"):
        box = before["bp"]
        config = box.BoxPropagationConfig(**vars(agent.propagator.config))
        agent.propagator = box.BoxPropagator(model.features, config, stride=model.stride)
    return agent


def _run_head(env: gym.Env, agent_name: str, sequence: str, model: AppearanceModel,
              timer: TimedFeatures, before: dict[str, types.ModuleType] | None,
              frames: int) -> tuple[float, float]:
    """Seconds per frame of the loop (act + env step) after the first, and backbone share."""
    agent = _make_head(agent_name, model, before)
    obs, info = env.reset(options={"sequence": sequence})
    agent.reset(obs, info)
    obs, *_ = env.step(agent.act(obs))  # the first answer: the given target
    timer.seconds = 0.0
    start = time.perf_counter()
    played = 0
    while played < frames:
        obs, _, terminated, truncated, _ = env.step(agent.act(obs))
        played += 1
        if terminated or truncated:
            break
    seconds = (time.perf_counter() - start) / played
    return seconds, timer.seconds / played / seconds


def heads(cfg: Config) -> None:
    print(f"\n== heads end to end: before ({cfg.before}, torch) vs after (current code, "
          f"runtime='auto'), {cfg.threads} threads, {cfg.frames} frames after the first ==")
    before_modules = {
        "lp": module_at(cfg.before, "agents/primitives/label_propagation.py", "_lp_before"),
        "bp": module_at(cfg.before, "agents/primitives/box_propagation.py", "_bp_before"),
    }
    models = {"before": AppearanceModel(runtime="torch", num_threads=cfg.threads),
              "after": AppearanceModel(runtime="auto", num_threads=cfg.threads)}
    timers = {name: TimedFeatures(model) for name, model in models.items()}
    print(f"after: runtime {models['after'].runtime}")
    print(f"{'head':<10} {'sequence':<22} {'before s/f':>10} {'after s/f':>10} {'speed-up':>8} "
          f"{'FPS after':>9} {'backbone before/after':>22}")
    for head, (env_id, folder, agent_name, sequence) in HEADS.items():
        env = gym.make(env_id, root=str(DATA / folder))
        sequence = sequence or env.unwrapped.sequence_names[0]
        per_frame: dict[str, list[float]] = {"before": [], "after": []}
        shares: dict[str, list[float]] = {"before": [], "after": []}
        for _ in range(max(2, cfg.repeats // 2)):
            for name, model in models.items():
                seconds, share = _run_head(
                    env, agent_name, sequence, model, timers[name],
                    before_modules if name == "before" else None, cfg.frames)
                per_frame[name].append(seconds)
                shares[name].append(share)
        before, after = min(per_frame["before"]), min(per_frame["after"])
        share_before, share_after = (statistics.median(shares[n]) for n in ("before", "after"))
        print(f"{head:<10} {sequence[:22]:<22} {before:10.3f} {after:10.3f} "
              f"{before / after:7.2f}x {1 / after:9.2f} {share_before:14.0%} / {share_after:4.0%}")
    print("(s/frame includes the env's decode and scoring: the whole loop, end to end)")


# ---------------------------------------------------------------------- memory
def memory(cfg: Config) -> None:
    print("\n== memory: peak RSS of a VOS run (DAVIS blackswan 480p, M = 6), fresh process ==")
    for name in available_runtimes():
        code = (
            PEAK_RSS_GIB
            + "import torch, gymnasium as gym, unitrack_env\n"
            "from unitrack_env.agents import make_agent\n"
            f"torch.set_num_threads({cfg.threads})\n"
            f"env = gym.make('UniTrack/DAVIS-v0', root={str(DATA / 'DAVIS')!r})\n"
            f"agent = make_agent('unitrack-vos', runtime={name!r})\n"
            "obs, info = env.reset(options={'sequence': 'blackswan'})\n"
            "before = peak_rss_gib()\n"
            "agent.reset(obs, info)\n"
            f"for _ in range({max(cfg.frames, 8)}):\n"
            "    obs, *_ = env.step(agent.act(obs))\n"
            "print(agent.model.runtime, before, peak_rss_gib())\n"
        )
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True, cwd=REPO)
        runtime, before, peak = out.stdout.split()[-3:]
        print(f"{name:<12} peak RSS {float(peak):.2f} GiB (runtime {runtime}; "
              f"{float(before):.2f} GiB before the agent's first frame)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="backbone,propagation,heads,memory")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--before", default=BEFORE)
    args = parser.parse_args()
    cfg = Config(tuple(args.parts.split(",")), args.threads, args.repeats, args.frames,
                 args.before)
    torch.set_num_threads(cfg.threads)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f"torch {torch.__version__}; {cfg.threads} threads; load average {load}; "
          f"peak RSS so far {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    for part in cfg.parts:
        {"backbone": backbone, "propagation": propagation, "heads": heads,
         "memory": memory}[part](cfg)


if __name__ == "__main__":
    main()

"""ViT-S/14 vs EfficientNet-Lite0 (and the ViT stride options): ms per frame per head.

Usage (from the repository root)::

    .venv/bin/python benchmarks/vit.py --frames 3 --repeats 2 --threads 2 --runtime torch

Side by side in one run: the models take turns (round robin, ``--repeats`` rounds) on each
head and each row reports the fastest round, so load from other processes on a shared machine
hits all of them alike; read the ratios. Speed does not depend on the weights, so every model
is randomly initialised (``weights="random"``; Lite0 with ``arch="efficientnet-lite0"``).

Parts:

* ``backbone``: ``AppearanceModel.features`` at each head's input size (SOT 3 crops of
  520 x 520, DAVIS 854 x 480, MOT letterbox 1088 x 608): ms, the map size, the token count.
* ``heads``: ms per frame of ``agent.act`` (after the first frame) per head: VOS (DAVIS
  blackswan), SOT XCorr and DCF (OTB Crossing), MOT (MOT17-05, letterboxed to 1088 x 608).

Models: ``lite0`` (stride 8), ``vit-s14`` (stride 14), ``vit-s14-s8o`` (``stride="8"``:
overlapping patch embedding, 3x the tokens), ``vit-s14-s8u`` (``stride="8-upsample"``) and
``vit-b8`` (ViT-B/8: 4,225 tokens per SOT crop, 10,336 at the MOT letterbox). ``--models``
picks a subset (the default leaves out ``vit-b8``: minutes per frame on a CPU).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from _timing import PEAK_RSS_GIB, timed_acts  # a sibling file (the script's folder)

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents.appearance.model import AppearanceModel
from unitrack_env.agents.base import make_agent

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / ".." / "shared" / "data"

MODELS: dict[str, dict[str, Any]] = {
    "lite0": {"arch": "efficientnet-lite0"},
    "vit-s14": {"arch": "vit_small_patch14"},
    "vit-s14-s8o": {"arch": "vit_small_patch14", "stride": "8"},
    "vit-s14-s8u": {"arch": "vit_small_patch14", "stride": "8-upsample"},
    "vit-b8": {"arch": "vit_base_patch8"},
}

SIZES: dict[str, tuple[int, int, int]] = {  # batch, height, width
    "sot 3x520": (3, 520, 520), "vos 854x480": (1, 480, 854), "mot 1088x608": (1, 608, 1088),
}

HEADS: dict[str, tuple[str, str, str, str]] = {
    "vos": ("UniTrack/DAVIS-v0", "DAVIS", "unitrack-vos", "blackswan"),
    "sot-xcorr": ("UniTrack/OTB-v0", "OTB", "unitrack-xcorr", "Crossing"),
    "sot-dcf": ("UniTrack/OTB-v0", "OTB", "unitrack-dcf", "Crossing"),
    "mot": ("UniTrack/MOT17-v0", "MOT17", "unitrack", "MOT17-05-FRCNN"),
}


def best_of(candidates: dict[str, Callable[[], float]], repeats: int) -> dict[str, float]:
    """Each candidate's fastest of ``repeats`` rounds, the candidates taking turns."""
    times: dict[str, list[float]] = {name: [] for name in candidates}
    for _ in range(repeats):
        for name, run in candidates.items():
            times[name].append(run())
    return {name: min(values) for name, values in times.items()}


def backbone(models: dict[str, AppearanceModel], repeats: int, sizes: list[str]) -> None:
    rng = np.random.default_rng(0)
    print("\n== backbone: ms per call (fastest round) ==")
    print(f"{'input':<14}" + "".join(f"{name:>22}" for name in models))
    for label, (batch, height, width) in SIZES.items():
        if label.split()[0] not in sizes:
            continue
        images = rng.integers(0, 256, (batch, height, width, 3), dtype=np.uint8)
        for model in models.values():
            model.features(images)  # warm-up (and export/compile for a compiled runtime)

        def timed(model: AppearanceModel, images: np.ndarray = images) -> Callable[[], float]:
            def run() -> float:
                start = time.perf_counter()
                model.features(images)
                return time.perf_counter() - start
            return run

        best = best_of({name: timed(model) for name, model in models.items()}, repeats)
        cells = []
        for name, model in models.items():
            _, h, w = model.feature_shape(height, width)
            cells.append(f"{best[name] * 1e3:9.0f} ms {h:3d}x{w:<3d}")
        print(f"{label:<14}" + "".join(f"{c:>22}" for c in cells))
    reference = next(iter(models))
    print(f"(map size h x w; ratios to {reference}: see the heads part)")
    scope: dict[str, Any] = {}
    exec(PEAK_RSS_GIB, scope)  # the process's peak: run one model and size to read its own
    print(f"peak resident memory of this process: {scope['peak_rss_gib']():.2f} GiB")


def _head_run(env: gym.Env, agent_name: str, sequence: str, model: AppearanceModel,
              frames: int) -> Callable[[], float]:
    def run() -> float:
        options = {"feature_cache": False} if agent_name == "unitrack" else {}
        agent = make_agent(agent_name, appearance_model=model, **options)
        obs, info = env.reset(options={"sequence": sequence})
        agent.reset(obs, info)
        obs, *_ = env.step(agent.act(obs))  # the first answer: the given target
        seconds, played, _ = timed_acts(env, agent, obs, frames)
        return seconds / played
    return run


def heads(models: dict[str, AppearanceModel], frames: int, repeats: int) -> None:
    print(f"\n== heads: ms per frame of agent.act ({frames} frames after the first, "
          "fastest round) ==")
    reference = next(iter(models))
    print(f"{'head':<10}" + "".join(f"{name:>14}" for name in models)
          + "".join(f"{name + '/' + reference:>22}" for name in list(models)[1:]))
    for head, (env_id, folder, agent_name, sequence) in HEADS.items():
        env = gym.make(env_id, root=str(DATA / folder))
        best = best_of({name: _head_run(env, agent_name, sequence, model, frames)
                        for name, model in models.items()}, repeats)
        env.close()
        ratios = [best[name] / best[reference] for name in list(models)[1:]]
        print(f"{head:<10}" + "".join(f"{best[n] * 1e3:11.0f} ms" for n in models)
              + "".join(f"{r:21.1f}x" for r in ratios))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="backbone,heads")
    parser.add_argument("--models", default=",".join(m for m in MODELS if m != "vit-b8"))
    parser.add_argument("--sizes", default="sot,vos,mot", help="backbone input sizes")
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runtime", default="torch",
                        choices=("torch", "openvino", "onnxruntime", "auto"))
    args = parser.parse_args()
    models = {name: AppearanceModel("random", num_threads=args.threads, runtime=args.runtime,
                                    **MODELS[name]) for name in args.models.split(",")}
    print(f"runtime {args.runtime}, {args.threads} threads; models: "
          + ", ".join(f"{n} (stride {m.stride})" for n, m in models.items()))
    parts = args.parts.split(",")
    if "backbone" in parts:
        backbone(models, args.repeats, args.sizes.split(","))
    if "heads" in parts:
        heads(models, args.frames, args.repeats)


if __name__ == "__main__":
    main()

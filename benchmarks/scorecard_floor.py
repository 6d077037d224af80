"""How fast can the fixture scorecard be in float32? The single-object cells' backbone floor.

Usage (from the repository root)::

    PYTHONPATH=. python benchmarks/scorecard_floor.py --data ../shared/data --threads 2

The single-object heads feed the backbone three 520 x 520 scale crops per frame (UniTrack's
search region at 3 scales), once per frame, for each head (XCorr, DCF) and model. This prints:

* the float32 matrix-product rate of this CPU (one ``4096 x 4096 x 4096`` product, best of
  5; bfloat16 beside it for reference);
* per model: its GFLOP per SOT frame (:func:`network_gflops`), the seconds OpenVINO takes for
  one frame's three crops (best of 5 after a warm-up) and the rate that is;
* the SOT cells' frames in the scorecard of ``--data`` (both heads), their backbone GFLOP,
  and those GFLOP at the best float32 rate measured here (the matrix product's or a model's,
  whichever is higher: OpenVINO's convolutions beat torch's matrix product); with
  ``--baseline SECONDS`` (a whole card's time) the share of a 2x and a 3x budget that this
  part alone takes.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch


def product_rate(dtype: torch.dtype, size: int = 4096) -> float:
    """GFLOP/s of one ``size`` cube matrix product in ``dtype`` (best of 5)."""
    a = torch.randn(size, size).to(dtype)
    b = torch.randn(size, size).to(dtype)
    a @ b
    best = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - start)
    return 2 * size**3 / best / 1e9


def frame_seconds(weights: str, threads: int) -> float:
    """OpenVINO seconds for one SOT frame's three 520 x 520 crops (best of 5, warm)."""
    from unitrack_env.agents.appearance import AppearanceModel

    model = AppearanceModel(weights=weights, runtime="openvino", num_threads=threads)
    crops = np.random.default_rng(0).integers(0, 256, (3, 520, 520, 3), dtype=np.uint8)
    model.features(crops)
    best = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        model.features(crops)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="folder holding OTB/")
    parser.add_argument("--model", action="append", help="default: imagenet-lite0, random")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--baseline", type=float, help="a whole card's seconds, e.g. 1357")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    from pathlib import Path

    from unitrack_env.agents.appearance.architectures import network_gflops
    from unitrack_env.agents.appearance.weights import load_weights
    from unitrack_env.evaluation.scorecard.plan import ModelSpec, plan

    models = [ModelSpec.parse(m) for m in args.model or ["imagenet-lite0", "random"]]
    float32, bf16 = product_rate(torch.float32), product_rate(torch.bfloat16)
    print(f"matrix product, {args.threads} threads: float32 {float32:.0f} GFLOP/s, "
          f"bfloat16 {bf16:.0f} GFLOP/s")
    cells, _, _ = plan(models, ["sot"], Path(args.data))
    total_gflop = total_seconds = best_model = 0.0
    for spec in models:
        loaded = load_weights(spec.weights, arch=spec.arch, layer=spec.layer, stride=spec.stride)
        gflop = 3 * network_gflops(loaded.module, loaded.layers, [(520, 520)])[0]
        seconds = frame_seconds(spec.weights, args.threads)
        frames = sum(c.frames for c in cells if c.model == spec.name)
        total_gflop += gflop * frames
        total_seconds += seconds * frames
        best_model = max(best_model, gflop / seconds)
        print(f"{spec.name}: {gflop:.1f} GFLOP per SOT frame, OpenVINO {seconds * 1e3:.0f} ms "
              f"({gflop / seconds:.0f} GFLOP/s); {frames} frames in the SOT cells: "
              f"{gflop * frames / 1e3:.1f} TFLOP, {seconds * frames:.0f} s of backbone")
    best = max(float32, best_model)
    floor = total_gflop / best
    print(f"SOT cells' backbone: {total_gflop / 1e3:.1f} TFLOP, OpenVINO {total_seconds:.0f} s; "
          f"at the best float32 rate measured here ({best:.0f} GFLOP/s) {floor:.0f} s")
    if args.baseline:
        for factor in (2, 3):
            budget = args.baseline / factor
            print(f"{factor}x faster than {args.baseline:.0f} s = {budget:.0f} s; the SOT "
                  f"backbone alone at that rate is {floor / budget:.0%} of it")


if __name__ == "__main__":
    main()

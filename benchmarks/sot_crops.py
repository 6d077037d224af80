"""What the SOT heads' exact crops cost per frame, beside the backbone that reads them.

Usage (from the repository root)::

    python benchmarks/sot_crops.py --data ../shared/data --repeats 20

On a real OTB frame (Crossing's first, or a random 640 x 480 image without ``--data``), a
DCF step's crops (three search scales and the update crop, 520 x 520, the paper's setting)
are cut by the library's exact float bilinear sampling (``crop_windows``) and by the uint8
``cv2.warpAffine`` sampling the heads used before the stability fix
(``sot_stability.cv2_crop_windows``); the appearance model (ImageNet-Lite0, the default
runtime) then computes their features. The three are timed in turn, ``--repeats`` times,
and the medians printed with two ratios: exact / uint8 crops, and the step's time with exact
crops over its time with uint8 crops (crops + backbone). Read the ratios: the absolute times
depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from sot_stability import cv2_crop_windows

from unitrack_env.agents.appearance.model import AppearanceModel
from unitrack_env.agents.primitives.box_propagation import crop_windows
from unitrack_env.frames import read_rgb


def frame(data: Path | None) -> np.ndarray:
    """Crossing's first frame when the fixture is there, else a random 640 x 480 image."""
    path = None if data is None else data / "OTB" / "Crossing" / "img" / "0001.jpg"
    if path is not None and path.is_file():
        return read_rgb(path)
    return np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=None, help="folder holding OTB/")
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--crop-size", type=int, default=520)
    a = p.parse_args()
    image = frame(a.data)
    height, width = image.shape[:2]
    centre = (width / 2 + 0.37, height / 2 - 0.21)
    # a 40 x 90 target at context 4.5: three scales and the update crop
    windows = np.array([[40.0, 90.0]]) * 4.5 * np.array([[1 / 1.0275], [1.0], [1.0275], [1.0]])
    model = AppearanceModel()
    model.features(crop_windows(image, centre, windows, a.crop_size))  # export, warm-up
    times: dict[str, list[float]] = {"exact crops": [], "uint8 crops": [], "backbone": []}
    for _ in range(a.repeats):
        start = time.perf_counter()
        crops = crop_windows(image, centre, windows, a.crop_size)
        times["exact crops"].append(time.perf_counter() - start)
        start = time.perf_counter()
        cv2_crop_windows(image, centre, windows, a.crop_size)
        times["uint8 crops"].append(time.perf_counter() - start)
        start = time.perf_counter()
        model.features(crops)
        times["backbone"].append(time.perf_counter() - start)
    ms = {name: 1000 * statistics.median(values) for name, values in times.items()}
    print(f"frame {width}x{height}, {len(windows)} crops of {a.crop_size}, "
          f"median of {a.repeats}, runtime {model.runtime_label(a.crop_size, a.crop_size)}")
    print("| part | ms per step |\n|---|---|")
    for name, value in ms.items():
        print(f"| {name} | {value:.1f} |")
    print(f"exact / uint8 crops: {ms['exact crops'] / ms['uint8 crops']:.1f}x; step with exact "
          f"crops / with uint8 crops: "
          f"{(ms['exact crops'] + ms['backbone']) / (ms['uint8 crops'] + ms['backbone']):.3f}x")


if __name__ == "__main__":
    main()

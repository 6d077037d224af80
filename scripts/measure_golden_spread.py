"""Measure how much the repository's golden episodes move across CPU kernels and thread counts.

Each golden file is replayed in a fresh process under several settings that change the
floating-point order of the appearance model's arithmetic, the way another machine would:

* ``ATEN_CPU_CAPABILITY`` = ``default`` (no vector kernels), ``avx2``, or native (``avx512``
  on the machine where the figures in ``docs/regression-tests.md`` were measured);
* ``ONEDNN_MAX_CPU_ISA`` = ``AVX2`` (oneDNN's convolutions without AVX-512);
* the agent's ``num_threads`` = 1 or 2 (intra-op parallel reductions split differently);
* for numpy/scipy code (the baselines' Kalman filters, IoU, Hungarian matching, the
  official scorers): ``NPY_DISABLE_CPU_FEATURES`` (numpy without its AVX-512 kernels),
  ``OPENBLAS_CORETYPE=Sandybridge`` (OpenBLAS's AVX kernels instead of the native ones) and
  ``MKL_ENABLE_INSTRUCTIONS=AVX2`` (torch's MKL without AVX-512);
* ``noise-1e-05/s0`` .. ``s3``: every feature map of the appearance model multiplied by
  ``1 + 1e-5 * N(0, 1)`` (four seeds). The kernel settings above are only the kernels this
  machine has; another CPU rounds differently again. An episode that sits on a knife edge
  (a tracker choosing between two nearly equal peaks) shows it here as two clusters of
  values: such an episode cannot be a golden at any tolerance (choose another sequence).

The feature cache is off in the replays (a cached feature map would hide the kernels).

It prints, per golden file and metric, the golden value and the largest distance from it
over the settings; ``docs/regression-tests.md`` explains how the tolerances were set from it.

Usage::

    python scripts/measure_golden_spread.py [tests/goldens/unitrack-xcorr-*.json ...] \
        [--settings native/1,blas-numpy-mkl/1] [--json out]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: numpy's AVX-512 dispatch targets (disabled in one setting).
_AVX512 = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR"
#: Real-data goldens store no root (machine-specific): where the project's fixtures are.
REAL_ROOTS = {"UniTrack/MOT17-v0": "MOT17", "UniTrack/MOT15-v0": "MOT15"}
SHARED = REPO.parent / "shared" / "data"

#: Relative size of the feature noise of the ``noise-*`` settings: about 6 times the change
#: between kernel families (relative RMS 1.6e-6 between the native AVX-512 kernels and
#: ATEN_CPU_CAPABILITY=default with ONEDNN_MAX_CPU_ISA=AVX2, on a 320x240 frame).
NOISE = 1e-5

#: (label, extra environment variables, num_threads override)
SETTINGS: tuple[tuple[str, dict[str, str], int], ...] = (
    ("native/1", {}, 1),
    ("native/2", {}, 2),
    ("default/1", {"ATEN_CPU_CAPABILITY": "default"}, 1),
    ("default/2", {"ATEN_CPU_CAPABILITY": "default"}, 2),
    ("avx2/1", {"ATEN_CPU_CAPABILITY": "avx2"}, 1),
    ("onednn-avx2/1", {"ONEDNN_MAX_CPU_ISA": "AVX2"}, 1),
    ("blas-numpy-mkl/1", {"NPY_DISABLE_CPU_FEATURES": _AVX512, "OPENBLAS_CORETYPE": "Sandybridge",
                          "MKL_ENABLE_INSTRUCTIONS": "AVX2"}, 1),
    *((f"noise-{NOISE:g}/s{seed}", {"UNITRACK_SPREAD_NOISE": f"{NOISE}:{seed}"}, 1)
      for seed in range(4)),
)

_CHILD = """
import json, os, sys
import torch
from unitrack_env.agents.appearance import AppearanceModel
from unitrack_env.evaluation.regression.golden import EpisodeRecord, record_episode
noise = os.environ.get("UNITRACK_SPREAD_NOISE")
if noise:
    scale, seed = float(noise.split(":")[0]), int(noise.split(":")[1])
    generator = torch.Generator().manual_seed(seed)
    exact = AppearanceModel.features
    def noisy(self, images):
        out = exact(self, images)
        return out * (1 + scale * torch.randn(out.shape, generator=generator))
    AppearanceModel.features = AppearanceModel.__call__ = noisy
golden = EpisodeRecord.load(sys.argv[1])
kwargs = dict(golden.agent_kwargs)
if "num_threads" in kwargs:
    kwargs["num_threads"] = int(sys.argv[2])
env_kwargs = dict(golden.env_kwargs)
if sys.argv[3]:
    env_kwargs["root"] = sys.argv[3]
actual = record_episode(golden.env_id, golden.agent, golden.sequence,
                        env_kwargs=env_kwargs, agent_kwargs=kwargs)
print(json.dumps({"metrics": actual.metrics, "digest": actual.digest}))
"""


def replay(path: Path, env: dict[str, str], threads: int) -> dict:
    """One replay of a golden file in a fresh interpreter under ``env``."""
    golden = json.loads(path.read_text())
    folder = REAL_ROOTS.get(golden["env_id"])
    real = folder is not None and not golden["sequence"].startswith("SYN")
    root = str(SHARED / folder) if real else ""
    full_env = {**os.environ, "UNITRACK_FEATURE_CACHE": "off", **env}
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(threads), root],
                         capture_output=True, text=True, env=full_env, check=True, cwd=REPO)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    """Replay every file under every setting and print the spread."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("goldens", nargs="*", type=Path)
    parser.add_argument("--json", type=Path, help="also write the raw results here")
    parser.add_argument("--settings", help="comma-separated labels of SETTINGS (default: all)")
    args = parser.parse_args(argv)
    files = args.goldens or sorted((REPO / "tests" / "goldens").glob("unitrack*.json"))
    chosen = args.settings.split(",") if args.settings else [label for label, _, _ in SETTINGS]
    settings = [s for s in SETTINGS if s[0] in chosen]
    results: dict[str, dict] = {}
    for path in files:
        golden = json.loads(path.read_text())
        runs = {}
        for label, env, threads in settings:
            runs[label] = replay(path, env, threads)
            print(f"{path.name} {label}: {len(set(r['digest'] for r in runs.values()))} "
                  "distinct action digests so far", file=sys.stderr, flush=True)
        results[path.name] = {"golden": golden["metrics"], "runs": runs}
        print(f"\n{path.name}")
        for name, old in sorted(golden["metrics"].items()):
            values = [r["metrics"][name] for r in runs.values()]
            spread = max(abs(v - old) for v in values)
            if spread > 0:
                each = ", ".join(f"{k}={r['metrics'][name]:.6f}" for k, r in runs.items())
                print(f"  {name:<24} golden {old:.6f}  max |change| {spread:.6f}  ({each})")
        digests = {r["digest"] for r in runs.values()}
        print(f"  distinct action digests: {len(digests)} of {len(runs)} settings")
        if args.json:
            args.json.write_text(json.dumps(results, indent=2, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Scorecard cells per minute: the local process pool against a local Ray, side by side.

Plays the same scorecard (default: pose propagation and SOT on the embedded synthetic data,
two models) once per backend into fresh folders, with the feature cache off so both do the
same work, and prints cells per minute, the ratio, the Ray start-up overhead, and whether the
two scorecards are equal. Run on a quiet machine:

    python benchmarks/scorecard_backends.py [--tasks pose-prop,sot] [--workers 2] [--repeats 1]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from unitrack_env.evaluation.scorecard import card as sc
from unitrack_env.evaluation.scorecard.plan import ModelSpec


def _timed(backend: str, tasks: list[str], workers: int, models: list[ModelSpec]) -> tuple[
        float, int, dict]:
    with tempfile.TemporaryDirectory(prefix=f"bench-{backend}-") as out:
        start = time.perf_counter()
        card = sc.scorecard(models, out=Path(out), tasks=tasks, backend=backend,
                            workers=workers)
        seconds = time.perf_counter() - start
        cells = sum(len(row["per_sequence"]) for row in card["rows"])
    return seconds, cells, card


def _ray_startup(workers: int) -> float:
    import ray

    start = time.perf_counter()
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    ray.get(ray.remote(lambda: 1).remote())
    seconds = time.perf_counter() - start
    ray.shutdown()
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", default="pose-prop,sot")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    os.environ["UNITRACK_FEATURE_CACHE"] = "off"
    tasks = args.tasks.split(",")
    models = [ModelSpec.parse("imagenet-lite0"), ModelSpec.parse("random")]
    rows = {"pool": [], "ray": []}
    cards = {}
    for _ in range(args.repeats):
        for backend in ("pool", "ray"):  # alternate, so load drifts hit both
            seconds, cells, card = _timed(backend, tasks, args.workers, models)
            rows[backend].append(cells / seconds * 60)
            cards[backend] = card
    startup = _ray_startup(args.workers)
    pool, ray_rate = max(rows["pool"]), max(rows["ray"])
    same = all(a["combined"] == b["combined"] and a["per_sequence"] == b["per_sequence"]
               for a, b in zip(cards["pool"]["rows"], cards["ray"]["rows"], strict=True))
    print(f"tasks {tasks}, {len(models)} models, {args.workers} workers / CPUs, "
          f"{cells} cells, best of {args.repeats}")
    print(f"pool: {pool:7.1f} cells/min")
    print(f"ray : {ray_rate:7.1f} cells/min   ratio ray/pool = {ray_rate / pool:.2f}")
    print(f"ray start-up (init + first task): {startup:.1f} s")
    print(f"scorecards equal: {same}")


if __name__ == "__main__":
    main()

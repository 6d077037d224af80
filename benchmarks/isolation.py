"""What playing ``--workers 1`` in a supervised child process costs, against playing in-process.

``unitrack evaluate`` plays ``--workers 1`` in one child process that the CLI watches (issue
43: a step stuck in C code holding the GIL, a segfault or a ``close()`` that never returns
then ends only what it was doing); ``--in-process`` plays as before. Prints, side by side, the
wall time of whole CLI runs both ways (best and median of ``--repeats``, alternated), the
overhead per run and per sequence, and whether the result files are byte-identical. It also
prints the in-process watchdog's cost per step (a kernel timer re-armed after each step).

Usage: python benchmarks/isolation.py [--env UniTrack/MOT16-v0] [--agent iou] [--repeats 5]
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

from unitrack_env.evaluation.watchdog import StepWatchdog


def evaluate(env: str, agent: str, out: Path, in_process: bool) -> float:
    """Wall seconds of one ``unitrack evaluate`` run in a fresh interpreter."""
    command = [sys.executable, "-m", "unitrack_env.evaluation.cli", "evaluate", "--env", env,
               "--agent", agent, "--out", str(out), "--overwrite", "--quiet",
               "--format", "json"]
    start = time.perf_counter()
    subprocess.run(command + (["--in-process"] if in_process else []), check=True,
                   capture_output=True, env=os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)})
    return time.perf_counter() - start


def result_bytes(out: Path) -> dict[str, bytes]:
    """The result files and the records' digests (seconds and FPS vary from run to run)."""
    files = {str(p.relative_to(out)): p.read_bytes() for p in sorted((out / "data").rglob("*"))
             if p.is_file()}
    for record in sorted((out / "sequences").glob("*.json")):
        data = json.loads(record.read_text())
        files[record.name] = json.dumps([data["digest"], data["results"]]).encode()
    return files


def beat_cost(steps: int) -> tuple[float, float]:
    """Microseconds per ``beat()``: with the kernel timer (main thread), without (a thread)."""
    costs = []
    for use_timer in (True, False):
        with StepWatchdog(300.0) as watchdog:
            watchdog._signals = watchdog._signals and use_timer  # without: the thread alone
            watchdog.start("x")
            start = time.perf_counter()
            for _ in range(steps):
                watchdog.beat()
            costs.append((time.perf_counter() - start) / steps * 1e6)
            watchdog.stop()
    return costs[0], costs[1]


def main() -> None:
    """Print the comparison."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env", default="UniTrack/MOT16-v0")
    parser.add_argument("--agent", default="iou")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    seconds: dict[bool, list[float]] = {True: [], False: []}
    with tempfile.TemporaryDirectory() as tmp:
        outs = {mode: Path(tmp) / ("here" if mode else "child") for mode in (True, False)}
        for _ in range(args.repeats):
            for mode in (True, False):  # alternated, so that load changes hit both alike
                seconds[mode].append(evaluate(args.env, args.agent, outs[mode], mode))
        identical = result_bytes(outs[True]) == result_bytes(outs[False])
        sequences = len(list((outs[True] / "sequences").glob("*.json")))
    print(f"{args.env}, agent {args.agent}, {sequences} sequence(s), {args.repeats} runs each")
    print(f"{'mode':<26}{'best s':>9}{'median s':>10}")
    for mode, label in ((True, "in-process (--in-process)"), (False, "supervised child")):
        print(f"{label:<26}{min(seconds[mode]):>9.2f}{statistics.median(seconds[mode]):>10.2f}")
    extra = statistics.median(seconds[False]) - statistics.median(seconds[True])
    print(f"overhead of the child: {extra:+.2f} s per run (median), "
          f"{extra / max(1, sequences):+.2f} s per sequence")
    print(f"result files byte-identical: {'yes' if identical else 'NO'}")
    timer, thread = beat_cost(100_000)
    print(f"watchdog beat(): {timer:.2f} us per step with the kernel timer, "
          f"{thread:.2f} us with the thread alone")


if __name__ == "__main__":
    main()

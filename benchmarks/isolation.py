"""What playing ``--workers 1`` in a supervised child process costs, against playing in-process.

``unitrack evaluate`` plays ``--workers 1`` in one child process that the CLI watches (issue
43: a step stuck in C code holding the GIL, a segfault or a ``close()`` that never returns
then ends only what it was doing); ``--in-process`` plays as before. Prints, side by side, the
wall time of whole CLI runs both ways (best and median of ``--repeats``, alternated), over
every sequence and over the first one alone; the child's overhead per run, and per extra
sequence (the difference between the two: the child keeps its environment and agent, so a
sequence adds only heartbeats); and whether the result files are byte-identical. It also
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

from unitrack_env.evaluation.run.watchdog import StepWatchdog


def evaluate(env: str, agent: str, out: Path, in_process: bool, *extra: str) -> float:
    """Wall seconds of one ``unitrack evaluate`` run in a fresh interpreter."""
    command = [sys.executable, "-m", "unitrack_env.evaluation.cli", "evaluate", "--env", env,
               "--agent", agent, "--out", str(out), "--overwrite", "--quiet",
               "--format", "json", *extra]
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
    seconds: dict[tuple[bool, bool], list[float]] = {}
    modes = [(here, one) for one in (False, True) for here in (True, False)]
    with tempfile.TemporaryDirectory() as tmp:
        outs = {mode: Path(tmp) / f"{mode[0]}-{mode[1]}" for mode in modes}
        first = ""
        for _ in range(args.repeats):
            for here, one in modes:  # alternated, so that load changes hit every mode alike
                if one and not first:
                    first = sorted((outs[True, False] / "sequences").glob("*.json"))[0].stem
                extra = ("--sequences", first) if one else ()
                seconds.setdefault((here, one), []).append(
                    evaluate(args.env, args.agent, outs[here, one], here, *extra))
        identical = result_bytes(outs[True, False]) == result_bytes(outs[False, False])
        sequences = len(list((outs[True, False] / "sequences").glob("*.json")))
    median = {mode: statistics.median(times) for mode, times in seconds.items()}
    print(f"{args.env}, agent {args.agent}, {sequences} sequence(s), {args.repeats} runs each")
    print(f"{'mode':<26}{'sequences':>10}{'best s':>9}{'median s':>10}")
    for (here, one), times in seconds.items():
        label = "in-process (--in-process)" if here else "supervised child"
        print(f"{label:<26}{1 if one else sequences:>10}{min(times):>9.2f}"
              f"{statistics.median(times):>10.2f}")
    per_run = median[False, False] - median[True, False]
    per_sequence = (per_run - (median[False, True] - median[True, True])) / max(1, sequences - 1)
    print(f"overhead of the child: {per_run:+.2f} s per run of {sequences} sequences (median), "
          f"{per_sequence:+.2f} s per extra sequence")
    print(f"result files byte-identical: {'yes' if identical else 'NO'}")
    timer, thread = beat_cost(100_000)
    print(f"watchdog beat(): {timer:.2f} us per step with the kernel timer, "
          f"{thread:.2f} us with the thread alone")


if __name__ == "__main__":
    main()

"""Scorecard wall time: this checkout against an older commit, side by side, and the ETA.

Runs ``unitrack scorecard`` with the same arguments from a ``git worktree`` of the old commit
(torch-only; default ``../wt-h24-base``, made with ``git worktree add ../wt-h24-base da65454``)
and from this checkout, alternating (``--repeats``), or both at once (``--concurrent``: on a
machine shared with other jobs, both then see the same load). Each run starts with empty
feature and runtime caches (a first run, as a new user sees it). Prints the wall times, their
ratio (and of the CPU seconds, the fairer figure on a machine shared with other jobs), the
largest difference between the two tables per column, and how the ETA of this
checkout's run compared with its real duration (after 1 s, at 10%, 50% and 90% of the run).

``--compare OLD_OUT NEW_OUT`` instead compares two finished or partly finished output folders
cell by cell (the seconds each sequence record holds), for runs too long to wait for.

    PYTHONPATH=$PWD python benchmarks/scorecard_speed.py --data ../shared/data --concurrent
    PYTHONPATH=$PWD python benchmarks/scorecard_speed.py --tasks pose-prop --workers 2
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _child(args: argparse.Namespace) -> None:
    """This checkout's scorecard, logging every ETA estimate (time, seconds left)."""
    from unitrack_env.evaluation.scorecard import card as sc
    from unitrack_env.evaluation.scorecard.plan import ModelSpec

    start = time.monotonic()
    log: list[tuple[float, float]] = []

    def estimate(left: float) -> None:  # written as it comes, for a run still going
        log.append((time.monotonic() - start, left))
        Path(args.eta_log).write_text(json.dumps({"total": None, "estimates": log}))

    sc.scorecard([ModelSpec.parse(m) for m in args.model], out=args.out,
                 tasks=args.tasks.split(",") if args.tasks else None, data=args.data,
                 workers=args.workers, on_estimate=estimate)
    total = time.monotonic() - start
    Path(args.eta_log).write_text(json.dumps({"total": total, "estimates": log}))


def _command(args: argparse.Namespace, which: str, out: Path, eta_log: Path) -> list[str]:
    models = [x for m in args.model for x in ("--model", m)]
    rest = [*(["--data", str(Path(args.data).resolve())] if args.data else []),
            *(["--tasks", args.tasks] if args.tasks else []), "--workers", str(args.workers)]
    if which == "old":
        return [str(Path(sys.executable).parent / "unitrack"), "scorecard", *models, *rest,
                "--out", str(out), "--quiet"]
    return [sys.executable, __file__, "--child", *models, *rest, "--out", str(out),
            "--eta-log", str(eta_log)]


def _start(args: argparse.Namespace, which: str, scratch: Path) -> tuple[subprocess.Popen, float]:
    root = Path(args.old).resolve() if which == "old" else REPO
    env = dict(os.environ, PYTHONPATH=str(root),
               UNITRACK_FEATURE_CACHE=str(scratch / which / "features"),
               UNITRACK_RUNTIME_CACHE=str(scratch / which / "runtime"),
               XDG_CACHE_HOME=str(scratch / which / "xdg"))
    env.pop("UNITRACK_RUNTIME", None)  # each commit's own default
    (scratch / which).mkdir(parents=True, exist_ok=True)
    command = _command(args, which, scratch / which / "out", scratch / which / "eta.json")
    return subprocess.Popen(["nice", "-n", "5", *command], cwd=root, env=env,
                            stdout=subprocess.DEVNULL), time.monotonic()


def _table_difference(old: Path, new: Path) -> dict[str, float]:
    """Largest absolute difference per (task, head, metric) between two scorecards."""
    rows = [{(r["model"], r["task"], r["head"]): r["combined"] for r in
             json.loads((path / "scorecard.json").read_text())["rows"]} for path in (old, new)]
    worst: dict[str, float] = {}
    for key, metrics in rows[0].items():
        for name, value in metrics.items():
            other = rows[1].get(key, {}).get(name)
            if value is not None and other is not None:
                column = f"{key[1]} {key[2]} {name}"
                worst[column] = max(worst.get(column, 0.0), abs(value - other))
    return worst


def _eta_report(path: Path) -> None:
    log = json.loads(path.read_text())
    total, estimates = log["total"], log["estimates"]
    for fraction in (0.0, 0.1, 0.5, 0.9):
        at = max(1.0, fraction * total) if fraction else 0.0
        seen = [e for e in estimates if e[0] <= at] or estimates[:1]
        when, left = seen[-1]
        print(f"  ETA at {when:7.1f} s predicted the end at {when + left:7.1f} s; real "
              f"{total:7.1f} s ({(when + left) / total - 1:+.0%})")


def compare_folders(old: Path, new: Path) -> None:
    """Per-cell seconds of the cells both folders finished (sequence records)."""
    def seconds(out: Path) -> dict[str, float]:
        return {str(p.relative_to(out)): json.loads(p.read_text())["seconds"]
                for p in (out / "cells").rglob("*.json") if "sequences" in p.parts}

    a, b = seconds(old), seconds(new)
    common = sorted(set(a) & set(b))
    for name in common:
        print(f"{name:70s} {a[name]:9.1f} s {b[name]:9.1f} s  x{a[name] / max(b[name], 1e-9):.2f}")
    old_sum, new_sum = sum(a[n] for n in common), sum(b[n] for n in common)
    print(f"{len(common)} common cells: old {old_sum:.0f} s, new {new_sum:.0f} s, "
          f"ratio x{old_sum / max(new_sum, 1e-9):.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", action="append")
    parser.add_argument("--data")
    parser.add_argument("--tasks")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--old", default=str(REPO.parent / "wt-h24-base"))
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--concurrent", action="store_true")
    parser.add_argument("--only", choices=("old", "new"))
    parser.add_argument("--compare", nargs=2, type=Path)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    parser.add_argument("--eta-log", help=argparse.SUPPRESS)
    args = parser.parse_args()
    args.model = args.model or ["imagenet-lite0", "random"]
    if args.child:
        return _child(args)
    if args.compare:
        return compare_folders(*args.compare)
    kinds = [args.only] if args.only else ["old", "new"]
    for repeat in range(args.repeats):
        scratch = Path(tempfile.mkdtemp(prefix="scorecard-speed-"))
        batches = [kinds] if args.concurrent else [[k] for k in kinds]
        walls: dict[str, float] = {}
        cpu: dict[str, float] = {}
        for batch in batches:
            started = {k: _start(args, k, scratch) for k in batch}
            kinds_of = {process.pid: (k, began) for k, (process, began) in started.items()}
            while kinds_of:  # whichever ends first; CPU seconds include its workers
                pid, status, usage = os.wait4(-1, 0)
                if pid not in kinds_of:
                    continue
                kind, began = kinds_of.pop(pid)
                if status != 0:
                    raise SystemExit(f"{kind} scorecard failed (wait status {status})")
                walls[kind] = time.monotonic() - began
                cpu[kind] = usage.ru_utime + usage.ru_stime
        print(f"run {repeat + 1}: " + ", ".join(f"{k} {walls[k]:.0f} s wall, {cpu[k]:.0f} s CPU"
                                                 for k in walls))
        if len(walls) == 2:
            print(f"  old / new = x{walls['old'] / walls['new']:.2f} wall, "
                  f"x{cpu['old'] / cpu['new']:.2f} CPU")
            worst = _table_difference(scratch / "old" / "out", scratch / "new" / "out")
            for column, diff in sorted(worst.items(), key=lambda kv: -kv[1])[:8]:
                print(f"  table moved {diff:.4f} in {column}")
        if "new" in walls:
            _eta_report(scratch / "new" / "eta.json")
        print(f"  folders: {scratch}")


if __name__ == "__main__":
    main()

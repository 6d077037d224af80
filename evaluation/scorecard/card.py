"""The paper's question in one command: how well does a representation track, on every task?

``unitrack scorecard`` plays every task's UniTrack head with one shared appearance model per
row (one per ``--model``) and each task's appearance-free baseline, over every sequence of the
data it finds, and reports the metrics of the paper's Table 2 and a radar chart
(:mod:`unitrack_env.evaluation.scorecard.radar`).

:func:`play_cell` plays each cell (model, task, head, sequence) wherever the backend runs it
and returns its files as bytes; the driver writes them into
``<out>/cells/<model>/<task>/<head>/`` (the runner's layout), so finished cells survive an
interruption and no shared file system is needed. The runner then scores each folder, reusing
every unchanged cell: the numbers are exactly those of ``unitrack evaluate``. As in Table 2,
association heads run without motion ("motion cues are discarded to better highlight
distinctions between different representations"; ``motion=True`` keeps them).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import gymnasium as gym

import unitrack_env
from unitrack_env.io import atomic_write_bytes, atomic_write_text

from ..run.backends import make_backend
from ..run.ownership import hold_folder
from ..run.resume import RunMismatch, restamp_sequences, stale_sequences
from ..run.runner import RunFailed, check_out_folder, run
from ..run.workers import SequenceFailure, refuse_unguarded_script
from .eta import megapixel_gflops, schedule, setup_seconds
from .flops import estimated_megapixel_gflops
from .plan import BASELINE, TASKS, Cell, ModelSpec, Source, plan
from .radar import draw_radar
from .table import markdown_table, ran_on, rows_csv


def play_cell(cell: Cell, threads: int | None = None) -> dict[str, Any]:
    """Play one cell in a scratch folder; return its files (as bytes) and its metrics.

    Runs where the backend puts it (another process or machine); nothing is written to the
    driver's output folder from here.
    """
    started = time.monotonic()
    if threads:
        import torch  # lazy: start-up cost (+1.4 s; the baselines' cells never load torch)

        torch.set_num_threads(threads)
    with (tempfile.TemporaryDirectory(prefix="unitrack-cell-") as scratch,
          warnings.catch_warnings(record=True) as caught):
        warnings.simplefilter("always")  # every cell reports its own; the driver shows each once
        out = Path(scratch)
        report = run(cell.env_id, cell.agent, out=out, env_kwargs=cell.env_kwargs,
                     agent_kwargs=cell.agent_kwargs, sequences=[cell.sequence], progress=False)
        # The scratch folder holds this one sequence: every result file and its record.
        files = {str(path.relative_to(out)): path.read_bytes()
                 for sub in ("data", "sequences") for path in (out / sub).rglob("*")
                 if path.is_file()}
        metrics = report.scores.per_sequence.get(cell.sequence, {}) if report.scores else {}
    return {"files": files, "metrics": metrics, "seconds": time.monotonic() - started,
            "warnings": sorted({str(w.message) for w in caught})}


def store_cell(out: Path, cell: Cell, payload: dict[str, Any]) -> None:
    """Write a played cell's files into its run folder (data first, the record last)."""
    folder = out / "cells" / cell.folder
    files = payload["files"]
    for relative in sorted(files, key=lambda name: name.startswith("sequences")):
        atomic_write_bytes(folder / relative, files[relative])


def cell_done(out: Path, cell: Cell) -> bool:
    """Whether the cell's record is in the output folder."""
    return (out / "cells" / cell.folder / "sequences" / f"{cell.sequence}.json").is_file()


def _other_model(folder: Path, difference: str, model: str) -> ValueError:
    """The error for a cell folder that holds another model's cells under this label."""
    return ValueError(f"{folder} holds the cells of another model labelled {model!r} "
                      f"({difference}); give this model another label= or use another --out")


def cells_to_play(out: Path, cells: Sequence[Cell]) -> list[Cell]:
    """The cells to play: those without a record in ``out``, and stale stored ones.

    A stored cell is stale when its data or code changed since it was played; the runner
    would replay it while the card is scored, so it goes to the workers instead.
    """
    stored: dict[str, list[Cell]] = {}
    for cell in cells:
        if cell_done(out, cell):
            stored.setdefault(cell.folder, []).append(cell)
    stale: set[tuple[str, str]] = set()
    for folder, members in stored.items():
        first = members[0]
        try:
            stale |= {(folder, name) for name in stale_sequences(
                first.env_id, first.agent, out / "cells" / folder, env_kwargs=first.env_kwargs,
                agent_kwargs=first.agent_kwargs, sequences=[c.sequence for c in members])}
        except RunMismatch as exc:  # refused before any cell overwrites another model's
            raise _other_model(exc.out, exc.difference, first.model) from None
    return [c for c in cells if not cell_done(out, c) or (c.folder, c.sequence) in stale]


def restamp_cells(out: Path, cells: Sequence[Cell]) -> dict[str, list[str] | str]:
    """Keep stored cells whose only change is the agent's code (``--restamp``).

    Returns, for each stale stored cell, the changed code files (kept) or why it cannot be
    kept (:mod:`.restamp`); nothing is played.
    """
    stored: dict[str, list[Cell]] = {}
    for cell in cells:
        if cell_done(out, cell):
            stored.setdefault(cell.folder, []).append(cell)
    outcome: dict[str, list[str] | str] = {}
    for folder, members in stored.items():
        first, by_name = members[0], {c.sequence: c for c in members}
        try:
            kept = restamp_sequences(first.env_id, first.agent, out / "cells" / folder,
                                     env_kwargs=first.env_kwargs,
                                     agent_kwargs=first.agent_kwargs, sequences=list(by_name))
        except RunMismatch as exc:
            raise _other_model(exc.out, exc.difference, first.model) from None
        outcome |= {by_name[name].label: result for name, result in kept.items()}
    return outcome


def _finite(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def combine(out: Path, cells: list[Cell], sources: dict[str, Source]) -> dict[str, Any]:
    """Score every (model, task, head) folder with the runner; the scorecard's content."""
    groups: dict[tuple[str, str, str], list[Cell]] = {}
    for cell in cells:
        groups.setdefault((cell.model, cell.task, cell.head), []).append(cell)
    rows = []
    runtimes: dict[str, int] = {}
    unrecorded = 0
    for (model, task, head), members in groups.items():
        first = members[0]
        try:
            report = run(first.env_id, first.agent, out=out / "cells" / first.folder,
                         env_kwargs=first.env_kwargs, agent_kwargs=first.agent_kwargs,
                         sequences=[c.sequence for c in members], progress=False)
        except RunMismatch as exc:
            raise _other_model(exc.out, exc.difference, model) from None
        scores = report.scores
        for cell in members if model != BASELINE else ():
            labels = report.records[cell.sequence].runtimes
            unrecorded += labels is None
            for label in labels or ():
                runtimes[label] = runtimes.get(label, 0) + 1
        rows.append({
            "model": model, "task": task, "head": head, "agent": first.agent,
            "env_id": first.env_id, "agent_kwargs": first.agent_kwargs,
            "source": asdict(sources[task]),
            "combined": {k: _finite(v) for k, v in (scores.combined if scores else {}).items()},
            "per_sequence": {s: {k: _finite(v) for k, v in m.items()}
                             for s, m in (scores.per_sequence if scores else {}).items()},
        })
    return {"version": 1, "unitrack_env": unitrack_env.__version__,
            "models": sorted({c.model for c in cells if c.model != BASELINE},
                             key=[c.model for c in cells].index),
            "tasks": list(dict.fromkeys(c.task for c in cells)),
            "sources": {task: asdict(source) for task, source in sources.items()},
            "rows": rows, "runtime": ran_on(runtimes, unrecorded)}


def write_outputs(out: Path, card: dict[str, Any], *, radar_scale: str = "rank") -> list[Path]:
    """``scorecard.json``, ``.csv``, ``.md`` and (with matplotlib) the radar chart PNG/SVG."""
    atomic_write_text(out / "scorecard.json", json.dumps(card, indent=2, allow_nan=False))
    atomic_write_text(out / "scorecard.csv", rows_csv(card))
    atomic_write_text(out / "scorecard.md", markdown_table(card))
    written = [out / "scorecard.json", out / "scorecard.csv", out / "scorecard.md"]
    written += draw_radar(card, out / "scorecard", scale=radar_scale)
    return written


def _checked_request(models: Sequence[ModelSpec], tasks: Sequence[str] | None,
                     data: str | os.PathLike | None) -> tuple[list[str], Path | None]:
    """Task names and data folder; refused if wrong (models are checked by :func:`_gflops`)."""
    names = list(tasks) if tasks else list(TASKS)
    unknown = [t for t in names if t not in TASKS]
    if unknown:
        raise ValueError(f"unknown tasks {unknown}; valid: {', '.join(TASKS.every())}")
    if not models:
        raise ValueError("give at least one --model (e.g. imagenet-lite0)")
    labels = [m.name for m in models]
    if len(set(labels)) != len(labels):
        raise ValueError(f"two models have the same label {labels}; add label= to one")
    data_path = Path(data).expanduser() if data is not None else None
    if data_path is not None and not data_path.is_dir():
        raise ValueError(f"--data {data} is not a folder")
    return names, data_path


def _gflops(models: Sequence[ModelSpec], names: list[str]) -> dict[str, dict[str, float]]:
    """Each model's GFLOP per megapixel per task, counted on the built network.

    Loads every model: a bad checkpoint or layer is one error now, not one per cell later.
    """
    # lazy: start-up cost (the appearance package loads torch, +1.4 s: the first ETA comes first)
    from unitrack_env.agents.appearance.weights import load_weights

    gflops: dict[str, dict[str, float]] = {}
    for m in models:
        loaded = load_weights(m.weights, arch=m.arch, layer=m.layer, stride=m.stride)
        gflops[m.name] = megapixel_gflops(loaded.module, loaded.layers, names)
    return gflops


def _check_environments(sources: dict[str, Source]) -> None:
    """Make each task's environment once, before any cell plays.

    What an environment refuses (a missing scoring library, a bad option) is then one error
    at the door, not one per cell.
    """
    for source in sources.values():
        gym.make(source.env_id, **({"root": source.root} if source.root else {})).close()


def _first_estimate(out: Path, models: Sequence[ModelSpec], names: list[str],
                    data: Path | None, *, slots: int, motion: bool, runtime: str | None,
                    on_estimate: Callable[[float], None]) -> None:
    """The ETA before torch is imported or synthetic data are written.

    Frame counts from the benchmarks (or the synthetic specs), GFLOP from
    :mod:`.flops` and the time to set up (:func:`~.eta.setup_seconds`);
    the exact ETA follows when the cells start.
    """
    cells, _, pending = plan(models, names, data, motion=motion, runtime=runtime,
                             generate=False)
    todo = [c for c in cells if not cell_done(out, c)]
    gflops = {m.name: estimated_megapixel_gflops(m.weights, m.arch, m.layer, m.stride, names)
              for m in models}
    # "auto" is taken to find a compiled runtime; the exact choice (torch's import) follows.
    chosen = runtime or os.environ.get("UNITRACK_RUNTIME", "").strip() or "auto"
    _, clock = schedule(todo, BASELINE, slots, chosen == "torch", gflops)
    # Each task has one baseline head: its cells hold the task's sequences once.
    generated = sum(c.frames for c in cells if c.task in pending and c.model == BASELINE)
    on_estimate(setup_seconds(generated) + clock.remaining())


def _slots(backend: str, workers: int) -> int:
    """Cells running at once."""
    return 1 if backend == "pool" and workers <= 1 else workers


def _play_all(out: Path, cells: list[Cell], *, backend: str, workers: int, address: str | None,
              on_progress: Callable[[int, int, Cell | None], None] | None,
              on_estimate: Callable[[float], None] | None = None,
              torch_runtime: bool = False, gflop_per_mp: dict | None = None) -> None:
    """Play and store every cell not done yet, longest first; each warning is shown once.

    ``on_estimate`` gets the seconds left (:class:`~.eta.CellClock`) at the start
    and after every cell; ``gflop_per_mp`` is :func:`~.eta.schedule`'s.
    """
    todo, clock = schedule(cells_to_play(out, cells), BASELINE,
                           _slots(backend, workers), torch_runtime, gflop_per_mp)
    position = {id(cell): i for i, cell in enumerate(todo)}
    done = len(cells) - len(todo)
    if on_progress is not None:
        on_progress(done, len(cells), None)
    if on_estimate is not None:
        on_estimate(clock.remaining())
    failures: dict[str, str] = {}
    shown: set[str] = set()
    with make_backend(backend, workers=workers, address=address) as run_cells:
        for cell, payload in run_cells(play_cell, todo):
            if isinstance(payload, BaseException):
                failures[cell.label] = SequenceFailure.describe(payload)
            else:
                for text in payload.get("warnings", ()):
                    if text not in shown:  # the same data warning from every model and head
                        shown.add(text)
                        warnings.warn(text, UserWarning, stacklevel=3)
                store_cell(out, cell, payload)
                done += 1
            seconds = None if isinstance(payload, BaseException) else payload.get("seconds")
            clock.finished(position.get(id(cell), 0), seconds)
            if on_progress is not None:
                on_progress(done, len(cells), cell)
            if on_estimate is not None:
                on_estimate(clock.remaining())
    if failures:
        raise RunFailed(failures, out)


def scorecard(models: Sequence[ModelSpec], *, out: str | os.PathLike,
              tasks: Sequence[str] | None = None, data: str | os.PathLike | None = None,
              backend: str = "pool", workers: int = 1, address: str | None = None,
              motion: bool = False, runtime: str | None = None, radar_scale: str = "rank",
              on_progress: Callable[[int, int, Cell | None], None] | None = None,
              on_estimate: Callable[[float], None] | None = None,
              restamp: bool = False,
              on_restamp: Callable[[str, list[str] | str], None] | None = None,
              ) -> dict[str, Any]:
    """Play, store and score every cell; write the outputs; return the scorecard.

    Args:
        models: the appearance models (rows).
        out: output folder; rerunning with the same folder reuses finished cells.
        tasks: task names (default: all of :data:`TASKS`).
        data: a folder holding benchmark folders (``MOT17/``, ``DAVIS/``...); tasks without
            one use the embedded synthetic data (marked as such everywhere).
        backend: ``"pool"`` (local processes) or ``"ray"``.
        workers: processes of the pool (Ray uses the cluster's CPUs).
        address: Ray cluster address (``auto``, ``ray://host:port``; None: a local Ray).
        motion: keep motion cues in the association heads (the paper's Table 2 drops them).
        runtime: ``torch``, ``openvino``, ``onnxruntime`` or ``auto`` (None:
            ``$UNITRACK_RUNTIME``, else ``auto``).
        radar_scale: ``"rank"`` (the paper's Figure 1) or ``"value"``.
        on_progress: called with (cells done, cells in all, the cell just finished).
        on_estimate: called with the estimated seconds left: first within about a second
            (before the models load or synthetic data are written), then when the cells
            start and after each cell.
        restamp: keep stored cells whose only change is the agent's code (:mod:`.restamp`).
        on_restamp: gets each such cell's label and changed files, or why it is replayed.
    """
    names, data_path = _checked_request(models, tasks, data)
    out = Path(out)
    if on_estimate is not None:
        _first_estimate(out, models, names, data_path, slots=_slots(backend, workers),
                        motion=motion, runtime=runtime, on_estimate=on_estimate)
    gflops = _gflops(models, names)
    if backend == "pool" and workers > 1:
        refuse_unguarded_script()
    # lazy: start-up cost (the appearance package loads torch, +1.4 s: the first ETA comes first)
    from unitrack_env.agents.appearance.runtime import resolve_runtime

    chosen = resolve_runtime(runtime)  # not installed: one error now, not one per cell
    check_out_folder(out)
    with hold_folder(out, "scorecard"):  # one scorecard at a time (each cell run locks too)
        cells, sources, _ = plan(models, names, data_path, motion=motion, runtime=runtime)
        _check_environments(sources)
        for label, result in (restamp_cells(out, cells) if restamp else {}).items():
            (on_restamp or (lambda *_: None))(label, result)
        _play_all(out, cells, backend=backend, workers=workers, address=address,
                  on_progress=on_progress, on_estimate=on_estimate,
                  torch_runtime=chosen == "torch", gflop_per_mp=gflops)
        card = combine(out, cells, sources)
        write_outputs(out, card, radar_scale=radar_scale)
    return card

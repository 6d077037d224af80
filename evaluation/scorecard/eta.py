"""What a scorecard cell costs, in what order cells run, and when the whole card will end.

Before a cell runs, its cost is estimated from its frame count, the network input its head
feeds the backbone per frame and the model's GFLOP per megapixel of that input
(:func:`cell_cost`, constants measured on the project's 2-core CPU), scaled by the threads
each worker gets. Cells are then played longest first (:func:`longest_first`), so that the
last cells of a pool are short and no worker idles while another finishes a long sequence.

:class:`CellClock` turns the estimates into an ETA the moment the card starts, and corrects
them with the measured speed as cells finish: each (model, task/head) group's estimates are
scaled by the ratio of measured to estimated seconds of its finished cells (before any of its
cells finished, by that of its model's finished cells, else of all). The ETA is the end of a
list schedule of the remaining cells over the workers, counting the time the running cells
have already spent. The scorecard's first estimate, made before the models load
(:mod:`.flops`), adds the seconds still to come before the cells start
(:func:`setup_seconds`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .plan import TASKS

#: Network input per frame of a task whose benchmark declares no scorecard column (each
#: column states its own ``input_size``: SOT feeds three 520 x 520 scale crops; VOS the
#: DAVIS 480p frame; MOT, MOTS, PoseTrack and VIS the 1088 x 608 letterbox; pose propagation
#: the JHMDB 320 x 240 frame).
DEFAULT_INPUT: tuple[int, int, int] = (1, 512, 512)

#: Backbone seconds per frame = megapixels x (PIXEL_SECONDS + GFLOP per megapixel x
#: GFLOP_SECONDS): OpenVINO, 1 worker of 2 cores, fitted to the fixture scorecard's SOT cells
#: (EfficientNet-Lite0, 24 GFLOP/MP: 0.25 s/MP; ResNet-18 layer3, 105 GFLOP/MP: 0.65 s/MP).
#: Eager torch is about TORCH_FACTOR times slower. Per frame besides the backbone (decoding,
#: the head itself; label propagation dominates VOS and pose propagation): the column's
#: ``head_seconds``, else ASSOCIATION_SECONDS.
#: Threads of the calibration, and how a cell's time grows with fewer: (2 / threads) ** 0.75
#: (the synthetic scorecard's cells took 1.6-1.7x longer on 1 thread of 2 workers).
CALIBRATION_THREADS: int = 2
THREAD_SCALING: float = 0.75
PIXEL_SECONDS: float = 0.13
GFLOP_SECONDS: float = 0.005
LITE0_GFLOP_PER_MP: float = 24.3
ASSOCIATION_SECONDS: float = 0.05
BASELINE_SECONDS: float = 0.01
TORCH_FACTOR: float = 4.0
#: Fixed cost of a cell (a process starting a sequence: the environment, the model; for a
#: baseline, the environment only).
CELL_SECONDS: float = 2.0
BASELINE_CELL_SECONDS: float = 0.2
#: Between the scorecard's first estimate and the exact one (:func:`setup_seconds`):
#: importing torch, building and loading the models, reading the data to plan; and per
#: annotated frame of an embedded synthetic data set written on first use (its sequences
#: without ground truth are written too; benchmarks/scorecard_first_eta.py times it).
SETUP_SECONDS: float = 3.0
SYNTHETIC_FRAME_SECONDS: float = 0.01


def input_size(task: str) -> tuple[int, int, int]:
    """``(images, height, width)`` per frame of ``task``'s appearance head (its column's)."""
    return TASKS[task].input_size if task in TASKS else DEFAULT_INPUT


def cell_cost(task: str, frames: int, *, appearance: bool, torch_runtime: bool = False,
              gflop_per_mp: float = LITE0_GFLOP_PER_MP) -> float:
    """Estimated seconds of one cell: ``frames`` frames of ``task``'s head.

    Args:
        task: The task name (a key of :data:`~.plan.TASKS`).
        frames: Frames of the sequence.
        appearance: Whether the head runs the appearance model (baselines do not).
        torch_runtime: The backbone runs in eager torch (slower).
        gflop_per_mp: The backbone's GFLOP per megapixel at the task's input
            (:func:`megapixel_gflops`).
    """
    if not appearance:
        return BASELINE_CELL_SECONDS + frames * BASELINE_SECONDS
    images, height, width = input_size(task)
    megapixels = images * height * width / 1e6
    backbone = megapixels * (PIXEL_SECONDS + gflop_per_mp * GFLOP_SECONDS)
    backbone *= TORCH_FACTOR if torch_runtime else 1.0
    seconds = TASKS[task].head_seconds if task in TASKS else None
    head = ASSOCIATION_SECONDS if seconds is None else seconds
    return CELL_SECONDS + frames * (backbone + head)


def setup_seconds(synthetic_frames: int = 0) -> float:
    """Estimated seconds before the cells start: the setup and the synthetic data to write.

    Args:
        synthetic_frames: Annotated frames of the synthetic data sets not generated yet.
    """
    return SETUP_SECONDS + synthetic_frames * SYNTHETIC_FRAME_SECONDS


def megapixel_gflops(module: Any, layers: tuple[str, ...], tasks: Sequence[str],
                     ) -> dict[str, float]:
    """A network's GFLOP per megapixel of each task's input (:func:`input_size`)."""
    # lazy: start-up cost (the appearance package loads torch, +1.4 s: the first ETA comes first)
    from unitrack_env.agents.appearance.architectures import network_gflops

    sizes = [input_size(task)[1:] for task in tasks]
    flops = network_gflops(module, layers, sizes)
    return {task: g / (h * w / 1e6) for task, g, (h, w) in zip(tasks, flops, sizes, strict=True)}


def longest_first(costs: Sequence[float]) -> list[int]:
    """Indices of the cells, most expensive first (ties keep the plan's order)."""
    return sorted(range(len(costs)), key=lambda i: (-costs[i], i))


@dataclass
class _Slot:
    index: int
    started: float


class CellClock:
    """ETA of a set of cells played in order by ``workers`` workers.

    Args:
        costs: Estimated seconds of each cell, in the order they are submitted.
        groups: Each cell's group (cells of a group run at a common speed).
        workers: Cells running at once.
        now: Start time (``time.monotonic()``).
    """

    def __init__(self, costs: Sequence[float], groups: Sequence[Hashable], workers: int,
                 now: float | None = None) -> None:
        self.costs = list(costs)
        self.groups = list(groups)
        self.workers = max(1, workers)
        start = time.monotonic() if now is None else now
        self._next = min(self.workers, len(self.costs))
        self._running = [_Slot(i, start) for i in range(self._next)]
        self._measured: dict[Hashable, list[float]] = {}  # group -> [measured, estimated]

    def finished(self, index: int, seconds: float | None, now: float | None = None) -> None:
        """Cell ``index`` finished after ``seconds`` of work (None: time since it started)."""
        now = time.monotonic() if now is None else now
        slot = next((s for s in self._running if s.index == index), None)
        if slot is not None:
            self._running.remove(slot)
        elif self._running:  # finished out of order: the oldest running slot frees up
            slot = self._running.pop(0)
        if seconds is None and slot is not None:
            seconds = now - slot.started
        if seconds is not None:
            pair = self._measured.setdefault(self.groups[index], [0.0, 0.0])
            pair[0] += seconds
            pair[1] += self.costs[index]
        if self._next < len(self.costs):
            self._running.append(_Slot(self._next, now))
            self._next += 1

    def _rate(self, group: Hashable) -> float:
        """Measured / estimated seconds of finished cells of the group, else of its model.

        A group is ``(model, head)``; with no finished cell of the model, every finished
        cell's ratio, else 1.
        """

        def model(g: Hashable) -> Hashable:
            return g[0] if isinstance(g, tuple) else g

        for keep in (lambda g: g == group, lambda g: model(g) == model(group), lambda g: True):
            pairs = [pair for g, pair in self._measured.items() if keep(g)]
            estimated = sum(pair[1] for pair in pairs)
            if estimated > 0:
                return sum(pair[0] for pair in pairs) / estimated
        return 1.0

    def remaining(self, now: float | None = None) -> float:
        """Seconds until the last cell ends (a list schedule over the workers)."""
        now = time.monotonic() if now is None else now
        free = [max(0.0, self.costs[s.index] * self._rate(self.groups[s.index])
                    - (now - s.started)) for s in self._running]
        free += [0.0] * (self.workers - len(free))
        for index in range(self._next, len(self.costs)):
            slot = min(range(len(free)), key=free.__getitem__)
            free[slot] += self.costs[index] * self._rate(self.groups[index])
        return max(free) if free else 0.0


def schedule(cells: Sequence[Any], baseline: str, workers: int, torch_runtime: bool = False,
             gflop_per_mp: Mapping[str, Mapping[str, float]] | None = None,
             ) -> tuple[list[Any], CellClock]:
    """Scorecard cells longest first, and the clock of their ETA.

    Args:
        cells: :class:`~unitrack_env.evaluation.scorecard.plan.Cell` objects (task, head, model,
            frames).
        baseline: The row label of the appearance-free baselines.
        workers: Cells running at once.
        torch_runtime: The appearance models run in eager torch.
        gflop_per_mp: model -> task -> its backbone's GFLOP per megapixel of the task's
            input (:func:`megapixel_gflops`; None: EfficientNet-Lite0's for every model).
    """
    # Each of the workers has cpu_count / workers threads; the constants are for 2 threads.
    threads = max(1, (os.cpu_count() or 1) // max(1, workers))
    slower = (CALIBRATION_THREADS / min(threads, CALIBRATION_THREADS)) ** THREAD_SCALING

    def cost(cell: Any) -> float:
        appearance = cell.model != baseline
        flops = gflop_per_mp[cell.model][cell.task] if appearance and gflop_per_mp else \
            LITE0_GFLOP_PER_MP
        return slower * cell_cost(cell.task, cell.frames, appearance=appearance,
                                  torch_runtime=torch_runtime, gflop_per_mp=flops)

    costs = [cost(c) for c in cells]
    order = longest_first(costs)
    ordered = [cells[i] for i in order]
    clock = CellClock([costs[i] for i in order],
                      [(c.model, f"{c.task}/{c.head}") for c in ordered], workers)
    return ordered, clock

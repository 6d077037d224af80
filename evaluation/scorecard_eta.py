"""What a scorecard cell costs, in what order cells run, and when the whole card will end.

Before a cell runs, its cost is estimated from its frame count and the network input its head
feeds the backbone per frame (:func:`cell_cost`: seconds per frame = a per-head constant plus
seconds per megapixel of input, both measured on the project's 2-core CPU). Cells are then
played longest first (:func:`longest_first`), so that the last cells of a pool are short and
no worker idles while another finishes a long sequence.

:class:`CellClock` turns the estimates into an ETA the moment the card starts, and corrects
them with the measured speed as cells finish: each (task, head) group's estimates are scaled
by the ratio of measured to estimated seconds of its finished cells (before any of its cells
finished, by the ratio over all finished cells). The ETA is the end of a list schedule of the
remaining cells over the workers, counting the time the running cells have already spent.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

#: Network input per frame, in megapixels, of each task's appearance head: SOT feeds three
#: 520 x 520 scale crops; VOS the DAVIS 480p frame; MOT, MOTS, PoseTrack and VIS the
#: 1088 x 608 letterbox; pose propagation the JHMDB 320 x 240 frame.
INPUT_MEGAPIXELS: dict[str, float] = {
    "sot": 3 * 520 * 520 / 1e6, "vos": 480 * 854 / 1e6, "mot": 1088 * 608 / 1e6,
    "mots": 1088 * 608 / 1e6, "posetrack": 1088 * 608 / 1e6, "vis": 1088 * 608 / 1e6,
    "pose-prop": 320 * 240 / 1e6,
}

#: Seconds per megapixel of backbone input (OpenVINO, 1 worker of 2 cores; eager torch is
#: about 4x this), and per frame besides the backbone (decoding, the head itself; label
#: propagation dominates VOS and pose propagation).
SECONDS_PER_MEGAPIXEL: float = 0.25
HEAD_SECONDS: dict[str, float] = {"sot": 0.02, "vos": 0.6, "pose-prop": 0.15}
ASSOCIATION_SECONDS: float = 0.05
BASELINE_SECONDS: float = 0.01
#: Slower backbone of eager torch, relative to a compiled runtime.
TORCH_FACTOR: float = 4.0
#: Fixed cost of a cell (a process starting a sequence: the environment, the model).
CELL_SECONDS: float = 2.0


def cell_cost(task: str, frames: int, *, appearance: bool, torch_runtime: bool = False) -> float:
    """Estimated seconds of one cell: ``frames`` frames of ``task``'s head.

    Args:
        task: The task name (a key of :data:`INPUT_MEGAPIXELS`).
        frames: Frames of the sequence.
        appearance: Whether the head runs the appearance model (baselines do not).
        torch_runtime: The backbone runs in eager torch (slower).
    """
    if not appearance:
        return CELL_SECONDS + frames * BASELINE_SECONDS
    megapixels = INPUT_MEGAPIXELS.get(task, 0.5)
    backbone = megapixels * SECONDS_PER_MEGAPIXEL * (TORCH_FACTOR if torch_runtime else 1.0)
    head = HEAD_SECONDS.get(task, ASSOCIATION_SECONDS)
    return CELL_SECONDS + frames * (backbone + head)


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

    def __init__(self, costs: Sequence[float], groups: Sequence[str], workers: int,
                 now: float | None = None) -> None:
        self.costs = list(costs)
        self.groups = list(groups)
        self.workers = max(1, workers)
        start = time.monotonic() if now is None else now
        self._next = min(self.workers, len(self.costs))
        self._running = [_Slot(i, start) for i in range(self._next)]
        self._measured: dict[str, list[float]] = {}  # group -> [measured, estimated]

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

    def _rate(self, group: str) -> float:
        pair = self._measured.get(group)
        if pair and pair[1] > 0:
            return pair[0] / pair[1]
        total = [sum(p[i] for p in self._measured.values()) for i in (0, 1)]
        return total[0] / total[1] if total[1] > 0 else 1.0

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


def schedule(cells: Sequence[Any], baseline: str, workers: int,
             torch_runtime: bool = False) -> tuple[list[Any], CellClock]:
    """Scorecard cells longest first, and the clock of their ETA.

    Args:
        cells: :class:`~unitrack_env.evaluation.scorecard.Cell` objects (task, head, model,
            frames).
        baseline: The row label of the appearance-free baselines.
        workers: Cells running at once.
        torch_runtime: The appearance models run in eager torch.
    """
    costs = [cell_cost(c.task, c.frames, appearance=c.model != baseline,
                       torch_runtime=torch_runtime) for c in cells]
    order = longest_first(costs)
    ordered = [cells[i] for i in order]
    clock = CellClock([costs[i] for i in order], [f"{c.task}/{c.head}" for c in ordered],
                      workers)
    return ordered, clock

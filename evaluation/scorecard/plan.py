"""What a scorecard is made of: its tasks, heads and models, each task's data, and its cells.

:func:`plan` lists every cell (model x task head x sequence) with its frame count, read
from each task's benchmark (:func:`unitrack_env.benchmarks.benchmark_for`: no environment
is made, no agent or torch imported). With ``generate=False`` the embedded synthetic data
sets are counted from their writers' specs
(:func:`unitrack_env.datasets.synthetic.cache.annotated_frames`), neither generated nor
read: the scorecard's first ETA comes from that plan, at once. The tasks, their heads and
metrics are those the registered benchmarks declare (:data:`TASKS`).
"""

from __future__ import annotations

import contextlib
import inspect
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import unitrack_env
from unitrack_env.benchmarks import benchmark_class, benchmark_for
from unitrack_env.benchmarks.views import ScorecardColumn
from unitrack_env.datasets.synthetic.cache import SpecsOnly, annotated_frames, specs_only
from unitrack_env.registration import variant, variants


@dataclass(frozen=True)
class Task(ScorecardColumn):
    """A task of the scorecard: its benchmark's ``scorecard`` column, under the task's name."""

    name: str = ""


class _Tasks(Mapping[str, Task]):
    """The scorecard's tasks, in column order, read from the registration table.

    Every registered benchmark that declares a ``scorecard`` column, rows registered at run
    time included, under the column's ``task`` name (default: the benchmark's task).
    Iterating gives the default task set; an ``opt_in`` column is left out of it but found by
    name (``TASKS[name]``, ``name in TASKS``; all: :meth:`every`).
    """

    _rows: tuple = ()
    _cached: dict[str, Task] = {}

    def _table(self) -> dict[str, Task]:
        rows = variants()
        if rows != self._rows:
            self._rows, self._cached = rows, self._read(rows)
        return self._cached

    @staticmethod
    def _read(rows: tuple) -> dict[str, Task]:
        found: dict[str, Task] = {}
        for row in rows:
            cls = benchmark_class(row) if row.scoring else None
            column = cls.scorecard if cls is not None else None
            name = column and (column.task or cls.task)
            if column is not None and name not in found:
                found[name] = Task(**{f.name: getattr(column, f.name)
                                      for f in fields(column)}, name=name)
        return dict(sorted(found.items(), key=lambda item: item[1].order))

    def __getitem__(self, name: str) -> Task:
        return self._table()[name]

    def __iter__(self) -> Iterator[str]:
        return iter([name for name, task in self._table().items() if not task.opt_in])

    def __len__(self) -> int:
        return len(list(iter(self)))

    def every(self) -> list[str]:
        """Every task's name, opt-in columns included, in column order."""
        return list(self._table())


#: The tasks in the paper's Table 2 order, then the appendix tasks (and a user's own).
TASKS: _Tasks = _Tasks()
#: Row label of the appearance-free baselines.
BASELINE = "baseline (no appearance)"


@dataclass(frozen=True)
class ModelSpec:
    """One appearance model (a scorecard row).

    ``weights[,arch=..][,layer=..][,stride=..][,label=..]`` (``stride``: ViT only).
    """

    weights: str
    arch: str | None = None
    layer: str | None = None
    label: str = ""
    stride: str | None = None

    @classmethod
    def parse(cls, text: str) -> ModelSpec:
        """Read ``imagenet-lite0``, ``random,arch=resnet18`` or ``moco.pth,layer=layer3``."""
        weights, *options = [part.strip() for part in text.split(",")]
        values: dict[str, str] = {}
        for option in options:
            key, sep, value = option.partition("=")
            if not sep or key not in ("arch", "layer", "stride", "label"):
                raise ValueError(f"--model '{text}': options are arch=, layer=, stride= and "
                                 "label= "
                                 f"(comma-separated after the weights); got '{option}'")
            values[key] = value
        if not weights:
            raise ValueError(f"--model '{text}' names no weights")
        return cls(weights, values.get("arch"), values.get("layer"), values.get("label", ""),
                   values.get("stride"))

    @property
    def name(self) -> str:
        """The row label: ``label=``, or the weights (a file's stem) with arch and layer."""
        if self.label:
            return self.label
        base = Path(self.weights).stem if os.sep in self.weights or "." in self.weights \
            else self.weights
        stride = f"s{self.stride}" if self.stride else ""
        return "+".join(part for part in (base, self.arch, self.layer, stride) if part)

    def agent_kwargs(self) -> dict[str, Any]:
        """The appearance options every UniTrack head takes.

        A checkpoint file is given by its absolute path: the same file typed from another
        folder is the same run (and resumes).
        """
        path = Path(self.weights).expanduser()
        weights = str(path.resolve()) if path.is_file() else self.weights
        kwargs: dict[str, Any] = {"weights": weights}
        if self.arch:
            kwargs["arch"] = self.arch
        if self.layer:
            kwargs["layer"] = self.layer
        if self.stride:
            kwargs["stride"] = self.stride
        return kwargs


@dataclass(frozen=True)
class Source:
    """Where a task's data came from: ``benchmark``, ``fixture`` or ``synthetic``."""

    kind: str
    root: str | None = None
    env_id: str = ""


def data_source(data: Path | None, task: Task) -> Source:
    """The first environment of ``task`` whose folder is in ``data``, else synthetic data.

    A folder counts as a ``fixture`` (real data, but a small sample, as in ``../shared``)
    when its data folder's ``README.md`` starts with a heading that says so; otherwise as the
    ``benchmark``.
    """
    if data is not None:
        for env_id in task.env_ids:
            folder = unitrack_env.variant(env_id).folder
            if folder and (data / folder).is_dir():
                readme = data / "README.md"
                head = readme.read_text(errors="replace").lstrip()[:200] if readme.is_file() \
                    else ""
                kind = "fixture" if head.startswith("#") and "fixture" in head.split("\n")[
                    0].lower() else "benchmark"
                return Source(kind, str((data / folder).resolve()), env_id)
    return Source("synthetic", None, task.env_ids[0])


@dataclass(frozen=True)
class Cell:
    """One (model, task, head, sequence): the unit of work a backend schedules."""

    model: str
    task: str
    head: str
    agent: str
    env_id: str
    sequence: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    agent_kwargs: dict[str, Any] = field(default_factory=dict)
    frames: int = 0

    @property
    def folder(self) -> Path:
        """The cell's run folder below ``<out>/cells``."""
        return Path(_safe(self.model)) / self.task / _safe(self.head)

    @property
    def label(self) -> str:
        """Short description for progress displays."""
        return f"{self.model} / {self.task} {self.head} / {self.sequence}"


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.+" else "_" for c in name)


def _split(env_id: str, env_kwargs: dict[str, Any]) -> Any:
    """The ``split`` argument the benchmark of ``env_id`` is built with (None: it has none)."""
    row = variant(env_id)
    parameters = inspect.signature(benchmark_class(row).build).parameters
    defaults = {name: p.default for name, p in parameters.items()
                if p.default is not inspect.Parameter.empty}
    return {**defaults, **row.kwargs, **env_kwargs}.get("split")


def task_frames(source: Source, *, generate: bool = True) -> tuple[dict[str, int], bool]:
    """Frames of each sequence of ``source`` that can be scored; whether data are to be written.

    With ``generate=False`` the embedded synthetic data are counted from their writer's spec
    (the same counts, tests/evaluation/test_scorecard_plan.py), neither read nor written; the
    flag says whether they are still to be generated. Else they are generated if need be.
    """
    env_kwargs = {"root": source.root} if source.root else {}
    try:
        with contextlib.nullcontext() if generate else specs_only():
            benchmark = benchmark_for(source.env_id, **env_kwargs)
    except SpecsOnly as synthetic:
        return annotated_frames(synthetic.benchmark, synthetic.kind,
                                _split(source.env_id, env_kwargs)), not synthetic.generated
    return {name: benchmark.sequence_length(name) for name in benchmark.sequence_names
            if benchmark.has_ground_truth(name)}, False


def plan(models: Sequence[ModelSpec], tasks: Sequence[str], data: Path | None, *,
         motion: bool = False, runtime: str | None = None, generate: bool = True,
         ) -> tuple[list[Cell], dict[str, Source], list[str]]:
    """Every cell of the scorecard, each task's data source, and the tasks still to generate.

    The last are the tasks whose synthetic data are not generated yet, with
    ``generate=False`` (counted from the specs); by default they are generated now.
    """
    cells: list[Cell] = []
    sources: dict[str, Source] = {}
    pending: list[str] = []
    rows = [(m.name, m.agent_kwargs() | ({"runtime": runtime} if runtime else {}))
            for m in models]
    for name in tasks:
        task = TASKS[name]
        source = sources[name] = data_source(data, task)
        env_kwargs = {"root": source.root} if source.root else {}
        frames, to_generate = task_frames(source, generate=generate)
        if to_generate:
            pending.append(name)
        for head in (*task.heads, task.baseline):
            for model, appearance in (rows if head.appearance else [(BASELINE, {})]):
                kwargs = dict(appearance)
                if head.association and not motion:
                    kwargs["use_motion"] = False
                cells += [Cell(model, name, head.label, head.agent, source.env_id, sequence,
                               env_kwargs, kwargs, length) for sequence, length in frames.items()]
    return cells, sources, pending

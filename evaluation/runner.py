"""Play an agent over every sequence of an environment, write official results, score them.

More in docs/module-notes.md.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

import unitrack_env
from unitrack_env.agents.base import agent_class, close_agent
from unitrack_env.agents.loading import portable_reference
from unitrack_env.agents.options import check_options
from unitrack_env.benchmarks.base import Benchmark, select_sequences
from unitrack_env.io import atomic_write_text, file_in_the_way
from unitrack_env.metrics.report import ScoreReport

from .episode import SequenceRecord, recorded_results
from .identity import (
    RunIdentity,
    option_changes,
    placeless_options,
    placeless_reference,
    result_digest,
)
from .ownership import Manifest, hold_folder, outside, own_folder, settle
from .serial import play_here
from .watchdog import DEFAULT_STEP_TIMEOUT
from .workers import (
    SequenceFailure,
    play_in_workers,
    refuse_unguarded_script,
)


class RunFailed(RuntimeError):
    """Some sequences failed; the others finished and were kept (``failures`` by name).

    ``errors`` holds this process's exceptions with tracebacks (``workers=1``); workers send
    messages only.
    """

    def __init__(self, failures: dict[str, str], out: Path,
                 errors: dict[str, BaseException] | None = None) -> None:
        self.failures = dict(failures)
        self.out = Path(out)
        self.errors = dict(errors or {})
        lines = "\n".join(f"  {name}: {message}" for name, message in failures.items())
        super().__init__(
            f"{len(failures)} sequence(s) failed (finished ones are kept in {out}; fix the "
            f"cause and run the same command again to resume):\n{lines}"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.failures, self.out))


class RunMismatch(ValueError):
    """The output folder holds another run (``difference`` says what differs)."""

    def __init__(self, out: Path, difference: str) -> None:
        self.out, self.difference = out, difference
        super().__init__(f"{out} already holds a different run ({difference}); choose another "
                         "--out, or replace it with --overwrite (overwrite=True in run())")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.out, self.difference))


class OutputError(OSError):
    """The output folder cannot be written (read-only, full, failing disk)."""


@dataclass(frozen=True)
class RunSpec:
    """What to run: everything a worker process needs to rebuild the env and the agent.

    ``agent`` is what the user named (a registered name or a reference); ``agent_ref`` is
    the importable ``module:Class`` it resolved to, used by workers and resumed runs.
    """

    env_id: str
    agent: str
    agent_ref: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    agent_kwargs: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """JSON-friendly form (paths as strings)."""
        return json.loads(json.dumps(asdict(self), default=str))

    def make_agent(self) -> Any:
        """Build the agent (by reference when there is one, so workers need no registry)."""
        return agent_class(self.agent_ref or self.agent)(**self.agent_kwargs)

    def make_env(self) -> gym.Env:
        """Build the environment."""
        unitrack_env.register_all()
        return gym.make(self.env_id, **self.env_kwargs)


@dataclass
class RunReport:
    """The outcome of :func:`run`."""

    out: Path
    records: dict[str, SequenceRecord]
    scores: ScoreReport | None
    skipped: list[str]
    replayed: dict[str, str] = field(default_factory=dict)

    @property
    def combined(self) -> dict[str, float]:
        """Combined metrics over all sequences (empty for splits without ground truth)."""
        return self.scores.combined if self.scores is not None else {}


def json_safe(value: Any) -> Any:
    """Replace NaN/inf floats (metrics of sequences with nothing to score) by None (null)."""
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def save_episode(out: Path, env: gym.Env, record: SequenceRecord,
                 benchmark: Benchmark) -> None:
    """Write the finished episode's results, then its record (the record marks it done)."""
    base = env.unwrapped
    try:
        benchmark.write(out / "data", record.sequence, recorded_results(env))
        record.results = result_digest(out / "data", record.sequence, base.sequence_names)
        atomic_write_text(out / "sequences" / f"{record.sequence}.json",
                          json.dumps(record.to_json(), indent=2))
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write the results of '{record.sequence}' to "
                                     f"{out}: {exc.strerror or exc}") from exc


def _record_path(out: Path, sequence: str) -> Path:
    return out / "sequences" / f"{sequence}.json"


def _stale_reason(out: Path, base: Any, name: str, inputs: str) -> str | None:
    """Why a finished sequence must be played again (None: keep it)."""
    try:
        record = SequenceRecord.from_json(json.loads(_record_path(out, name).read_text()))
    except (OSError, ValueError, TypeError):
        return "its record is unreadable"
    if record.inputs != inputs:
        return "its inputs (data files, agent code or options) changed since it was played"
    if record.results != result_digest(out / "data", name, base.sequence_names):
        return "its result files are missing or were changed since it was played"
    return None


def _resolve_agent(agent: str | type, agent_kwargs: dict[str, Any], workers: int,
                   env_id: str) -> tuple[type, str, str | None]:
    """The agent class, its name for the record and its importable reference (checked)."""
    if workers > 1:
        refuse_unguarded_script()
    cls = agent_class(agent)  # a name, a reference or a class; anything else: TypeError
    name = agent if isinstance(agent, str) else (getattr(cls, "name", "") or cls.__qualname__)
    check_options(cls, agent_kwargs, agent=name)
    task = unitrack_env.task_of(env_id)
    tasks = getattr(cls, "tasks", ())
    if tasks and task not in tasks:
        from unitrack_env.agents.base import agents_for_task

        raise ValueError(f"agent '{name}' plays {', '.join(tasks)}, not {task} ({env_id}); "
                         f"agents for {task}: {', '.join(agents_for_task(task)) or 'none'}")
    reference = portable_reference(cls)
    if reference is None and workers > 1:
        raise ValueError(
            f"agent class {cls.__qualname__} is defined where worker processes cannot "
            "import it (a notebook, python -c, exec, or inside a function); move it to the "
            "top level of a module (or a .py file and pass 'path/to/file.py:ClassName'), or "
            "use workers=1"
        )
    return cls, name, reference


def check_out_folder(out: Path) -> None:
    """Refuse an output folder that is a file (or lies below one) before any work."""
    blocker = file_in_the_way(out)
    if blocker is not None:
        raise OutputError(f"cannot write to {out}: {blocker} is a file, not a folder; "
                          "give --out a folder")


#: run.json fields as a difference names them.
_RUN_FIELDS = {"env_id": "env", "agent": "agent", "agent_ref": "agent class",
               "env_kwargs": "env option", "agent_kwargs": "agent option"}


def _run_difference(previous: Any, spec: RunSpec) -> str:
    """What differs between a stored ``run.json`` and ``spec``, in a user's words."""
    if not isinstance(previous, dict):
        return "its run.json is unreadable"
    now = spec.to_json()
    changes = []
    for key, label in _RUN_FIELDS.items():
        old, new = previous.get(key), now.get(key)
        if isinstance(old, dict) and isinstance(new, dict):
            changes += option_changes(old, new, label)
        elif old != new:
            changes.append(f"{label}: {old!r} -> {new!r}")
    return "; ".join(changes) or "another run.json format"


def _same_run(previous: Any, now: dict[str, Any]) -> bool:
    """Whether a stored ``run.json`` describes this run; its files may have moved.

    Another ``root`` holding the same data resumes: the sequences' input fingerprints name
    files relative to it, and a sequence whose files differ is played again. So do a
    checkpoint (any option naming a file) and an agent file given from another folder: the
    identity counts them by base name and content.
    """
    if not isinstance(previous, dict) or not all(
            isinstance(previous.get(key), dict) for key in ("env_kwargs", "agent_kwargs")):
        return previous == now

    def placeless_run(run: dict[str, Any]) -> dict[str, Any]:
        env = {k: v for k, v in run["env_kwargs"].items() if k != "root"}
        return run | {"env_kwargs": placeless_options(env, now["env_kwargs"]),
                      "agent_kwargs": placeless_options(run["agent_kwargs"],
                                                                 now["agent_kwargs"]),
                      "agent": placeless_reference(run.get("agent")),
                      "agent_ref": placeless_reference(run.get("agent_ref")),
                      "rooted": "root" in run["env_kwargs"]}

    return placeless_run(previous) == placeless_run(now)


def _prepare_out(out: Path, spec: RunSpec, overwrite: bool, manifest: Manifest) -> None:
    run_file = out / "run.json"
    if run_file.is_file() and not overwrite:
        try:
            previous = json.loads(run_file.read_text())
        except ValueError:
            previous = None
        if not _same_run(previous, spec.to_json()):
            raise RunMismatch(out, _run_difference(previous, spec))
    try:
        manifest.add(run_file)
        atomic_write_text(run_file, json.dumps(spec.to_json(), indent=2))
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write to {out}: {exc.strerror or exc}") from exc


def _sequence_lengths(bench: Benchmark, todo: list[str]
                      ) -> tuple[dict[str, int], dict[str, str]]:
    """Frames of each sequence to play, read before any is played.

    A sequence whose files fail the readers' checks is a failure of its own and the others
    still play (OTB and DAVIS read a whole sequence here, MOTChallenge its ``seqinfo.ini``).
    """
    lengths: dict[str, int] = {}
    failures: dict[str, str] = {}
    for name in todo:
        try:
            lengths[name] = bench.sequence_length(name)
        except (ValueError, KeyError, OSError) as exc:
            failures[name] = SequenceFailure.describe(exc)
    return lengths, failures


def _score_and_write(out: Path, spec: RunSpec, bench: Benchmark, names: list[str],
                     records: dict[str, SequenceRecord]) -> ScoreReport | None:
    with_gt = bench.scorable(names)
    scores = bench.score_folder(out / "data", with_gt) if with_gt else None
    payload: dict[str, Any] = {
        "env_id": spec.env_id,
        "agent": spec.agent,
        "sequences": {name: records[name].to_json() for name in names},
    }
    if scores is not None:
        payload |= {"benchmark": scores.benchmark, "per_sequence": scores.per_sequence,
                    "combined": scores.combined, "combined_covers": scores.coverage_json()}
    else:
        payload["note"] = "this split has no ground truth; results were written, not scored"
    atomic_write_text(out / "metrics.json", json.dumps(json_safe(payload), indent=2,
                                                       allow_nan=False))
    if scores is not None:  # per-frame error events beside the results (never fails the run)
        from .events import write_run_events

        write_run_events(out, bench, with_gt)
    return scores


def run(
    env_id: str,
    agent: str | type,
    *,
    out: str | os.PathLike,
    env_kwargs: dict[str, Any] | None = None,
    agent_kwargs: dict[str, Any] | None = None,
    sequences: Sequence[str] | None = None,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
    step_timeout: float | None = DEFAULT_STEP_TIMEOUT,
) -> RunReport:
    """Evaluate an agent on every sequence of an environment.

    ``agent`` is a registered name (``"iou"``), a reference (``"my_module:MyTracker"``,
    ``"path/to/file.py:MyTracker"``) or the class; ``env_kwargs`` go to ``gym.make``;
    ``out`` is reused to resume unless ``overwrite`` (which deletes only files of our runs,
    per ``out/manifest.json``); ``step_timeout`` None or 0 means no limit. Returns a
    :class:`RunReport`, the metrics also in ``out/metrics.json``.

    Raises:
        RunFailed: some sequences failed (the others are kept; rerun to resume).
        OutputInUse: another process is writing into ``out``.
        OutputError: ``out`` cannot be written, or files no run of ours wrote are in the way.
    """
    agent_kwargs = dict(agent_kwargs or {})
    sequences = [sequences] if isinstance(sequences, str) else sequences  # a name, not letters
    cls, name, reference = _resolve_agent(agent, agent_kwargs, workers, env_id)
    spec = RunSpec(env_id, name, reference, dict(env_kwargs or {}), agent_kwargs)
    out = Path(out)
    check_out_folder(out)
    env = spec.make_env()
    try:
        base = env.unwrapped
        names = select_sequences(sequences, base.sequence_names, env_id)
        bench = base.scoring
        agent_obj = cls(**agent_kwargs)
    except BaseException:
        env.close()
        raise
    try:
        with hold_folder(out, f"agent {name} on {env_id}"):
            return _run_owned(spec, env, bench, agent_obj, out, names,
                              _Options(workers, progress, step_timeout, overwrite))
    finally:
        close_agent(agent_obj)
        env.close()


def stale_sequences(env_id: str, agent: str | type, out: str | os.PathLike[str], *,
                    env_kwargs: dict[str, Any] | None = None,
                    agent_kwargs: dict[str, Any] | None = None,
                    sequences: Sequence[str] | None = None) -> dict[str, str]:
    """The finished sequences in ``out`` that :func:`run` would play again, with the reason.

    Nothing is played and the agent is not built: its class is imported (its code counts in
    the fingerprints) and the environment reads its files. Sequences without a record are
    not listed (they are unplayed, not stale).

    Raises:
        RunMismatch: ``out`` holds another run (as :func:`run` would refuse it; its
            sequences are not stale, they are someone else's).
    """
    agent_kwargs = dict(agent_kwargs or {})
    cls = agent_class(agent)
    name = agent if isinstance(agent, str) else (getattr(cls, "name", "") or cls.__qualname__)
    spec = RunSpec(env_id, name, portable_reference(cls), dict(env_kwargs or {}), agent_kwargs)
    out = Path(out)
    if (out / "run.json").is_file():
        try:
            previous = json.loads((out / "run.json").read_text())
        except ValueError:
            previous = None
        if not _same_run(previous, spec.to_json()):
            raise RunMismatch(out, _run_difference(previous, spec))
    env = spec.make_env()
    try:
        base = env.unwrapped
        names = select_sequences(sequences, base.sequence_names, env_id)
        identity = RunIdentity.of(spec)
        stale = {}
        for n in names:
            if not _record_path(out, n).is_file():
                continue
            inputs = identity.sequence_fingerprint(outside(base.sequence_inputs(n), out),
                                                   base.inputs_root())
            if (why := _stale_reason(out, base, n, inputs)) is not None:
                stale[n] = why
        return stale
    finally:
        env.close()


@dataclass(frozen=True)
class _Options:
    workers: int
    progress: bool
    step_timeout: float | None
    overwrite: bool


def _run_owned(spec: RunSpec, env: gym.Env, bench: Benchmark, agent_obj: Any, out: Path,
               names: list[str], options: _Options) -> RunReport:
    """The run, once ``out`` is locked: claim the folder, fingerprint the inputs, play."""
    base = env.unwrapped
    identity = RunIdentity.of(spec)
    inputs = {n: identity.sequence_fingerprint(outside(base.sequence_inputs(n), out),
                                               base.inputs_root()) for n in names}
    manifest = own_folder(out, base.sequence_names, names, options.overwrite)
    _prepare_out(out, spec, options.overwrite, manifest)
    return _run_prepared(spec, env, bench, agent_obj, out, names, inputs, manifest, options)


def _run_prepared(spec: RunSpec, env: gym.Env, bench: Benchmark, agent_obj: Any, out: Path,
                  names: list[str], inputs: dict[str, str], manifest: Manifest,
                  options: _Options) -> RunReport:
    base = env.unwrapped
    finished = [n for n in names if _record_path(out, n).is_file()]
    replayed = {n: why for n in finished
                if (why := _stale_reason(out, base, n, inputs[n])) is not None}
    skipped = [n for n in finished if n not in replayed]
    lengths, failures = _sequence_lengths(bench, [n for n in names if n not in skipped])
    todo = list(lengths)

    from .progress import RunProgress

    causes: dict[str, BaseException] = {}
    manifest.claim(todo)
    try:
        with RunProgress(sum(lengths.values()), enabled=options.progress) as bar:
            if options.workers <= 1 or len(todo) <= 1:
                records, played = play_here(spec, env, bench, agent_obj, out, todo, inputs,
                                             bar, causes, options.step_timeout)
            else:
                records, played = play_in_workers(spec, out, todo, inputs, lengths,
                                                  options.workers, bar, options.step_timeout)
    finally:
        with contextlib.suppress(OSError):  # a full disk: the claims still say they are ours
            for name in todo:
                settle(manifest, name, base.sequence_names)
    failures |= played
    if failures:  # in this process, the first failure's traceback (the agent's code) is kept
        raise RunFailed(failures, out, causes) from next(iter(causes.values()), None)
    for name in skipped:
        records[name] = SequenceRecord.from_json(json.loads(_record_path(out, name).read_text()))
    from .events import events_path

    manifest.add(out / "metrics.json", *(events_path(out, name) for name in names))
    scores = _score_and_write(out, spec, bench, names, records)
    return RunReport(out, {n: records[n] for n in names}, scores, skipped, replayed)

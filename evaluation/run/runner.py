"""Play an agent over every sequence of an environment, write official results, score them.

The run folder has TrackEval's tracker layout, so ``unitrack score`` or TrackEval can score it
again (its files: docs/evaluation.md); one run at a time owns it (:mod:`.ownership`), and a
step over ``step_timeout`` fails its sequence (:mod:`.watchdog`). The runner knows no task:
the id's benchmark writes the results, says which sequences can be scored and scores them. A
sequence is finished once its record exists, written after its results, every file to a
temporary name then renamed: a crash or Ctrl-C never leaves half a file nor loses a finished
sequence. Running again resumes, keeping a finished sequence only while its inputs have the
recorded fingerprint and its result files the recorded digest (:mod:`.resume`).
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

import unitrack_env
from unitrack_env.agents.base import agent_class, agents_for_task, close_agent
from unitrack_env.agents.loading import portable_reference
from unitrack_env.agents.options import check_options
from unitrack_env.benchmarks.base import Benchmark, select_sequences
from unitrack_env.io import atomic_write_text, file_in_the_way
from unitrack_env.metrics.report import ScoreReport

from ..analysis.events import events_path, write_run_events
from ..analysis.tables import json_safe
from .episode import OutputError, SequenceRecord
from .identity import RunIdentity, Stamp
from .integrity import data_fingerprint
from .ownership import Manifest, hold_folder, outside, own_folder, settle
from .progress import RunProgress
from .ray_sequences import play_on_ray
from .repetitions import repetition_scores
from .restamp import restamp_record
from .resume import check_run_json, record_path, stale_reason
from .run_spec import RunSpec
from .serial import play_here, play_isolated
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


@dataclass
class RunReport:
    """The outcome of :func:`run`."""

    out: Path
    records: dict[str, SequenceRecord]
    scores: ScoreReport | None
    skipped: list[str]
    replayed: dict[str, str] = field(default_factory=dict)
    restamped: dict[str, list[str]] = field(default_factory=dict)
    """Sequences kept across an edit of the agent's code (``restamp=True``), with the files."""
    repetitions: dict[str, Any] | None = None
    """With ``repeats > 1``: every repetition's scores and their spread
    (:func:`.repetitions.repetition_scores`, also in ``metrics.json``)."""

    @property
    def combined(self) -> dict[str, float]:
        """Combined metrics over all sequences (empty for splits without ground truth)."""
        return self.scores.combined if self.scores is not None else {}


def _resolve_agent(agent: str | type, agent_kwargs: dict[str, Any], elsewhere: bool,
                   env_id: str) -> tuple[type, str, str | None]:
    """The agent class, its name for the record and its importable reference (checked).

    ``elsewhere``: the agent plays in other processes, which must be able to import it.
    """
    if elsewhere:
        refuse_unguarded_script()
    cls = agent_class(agent)  # a name, a reference or a class; anything else: TypeError
    name = agent if isinstance(agent, str) else (getattr(cls, "name", "") or cls.__qualname__)
    check_options(cls, agent_kwargs, agent=name)
    task = unitrack_env.task_of(env_id)
    tasks = getattr(cls, "tasks", ())
    if tasks and task not in tasks:
        raise ValueError(f"agent '{name}' plays {', '.join(tasks)}, not {task} ({env_id}); "
                         f"agents for {task}: {', '.join(agents_for_task(task)) or 'none'}")
    reference = portable_reference(cls)
    if reference is None and elsewhere:
        raise ValueError(
            f"agent class {cls.__qualname__} is defined where worker processes cannot "
            "import it (a notebook, python -c, exec, or inside a function); move it to the "
            "top level of a module (or a .py file and pass 'path/to/file.py:ClassName'), or "
            "use workers=1 (isolate=False)"
        )
    return cls, name, reference


def check_out_folder(out: Path) -> None:
    """Refuse an output folder that is a file (or lies below one) before any work."""
    blocker = file_in_the_way(out)
    if blocker is not None:
        raise OutputError(f"cannot write to {out}: {blocker} is a file, not a folder; "
                          "give --out a folder")


def _prepare_out(out: Path, spec: RunSpec, overwrite: bool, manifest: Manifest) -> None:
    run_file = out / "run.json"
    if not overwrite:
        check_run_json(out, spec)
    try:
        manifest.add(run_file)
        atomic_write_text(run_file, json.dumps(spec.to_json(), indent=2))
    except OSError as exc:
        raise OutputError(exc.errno, f"cannot write to {exc.filename or out}: "
                                     f"{exc.strerror or exc}") from exc


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
                     records: dict[str, SequenceRecord],
                     ) -> tuple[ScoreReport | None, dict[str, Any] | None]:
    with_gt = bench.scorable(names)
    scores = bench.score_folder(out / "data", with_gt) if with_gt else None
    payload: dict[str, Any] = {
        "env_id": spec.env_id,
        "agent": spec.agent,
        "sequences": {name: records[name].to_json() for name in names},
    }
    repeated = None
    if scores is not None:
        payload |= {"benchmark": scores.benchmark, "per_sequence": scores.per_sequence,
                    "combined": scores.combined, "combined_covers": scores.coverage_json()}
        if spec.repeats > 1:
            repeated = repetition_scores(bench, out / "data", list(scores.per_sequence),
                                         spec.repeats)
            payload["repetitions"] = repeated
    else:
        payload["note"] = "this split has no ground truth; results were written, not scored"
    try:
        atomic_write_text(out / "metrics.json", json.dumps(json_safe(payload), indent=2,
                                                           allow_nan=False))
    except OSError as exc:  # a full disk: one sentence, and the results stay
        raise OutputError(exc.errno, f"cannot write {out / 'metrics.json'}: "
                                     f"{exc.strerror or exc}; the results of the "
                                     f"{len(records)} finished sequence(s) are kept in "
                                     f"{out / 'data'}: free space and run the same command "
                                     "again to score them") from exc
    if scores is not None:  # per-frame error events beside the results (never fails the run)
        write_run_events(out, bench, with_gt)
    return scores, repeated


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
    restamp: bool = False,
    isolate: bool = False,
    backend: str = "local",
    address: str | None = None,
    repeats: int = 1,
) -> RunReport:
    """Evaluate an agent on every sequence of an environment.

    ``agent`` is a registered name (``"iou"``), a reference (``"my_module:MyTracker"``,
    ``"path/to/file.py:MyTracker"``) or the class; ``env_kwargs`` go to ``gym.make``;
    ``out`` is reused to resume unless ``overwrite`` (which deletes only files of our runs,
    per ``out/manifest.json``); ``step_timeout`` None or 0 means no limit. ``restamp``
    keeps finished sequences whose only change is the agent's code (:mod:`.restamp`: you
    vouch that the edit cannot change them). ``isolate`` plays ``workers=1`` in one
    supervised child process (:func:`.serial.play_isolated`, the CLI's default): a step
    stuck in native code, a crash or a hung ``close()`` then ends only what it was doing.
    ``backend="ray"`` plays each sequence as a Ray task (:mod:`.ray_sequences`; ``address``:
    a cluster, default a local Ray). ``repeats``: plays per sequence (:mod:`.repetitions`).
    Returns a :class:`RunReport`, the metrics also in ``out/metrics.json``.

    Raises:
        RunFailed: some sequences failed (the others are kept; rerun to resume).
        OutputInUse: another process is writing into ``out``.
        OutputError: ``out`` cannot be written, or files no run of ours wrote are in the way.
    """
    agent_kwargs = dict(agent_kwargs or {})
    options = _Options(workers, progress, step_timeout, overwrite, restamp, isolate, backend,
                       address)
    sequences = [sequences] if isinstance(sequences, str) else sequences  # a name, not letters
    cls, name, reference = _resolve_agent(agent, agent_kwargs, options.elsewhere, env_id)
    spec = RunSpec(env_id, name, reference, dict(env_kwargs or {}), agent_kwargs, repeats)
    check_out_folder(out := Path(out))
    env = spec.make_env()
    try:
        base = env.unwrapped
        names = select_sequences(sequences, base.sequence_names, env_id)
        bench = base.scoring
        agent_obj = cls(**agent_kwargs)  # its checks refuse bad options before the first frame
    except BaseException:
        env.close()
        raise
    try:
        with hold_folder(out, f"agent {name} on {env_id}"):
            return _run_owned(spec, env, bench, agent_obj, out, names, options)
    finally:
        if not isolate:  # isolated, only the children's copies play, and they close them
            close_agent(agent_obj)
        env.close()


@dataclass(frozen=True)
class _Options:
    workers: int
    progress: bool
    step_timeout: float | None
    overwrite: bool
    restamp: bool = False
    isolate: bool = False
    backend: str = "local"
    address: str | None = None

    def __post_init__(self) -> None:
        if self.backend not in ("local", "ray") or (self.address is not None
                                                     and self.backend != "ray"):
            raise ValueError(f"backend must be 'local' or 'ray' (got {self.backend!r}); "
                             "--address goes with --backend ray")

    @property
    def elsewhere(self) -> bool:
        """Whether the agent plays in other processes (which must be able to import it)."""
        return self.workers > 1 or self.isolate or self.backend == "ray"


def _run_owned(spec: RunSpec, env: gym.Env, bench: Benchmark, agent_obj: Any, out: Path,
               names: list[str], options: _Options) -> RunReport:
    """The run, once ``out`` is locked: claim the folder, fingerprint the inputs, play."""
    base = env.unwrapped
    identity = RunIdentity.of(spec)
    stamps = {n: identity.stamp(outside(base.sequence_inputs(n), out), base.inputs_root(),
                                data_fingerprint(getattr(base, "dataset", None), n, out))
              for n in names}
    manifest = own_folder(out, base.sequence_names, names, options.overwrite)
    _prepare_out(out, spec, options.overwrite, manifest)
    return _run_prepared(spec, env, bench, agent_obj, out, names, stamps, manifest, options)


def _run_prepared(spec: RunSpec, env: gym.Env, bench: Benchmark, agent_obj: Any, out: Path,
                  names: list[str], stamps: dict[str, Stamp], manifest: Manifest,
                  options: _Options) -> RunReport:
    base = env.unwrapped
    finished = [n for n in names if record_path(out, n).is_file()]
    replayed = {n: why for n in finished
                if (why := stale_reason(out, base, n, stamps[n])) is not None}
    restamped: dict[str, list[str]] = {}
    for n in list(replayed) if options.restamp else []:
        kept = restamp_record(out, spec, base, n, outside(base.sequence_inputs(n), out),
                              stamps[n])
        if isinstance(kept, list):
            restamped[n] = kept
            del replayed[n]  # kept: skipped below
        else:
            replayed[n] += f" (not re-stamped: {kept})"
    skipped = [n for n in finished if n not in replayed]
    lengths, failures = _sequence_lengths(bench, [n for n in names if n not in skipped])
    todo = list(lengths)

    causes: dict[str, BaseException] = {}
    manifest.claim(todo)
    try:
        with RunProgress(sum(lengths.values()) * spec.repeats, enabled=options.progress) as bar:
            if options.backend == "ray" and todo:
                records, played = play_on_ray(spec, out, todo, stamps, lengths, bar=bar,
                                              workers=options.workers, address=options.address)
            elif options.isolate and (options.workers <= 1 or len(todo) <= 1):
                records, played = play_isolated(spec, out, todo, stamps, bar, causes,
                                                options.step_timeout)
            elif options.workers <= 1 or len(todo) <= 1:
                records, played = play_here(spec, env, bench, agent_obj, out, todo, stamps,
                                             bar, causes, options.step_timeout)
            else:
                records, played = play_in_workers(spec, out, todo, stamps, lengths,
                                                  options.workers, bar, options.step_timeout)
    finally:
        with contextlib.suppress(OSError):  # a full disk: the claims still say they are ours
            for name in todo:
                settle(manifest, name, base.sequence_names)
    failures |= played
    if failures:  # in this process, the first failure's traceback (the agent's code) is kept
        raise RunFailed(failures, out, causes) from next(iter(causes.values()), None)
    for name in skipped:
        records[name] = SequenceRecord.from_json(json.loads(record_path(out, name).read_text()))
    manifest.add(out / "metrics.json", *(events_path(out, name) for name in names))
    scores, repeated = _score_and_write(out, spec, bench, names, records)
    return RunReport(out, {n: records[n] for n in names}, scores, skipped, replayed,
                     restamped, repeated)

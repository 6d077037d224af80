"""Play an agent over every sequence of an environment, write official results, score them.

Output folder layout (TrackEval's tracker layout, so the folder can be scored again with
``unitrack score`` or TrackEval itself)::

    <out>/run.json                 what was run (env id, env and agent arguments)
    <out>/data/...                 results in the task's official format (MOT:
                                   ``<sequence>.txt``), written atomically by the env
    <out>/sequences/<sequence>.json  per-sequence record: frames, seconds, FPS, digest
    <out>/metrics.json             per-sequence and combined official metrics

The runner knows no task: it relies on the environment's results contract
(:class:`unitrack_env.envs.base.SequenceEnv`: ``write_episode``, ``score_folder``,
``sequence_length``, ``has_ground_truth``, ``episode_digest``). A sequence counts as
finished once its record exists; the record is written after the results, and every file is
written with write-to-temp-then-rename, so a crash or Ctrl-C never leaves a half file and
never loses a finished sequence. Running again with the same ``out`` resumes: finished
sequences are skipped.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import gymnasium as gym

import unitrack_env
from unitrack_env.agents import make_agent
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.report import ScoreReport


@dataclass(frozen=True)
class RunSpec:
    """What to run: everything a worker process needs to rebuild the env and the agent."""

    env_id: str
    agent: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    agent_kwargs: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """JSON-friendly form (paths as strings)."""
        return json.loads(json.dumps(asdict(self), default=str))


@dataclass
class SequenceRecord:
    """What one finished episode left behind."""

    sequence: str
    frames: int
    seconds: float
    digest: str
    episode_return: float

    @property
    def fps(self) -> float:
        """Frames per second of the whole episode (env + agent)."""
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


@dataclass
class RunReport:
    """The outcome of :func:`run`."""

    out: Path
    records: dict[str, SequenceRecord]
    scores: ScoreReport | None
    skipped: list[str]

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


def play_episode(
    env: gym.Env,
    agent: Any,
    sequence: str,
    *,
    on_frame: Callable[[], None] | None = None,
) -> tuple[SequenceRecord, dict[str, Any]]:
    """Play one sequence; return its record and the final info (results stay in the env)."""
    start = time.perf_counter()
    observation, info = env.reset(options={"sequence": sequence})
    agent.reset(observation, info)
    frames, total = 0, 0.0
    terminated = truncated = False
    while not (terminated or truncated):
        try:
            action = agent.act(observation)
        except Exception as exc:
            raise RuntimeError(
                f"agent '{getattr(agent, 'name', type(agent).__name__)}' failed on sequence "
                f"'{sequence}', frame {info.get('frame_index')}: {exc}"
            ) from exc
        observation, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        frames += 1
        if on_frame is not None:
            on_frame()
    seconds = time.perf_counter() - start
    record = SequenceRecord(sequence, frames, seconds, env.unwrapped.episode_digest(), total)
    return record, info


def _finished(out: Path, sequence: str) -> bool:
    return (out / "sequences" / f"{sequence}.json").is_file()


def _save(out: Path, env: gym.Env, record: SequenceRecord) -> None:
    env.unwrapped.write_episode(out / "data")
    payload = asdict(record) | {"fps": record.fps}
    atomic_write_text(out / "sequences" / f"{record.sequence}.json", json.dumps(payload, indent=2))


def _make(spec: RunSpec) -> tuple[gym.Env, Any]:
    unitrack_env.register_all()
    env = gym.make(spec.env_id, **spec.env_kwargs)
    agent = make_agent(spec.agent, **spec.agent_kwargs)
    return env, agent


def _worker(spec: RunSpec, out: str, sequence: str, threads: int | None) -> dict[str, Any]:
    if threads:
        import torch

        torch.set_num_threads(threads)
    env, agent = _make(spec)
    try:
        record, _ = play_episode(env, agent, sequence)
        _save(Path(out), env, record)
        return asdict(record)
    finally:
        agent.close()
        env.close()


def _check_run_file(out: Path, spec: RunSpec, overwrite: bool) -> None:
    run_file = out / "run.json"
    if run_file.is_file() and not overwrite:
        previous = json.loads(run_file.read_text())
        if previous != spec.to_json():
            raise ValueError(
                f"{out} already holds a different run ({previous.get('agent')} on "
                f"{previous.get('env_id')}); choose another --out, or pass overwrite=True "
                f"(--overwrite) to replace it"
            )
    if overwrite:
        for sub in ("data", "sequences"):
            if (out / sub).is_dir():
                shutil.rmtree(out / sub)
    atomic_write_text(run_file, json.dumps(spec.to_json(), indent=2))


def run(
    env_id: str,
    agent: str,
    *,
    out: str | os.PathLike,
    env_kwargs: dict[str, Any] | None = None,
    agent_kwargs: dict[str, Any] | None = None,
    sequences: Sequence[str] | None = None,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
) -> RunReport:
    """Evaluate a registered agent on every sequence of an environment.

    Args:
        env_id: a registered id, e.g. ``"UniTrack/MOT17-v0"``.
        agent: a registered agent name, e.g. ``"iou"``.
        out: output folder (see the module docstring); reused to resume.
        env_kwargs: keyword arguments of ``gym.make`` (``root``, ``split``, ...).
        agent_kwargs: keyword arguments of the agent.
        sequences: only these sequences (default: all of the split).
        workers: parallel worker processes across sequences (1 = in this process).
        overwrite: discard an existing run in ``out`` instead of resuming it.
        progress: show a progress bar with FPS and ETA.

    Returns:
        A :class:`RunReport`; ``metrics.json`` in ``out`` holds the same metrics.
    """
    spec = RunSpec(env_id, agent, dict(env_kwargs or {}), dict(agent_kwargs or {}))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _check_run_file(out, spec, overwrite)
    env, agent_obj = _make(spec)
    base = env.unwrapped
    names = list(sequences) if sequences is not None else list(base.sequence_names)
    unknown = [s for s in names if s not in base.sequence_names]
    if unknown:
        env.close()
        raise ValueError(f"unknown sequences {unknown}; available: {base.sequence_names}")
    skipped = [s for s in names if _finished(out, s)]
    todo = [s for s in names if s not in skipped]
    lengths = {s: base.sequence_length(s) for s in todo}
    records: dict[str, SequenceRecord] = {}

    from unitrack_env.evaluation.progress import RunProgress

    with RunProgress(sum(lengths.values()), enabled=progress) as bar:
        if workers <= 1 or len(todo) <= 1:
            try:
                for name in todo:
                    bar.start_sequence(name)
                    record, _ = play_episode(env, agent_obj, name, on_frame=bar.advance)
                    _save(out, env, record)
                    records[name] = record
            finally:
                agent_obj.close()
                env.close()
        else:
            agent_obj.close()
            env.close()
            threads = max(1, (os.cpu_count() or 1) // workers)
            context = get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
                futures = {pool.submit(_worker, spec, str(out), s, threads): s for s in todo}
                for future in as_completed(futures):
                    record = SequenceRecord(**future.result())
                    records[record.sequence] = record
                    bar.advance(lengths[record.sequence])

    for name in skipped:
        data = json.loads((out / "sequences" / f"{name}.json").read_text())
        data.pop("fps", None)
        records[name] = SequenceRecord(**data)
    with_gt = [n for n in names if base.has_ground_truth(n)]
    scores = base.score_folder(out / "data", with_gt) if with_gt else None
    payload: dict[str, Any] = {
        "env_id": env_id,
        "agent": agent,
        "sequences": {name: asdict(records[name]) | {"fps": records[name].fps} for name in names},
    }
    if scores is not None:
        payload |= {"benchmark": scores.benchmark, "per_sequence": scores.per_sequence,
                    "combined": scores.combined}
    else:
        payload["note"] = "this split has no ground truth; results were written, not scored"
    atomic_write_text(out / "metrics.json", json.dumps(json_safe(payload), indent=2,
                                                       allow_nan=False))
    return RunReport(out, {n: records[n] for n in names}, scores, skipped)

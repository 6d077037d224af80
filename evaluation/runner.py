"""Play an agent over every sequence of an environment, write official results, score them.

Output folder layout (TrackEval's tracker layout, so the folder can be scored again with
``unitrack score`` or TrackEval itself)::

    <out>/run.json                 what was run (env id, env and agent arguments)
    <out>/data/<sequence>.txt      results in the official format, written atomically
    <out>/sequences/<sequence>.json  per-sequence record: frames, seconds, FPS, digest
    <out>/metrics.json             per-sequence and combined metrics (TrackEval names)

A sequence counts as finished once both its result file and its record exist; both are
written with write-to-temp-then-rename, so a crash or Ctrl-C never leaves a half file and
never loses a finished sequence. Running again with the same ``out`` resumes: finished
sequences are skipped.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import unitrack_env
from evaluation._agents import agents_module
from evaluation.scoring import ScoreReport, score_results

#: Format of the floats in result files (MOTChallenge files use 2 decimals; keep 3).
RESULT_FORMAT = ("%d", "%d", "%.3f", "%.3f", "%.3f", "%.3f", "%g", "%d", "%d", "%d")


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


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def format_results(rows: np.ndarray) -> str:
    """Format MOTChallenge result rows (``frame, id, x, y, w, h, conf, -1, -1, -1``)."""
    lines = []
    for row in np.asarray(rows).reshape(-1, 10):
        lines.append(",".join(fmt % value for fmt, value in zip(RESULT_FORMAT, row, strict=True)))
    return "\n".join(lines) + ("\n" if lines else "")


def play_episode(
    env: gym.Env,
    agent: Any,
    sequence: str,
    *,
    on_frame: Callable[[], None] | None = None,
) -> tuple[np.ndarray, SequenceRecord, dict[str, Any]]:
    """Play one sequence; return its result rows, its record and the final info."""
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
    base = env.unwrapped
    record = SequenceRecord(sequence, frames, seconds, base.episode_digest(), total)
    return base.episode_results(), record, info


def _finished(out: Path, sequence: str) -> bool:
    return (out / "data" / f"{sequence}.txt").is_file() and (
        out / "sequences" / f"{sequence}.json"
    ).is_file()


def _save(out: Path, rows: np.ndarray, record: SequenceRecord) -> None:
    atomic_write_text(out / "data" / f"{record.sequence}.txt", format_results(rows))
    payload = asdict(record) | {"fps": record.fps}
    atomic_write_text(out / "sequences" / f"{record.sequence}.json", json.dumps(payload, indent=2))


def _make(spec: RunSpec) -> tuple[gym.Env, Any]:
    unitrack_env.register_all()
    env = gym.make(spec.env_id, **spec.env_kwargs)
    agent = agents_module().make_agent(spec.agent, **spec.agent_kwargs)
    return env, agent


def _worker(spec: RunSpec, out: str, sequence: str, threads: int | None) -> dict[str, Any]:
    if threads:
        import torch

        torch.set_num_threads(threads)
    env, agent = _make(spec)
    try:
        rows, record, _ = play_episode(env, agent, sequence)
        _save(Path(out), rows, record)
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
            for path in (out / sub).glob("*"):
                path.unlink()
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

    from evaluation.progress import RunProgress

    with RunProgress(sum(lengths.values()), enabled=progress) as bar:
        if workers <= 1 or len(todo) <= 1:
            try:
                for name in todo:
                    bar.start_sequence(name)
                    rows, record, _ = play_episode(env, agent_obj, name, on_frame=bar.advance)
                    _save(out, rows, record)
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
    scores = _score(spec, base, out, names)
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
    atomic_write_text(out / "metrics.json", json.dumps(payload, indent=2))
    return RunReport(out, {n: records[n] for n in names}, scores, skipped)


def _score(spec: RunSpec, base: Any, out: Path, names: list[str]) -> ScoreReport | None:
    with_gt = [n for n in names if base.dataset.has_ground_truth(n)]
    if not with_gt:
        return None
    return score_results(base.dataset.split_dir, out / "data", benchmark=base.benchmark,
                         sequences=with_gt)

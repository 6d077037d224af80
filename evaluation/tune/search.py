"""``unitrack tune``: a hyper-parameter search over a head's options, on Optuna.

The search space names agent options (``new_track_score``, ``appearance_threshold``: a
head's config is flat): ``NAME=LOW..HIGH`` (a float range when a bound has a
decimal point, else an integer range; ``:log`` for a log scale) or ``NAME=A|B|C`` (choices,
read as ``--agent-arg`` reads values). Names, bounds and choices are checked with
:func:`~unitrack_env.agents.options.check_options` (as ``--agent-arg`` is) and by making
the agent with every bound and choice, before any trial runs.

Each trial is an ordinary run folder (``<out>/trials/<digest of its setting>``: resumable,
scored by the runner's scorer) on the tuning split. The study lives in ``<out>/optuna.db``
(SQLite): the same command resumes it, a trial interrupted half-way continues in its folder.
Trials share a feature cache in ``<out>/feature-cache`` (unless ``feature_cache`` is given),
so only the first one runs the backbone. The best setting and the defaults are then played on
the validation split and compared with ``unitrack compare``'s paired interval.
"""

from __future__ import annotations

import ast
import contextlib
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from unitrack_env.agents.base import agent_class, close_agent
from unitrack_env.agents.options import agent_options, check_options
from unitrack_env.benchmarks import benchmark_for
from unitrack_env.benchmarks.base import select_sequences
from unitrack_env.io import atomic_write_text

from ..analysis.compare import COMBINED
from ..analysis.intervals import compare_runs
from ..run.ownership import hold_folder
from ..run.runner import check_out_folder, run

#: Name of the Optuna study inside its storage.
STUDY = "unitrack-tune"


@dataclass(frozen=True)
class Dimension:
    """One searched option: a range (``low``..``high``, maybe ``log``) or ``choices``."""

    name: str
    low: float | int | None = None
    high: float | int | None = None
    log: bool = False
    choices: tuple[Any, ...] = ()

    def suggest(self, trial: Any) -> Any:
        """The trial's value (Optuna's suggest API)."""
        if self.choices:
            return trial.suggest_categorical(self.name, list(self.choices))
        if isinstance(self.low, int) and isinstance(self.high, int):
            return trial.suggest_int(self.name, self.low, self.high, log=self.log)
        return trial.suggest_float(self.name, float(self.low), float(self.high), log=self.log)

    def corners(self) -> list[Any]:
        """The values checked before the search: both bounds, or every choice."""
        return list(self.choices) if self.choices else [self.low, self.high]


def _literal(text: str) -> Any:
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_dimension(text: str) -> Dimension:
    """Read ``NAME=LOW..HIGH[:log]`` or ``NAME=A|B|C``."""
    name, sep, rest = text.partition("=")
    name = name.strip().replace("-", "_")
    if not sep or not name or not rest.strip():
        raise ValueError(f"--space '{text}': give NAME=LOW..HIGH, NAME=LOW..HIGH:log or "
                         "NAME=A|B|C")
    if ".." in rest and "|" not in rest:
        bounds, _, scale = rest.partition(":")
        if scale not in ("", "log"):
            raise ValueError(f"--space '{text}': the only scale is :log")
        low_text, high_text = (part.strip() for part in bounds.split("..", 1))
        low, high = _literal(low_text), _literal(high_text)
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (low, high)):
            raise ValueError(f"--space '{text}': the bounds must be numbers")
        if isinstance(low, float) or isinstance(high, float):
            low, high = float(low), float(high)
        if not low < high or (scale == "log" and low <= 0):
            raise ValueError(f"--space '{text}': need LOW < HIGH" + (
                " and LOW > 0 on a log scale" if scale else ""))
        return Dimension(name, low, high, log=scale == "log")
    choices = tuple(_literal(part.strip()) for part in rest.split("|"))
    if len(choices) < 2 or len(set(map(repr, choices))) != len(choices):
        raise ValueError(f"--space '{text}': give two or more different choices, A|B")
    return Dimension(name, choices=choices)


def apply(base: dict[str, Any], params: dict[str, Any]) -> dict[str, Any]:
    """The agent options of a setting: ``base`` with ``params``."""
    return {**base, **params}


def check_space(agent: str, space: list[Dimension], base: dict[str, Any]) -> None:
    """Refuse an unknown option, a value of the wrong type, or a setting the agent rejects."""
    cls = agent_class(agent)
    names = [d.name for d in space]
    if len(set(names)) != len(names):
        raise ValueError(f"--space names an option twice: {', '.join(names)}")
    for d in space:
        if d.name in base:
            raise ValueError(f"--space {d.name} is also fixed by --agent-arg; give it once")
        for value in d.corners():  # typed already: checked as --agent-arg checks its values
            check_options(cls, {d.name: value}, agent=agent)
    # Make the agent with every bound and choice: what its own config refuses (a value out
    # of its range) is one error now.
    for i in range(max(len(d.corners()) for d in space)):
        setting = {d.name: d.corners()[min(i, len(d.corners()) - 1)] for d in space}
        try:
            close_agent(cls(**apply(base, setting)))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"--space: agent '{agent}' refuses {setting}: {exc}") from None


def setting_digest(params: dict[str, Any]) -> str:
    """The folder name of a setting's trial run (the same setting resumes the same run)."""
    text = json.dumps(params, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass
class TuneSpec:
    """What a search is: stored in ``<out>/tune-spec.json``; a resume must match it."""

    env_id: str
    agent: str
    space: list[dict[str, Any]]
    metric: str
    direction: str
    tune_sequences: list[str]
    validation_sequences: list[str]
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    agent_kwargs: dict[str, Any] = field(default_factory=dict)

    def check_against(self, out: Path) -> None:
        """Write the spec, or refuse when ``out`` holds another search."""
        path = out / "tune-spec.json"
        mine = json.loads(json.dumps(asdict(self), default=repr))
        if path.is_file():
            stored = json.loads(path.read_text(encoding="utf-8"))
            changed = sorted(k for k in mine if stored.get(k) != mine[k])
            if changed:
                raise ValueError(f"{out} holds another search (its {', '.join(changed)} "
                                 "differ); use another --out")
        else:
            atomic_write_text(path, json.dumps(mine, indent=2))


def _check_sequences(env_id: str, env_kwargs: dict[str, Any], metric: str,
                     tune: list[str], validation: list[str]) -> None:
    bench = benchmark_for(env_id, **env_kwargs)
    if metric not in bench.columns:
        raise ValueError(f"--metric {metric}: {env_id} scores {', '.join(bench.columns)}")
    for names, option in ((tune, "--tune-sequences"), (validation, "--validation-sequences")):
        select_sequences(names, bench.sequence_names, f"{option} of {env_id}")
    both = sorted(set(tune) & set(validation))
    if both:
        raise ValueError(f"{', '.join(both)} in both --tune-sequences and "
                         "--validation-sequences: the validation split must be unseen")


def _cache_option(agent: str, base: dict[str, Any], out: Path) -> dict[str, Any]:
    """``base`` with the search's own feature cache, when the agent has one and none is set."""
    if "feature_cache" in agent_options(agent_class(agent)) and "feature_cache" not in base:
        return {**base, "feature_cache": str((out / "feature-cache").resolve())}
    return base


@contextlib.contextmanager
def _cache_tracking(base: dict[str, Any]) -> Iterator[Callable[[], str | None]]:
    """The feature cache's hits and misses in the block (None without a cache folder)."""
    folder = base.get("feature_cache")
    if not isinstance(folder, str):
        yield lambda: None
        return
    # lazy: start-up cost (the appearance package loads torch, +1.4 s; only cached agents need it)
    from unitrack_env.agents.appearance.cache_runs import track_cache_run

    with track_cache_run(folder) as cache_run:
        yield cache_run.summary


def _optuna() -> Any:
    try:
        import optuna  # lazy: optional dependency (optuna, [tune])
    except ImportError:
        raise ImportError("unitrack tune needs Optuna: pip install 'unitrack-env[tune]'") \
            from None
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def _study(optuna: Any, out: Path, direction: str, seed: int) -> Any:
    """The study in ``<out>/optuna.db``; trials interrupted before are queued again.

    The sampler's seed moves on with the trials already there: a resumed search does not
    draw the settings it drew before.
    """
    storage = f"sqlite:///{(out / 'optuna.db').resolve()}"
    study = optuna.load_study(study_name=STUDY, storage=storage) if (
        out / "optuna.db").is_file() and STUDY in optuna.get_all_study_names(storage) else None
    done = len(study.trials) if study is not None else 0
    study = optuna.create_study(study_name=STUDY, storage=storage, load_if_exists=True,
                                direction=direction,
                                sampler=optuna.samplers.TPESampler(seed=seed + done))
    finished = {setting_digest(t.params) for t in study.trials if t.state.name == "COMPLETE"}
    finished |= {setting_digest(t.system_attrs.get("fixed_params", {}))  # queued already
                 for t in study.trials if t.state.name == "WAITING"}
    for t in study.trials:
        if t.state.name in ("FAIL", "RUNNING") and setting_digest(t.params) not in finished:
            if t.state.name == "RUNNING":  # killed, not interrupted: mark it over
                study._storage.set_trial_state_values(t._trial_id, optuna.trial.TrialState.FAIL)
            study.enqueue_trial(t.params)  # (skip_if_exists would see the failed one)
            finished.add(setting_digest(t.params))
    return study


def play_trial(spec: TuneSpec, base: dict[str, Any], params: dict[str, Any],
               out: Path) -> dict[str, Any]:
    """Play one setting on the tuning split in ``<out>/trials/<digest>`` (both backends).

    Returns its value, seconds, CPU seconds, sequences played, cache summary and folder. A
    folder finished before is read back, not played again (``played`` is then 0).
    """
    folder = out / "trials" / setting_digest(params)
    started, cpu = time.monotonic(), time.process_time()
    with _cache_tracking(base) as cache_summary:
        report = run(spec.env_id, spec.agent, out=folder, env_kwargs=spec.env_kwargs,
                     agent_kwargs=apply(base, params), sequences=spec.tune_sequences,
                     progress=False)
    seconds, cpu = time.monotonic() - started, time.process_time() - cpu
    value = (report.scores.combined if report.scores else {}).get(spec.metric)
    if value is None or not math.isfinite(value):
        raise ValueError(f"{spec.metric} is undefined on the tuning split for {params}")
    return {"value": float(value), "seconds": seconds, "cpu_seconds": cpu,
            "played": len(report.records) - len(report.skipped),
            "feature_cache": cache_summary(), "folder": str(folder.relative_to(out))}


def _objective(spec: TuneSpec, space: list[Dimension], base: dict[str, Any], out: Path,
               on_trial: Callable[[dict[str, Any]], None] | None) -> Callable[[Any], float]:
    def objective(trial: Any) -> float:
        params = {d.name: d.suggest(trial) for d in space}
        trial.set_user_attr("folder", str(Path("trials", setting_digest(params))))
        row = play_trial(spec, base, params, out)
        for name in ("seconds", "cpu_seconds", "played", "feature_cache"):
            trial.set_user_attr(name, row[name])
        if on_trial is not None:
            on_trial({"number": trial.number, "params": params, **row})
        return row["value"]

    return objective


def history(study: Any) -> list[dict[str, Any]]:
    """Every trial: number, state, setting, value, seconds, sequences played, folder."""
    keys = ("seconds", "cpu_seconds", "played", "feature_cache", "folder")
    return [{"number": t.number, "state": t.state.name, "params": t.params, "value": t.value,
             **{k: t.user_attrs.get(k) for k in keys}} for t in study.trials]


def _median(values: list[float]) -> float:
    values = sorted(values)
    middle = len(values) // 2
    return values[middle] if len(values) % 2 else (values[middle - 1] + values[middle]) / 2


def trial_cost(rows: list[dict[str, Any]]) -> dict[str, float] | None:
    """The first trial against the median of the later ones that played.

    None when the first trial (the one that ran the backbone) was interrupted: its cost is
    not recorded. In wall-clock and in CPU seconds (CPU time is the steadier on a shared machine).
    """
    played = [r for r in rows if r["state"] == "COMPLETE" and r["played"]]
    if len(played) < 2 or played[0]["number"] != rows[0]["number"]:
        return None  # the first trial (the one that ran the backbone) was interrupted
    out = {}
    for key, name in (("seconds", ""), ("cpu_seconds", "cpu_")):
        if all(r.get(key) is not None for r in played):
            later = _median([r[key] for r in played[1:]])
            out |= {f"first_{name}seconds": played[0][key],
                    f"later_median_{name}seconds": later, f"{name}ratio": later / played[0][key]}
    return out


def validate(spec: TuneSpec, base: dict[str, Any], best: dict[str, Any],
             out: Path) -> dict[str, Any]:
    """Play the defaults and the best setting on the validation split; compare them.

    The interval is ``unitrack compare``'s (paired jackknife, best minus defaults) where
    the task and metric have one; otherwise only both values are given.
    """
    folders = {"defaults": out / "validation" / "defaults",
               "best": out / "validation" / f"best-{setting_digest(best)}"}
    values = {}
    for name, folder in folders.items():
        report = run(spec.env_id, spec.agent, out=folder, env_kwargs=spec.env_kwargs,
                     agent_kwargs=apply(base, best if name == "best" else {}),
                     sequences=spec.validation_sequences, progress=False)
        values[name] = (report.scores.combined if report.scores else {}).get(spec.metric)
    result: dict[str, Any] = {"sequences": spec.validation_sequences, "metric": spec.metric,
                              **values, "folders": {k: str(v.relative_to(out))
                                                    for k, v in folders.items()}}
    bench = benchmark_for(spec.env_id, **spec.env_kwargs)
    if not bench.intervals:
        result["note"] = f"no interval: `compare` refuses {bench.task} runs ({bench.no_intervals})"
        return result
    comparison = compare_runs(folders["best"], folders["defaults"])
    diff = comparison.rows[COMBINED].get(spec.metric)
    if diff is None:
        result["note"] = f"no interval: `compare` has none for {spec.metric}"
    else:
        result.update(diff=diff.diff, low=diff.low, high=diff.high, reliable=diff.reliable,
                      significant=diff.significant)
    result["notes"] = comparison.notes
    return result


#: A search: (spec, space, base options, out, trials, seed, on_trial) -> (best, history).
Search = Callable[[TuneSpec, list[Dimension], dict[str, Any], Path, int, int,
                   Callable[[dict[str, Any]], None] | None],
                  tuple[dict[str, Any], list[dict[str, Any]]]]


def optuna_search(spec: TuneSpec, space: list[Dimension], base: dict[str, Any], out: Path,
                  trials: int, seed: int, on_trial: Callable[[dict[str, Any]], None] | None
                  ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The study in ``<out>/optuna.db``, run until ``trials`` trials are complete."""
    study = _study(_optuna(), out, spec.direction, seed)
    complete = sum(t.state.name == "COMPLETE" for t in study.trials)
    if complete < trials:
        study.optimize(_objective(spec, space, base, out, on_trial),
                       n_trials=trials - complete, catch=())
    best = study.best_trial
    return {"number": best.number, "params": best.params, "value": best.value}, history(study)


def tune(spec: TuneSpec, *, out: str | os.PathLike, trials: int, seed: int = 0,
         on_trial: Callable[[dict[str, Any]], None] | None = None,
         search: Search = optuna_search, backend: str = "optuna",
         check: Callable[[], Any] = _optuna) -> dict[str, Any]:
    """Search, validate, write ``<out>/tune.json``; return its content.

    Resumable: the same call on the same ``out`` continues the search until ``trials``
    trials are complete (those done are kept, an interrupted one resumes in its folder).
    ``search`` is Optuna's by default (``backend`` names it in the result; ``check``
    refuses a missing library before anything runs).
    """
    space = [Dimension(**d) for d in spec.space]
    _check_sequences(spec.env_id, spec.env_kwargs, spec.metric, spec.tune_sequences,
                     spec.validation_sequences)
    check_space(spec.agent, space, spec.agent_kwargs)
    check()
    out = Path(out).resolve()
    check_out_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    with hold_folder(out, f"tune {spec.agent} on {spec.env_id}"):
        spec.check_against(out)
        base = _cache_option(spec.agent, spec.agent_kwargs, out)
        best, rows = search(spec, space, base, out, trials, seed, on_trial)
        result = {"spec": json.loads(json.dumps(asdict(spec), default=repr)),
                  "backend": backend, "best": best, "history": rows,
                  "cost": trial_cost(rows), "validation": validate(spec, base, best["params"],
                                                                   out)}
        atomic_write_text(out / "tune.json", json.dumps(result, indent=2, default=repr))
    return result

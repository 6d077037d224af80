"""``unitrack tune --backend ray``: the search's trials as Ray Tune trials.

The same trial as on Optuna (:func:`.search.play_trial`: a run folder ``<out>/trials/<digest>``
on the tuning split, the shared feature cache), drawn by Ray Tune's ``OptunaSearch`` (TPE,
seeded) and scheduled by a ``tune.Tuner`` on a local Ray or a cluster (``address``). Each
trial asks for one CPU. On a cluster ``<out>`` must be a folder every node sees (a shared
file system): the trial folders, the feature cache and Ray Tune's experiment
(``<out>/ray/unitrack-tune``) live there.

Resume is Ray Tune's experiment restore: the same command on the same ``<out>`` restores
the experiment, keeps its finished trials and plays the unfinished ones again (an
interrupted trial continues in its run folder: its finished sequences are kept).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .search import Dimension, TuneSpec, play_trial

#: The experiment's name inside ``<out>/ray``.
EXPERIMENT = "unitrack-tune"


def check_ray_tune() -> None:
    """Refuse a missing Ray Tune (or its ``pyarrow``) before anything runs."""
    try:
        # lazy: optional dependency (ray[tune])
        import ray.tune  # noqa: F401
        from ray.tune.search.optuna import OptunaSearch  # noqa: F401
    except ImportError:
        raise ImportError("unitrack tune --backend ray needs Ray Tune and Optuna: pip install "
                          "'unitrack-env[ray,tune]'") from None


def _domain(d: Dimension) -> Any:
    from ray import tune  # lazy: optional dependency (ray[tune])

    if d.choices:
        return tune.choice(list(d.choices))
    if isinstance(d.low, int) and isinstance(d.high, int):  # Ray's integer upper is exclusive
        return (tune.lograndint if d.log else tune.randint)(d.low, d.high + 1)
    return (tune.loguniform if d.log else tune.uniform)(float(d.low), float(d.high))


def _trainable(spec: TuneSpec, base: dict[str, Any], names: list[str],
               out: Path) -> Callable[[dict[str, Any]], None]:
    def trial(config: dict[str, Any]) -> None:
        import time

        from ray import tune  # lazy: optional dependency (ray[tune])

        started = time.time()
        row = play_trial(spec, base, {n: config[n] for n in names}, out)
        tune.report({**row, "started": started})

    return trial


def _history(grid: Any, names: list[str]) -> list[dict[str, Any]]:
    """Every trial, in the order they started (errored ones last), as Optuna's history."""
    keys = ("value", "seconds", "cpu_seconds", "played", "feature_cache", "folder")
    results = sorted(grid, key=lambda r: (r.error is not None,
                                          (r.metrics or {}).get("started", 0.0)))
    rows = []
    for number, r in enumerate(results):
        metrics = r.metrics or {}
        state = "FAIL" if r.error else "COMPLETE" if "value" in metrics else "STOPPED"
        rows.append({"number": number, "state": state,
                     "params": {n: (r.config or {}).get(n) for n in names},
                     **{k: metrics.get(k) for k in keys}})
    return rows


def ray_search(address: str | None = None) -> Callable[..., Any]:
    """A search for :func:`.search.tune` on Ray Tune (local Ray when ``address`` is None)."""

    def search(spec: TuneSpec, space: list[Dimension], base: dict[str, Any], out: Path,
               trials: int, seed: int, on_trial: Callable[[dict[str, Any]], None] | None
               ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
        import optuna  # lazy: optional dependency (optuna)
        import ray  # lazy: optional dependency (ray[tune])
        from ray import tune  # lazy: optional dependency (ray[tune])
        from ray.tune.search.optuna import OptunaSearch  # lazy: optional dependency (ray[tune])

        # Trials keep the command's working directory (relative data paths stay valid).
        os.environ.setdefault("RAY_CHDIR_TO_TRIAL_DIR", "0")
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        started = not ray.is_initialized()
        if started:
            ray.init(address=address, num_cpus=1 if address is None else None,
                     include_dashboard=False, log_to_driver=False, configure_logging=False)
        try:
            grid = _fit(spec, space, base, out, trials, seed, on_trial, tune, OptunaSearch)
        finally:
            if started:
                ray.shutdown()
        names = [d.name for d in space]
        rows = _history(grid, names)
        complete = [r for r in rows if r["state"] == "COMPLETE"]
        errors = [r.error for r in grid if r.error is not None]
        if errors:
            raise ValueError(f"{len(errors)} trial(s) failed (the same command plays them "
                             f"again): {errors[0]}")
        if any(r["state"] == "STOPPED" for r in rows):
            raise KeyboardInterrupt  # stopped before the end: the same command resumes
        if len(complete) < trials:
            raise ValueError(f"the Ray Tune experiment in {out / 'ray'} has {len(rows)} "
                             f"trials: on Ray, --trials is the first run's ({len(rows)}); "
                             "use another --out for more")
        pick = max if spec.direction == "maximize" else min
        best = pick(complete, key=lambda r: r["value"])
        return {k: best[k] for k in ("number", "params", "value")}, rows

    return search


def _fit(spec: TuneSpec, space: list[Dimension], base: dict[str, Any], out: Path,
         trials: int, seed: int, on_trial: Callable[[dict[str, Any]], None] | None,
         tune: Any, optuna_search: Any) -> Any:
    """Restore the experiment in ``<out>/ray`` or start it; run it to the end."""
    names = [d.name for d in space]
    trainable = tune.with_resources(_trainable(spec, base, names, out), {"cpu": 1})
    path = out / "ray" / EXPERIMENT
    if tune.Tuner.can_restore(str(path)):
        tuner = tune.Tuner.restore(str(path), trainable, resume_unfinished=True,
                                   resume_errored=True)
    else:
        searcher = optuna_search(metric="value", mode=spec.direction[:3], seed=seed)
        callbacks = [_Printer(on_trial, names)] if on_trial is not None else []
        tuner = tune.Tuner(
            trainable, param_space={d.name: _domain(d) for d in space},
            tune_config=tune.TuneConfig(search_alg=searcher, num_samples=trials),
            run_config=tune.RunConfig(name=EXPERIMENT, storage_path=str(out / "ray"),
                                      verbose=0, callbacks=callbacks))
    return tuner.fit()


class _Printer:
    """A Ray Tune callback: each finished trial's row to ``on_trial`` (as on Optuna).

    Ray Tune stores its callbacks with the experiment; a stored one prints nothing.
    """

    def __new__(cls, on_trial: Callable[[dict[str, Any]], None], names: list[str]) -> Any:
        from ray.tune import Callback  # lazy: optional dependency (ray[tune])

        class Printer(Callback):
            def on_trial_result(self, iteration: int, trials: list, trial: Any,
                                result: dict[str, Any], **info: Any) -> None:
                if on_trial is None or self.__dict__.get("stored"):
                    return
                keys = ("value", "seconds", "cpu_seconds", "played", "feature_cache")
                on_trial({"number": trials.index(trial),
                          "params": {n: trial.config.get(n) for n in names},
                          **{k: result.get(k) for k in keys}})

            def __reduce__(self) -> Any:
                return (_stored, ())

        return Printer()


def _stored() -> Any:
    """What a stored :class:`_Printer` comes back as: a callback that does nothing."""
    from ray.tune import Callback  # lazy: optional dependency (ray[tune])

    return Callback()

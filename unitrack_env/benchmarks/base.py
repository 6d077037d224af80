"""What every benchmark shares: ground truth, the official result format, folder scoring.

A benchmark is the evaluation half of a task (as in TrackEval): it knows which sequences
can be scored, writes and reads results in the official format, scores folders and names
the table columns. It never plays an episode, so a folder can be scored on its own.
``results`` is what an environment records for one sequence; each subclass states its form.
"""

from __future__ import annotations

import hashlib
import os
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
from PIL import Image

from unitrack_env.benchmarks.views import Attributes, Curve, ReportView, ScorecardColumn
from unitrack_env.errors import DataFormatError
from unitrack_env.fingerprint import sequence_files
from unitrack_env.metrics.report import ScoreReport
from unitrack_env.roots import resolve_root

if TYPE_CHECKING:
    import pandas as pd

    from unitrack_env.metrics.events_mot import EventRows
    from unitrack_env.metrics.mot_stats import MotStats


def data_root(root: str | os.PathLike | None, folder: str, *synthetic_args: Any,
              **synthetic_kwargs: Any) -> tuple[Path, bool]:
    """The data set folder to read and whether it is the embedded synthetic default.

    ``root`` wins, then ``$UNITRACK_DATA/<folder>``, else the synthetic data (built once).
    """
    path = resolve_root(root, folder)
    if path is not None:
        return path, False
    # lazy: start-up cost (unitrack_env.datasets.synthetic, every generator)
    from unitrack_env.datasets.synthetic.cache import ensure_synthetic

    return Path(ensure_synthetic(*synthetic_args, **synthetic_kwargs)), True


def select_sequences(requested: Iterable[str] | None, available: Iterable[str],
                     where: object) -> list[str]:
    """Validate a user's ``sequences=`` against the data set (None: all of them)."""
    available = list(available)
    if requested is None:
        return available
    requested = [requested] if isinstance(requested, str) else list(requested)
    missing = [s for s in requested if s not in available]
    if missing:
        raise ValueError(
            f"sequences {missing} are not in {where}; available: {', '.join(available)}")
    return requested


def one_of(label: str, value: str, valid: Iterable[str]) -> str:
    """``value`` if it is one of ``valid`` (e.g. a rule set), else a ValueError naming them."""
    valid = list(valid)
    if value not in valid:
        raise ValueError(f"unknown {label} '{value}'; valid: {valid}")
    return value


#: A sequence record type of a data set reader.
SequenceT = TypeVar("SequenceT")


def rounded_digest(rows: np.ndarray) -> str:
    """SHA-256 of an array rounded to 1e-3 (the digest of numeric results)."""
    return hashlib.sha256(np.ascontiguousarray(np.round(rows, 3)).tobytes()).hexdigest()


def text_digest(text: str) -> str:
    """SHA-256 of a result text (the digest of results whose official form is text)."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class Benchmark(ABC):
    """One task's evaluation: ground-truth facts, official result files, folder scoring.

    Subclasses set :attr:`task` and :attr:`columns` and implement the abstract methods.
    :meth:`build` is the task's one builder, used by its environment and by
    :func:`unitrack_env.benchmarks.benchmark_for`. Everything else evaluation asks per task
    (error events, intervals, the report's drawing, the scorecard column) is a hook below
    whose default states that the task has none; evaluation never tests a task's name.
    """

    #: The task family (``"mot"``, ``"vos"``, ...), as in the registration table.
    task: ClassVar[str] = ""
    #: Result columns of tables (the metrics' official names), most important first.
    columns: ClassVar[tuple[str, ...]] = ()

    def __init__(self, dataset: Any, *, synthetic: bool = False) -> None:
        self.dataset = dataset
        self.synthetic = synthetic
        self._loaded: dict[str, Any] = {}

    def _load_once(self, name: str, read: Callable[[str], SequenceT]) -> SequenceT:
        """Sequence ``name`` as ``read`` returns it, read on the first call only."""
        if name not in self._loaded:
            self._loaded[name] = read(name)
        return self._loaded[name]

    @classmethod
    @abstractmethod
    def build(cls, *args: Any, **kwargs: Any) -> Benchmark:
        """Build the benchmark: resolve the data root and read the data set.

        Its named parameters are the environment's data arguments (``root``, ``split``, ...).
        """

    @property
    @abstractmethod
    def name(self) -> str:
        """The rule set scored, as score reports name it (``"MOT17"``, ``"DAVIS-2017"``)."""

    @property
    def sequence_names(self) -> list[str]:
        """Every sequence of the data set's split."""
        return list(self.dataset.sequence_names)

    def scorable(self, sequences: Iterable[str] | None = None) -> list[str]:
        """The sequences (default: all) that have ground truth to score against."""
        names = self.sequence_names if sequences is None else list(sequences)
        return [name for name in names if self.has_ground_truth(name)]

    @abstractmethod
    def sequence_length(self, name: str) -> int:
        """Number of frames (episode steps) of sequence ``name``, without loading it."""

    @abstractmethod
    def has_ground_truth(self, name: str) -> bool:
        """Whether sequence ``name`` can be scored."""

    @abstractmethod
    def write(self, folder: str | os.PathLike, sequence: str, results: Any) -> None:
        """Write one sequence's results below ``folder`` in the official format, atomically."""

    @abstractmethod
    def read(self, folder: str | os.PathLike, sequence: str) -> Any:
        """Read one sequence's result file(s) back from ``folder``."""

    def write_repetitions(self, folder: str | os.PathLike, sequence: str, runs: list[Any],
                          seconds: list[list[float]] | None = None) -> None:
        """Write every repetition of one sequence (``runs[0]`` is repetition 1), atomically.

        ``seconds``: each repetition's per-frame times of the agent. Default: repetition 1 as
        :meth:`write` writes it, repetition ``k`` the same way into
        ``<folder>/repeat-<k:03d>/`` (:func:`repetition_folder`); the times are not written.
        """
        for k, results in enumerate(runs, start=1):
            self.write(repetition_folder(folder, k), sequence, results)

    def score_repetition(self, folder: str | os.PathLike, sequences: list[str],
                         repetition: int) -> ScoreReport:
        """Score repetition ``repetition`` (1-based) alone, as :meth:`write_repetitions` wrote it.

        Default: :meth:`score_files` on :func:`repetition_folder`.
        """
        return self.score_files(repetition_folder(folder, repetition), sequences)

    @abstractmethod
    def digest(self, results: Any) -> str:
        """A stable SHA-256 digest of one sequence's results (the recorded actions)."""

    def has_results(self, folder: str | os.PathLike, name: str) -> bool:
        """Whether ``folder`` holds a result file of sequence ``name`` (any file of its)."""
        folder = Path(folder)
        return folder.is_dir() and bool(sequence_files(folder, name, self.sequence_names,
                                                       shared=False))

    def score_folder(self, folder: str | os.PathLike, sequences: Iterable[str] | None = None,
                     *, allow_missing: bool = False) -> ScoreReport:
        """Score the result files of ``sequences`` (default: every scorable one) in ``folder``.

        Missing result files raise MissingResults naming them (a partial split is not the
        benchmark's score) unless ``allow_missing``; the report's coverage says what was scored.
        """
        folder = Path(folder)
        if not folder.is_dir():
            raise DataFormatError(folder, "is a file; the results are a folder of result files"
                                  if folder.is_file() else "results folder not found")
        refuse_run_folder(folder)
        names = self.scorable() if sequences is None else list(dict.fromkeys(sequences))
        missing = [name for name in names if not self.has_results(folder, name)]
        if missing and (not allow_missing or len(missing) == len(names)):
            raise MissingResults(folder, missing, len(names), allow_missing)
        present = [name for name in names if name not in missing]
        report = self.score_files(folder, present)
        report.sequences_of = len(set(names) | set(self.scorable()))
        report.missing = missing
        return report

    @abstractmethod
    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score the result files of ``sequences`` (all present) with the official metrics."""

    @abstractmethod
    def score_sequence(self, sequence: str, results: Any) -> dict[str, float]:
        """The official metrics of one sequence's results.

        The environment's default ``episode_metrics`` puts them in ``info["metrics"]``.
        """

    # ---- what evaluation asks besides scoring; each default: the task has none ----------

    #: How ``unitrack report`` draws one sequence (default: no per-frame events shown).
    report_view: ClassVar[ReportView] = ReportView()
    #: The task's column of ``unitrack scorecard`` (None: not on the scorecard).
    scorecard: ClassVar[ScorecardColumn | None] = None
    #: How ``compare`` and ``scorecard --ci`` get intervals: ``"stats"`` (metrics recomputed
    #: from per-frame statistics, :meth:`frame_stats`), ``"frames"`` (metrics that are means
    #: over frames, :attr:`frame_metrics`), ``"counts"`` (each sequence's metrics are a
    #: function, :meth:`metrics_of_counts`, of per-frame additive counts, :meth:`frame_counts`,
    #: and the combined score is their mean over sequences) or ``""`` (none:
    #: :attr:`no_intervals` says why).
    intervals: ClassVar[str] = ""
    #: Why the task's metrics get no interval (``compare``'s refusal).
    no_intervals: ClassVar[str] = "its metrics are not means over frames"
    #: With ``intervals="frames"``: each interval metric's per-frame values, computed from
    #: the ``"frame"`` events of one sequence (a DataFrame of :meth:`sequence_events` rows).
    frame_metrics: ClassVar[Mapping[str, Callable[[pd.DataFrame], np.ndarray]]] = \
        MappingProxyType({})

    def sequence_events(self, folder: str | os.PathLike, sequence: str) -> EventRows | None:
        """The error events of one sequence's result files in ``folder``.

        Default None: the task has no per-frame events (``unitrack events`` says so).
        """
        return None

    def curves(self, folder: str | os.PathLike, sequences: list[str]) -> list[Curve]:
        """The plots of the combined scores of ``folder``'s result files (``unitrack plot``).

        Default []: the task has no such plots.
        """
        return []

    def sequence_attributes(self, sequences: list[str]) -> Attributes | None:
        """The challenge attributes of ``sequences`` (``unitrack plot --attributes``).

        Default None: the benchmark tags no attributes (or none of these sequences).
        """
        return None

    def frame_stats(self, folder: str | os.PathLike, sequence: str,
                    cls: str | None = None) -> MotStats:
        """With ``intervals="stats"``: one sequence's per-frame statistics of its results.

        ``cls``: one of :meth:`stat_classes` only (None: every class together).
        """
        raise NotImplementedError(f"{type(self).__name__} has no per-frame statistics")

    def stat_classes(self) -> tuple[str, ...]:
        """With ``intervals="stats"``: the classes :meth:`frame_stats` also gives one by one.

        Default (): the metrics have no classes.
        """
        return ()

    def frame_counts(self, folder: str | os.PathLike, sequence: str) -> dict[str, np.ndarray]:
        """With ``intervals="counts"``: ``{count: (frames,) per-frame values}`` of one sequence.

        Each count is additive over frames; summed over all frames, they give the sequence's
        metrics through :meth:`metrics_of_counts`.
        """
        raise NotImplementedError(f"{type(self).__name__} has no per-frame counts")

    def metrics_of_counts(self, counts: Mapping[str, float]) -> dict[str, float]:
        """With ``intervals="counts"``: a sequence's metrics from its summed counts."""
        raise NotImplementedError(f"{type(self).__name__} has no per-frame counts")

    def combine_weights(self, events: pd.DataFrame,
                        sequences: list[str]) -> dict[str, float] | None:
        """Each sequence's weight in the official combined score.

        ``events``: the run's ``"frame"`` events. Default None: all frames pooled.
        """
        return None

    def sequence_info(self, sequence: str) -> Any:
        """The dataset's ``info(sequence)``, else its loaded sequence's ``info`` or itself.

        What the report draws on (frame files, first frame, frame rate, annotations).
        """
        if callable(getattr(self.dataset, "info", None)):
            return self.dataset.info(sequence)
        loaded = self.dataset.load(sequence)
        return getattr(loaded, "info", None) or loaded

    def frame_image(self, sequence: str, frame: int) -> Path | None:
        """The image file of 1-based ``frame`` (the report's pictures).

        Default: the sequence info's ``frame_path`` (files numbered from its
        ``first_frame``), else the loaded sequence's ``frame_paths``; None when the dataset
        says neither or ``frame`` is out of range.
        """
        info = self.sequence_info(sequence)
        if callable(getattr(info, "frame_path", None)):
            return info.frame_path(int(getattr(info, "first_frame", 1)) + frame - 1)
        paths = tuple(getattr(info, "frame_paths", ()))
        return Path(paths[frame - 1]) if 1 <= frame <= len(paths) else None

    def frame_array(self, sequence: str, frame: int) -> np.ndarray | None:
        """1-based ``frame`` as uint8 RGB ``(H, W, 3)``, in the pixels its events are in.

        What the report draws on. Default: the file :meth:`frame_image` names, opened; None
        when there is none. A benchmark whose frames are not files (held in an archive or
        pickle) overrides this.
        """
        path = self.frame_image(sequence, frame)
        if path is None or not Path(path).is_file():
            return None
        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"))

    def frame_rate(self, sequence: str) -> float:
        """Frames per second of ``sequence`` (a clip's time of a frame).

        Default: the sequence info's ``frame_rate``, else 30.
        """
        return float(getattr(self.sequence_info(sequence), "frame_rate", 0) or 30.0)


def repetition_folder(folder: str | os.PathLike, repetition: int) -> Path:
    """Where repetition ``repetition`` (1-based) of a run's results is by default.

    ``folder`` itself for the first, ``<folder>/repeat-<k:03d>`` (``repeat-002`` ...) for the
    others.
    """
    return Path(folder) if repetition == 1 else Path(folder) / f"repeat-{repetition:03d}"


def refuse_run_folder(folder: str | os.PathLike) -> None:
    """Raise DataFormatError if ``folder`` is a run folder given where its ``data/`` belongs.

    Every form of ``unitrack score`` asks this one question before looking for result files.
    """
    folder = Path(folder)
    if (folder / "run.json").is_file() and (folder / "data").is_dir():
        raise DataFormatError(folder, "is the folder of a run; its result files are in "
                              f"{folder / 'data'}")


class MissingResults(DataFormatError):
    """Some sequences to score have no result file (``missing``, of ``expected``)."""

    def __init__(self, folder: Path, missing: list[str], expected: int,
                 allowed: bool = False) -> None:
        self.missing, self.expected, self.allowed = list(missing), expected, allowed
        shown = ", ".join(missing[:10]) + (f" and {len(missing) - 10} more"
                                           if len(missing) > 10 else "")
        if allowed:  # every one is missing: nothing to score
            advice = "nothing to score"
        else:
            advice = (f"a combined score over the other {expected - len(missing)} is not the "
                      "benchmark's; add --allow-missing (allow_missing=True) to score them "
                      "anyway")
        super().__init__(folder, f"no result file for {len(missing)} of the {expected} "
                                 f"sequences to score: {shown}; {advice}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.path, self.missing, self.expected, self.allowed))

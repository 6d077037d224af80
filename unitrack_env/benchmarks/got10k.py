"""GOT-10k's protocol (the ``got10k`` package, its own toolkit): AO, SR0.5, SR0.75, server files.

A :class:`~unitrack_env.benchmarks.otb.OTBBenchmark` of the ``"got10k"`` data format (its
reader: :class:`~unitrack_env.datasets.lasot.GOT10kDataset`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from unitrack_env.benchmarks.otb import OTBBenchmark, format_otb_results
from unitrack_env.benchmarks.sot_columns import GOT10K_COLUMN
from unitrack_env.benchmarks.views import Curve
from unitrack_env.datasets.sot import SOTSequence, read_box_file
from unitrack_env.errors import DataFormatError
from unitrack_env.io import atomic_write_text
from unitrack_env.metrics.report import ScoreReport
from unitrack_env.metrics.sot import bounded_overlap, got10k_overlaps, got10k_scores

if TYPE_CHECKING:
    import pandas as pd


class GOT10kBenchmark(OTBBenchmark):
    """GOT-10k's protocol: AO, SR0.5 and SR0.75 over the visible frames after the first.

    Results are written as the evaluation server's layout, ``<folder>/<seq>/<seq>_001.txt``
    (one ``x,y,w,h`` line per frame; ``_002``, ``_003`` for further repetitions, all pooled
    when scoring, as the toolkit does) and, from a run, ``<seq>/<seq>_time.txt``: the agent's
    seconds per frame, one comma-separated column per repetition (``%.8f``, as the toolkit's
    ``ExperimentGOT10k._record`` writes it). Frames the reader flags absent (``cover == 0``)
    are left out and boxes are clipped to the image; the combined row pools the frames of
    every sequence (not a mean of sequences).
    """

    columns = ("AO", "SR0.5", "SR0.75")
    scorecard = GOT10K_COLUMN

    @property
    def frame_metrics(self) -> Mapping[str, Callable[[pd.DataFrame], np.ndarray]]:
        """Per-frame AO, SR0.5 and SR0.75 (NaN for frames not scored: the first, absent ones).

        Weighted by visible frames (:meth:`combine_weights`) their means pool the frames, as
        the score does; the events hold repetition 1 (what ``unitrack evaluate`` writes).
        """
        def at(threshold: float | None) -> Callable[[pd.DataFrame], np.ndarray]:
            def per_frame(d: pd.DataFrame) -> np.ndarray:
                o = self._frame_overlaps(d)
                return o if threshold is None else np.where(np.isnan(o), np.nan, o > threshold)
            return per_frame

        return MappingProxyType({"AO": at(None), "SR0.5": at(0.5), "SR0.75": at(0.75)})

    def _frame_overlaps(self, d: pd.DataFrame) -> np.ndarray:
        loaded = self.load(str(d["sequence"].iloc[0]))
        rows = d["frame"].to_numpy(int) - 1
        pred = d[["tx", "ty", "tw", "th"]].to_numpy(float)
        overlaps = bounded_overlap(pred, loaded.boxes[rows], loaded.image_size)
        return np.where((rows == 0) | np.asarray(loaded.absent, bool)[rows], np.nan, overlaps)

    def _event_predictions(self, results: np.ndarray, gt: np.ndarray) -> np.ndarray:
        """The boxes as written: GOT-10k scores them unrepaired."""
        return np.asarray(results, dtype=np.float64)

    def _result_path(self, folder: str | os.PathLike, sequence: str, repetition: int = 1,
                     ) -> Path:
        return Path(folder) / sequence / f"{sequence}_{repetition:03d}.txt"

    def write(self, folder: str | os.PathLike, sequence: str, results: np.ndarray) -> None:
        """Write ``<folder>/<seq>/<seq>_001.txt`` (the server's layout), atomically."""
        atomic_write_text(self._result_path(folder, sequence), format_otb_results(results))

    def write_repetitions(self, folder: str | os.PathLike, sequence: str, runs: list[np.ndarray],
                          seconds: list[list[float]] | None = None) -> None:
        """Write ``<seq>/<seq>_<k>.txt`` for each repetition and ``<seq>_time.txt``, atomically.

        ``seconds``: each repetition's per-frame times (the time file's columns).
        """
        for k, results in enumerate(runs, start=1):
            path = self._result_path(folder, sequence, k)
            atomic_write_text(path, format_otb_results(results))
        if seconds:
            table = np.column_stack([np.asarray(s, dtype=np.float64) for s in seconds])
            atomic_write_text(Path(folder) / sequence / f"{sequence}_time.txt",
                              "".join(",".join(f"{v:.8f}" for v in row) + "\n" for row in table))

    def read(self, folder: str | os.PathLike, sequence: str) -> np.ndarray:
        """Read repetition 1; DataFormatError unless it has one box per frame."""
        return self._read_run(self._result_path(folder, sequence), self.load(sequence))

    def _read_run(self, path: Path, loaded: SOTSequence) -> np.ndarray:
        if not path.is_file():
            raise DataFormatError(path, f"no result file for sequence '{loaded.name}'")
        boxes = read_box_file(path)
        if len(boxes) != loaded.num_frames:
            raise DataFormatError(path, f"has {len(boxes)} boxes but '{loaded.name}' has "
                                        f"{loaded.num_frames} frames")
        return boxes

    def _overlaps(self, sequence: SOTSequence, results: np.ndarray) -> np.ndarray:
        cover = (~np.asarray(sequence.absent)).astype(int)
        return got10k_overlaps(results, sequence.boxes, cover, sequence.image_size)

    def score_sequence(self, sequence: str, results: np.ndarray) -> dict[str, float]:
        """AO, SR0.5 and SR0.75 of one run of a sequence."""
        loaded = self.load(sequence)
        return got10k_scores(self._overlaps(loaded, results))

    def score_files(self, folder: str | os.PathLike, sequences: list[str]) -> ScoreReport:
        """Score every repetition ``<seq>/<seq>_<k>.txt`` found, frames pooled."""
        per_sequence, pooled = {}, []
        for name in sequences:
            loaded = self.load(self.dataset.resolve(name))
            runs = sorted((Path(folder) / loaded.name).glob(f"{loaded.name}_[0-9][0-9][0-9].txt"))
            if not runs:
                runs = [self._result_path(folder, loaded.name)]  # its error names it
            overlaps = np.concatenate([self._overlaps(loaded, self._read_run(p, loaded))
                                       for p in runs])
            per_sequence[loaded.name] = got10k_scores(overlaps)
            pooled.append(overlaps)
        combined = got10k_scores(np.concatenate(pooled)) if pooled else {}
        return ScoreReport(self.name, per_sequence, combined)

    def score_repetition(self, folder: str | os.PathLike, sequences: list[str],
                         repetition: int) -> ScoreReport:
        """AO, SR0.5 and SR0.75 of repetition ``repetition``'s files alone (frames pooled)."""
        per_sequence, pooled = {}, []
        for name in sequences:
            loaded = self.load(self.dataset.resolve(name))
            path = self._result_path(folder, loaded.name, repetition)
            pooled.append(self._overlaps(loaded, self._read_run(path, loaded)))
            per_sequence[loaded.name] = got10k_scores(pooled[-1])
        combined = got10k_scores(np.concatenate(pooled)) if pooled else {}
        return ScoreReport(self.name, per_sequence, combined)

    def curves(self, folder: str | os.PathLike, sequences: list[str]) -> list[Curve]:
        """None drawn: GOT-10k's scores pool frames (OTB's plots would be another protocol)."""
        return []

    def combine_weights(self, events: pd.DataFrame, sequences: list[str]) -> dict[str, float]:
        """Visible frames after the first: GOT-10k pools frames."""
        return {s: float((~self.load(s).absent[1:]).sum()) for s in sequences}

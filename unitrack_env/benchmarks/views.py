"""What a benchmark declares for the report and the scorecard: plain values, no behaviour.

A :class:`~unitrack_env.benchmarks.base.Benchmark` subclass sets ``report_view`` (how
``unitrack report`` draws one of its sequences) and ``scorecard`` (its column of
``unitrack scorecard``: heads, baseline, metrics); evaluation reads them and never branches
on a task's name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

#: Every lane of box MOT's event timeline, in the order drawn.
ALL_LANES: tuple[str, ...] = ("fn", "fp", "idsw", "frag")


@dataclass(frozen=True)
class ReportView:
    """How the report draws a sequence of the task (the default: "No per-frame events")."""

    #: Event types drawn as lanes of counts per frame (empty: no lanes).
    lanes: tuple[str, ...] = ()
    #: What one count is ("masks", "joints"), said under the lanes ("": nothing said).
    unit: str = ""
    #: ``(events column, label)`` drawn as a curve over frames (None: no curve).
    value: tuple[str, str] | None = None
    #: Only events of this type carry :attr:`value` ("": every event row does).
    value_type: str = ""
    #: ID switches and bursts of misses pictured, from ``Benchmark.frame_image``.
    thumbnails: bool = False


@dataclass(frozen=True)
class Head:
    """One head (or baseline) of a task and the metrics the scorecard reports for it."""

    agent: str
    label: str
    metrics: tuple[str, ...]
    appearance: bool = True
    association: bool = False


@dataclass(frozen=True)
class ScorecardColumn:
    """A task's column of the scorecard.

    ``env_ids``: its environments, the first whose data folder is found wins (else the first
    one's synthetic default); ``axis``: the (head label, metric) drawn on the radar chart;
    ``order``: the column's place (the paper's Table 2 order); ``input_size``: the network
    input per frame of its appearance head, ``(images, height, width)``; ``head_seconds``:
    the head's own seconds per frame besides the backbone (None: the association heads');
    ``opt_in``: left out of the default task set, played only when asked for by name;
    ``task``: the column's name in the scorecard (``--tasks``), default the benchmark's task
    (a second column of a task, on another benchmark, needs its own); ``note``: a line the
    card prints under its table for this column (e.g. how far its numbers move).
    """

    title: str
    env_ids: tuple[str, ...]
    heads: tuple[Head, ...]
    baseline: Head
    axis: tuple[str, str]
    lower_is_better: frozenset[str] = frozenset()
    order: float = 100.0
    input_size: tuple[int, int, int] = (1, 512, 512)
    head_seconds: float | None = None
    opt_in: bool = False
    task: str = ""
    note: str = ""


def association_head(metrics: tuple[str, ...]) -> Head:
    """The ``unitrack`` association head (MOT, MOTS, PoseTrack, VIS) reporting ``metrics``."""
    return Head("unitrack", "UniTrack", metrics, association=True)


def iou_baseline(metrics: tuple[str, ...]) -> Head:
    """The appearance-free ``iou`` baseline reporting ``metrics``."""
    return Head("iou", "IoU baseline", metrics, appearance=False)


#: The network input of the association heads: the 1088 x 608 letterbox.
LETTERBOX: tuple[int, int, int] = (1, 608, 1088)


@dataclass(frozen=True)
class Curve:
    """One plot of a run's combined scores (a success or precision plot).

    ``x``: the thresholds; ``y``: the fraction of frames passing each; ``score``: what the
    legend shows, ``(metric, value)`` (``("AUC", 0.61)``).
    """

    title: str
    x_label: str
    x: tuple[float, ...]
    y: tuple[float, ...]
    score: tuple[str, float]


@dataclass(frozen=True)
class Attributes:
    """The challenge attributes of a benchmark's sequences (``unitrack plot --attributes``).

    ``codes`` and ``names``: every attribute, in the benchmark's order; ``of``: the codes of
    each sequence that has any record (a sequence missing here is in no attribute's row);
    ``metrics``: the result columns reported per attribute; ``source``: where the tags are
    from, said under the tables.
    """

    codes: tuple[str, ...]
    names: tuple[str, ...]
    of: Mapping[str, frozenset[str]]
    metrics: tuple[str, ...]
    source: str

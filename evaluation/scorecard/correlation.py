"""Correlation between two evaluations of the same models: Pearson's r and Spearman's rho.

Pure statistics, no I/O: :func:`correlate` takes paired values (one pair per model) and gives
both coefficients with percentile bootstrap intervals over models (models drawn with
replacement, a fixed seed, so the same numbers give the same interval). With fewer than
:data:`MIN_MODELS` models no coefficient is computed; with fewer than
:data:`MIN_TO_CONCLUDE` the coefficients are given but no interval and no conclusion: a
correlation over three or four points says next to nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Fewest models for a coefficient (two points always lie on a line).
MIN_MODELS = 3
#: Fewest models for a bootstrap interval and a conclusion.
MIN_TO_CONCLUDE = 5


def ranks(values: Sequence[float]) -> np.ndarray:
    """Ranks from 1, ties sharing their average rank (as Spearman's rho needs)."""
    x = np.asarray(values, dtype=float)
    order = np.argsort(x, kind="mergesort")
    sorted_x = x[order]
    out = np.empty(len(x))
    start = 0
    while start < len(x):
        stop = start
        while stop + 1 < len(x) and sorted_x[stop + 1] == sorted_x[start]:
            stop += 1
        out[order[start:stop + 1]] = (start + stop) / 2 + 1
        start = stop + 1
    return out


def pearson(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Pearson's r; None when either side is constant (r is undefined)."""
    a = np.asarray(x, dtype=float) - np.mean(x)
    b = np.asarray(y, dtype=float) - np.mean(y)
    denominator = np.sqrt(np.sum(a * a) * np.sum(b * b))
    if denominator == 0:
        return None
    return float(np.clip(np.sum(a * b) / denominator, -1.0, 1.0))


def spearman(x: Sequence[float], y: Sequence[float]) -> float | None:
    """Spearman's rho: Pearson's r of the (tie-averaged) ranks."""
    return pearson(ranks(x), ranks(y))


def bootstrap_interval(x: Sequence[float], y: Sequence[float], coefficient, *,
                       resamples: int = 2000, level: float = 0.95,
                       seed: int = 0) -> tuple[float, float] | None:
    """Percentile interval of ``coefficient(x, y)`` over models drawn with replacement.

    Draws where the coefficient is undefined (a constant side, e.g. one model drawn every
    time) are dropped; None when fewer than half of the draws are defined.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, len(x), size=(resamples, len(x)))
    values = [v for v in (coefficient(x[p], y[p]) for p in picks) if v is not None]
    if len(values) < resamples / 2:
        return None
    tail = (1 - level) / 2
    low, high = np.quantile(values, [tail, 1 - tail])
    return float(low), float(high)


@dataclass(frozen=True)
class Correlation:
    """Both coefficients between two evaluations over ``n`` models, and what they allow."""

    n: int
    pearson: float | None
    spearman: float | None
    pearson_ci: tuple[float, float] | None
    spearman_ci: tuple[float, float] | None
    verdict: str

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {"n": self.n, "pearson": self.pearson, "spearman": self.spearman,
                "pearson_ci": list(self.pearson_ci) if self.pearson_ci else None,
                "spearman_ci": list(self.spearman_ci) if self.spearman_ci else None,
                "verdict": self.verdict}


def _verdict(n: int, r: float | None, r_ci: tuple[float, float] | None,
             rho_ci: tuple[float, float] | None) -> str:
    if n < MIN_MODELS:
        return f"too few models ({n} < {MIN_MODELS}): no coefficient"
    if r is None:
        return "undefined: one of the two evaluations is the same for every model"
    if n < MIN_TO_CONCLUDE:
        return f"too few models to conclude ({n} < {MIN_TO_CONCLUDE}): no interval"
    if r_ci is None or rho_ci is None:
        return "no interval: most resamples are constant"
    if r_ci[0] > 0 and rho_ci[0] > 0:
        return "positive: both intervals exclude 0"
    if r_ci[1] < 0 and rho_ci[1] < 0:
        return "negative: both intervals exclude 0"
    return "no clear correlation: an interval contains 0"


def correlate(x: Sequence[float], y: Sequence[float], *, resamples: int = 2000,
              seed: int = 0) -> Correlation:
    """Pearson's r and Spearman's rho of paired values, with 95% bootstrap intervals."""
    if len(x) != len(y):
        raise ValueError(f"correlate needs paired values; got {len(x)} and {len(y)}")
    n = len(x)
    if n < MIN_MODELS:
        return Correlation(n, None, None, None, None, _verdict(n, None, None, None))
    r, rho = pearson(x, y), spearman(x, y)
    r_ci = rho_ci = None
    if n >= MIN_TO_CONCLUDE and r is not None:
        r_ci = bootstrap_interval(x, y, pearson, resamples=resamples, seed=seed)
        rho_ci = bootstrap_interval(x, y, spearman, resamples=resamples, seed=seed)
    return Correlation(n, r, rho, r_ci, rho_ci, _verdict(n, r, r_ci, rho_ci))

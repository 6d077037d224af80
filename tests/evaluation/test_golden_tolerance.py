"""Per-metric tolerances of golden files: names, patterns, default."""

from __future__ import annotations

from unitrack_env.evaluation.regression.golden import (
    DEFAULT_TOLERANCE,
    EpisodeRecord,
    compare_records,
    metric_tolerance,
)


def test_exact_name_then_pattern_then_default():
    tol = {"IDF1": 0.5, "IDF1/*": 0.1, "MOTA*": 0.2}
    assert metric_tolerance(tol, "IDF1") == 0.5
    assert metric_tolerance(tol, "IDF1/head_top") == 0.1
    assert metric_tolerance(tol, "MOTA/Knee") == 0.2
    assert metric_tolerance(tol, "IDSW") == DEFAULT_TOLERANCE
    assert metric_tolerance({"*": 3.0}, "anything") == 3.0
    assert metric_tolerance(0.25, "anything") == 0.25


def test_patterns_apply_in_comparisons():
    def record(**metrics: float) -> EpisodeRecord:
        return EpisodeRecord("E", "s", "a", metrics, "d", 3)

    golden, now = record(AUC=0.80, **{"PCK/a": 0.5}), record(AUC=0.82, **{"PCK/a": 0.56})
    assert compare_records(golden, now, tolerance={"AUC": 0.05, "PCK/*": 0.1}) == []
    problems = compare_records(golden, now, tolerance={"AUC": 0.05, "PCK/*": 0.01})
    assert len(problems) == 1 and "PCK/a" in problems[0]

"""Pearson's r and Spearman's rho with bootstrap intervals: hand-built cases, scipy as reference."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from unitrack_env.evaluation.scorecard.correlation import (
    MIN_TO_CONCLUDE,
    bootstrap_interval,
    correlate,
    pearson,
    ranks,
    spearman,
)


def test_known_answers():
    assert pearson([1, 2, 3], [2, 4, 6]) == pytest.approx(1.0)
    assert pearson([1, 2, 3], [3, 2, 1]) == pytest.approx(-1.0)
    # x = 1..4, y = 1,3,2,4: cov 4/... -> r = 0.8 exactly
    assert pearson([1, 2, 3, 4], [1, 3, 2, 4]) == pytest.approx(0.8)
    # monotone but not linear: rho is 1, r is not
    assert spearman([1, 2, 3, 4], [1, 8, 27, 1000]) == pytest.approx(1.0)
    assert pearson([1, 2, 3, 4], [1, 8, 27, 1000]) < 0.9
    assert pearson([1, 1, 1], [1, 2, 3]) is None  # a constant side: undefined


def test_ties_share_their_average_rank():
    assert list(ranks([10, 20, 20, 5])) == [2, 3.5, 3.5, 1]
    assert list(ranks([7, 7, 7])) == [2, 2, 2]


@pytest.mark.parametrize("seed", range(5))
def test_scipy_agrees_on_random_data_with_ties(seed):
    rng = np.random.default_rng(seed)
    x = rng.integers(0, 6, size=12).astype(float)  # ties on purpose
    y = x * 0.5 + rng.normal(size=12)
    assert pearson(x, y) == pytest.approx(stats.pearsonr(x, y).statistic, abs=1e-12)
    assert spearman(x, y) == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)


def test_bootstrap_interval_matches_scipy_percentile_bootstrap_loosely():
    rng = np.random.default_rng(3)
    x = rng.normal(size=30)
    y = x + rng.normal(size=30)
    low, high = bootstrap_interval(x, y, pearson, resamples=4000)
    reference = stats.bootstrap((x, y), lambda a, b: stats.pearsonr(a, b).statistic,
                                paired=True, vectorized=False, n_resamples=4000,
                                method="percentile", random_state=1).confidence_interval
    assert low < pearson(x, y) < high
    assert low == pytest.approx(reference.low, abs=0.05)
    assert high == pytest.approx(reference.high, abs=0.05)
    assert bootstrap_interval(x, y, pearson) == bootstrap_interval(x, y, pearson)  # seeded


def test_too_few_models_are_said_so():
    assert correlate([1, 2], [2, 1]).verdict.startswith("too few models (2 < 3)")
    four = correlate([1, 2, 3, 4], [1, 3, 2, 4])
    assert four.pearson == pytest.approx(0.8) and four.pearson_ci is None
    assert four.verdict == f"too few models to conclude (4 < {MIN_TO_CONCLUDE}): no interval"


def test_verdicts_over_enough_models():
    x = np.arange(20.0)
    assert correlate(x, 2 * x + 1).verdict == "positive: both intervals exclude 0"
    assert correlate(x, -x).verdict == "negative: both intervals exclude 0"
    noise = np.random.default_rng(0).normal(size=20)
    unclear = correlate(x, noise)
    assert unclear.verdict == "no clear correlation: an interval contains 0"
    assert unclear.pearson_ci[0] < 0 < unclear.pearson_ci[1]
    with pytest.raises(ValueError, match="paired values"):
        correlate([1, 2, 3], [1, 2])


# --- the study on a scorecard: options, CSV, files, figure bytes, report ---------------------

def _card(values: dict[str, float]) -> dict:
    """A scorecard of synthetic pose propagation with the given PCK@0.1 per model."""
    from unitrack_env.evaluation.scorecard.plan import BASELINE

    source = {"kind": "synthetic", "root": None, "env_id": "UniTrack/JHMDB-v0"}
    rows = [{"model": m, "task": "pose-prop", "head": "UniTrack" if m != BASELINE else
             "repeat-pose", "combined": {"PCK@0.1": v}, "per_sequence": {}, "source": source}
            for m, v in [*values.items(), (BASELINE, 0.1)]]
    return {"version": 1, "models": list(values), "tasks": ["pose-prop"],
            "sources": {"pose-prop": source}, "rows": rows, "runtime": "torch"}


def test_model_text_carries_external_metrics():
    from unitrack_env.evaluation.scorecard.correlation_study import (
        metric_direction,
        split_model_text,
    )

    assert split_model_text("moco.pth,label=MoCo-v2,probe:imagenet=71.1") == (
        "moco.pth,label=MoCo-v2", {"probe:imagenet": 71.1})
    assert split_model_text("random,normals:error:lower=21.5") == (
        "random", {"normals:error:lower": 21.5})
    assert metric_direction("normals:error:lower") == ("normals:error", True)
    assert metric_direction("probe:imagenet") == ("probe:imagenet", False)
    with pytest.raises(ValueError, match="probe:imagenet: 'high' is not a number"):
        split_model_text("random,probe:imagenet=high")
    with pytest.raises(ValueError, match="name it KIND:NAME"):
        metric_direction("imagenet:")


@pytest.mark.parametrize(("text", "message"), [
    ("name,probe:imagenet\na,1\n", "line 1: the header must be model,KIND:NAME"),
    ("model,imagenet\na,1\n", "line 1: external metric 'imagenet': name it KIND:NAME"),
    ("model,probe:imagenet\na,1,2\n", "line 2: 3 fields, the header has 2"),
    ("model,probe:imagenet\na,1\nb,x\n", "line 3, column probe:imagenet: 'x' is not a number"),
    ("model,probe:imagenet\na,1\na,2\n", "line 3: model 'a' is listed twice"),
])
def test_bad_external_csv_is_named_by_line(tmp_path, text, message):
    from unitrack_env.evaluation.scorecard.correlation_study import read_external_csv

    path = tmp_path / "probe.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_external_csv(path)


def test_scorecard_writes_the_study_and_the_report_shows_it(tmp_path, capsys):
    import json

    from unitrack_env.evaluation.cli import main
    from unitrack_env.evaluation.report.build import build_report

    card = tmp_path / "card" / "scorecard.json"
    card.parent.mkdir()
    card.write_text(json.dumps(_card({"a": 0.5, "b": 0.6, "c": 0.55, "d": 0.7})))
    probe = tmp_path / "probe.csv"
    probe.write_text("model,probe:imagenet,normals:error:lower\na,60,30\nb,70,25\nc,65,\n"
                     "d,75,20\nunknown,1,1\n")
    drawn = []
    for out in (tmp_path / "one", tmp_path / "two"):
        assert main(["scorecard", "--compare", str(card), "--external", str(probe),
                     "--out", str(out)]) == 0
        drawn.append({p.name: p.read_bytes() for p in out.glob("correlation*")})
    assert drawn[0] == drawn[1]  # same study, same bytes (figures included)
    assert sorted(drawn[0]) == ["correlation-normals-error-lower.png",
                                "correlation-normals-error-lower.svg",
                                "correlation-probe-imagenet.png",
                                "correlation-probe-imagenet.svg",
                                "correlation.json", "correlation.md"]
    result = json.loads(drawn[0]["correlation.json"])
    by_metric = {c["metric"]: c for c in result["correlations"]}
    assert by_metric["probe:imagenet"]["n"] == 4
    assert by_metric["probe:imagenet"]["spearman"] == pytest.approx(1.0)
    # error 30, 25, 20 for PCK 0.5, 0.6, 0.7: lower error goes with better tracking -> +1
    assert by_metric["normals:error:lower"]["pearson"] == pytest.approx(1.0)
    assert by_metric["normals:error:lower"]["verdict"].startswith("too few models to conclude")
    assert result["unmatched"] == ["unknown"]
    markdown = drawn[0]["correlation.md"].decode()
    assert "Left out (no normals:error:lower value): c." in markdown
    html = build_report([tmp_path / "one"], tmp_path / "report").read_text()
    assert "Correlation study" in html and "correlation-probe-imagenet.svg" in html
    assert (tmp_path / "report" / "correlation-probe-imagenet.svg").is_file()


def test_a_scorecard_without_external_numbers_writes_no_study(tmp_path, capsys):
    import json

    from unitrack_env.evaluation.cli import main

    card = tmp_path / "card" / "scorecard.json"
    card.parent.mkdir()
    card.write_text(json.dumps(_card({"a": 0.5, "b": 0.6, "c": 0.55})))
    assert main(["scorecard", "--compare", str(card), "--out", str(tmp_path / "o")]) == 0
    assert not list((tmp_path / "o").glob("correlation*"))


@pytest.mark.slow
def test_acceptance_three_models_with_probe_numbers_on_the_command_line(tmp_path, capsys):
    """`unitrack scorecard` plays three models and writes the study from --model numbers."""
    import json

    from unitrack_env.evaluation.cli import main

    out = tmp_path / "sc"
    assert main(["scorecard", "--model", "imagenet-lite0,probe:imagenet=75.1",
                 "--model", "random,label=random,probe:imagenet=4.0",
                 "--model", "random,arch=resnet18,label=random-r18,probe:imagenet=5.0",
                 "--tasks", "pose-prop", "--quiet", "--out", str(out)]) == 0
    result = json.loads((out / "correlation.json").read_text())
    (row,) = result["correlations"]
    assert row["n"] == 3 and row["pearson"] is not None
    assert row["verdict"] == "too few models to conclude (3 < 5): no interval"
    assert (out / "correlation-probe-imagenet.svg").is_file()
    assert "Correlation study" in capsys.readouterr().out or (out / "correlation.md").is_file()

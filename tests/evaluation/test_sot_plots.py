"""`unitrack plot`: success and precision plots of SOT runs, from the benchmark's own curves."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.plots.curves import run_curves
from unitrack_env.evaluation.run.runner import run


@pytest.fixture(scope="module")
def lasot_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A ``repeat-box`` run of LaSOT's synthetic default and a copy under another name."""
    root = tmp_path_factory.mktemp("sot-plots")
    a = root / "repeat"
    run("UniTrack/LaSOT-v0", "repeat-box", out=a, progress=False)
    b = root / "again"
    shutil.copytree(a, b)
    return a, b


def test_curves_are_the_scored_curves(lasot_runs) -> None:
    a, _ = lasot_runs
    combined = json.loads((a / "metrics.json").read_text())["combined"]
    _, curves = run_curves(a)
    by_title = {c.title: c for c in curves}
    assert list(by_title) == ["Success plot", "Precision plot", "Normalized precision plot"]
    success = by_title["Success plot"]
    assert success.score == ("AUC", pytest.approx(combined["AUC"]))
    assert np.mean(success.y) == pytest.approx(combined["AUC"])
    precision = by_title["Precision plot"]
    assert precision.y[precision.x.index(20.0)] == pytest.approx(combined["Precision@20px"])
    norm = by_title["Normalized precision plot"]
    assert norm.score[1] == pytest.approx(combined["NormPrecision"])


def test_plot_command_writes_the_same_bytes_twice(lasot_runs, tmp_path) -> None:
    a, b = lasot_runs
    assert main(["plot", str(a), str(b), "--out", str(tmp_path / "one")]) == 0
    assert main(["plot", str(a), str(b), "--out", str(tmp_path / "two")]) == 0
    names = sorted(p.name for p in (tmp_path / "one").iterdir())
    assert names == sorted(f"{stem}.{ext}" for stem in ("success-plot", "precision-plot",
                                                       "normalized-precision-plot")
                           for ext in ("png", "svg"))
    for name in names:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()
    svg = (tmp_path / "one" / "success-plot.svg").read_text()
    auc = json.loads((a / "metrics.json").read_text())["combined"]["AUC"]
    assert f"AUC {100 * auc:.1f}" in svg and "repeat (repeat-box)" in svg
    assert "again (repeat-box)" in svg and "<dc:date>" not in svg


def test_plot_of_runs_without_curves_is_one_clear_error(tmp_path, capsys) -> None:
    folder = tmp_path / "got10k"  # GOT-10k pools frames: it draws no OTB plots
    folder.mkdir()
    (folder / "run.json").write_text(json.dumps({"env_id": "UniTrack/GOT10k-v0",
                                                 "agent": "repeat-box"}))
    (folder / "metrics.json").write_text(json.dumps({"per_sequence": {}, "combined": {}}))
    assert main(["plot", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no success or precision plots" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()
    assert main(["plot", str(tmp_path / "nothing"), "--out", str(tmp_path / "out")]) == 2
    assert "no run.json" in capsys.readouterr().err


def test_report_shows_the_plots_of_sot_runs(lasot_runs, tmp_path) -> None:
    from unitrack_env.evaluation.report.build import build_report

    a, b = lasot_runs
    index = build_report([a, b], tmp_path / "report", thumbnails=1, resamples=20)
    html = index.read_text()
    for stem in ("success-plot", "precision-plot", "normalized-precision-plot"):
        assert f'<img src="curves-{stem}.svg"' in html
        assert (tmp_path / "report" / f"curves-{stem}.svg").is_file()
    assert build_report([a], tmp_path / "report", thumbnails=1) == index  # ours: replaced

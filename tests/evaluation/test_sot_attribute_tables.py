"""Per-attribute tables and the attribute radar of SOT runs (`unitrack plot --attributes`, report).

Known answers: an attribute's row is the benchmark's combination (LaSOT, OTB: the mean over
sequences) of the per-sequence scores of the sequences having it, read from the run's own
``metrics.json``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.datasets.lasot import LASOT_SYNTHETIC
from unitrack_env.datasets.sot_attributes import LASOT_CODES
from unitrack_env.datasets.synthetic.cache import ensure_synthetic
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.plots.attributes import markdown_table, run_attributes
from unitrack_env.evaluation.run.runner import run

DOC = Path(__file__).resolve().parents[2] / "docs" / "envs" / "sot-protocols.md"
#: The synthetic LaSOT test split's attributes written here (LaSOT toolkit's file format).
TAGS = {"walker-1": {"POC", "SV", "FM"}, "walker-2": {"POC", "ROT"}}


def _flags(codes: set[str]) -> str:
    return ",".join("1" if code in codes else "0" for code in LASOT_CODES) + "\n"


@pytest.fixture(scope="module")
def lasot_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A ``repeat-box`` run of a copy of LaSOT's synthetic default with ``att/`` files."""
    root = tmp_path_factory.mktemp("sot-attributes")
    data = root / "LaSOT"
    shutil.copytree(ensure_synthetic("LaSOT", LASOT_SYNTHETIC), data)
    (data / "att").mkdir()
    for name, codes in TAGS.items():
        (data / "att" / f"{name}.txt").write_text(_flags(codes))
    a = root / "repeat"
    run("UniTrack/LaSOT-v0", "repeat-box", out=a, env_kwargs={"root": str(data)},
        progress=False)
    b = root / "again"
    shutil.copytree(a, b)
    return a, b


def test_each_row_is_the_mean_of_the_sequences_having_the_attribute(lasot_runs) -> None:
    a, _ = lasot_runs
    per_sequence = json.loads((a / "metrics.json").read_text())["per_sequence"]
    assert sorted(per_sequence) == sorted(TAGS)
    table = run_attributes(a)
    assert table.metrics == ("AUC", "Precision@20px", "NormPrecision")
    assert [r.code for r in table.rows] == ["Overall", "POC", "ROT", "SV", "FM"]  # LaSOT order
    for row in table.rows:
        having = [s for s, codes in TAGS.items() if row.code == "Overall" or row.code in codes]
        assert row.sequences == len(having)
        for metric in table.metrics:
            expected = np.mean([per_sequence[s][metric] for s in having])
            assert row.values[metric] == pytest.approx(expected, abs=1e-12), (row.code, metric)
    # the two sequences score differently, so a wrong subset would show
    assert per_sequence["walker-1"]["AUC"] != pytest.approx(per_sequence["walker-2"]["AUC"])


def test_plot_attributes_writes_table_csv_and_radar_the_same_twice(lasot_runs, tmp_path,
                                                                   capsys) -> None:
    a, b = lasot_runs
    for out in ("one", "two"):
        assert main(["plot", str(a), str(b), "--out", str(tmp_path / out), "--attributes"]) == 0
    printed = capsys.readouterr().out
    for name in ("attributes.md", "attributes.csv", "attributes-radar.png",
                 "attributes-radar.svg"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()
    md = (tmp_path / "one" / "attributes.md").read_text()
    assert md.splitlines()[0].startswith("| Attribute | Sequences | AUC (repeat (repeat-box))")
    assert "| POC (Partial Occlusion) | 2 |" in md and "LaSOT evaluation toolkit" in md
    assert md.splitlines()[2] in printed
    rows = (tmp_path / "one" / "attributes.csv").read_text().splitlines()
    assert rows[0] == "run,attribute,name,sequences,AUC,Precision@20px,NormPrecision"
    assert len(rows) == 1 + 2 * 5
    svg = (tmp_path / "one" / "attributes-radar.svg").read_text()
    assert "AUC per attribute" in svg and "<dc:date>" not in svg


def test_report_shows_the_attribute_table_and_radar(lasot_runs, tmp_path) -> None:
    from unitrack_env.evaluation.report.build import build_report

    a, _ = lasot_runs
    html = build_report([a], tmp_path / "report", thumbnails=1, resamples=20).read_text()
    assert '<h2 id="attributes">' in html and '<img src="attributes-radar.svg"' in html
    assert html.count('<td class="text">POC</td>') == 1
    assert (tmp_path / "report" / "attributes-radar.svg").is_file()


def test_runs_without_attributes_get_one_clear_error_and_no_report_section(tmp_path,
                                                                          capsys) -> None:
    from unitrack_env.evaluation.report.build import build_report

    plain = tmp_path / "plain"  # the synthetic default has no att/ folder
    run("UniTrack/LaSOT-v0", "repeat-box", out=plain, progress=False)
    assert main(["plot", str(plain), "--out", str(tmp_path / "out"), "--attributes"]) == 2
    err = capsys.readouterr().err
    assert "no attributes for" in err and "Traceback" not in err
    html = build_report([plain], tmp_path / "report", thumbnails=1, resamples=20).read_text()
    assert 'id="attributes"' not in html


def test_otb_fixture_rows_follow_the_published_list(shared_data, tmp_path) -> None:
    """Crossing (SV DEF FM OPR BC) and Human3 (SV OCC DEF OPR BC), as OTB-2015 lists them."""
    out = tmp_path / "otb"
    with pytest.warns(UserWarning, match="trimmed copy"):
        run("UniTrack/OTB-v0", "repeat-box", out=out, env_kwargs={"root": str(
            shared_data / "OTB")}, progress=False)
    per_sequence = json.loads((out / "metrics.json").read_text())["per_sequence"]
    with pytest.warns(UserWarning, match="trimmed copy"):
        table = run_attributes(out)
    rows = {r.code: r for r in table.rows}
    assert list(rows) == ["Overall", "SV", "OCC", "DEF", "FM", "OPR", "BC"]
    assert rows["OCC"].values["AUC"] == pytest.approx(per_sequence["Human3"]["AUC"])
    assert rows["FM"].values["Precision@20px"] == pytest.approx(
        per_sequence["Crossing"]["Precision@20px"])
    assert rows["SV"].sequences == 2 and rows["OCC"].sequences == 1
    # the table in the docs, replayed
    documented = DOC.read_text().split("<!-- attributes-table")[1].split("<!-- /attributes")[0]
    assert documented.splitlines()[1:] == markdown_table([table]).splitlines()[:9]


def test_a_bad_attribute_file_is_refused_before_any_figure_is_written(lasot_runs, tmp_path,
                                                                     capsys) -> None:
    a, _ = lasot_runs
    spec = json.loads((a / "run.json").read_text())
    att = Path(spec["env_kwargs"]["root"]) / "att" / "walker-2.txt"
    good = att.read_text()
    att.write_text("1,0,2\n")
    try:
        assert main(["plot", str(a), "--out", str(tmp_path / "out"), "--attributes"]) == 2
    finally:
        att.write_text(good)
    err = capsys.readouterr().err
    assert "walker-2.txt, line 1: expected 14 flags 0 or 1" in err and "'1 0 2'" in err
    assert not (tmp_path / "out").exists()

"""The command line as a user meets it: version, help, formats, fitting tables, doctor."""

from __future__ import annotations

import argparse
import csv
import io
import json
import subprocess
import sys

import pytest

import unitrack_env
from unitrack_env.agents.primitives import label_propagation
from unitrack_env.benchmarks import task_columns
from unitrack_env.evaluation.analysis.tables import metrics_table
from unitrack_env.evaluation.cli import build_parser, doctor, main

ENV = "UniTrack/MOT16-v0"


def test_version(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0 and unitrack_env.__version__ in capsys.readouterr().out


def test_help_is_plain_text_and_documents_every_option():
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse internals
    for name, sub in commands.items():
        text = sub.format_help()
        assert "``" not in text and ":class:" not in text, name
        for action in sub._actions:  # noqa: SLF001
            if not isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
                assert action.help, f"{name} {action.option_strings} has no help"
    assert "examples:" in commands["evaluate"].format_help()
    for name, command in commands.items():  # issue 42: compare --help showed "95%%"
        assert "%%" not in command.format_help(), name


def test_formats_and_a_table_that_fits_80_columns(tmp_path, capsys):
    out = str(tmp_path / "r")
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", out, "--quiet",
                 "--format", "json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data["per_sequence"]) == {"SYN-01", "SYN-02"} and "HOTA" in data["combined"]
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", out, "--quiet",
                 "--format", "csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [r["sequence"] for r in rows] == ["SYN-01", "SYN-02", "COMBINED"]
    assert float(rows[2]["HOTA"]) == pytest.approx(data["combined"]["HOTA"])

    per_sequence = {"a-rather-long-sequence-name-01": data["per_sequence"]["SYN-01"]}
    table, dropped = metrics_table(per_sequence, data["combined"], "t", {"x": 1.0},
                                   task_columns("mot"), width=80)
    from rich.console import Console

    console = Console(width=80, file=io.StringIO())
    console.print(table)
    text = console.file.getvalue()
    assert "…" not in text and "a-rather-long-sequence-name-01" in text
    assert max(len(line) for line in text.splitlines()) <= 80
    assert dropped and dropped[-1] == "ML" and "HOTA" not in dropped


def test_output_to_a_file_or_pipe_keeps_every_column(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("COLUMNS", raising=False)  # issue 42: a pipe got 80 columns, 6 dropped
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    header = next(line for line in out.splitlines() if "HOTA" in line)
    for column in ("AssA", "MOTP", "CLR_FP", "CLR_FN", "MT", "ML", "FPS"):
        assert f" {column} " in header
    assert "do not fit" not in out


def test_render_writes_h264(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    from unitrack_env.evaluation.video import video_codec

    path = tmp_path / "v.mp4"
    assert main(["render", "--env", ENV, "--agent", "iou", "--sequence", "SYN-01",
                 "--out", str(path)]) == 0
    assert video_codec(path) == "h264"


def test_doctor_reports_problems_with_their_fix(monkeypatch, capsys):
    assert main(["doctor"]) == 0
    assert "trackeval" in capsys.readouterr().out

    def missing() -> doctor.Finding:
        return doctor.Finding("trackeval", "problem", "not installed",
                              "pip install --no-deps trackeval==1.3.0")

    monkeypatch.setattr(doctor, "CHECKS", (missing,))
    assert main(["doctor"]) == 1
    out = capsys.readouterr().out
    assert "PROBLEM trackeval" in out and "fix: pip install --no-deps trackeval==1.3.0" in out


def test_doctor_finds_the_gui_opencv(monkeypatch):
    monkeypatch.setattr(doctor, "_version",
                        lambda name: "4.11" if name == "opencv-python" else None)
    finding = doctor.check_opencv()
    assert finding.status == "problem" and "pip uninstall -y opencv-python" in finding.fix


def test_the_pytest_plugin_loads_without_the_heavy_parts():
    code = ("import sys, unitrack_env.evaluation.regression.plugin;"
            "heavy = [m for m in ('torch', 'unitrack_env.envs', 'unitrack_env.agents', "
            "'trackeval', 'cv2') if m in sys.modules]; print(heavy)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == "[]"


@pytest.mark.parametrize(("argv", "message"), [
    (["evaluate", "--workers", "0"], "argument --workers: 0 is not >= 1"),
    (["evaluate", "--step-timeout", "-1"], "argument --step-timeout: -1 is not a number >= 0"),
    (["evaluate", "--sequences", "SYN-01,"], "argument --sequences: 'SYN-01,' holds an empty"),
    (["render", "--sequence", "SYN-01", "--fps", "-5"], "argument --fps: -5 is not a positive"),
    (["render", "--sequence", "SYN-01", "--fps", "0"], "argument --fps: 0 is not a positive"),
    (["scorecard", "--model", "random", "--workers", "-3"], "argument --workers: -3 is not"),
])
def test_numbers_and_names_are_checked_by_the_parser(argv, message, tmp_path, capsys):
    command, *rest = argv
    env = [] if command == "scorecard" else ["--env", ENV, "--agent", "iou"]
    with pytest.raises(SystemExit) as exit_info:
        main([command, *env, "--out", str(tmp_path / "out.mp4"), *rest])
    assert exit_info.value.code == 2 and message in capsys.readouterr().err


def test_bf16_propagation_is_refused_before_the_first_frame(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(label_propagation, "cpu_flags", lambda: {"avx2"})
    assert main(["evaluate", "--env", "UniTrack/DAVIS-v0", "--agent", "unitrack-vos",
                 "--agent-arg", "propagation_precision=bf16",
                 "--agent-arg", "feature_cache=False",
                 "--out", str(tmp_path / "out"), "--quiet"]) != 0
    err = capsys.readouterr().err
    assert "propagation_precision='bf16'" in err and "avx512_bf16" in err
    assert "Traceback" not in err and not (tmp_path / "out" / "metrics.json").exists()


def test_a_subset_rerun_says_what_metrics_json_covers(tmp_path, capsys):
    out = str(tmp_path / "run")
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", out, "--quiet"]) == 0
    assert main(["evaluate", "--env", ENV, "--agent", "iou", "--out", out, "--quiet",
                 "--sequences", "SYN-01"]) == 0
    assert ("metrics.json covers the 1 sequence(s) asked for; 1 other finished sequence(s)"
            in capsys.readouterr().out.replace("\n", " "))


def test_undefined_metrics_are_explained(shared_data, tmp_path, capsys):
    # DAVIS 'tennis' in the fixtures has 2 frames: the official rules score neither.
    assert main(["evaluate", "--env", "UniTrack/DAVIS-v0", "--root", str(shared_data / "DAVIS"),
                 "--split", "train", "--sequences", "tennis", "--agent", "repeat-mask",
                 "--out", str(tmp_path / "run"), "--quiet"]) == 0
    assert "(undefined metrics, shown as - or nan, in tennis: nothing there to score" in \
        capsys.readouterr().out.replace("\n", " ")


def test_the_commands_show_this_packages_warnings_as_one_line():
    import warnings

    import unitrack_env.benchmarks.otb as ours
    from unitrack_env.evaluation.run.progress import one_line_warnings

    before = warnings.formatwarning
    with one_line_warnings():
        assert warnings.formatwarning("trimmed copy", UserWarning, ours.__file__, 64) == \
            "warning: trimmed copy\n"
        assert "numpy" in warnings.formatwarning("x", UserWarning, np_file(), 1)
    assert warnings.formatwarning is before  # restored: the command leaves no trace


def test_the_commands_show_each_warning_once():
    """A scorecard plays and scores many cells, each inside its own ``catch_warnings``; a data
    warning (a trimmed OTB copy) is still shown once per command."""
    import warnings

    import unitrack_env.benchmarks.otb as ours
    from unitrack_env.evaluation.run.progress import one_line_warnings

    with warnings.catch_warnings(record=True) as shown:  # what reaches the screen
        warnings.simplefilter("default")
        before = warnings.showwarning
        with one_line_warnings():
            for _ in range(3):
                with warnings.catch_warnings():  # resets Python's once-per-location memory
                    pass
                warnings.warn_explicit("trimmed copy", UserWarning, ours.__file__, 64)
            warnings.warn_explicit("another", UserWarning, ours.__file__, 64)
        assert warnings.showwarning is before
    assert [str(w.message) for w in shown] == ["trimmed copy", "another"]


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_data_warning_is_shown_once_with_worker_processes(tmp_path, workers):
    """The runner reads the sequences at the door (warning about a trimmed OTB copy) and its
    worker processes read them again: the workers skip what the command has shown (the
    command in a process of its own, as a user runs it: pytest records warnings itself)."""
    import shutil

    from unitrack_env.datasets.synthetic import ensure_synthetic

    root = tmp_path / "OTB"
    shutil.copytree(ensure_synthetic("OTB", "otb"), root)
    (root / "SynWalker").rename(root / "Crossing")  # an OTB-2015 name: 120 rows are due
    done = subprocess.run(
        [sys.executable, "-m", "unitrack_env.evaluation.cli", "evaluate", "--env",
         "UniTrack/OTB-v0", "--root", str(root), "--agent", "repeat-box", "--out",
         str(tmp_path / "run"), "--quiet", "--workers", workers],
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("reading a trimmed copy") == 1, done.stderr


def np_file() -> str:
    import numpy

    return numpy.__file__


# ------------------------------------------------ issue 22: scoring refuses incomplete results
@pytest.fixture(scope="module")
def one_missing(tmp_path_factory):
    """A finished iou run on synthetic MOT16 with SYN-02's result file deleted."""
    from unitrack_env.evaluation.run.runner import run

    out = tmp_path_factory.mktemp("score") / "run"
    full = run(ENV, "iou", out=out, progress=False)
    (out / "data" / "SYN-02.txt").unlink()
    return out / "data", full


def _gt() -> str:
    from unitrack_env.datasets.synthetic import ensure_synthetic

    return str(ensure_synthetic("MOT16") / "train")


@pytest.mark.parametrize("form", [["--env", ENV], ["--benchmark", "MOT16", "--gt", "{gt}"]])
def test_score_refuses_a_missing_result_file_in_every_form(one_missing, form, capsys):
    data, full = one_missing
    argv = ["score", *[a.format(gt=_gt()) for a in form], "--results", str(data)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "no result file for 1 of the 2 sequences to score: SYN-02" in err
    assert "--allow-missing" in err
    assert main([*argv, "--allow-missing", "--format", "json"]) == 0
    captured = capsys.readouterr()
    assert "COMBINED covers 1 of 2 sequences; no result file for SYN-02" in captured.err
    assert list(json.loads(captured.out)["per_sequence"]) == ["SYN-01"]
    assert main([*argv[:-2], "--results", str(data.parent / "data"), "--sequences",
                 "SYN-01"]) == 0  # asked for one: it is there
    assert "COMBINED (1 of 2 sequences)" in capsys.readouterr().out


def test_score_folder_api_refuses_missing_results(one_missing):
    from unitrack_env.benchmarks import benchmark_for
    from unitrack_env.benchmarks.base import MissingResults

    data, full = one_missing
    bench = benchmark_for(ENV)
    with pytest.raises(MissingResults, match="SYN-02") as caught:
        bench.score_folder(data)
    assert caught.value.missing == ["SYN-02"]
    partial = bench.score_folder(data, allow_missing=True)
    assert partial.coverage == "1 of 2 sequences" and partial.missing == ["SYN-02"]
    assert json.loads(partial.to_json())["sequences"] == {"scored": 1, "of": 2,
                                                          "missing": ["SYN-02"]}
    assert full.scores.coverage == "2 of 2 sequences"
    with pytest.raises(MissingResults, match="nothing to score"):
        bench.score_folder(data, ["SYN-02"], allow_missing=True)


@pytest.mark.parametrize("form", [["--env", ENV], ["--benchmark", "MOT16", "--gt", "{gt}"]])
def test_a_run_folder_given_as_results_points_to_its_data(one_missing, form, capsys):
    data, _ = one_missing  # issue 42: the --gt form said "no result file ... --allow-missing"
    argv = ["score", *[a.format(gt=_gt()) for a in form], "--results", str(data.parent)]
    for extra in ([], ["--allow-missing"]):
        assert main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert f"is the folder of a run; its result files are in {data}" in err
        assert "no result file" not in err and "nothing to score" not in err



def test_a_mistyped_command_gets_the_closest_and_help_imports_no_command():
    done = subprocess.run([sys.executable, "-m", "unitrack_env.evaluation.cli", "evaulate"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "did you mean evaluate?" in done.stderr, done.stderr
    script = ("import sys\nfrom unitrack_env.evaluation.cli import COMMANDS, main\n"
              "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
              "print([m for m, _ in COMMANDS.values()\n"
              "       if f'unitrack_env.evaluation.cli.{m}' in sys.modules])\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout + done.stderr

"""Per-frame error events: they sum exactly to TrackEval's counts, and the per-frame
statistics of the comparison give TrackEval's MOTA, IDF1 and HOTA at unit weights."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.evaluation.analysis.events import event_counts, events_path, load_events
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import run
from unitrack_env.metrics.events_mot import clear_events, preprocessed_frames
from unitrack_env.metrics.mot_stats import metrics_from_sums, mot_stats, weighted_sums
from unitrack_env.metrics.motchallenge import score_sequence

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "unitrack_env"))
from test_clear_stream import PETS, load_gt, mot17_sequences, perturbed_tracker  # noqa: E402

ENV = "UniTrack/MOT16-v0"
#: TrackEval field of each event type.
FIELDS = {"tp": "CLR_TP", "fp": "CLR_FP", "fn": "CLR_FN", "idsw": "IDSW", "frag": "Frag"}


@pytest.fixture(scope="module")
def iou_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("events") / "iou"
    run(ENV, "iou", out=out, progress=False, env_kwargs={"decode_frames": False})
    return out


def assert_counts_match(run_dir: Path) -> dict:
    metrics = json.loads((run_dir / "metrics.json").read_text())["per_sequence"]
    counts = event_counts(load_events(run_dir))
    for seq, values in metrics.items():
        got = {kind: counts.get(seq, {}).get(kind, 0) for kind in FIELDS}
        assert got == {kind: int(values[field]) for kind, field in FIELDS.items()}, seq
    return counts


def test_runner_writes_events_that_sum_to_trackeval(iou_run: Path) -> None:
    for seq in ("SYN-01", "SYN-02"):
        assert events_path(iou_run, seq).is_file()
    counts = assert_counts_match(iou_run)
    assert sum(c.get("idsw", 0) for c in counts.values()) > 0  # something to look at


def test_events_written_again_are_the_same_bytes(iou_run: Path, tmp_path, monkeypatch) -> None:
    """Scoring a stored run again (a committed scorecard) does not rewrite its event files."""
    import time

    from unitrack_env.evaluation.analysis.events import run_benchmark, write_sequence_events

    first = events_path(iou_run, "SYN-01").read_bytes()
    again = tmp_path / "again"
    shutil.copytree(iou_run, again)
    later = time.time() + 3600  # gzip would stamp this hour into its header
    monkeypatch.setattr(time, "time", lambda: later)
    assert write_sequence_events(again, run_benchmark(again), "SYN-01").read_bytes() == first


def test_events_of_an_older_run_are_computed_from_its_files(iou_run: Path, tmp_path) -> None:
    old = tmp_path / "old"
    shutil.copytree(iou_run, old)
    shutil.rmtree(old / "events")
    df = load_events(old, sequence="SYN-01", type="idsw")
    assert set(df["type"]) <= {"idsw"} and set(df["sequence"]) <= {"SYN-01"}
    assert events_path(old, "SYN-01").is_file() and not events_path(old, "SYN-02").exists()
    assert df.equals(load_events(iou_run, sequence="SYN-01", type="idsw"))
    row = df.iloc[0]
    assert row["track_id"] != row["prev_track_id"] and row["iou"] >= 0.5


def test_events_command(iou_run: Path, capsys) -> None:
    assert main(["events", str(iou_run), "--type", "idsw", "--format", "csv"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    metrics = json.loads((iou_run / "metrics.json").read_text())["per_sequence"]
    assert len(lines) - 1 == sum(int(m["IDSW"]) for m in metrics.values())
    assert main(["events", str(iou_run), "--sequence", "SYN-01", "--type", "fn"]) == 0
    assert "SYN-01" in capsys.readouterr().out
    assert main(["events", str(iou_run)]) == 0  # issue 42: no --type printed every event
    out = capsys.readouterr().out
    counts = event_counts(load_events(iou_run))
    assert f"{sum(sum(c.values()) for c in counts.values())} events" in out
    assert len(out.splitlines()) < 10 + len(counts) and "--type TYPE lists" in out
    assert all(f"SYN-0{i}" in out for i in (1, 2)) and " idsw " in out
    assert main(["events", str(iou_run), "--sequence", "NOPE"]) == 2
    assert "sequence 'NOPE' is not scored" in capsys.readouterr().err
    assert main(["events", str(iou_run.parent / "missing")]) == 2


@pytest.mark.parametrize("level", [0.5, 2.0])
def test_events_and_statistics_equal_trackeval_on_mot17_clips(level: float) -> None:
    seqs = mot17_sequences()
    if not seqs:
        pytest.skip("MOT17 fixtures not found")
    for i, seq in enumerate(seqs):
        gt, n = load_gt(seq)
        trk = perturbed_tracker(gt, n, seed=7 + i, level=level)
        frames = preprocessed_frames(gt, trk, n, "MOT17")
        types = np.array(clear_events(seq.name, frames).columns["type"])
        official = score_sequence(seq, trk, benchmark="MOT17")
        for kind, field in FIELDS.items():
            assert (types == kind).sum() == official[field], (seq.name, kind)
        got = metrics_from_sums(weighted_sums(mot_stats(frames), np.ones((1, n))))
        for name in ("HOTA", "DetA", "AssA", "IDF1", "MOTA"):
            assert got[name][0] == pytest.approx(official[name], abs=1e-12), (seq.name, name)


def test_weights_of_two_are_the_sequence_played_twice_for_idf1() -> None:
    if not (PETS / "gt" / "gt.txt").is_file():
        pytest.skip("PETS09 fixture not found")
    gt, n = load_gt(PETS)
    gt, n = gt[gt[:, 0] <= 60], 60
    trk = perturbed_tracker(gt, n, seed=3, level=1.0)
    stats = mot_stats(preprocessed_frames(gt, trk, n, "MOT15"))
    once = weighted_sums(stats, np.ones((1, n)))
    twice = weighted_sums(stats, np.full((1, n), 2.0))
    for key in ("tp", "fp", "fn", "idtp", "n_gt", "n_trk"):
        assert twice[key][0] == pytest.approx(2 * once[key][0])
    a, b = metrics_from_sums(once), metrics_from_sums(twice)
    for name in ("IDF1", "MOTA", "HOTA"):
        assert a[name][0] == pytest.approx(b[name][0])


def test_sot_and_vos_events_give_back_the_official_means(tmp_path: Path) -> None:
    sot = tmp_path / "sot"
    run("UniTrack/OTB-v0", "repeat-box", out=sot, progress=False)
    metrics = json.loads((sot / "metrics.json").read_text())["per_sequence"]
    events = load_events(sot)
    assert set(events["type"]) == {"frame"}
    for seq, frames in events.groupby("sequence"):
        success = (frames["iou"].to_numpy()[:, None] > np.linspace(0, 1, 21)).mean()
        assert success == pytest.approx(metrics[seq]["AUC"], abs=1e-3), seq
        assert frames["frame"].tolist() == list(range(1, len(frames) + 1))
    vos = tmp_path / "vos"
    run("UniTrack/DAVIS-v0", "repeat-mask", out=vos, progress=False)
    metrics = json.loads((vos / "metrics.json").read_text())["per_sequence"]
    for seq, frames in load_events(vos).groupby("sequence"):
        j_mean = frames.groupby("object")["j"].mean().mean()
        assert j_mean == pytest.approx(metrics[seq]["J-Mean"], abs=1e-3), seq


@pytest.mark.parametrize("damage", ["truncated", "not-gzip", "empty"])
def test_a_damaged_events_file_is_named_with_the_cure(iou_run: Path, tmp_path: Path,
                                                      damage: str) -> None:
    from unitrack_env.errors import DataFormatError

    copy = tmp_path / "run"
    shutil.copytree(iou_run, copy)
    path = events_path(copy, "SYN-01")
    data = path.read_bytes()
    path.write_bytes({"truncated": data[: len(data) // 2], "not-gzip": b"frame,type\n1,fp\n",
                      "empty": b""}[damage])
    with pytest.raises(DataFormatError) as info:
        load_events(copy)
    text = str(info.value)
    assert text.startswith(f"{path}: damaged events file (") and "unitrack events" in text
    assert "\n" not in text

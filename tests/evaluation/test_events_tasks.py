"""Error events of MOTS, PoseTrack and VIS: they sum exactly to the official scorer's counts
(MOTS, PoseTrack) and give back its AP50 (VIS), on synthetic episodes and the real fixtures."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.datasets.posetrack_json import read_posetrack_json
from unitrack_env.evaluation.analysis.events import event_counts, load_events, run_benchmark
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import run
from unitrack_env.metrics.events_mot import EventRows, mots_sequence_events
from unitrack_env.metrics.events_pose import posetrack_sequence_events
from unitrack_env.metrics.mots import score_sequence
from unitrack_env.metrics.posetrack import evaluate_video, evaluated_frames

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "unitrack_env"))
from test_mots import box_mask, records  # noqa: E402

MOT_FIELDS = {"tp": "CLR_TP", "fp": "CLR_FP", "fn": "CLR_FN", "idsw": "IDSW", "frag": "Frag"}


def counts(rows: EventRows) -> dict[str, int]:
    kinds, n = np.unique(rows.columns["type"], return_counts=True)
    return {str(k): int(c) for k, c in zip(kinds, n, strict=True)}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = {}
    for name in ("MOTS", "PoseTrack", "VIS"):
        out[name] = tmp_path_factory.mktemp("events") / name
        run(f"UniTrack/{name}-v0", "iou", out=out[name], progress=False)
    return out


def per_sequence(run_dir: Path) -> dict:
    return json.loads((run_dir / "metrics.json").read_text())["per_sequence"]


# ---------------------------------------------------------------------------- MOTS
@pytest.mark.parametrize(("benchmark", "first"), [("MOTS20", 1), ("KITTI-MOTS", 0)])
def test_mots_events_of_a_hand_made_episode_sum_to_trackeval(benchmark: str, first: int) -> None:
    """A switch, a fragmentation, a miss and a false positive inside an ignore region."""
    a, b, c = box_mask(0, 0, 3, 4), box_mask(4, 0, 8, 4), box_mask(0, 5, 8, 6)
    f = first - 1  # frame t of the story is file frame t + f
    gt = records([(t + f, 2001, 2, a) for t in range(1, 6)]
                 + [(t + f, 2002, 2, b) for t in (1, 2, 4, 5)]
                 + [(t + f, 10000, 10, c) for t in range(1, 6)])
    res = records([(t + f, i, 2, m) for t, i, m in [
        (1, 5, a), (2, 5, a), (3, 6, a), (5, 6, a), (1, 7, b), (4, 7, b), (5, 7, b), (2, 8, c),
        (3, 9, box_mask(4, 4, 8, 5))]])
    rows = mots_sequence_events("S", gt, res, first_frame=first, num_frames=5, class_id=2)
    official = score_sequence(gt, res, seq_length=5, benchmark=benchmark).summary
    assert counts(rows) == {k: int(official[f]) for k, f in MOT_FIELDS.items()
                            if official[f]} | {"tp": int(official["CLR_TP"])}
    assert counts(rows)["idsw"] == 1 and counts(rows)["frag"] >= 1 and counts(rows)["fp"] == 1
    switch = rows.columns["type"].index("idsw")
    assert (rows.columns["prev_track_id"][switch], rows.columns["track_id"][switch]) == (5, 6)
    assert rows.columns["x"][switch] == 0 and rows.columns["w"][switch] == 3  # the mask's box
    assert rows.columns["frame"][switch] == 3  # 1-based position, whatever the file numbering


def test_mots_run_events_sum_to_trackeval(runs: dict[str, Path]) -> None:
    got = event_counts(load_events(runs["MOTS"]))
    for seq, values in per_sequence(runs["MOTS"]).items():
        assert {k: got[seq].get(k, 0) for k in MOT_FIELDS} == {
            k: int(values[f]) for k, f in MOT_FIELDS.items()}, seq


# ---------------------------------------------------------------------------- PoseTrack
def pose_totals(gt, pred, drop_last_frame: bool) -> dict[str, int]:
    c = evaluate_video(gt, pred, drop_last_frame=drop_last_frame)
    return {"tp": int(c.detections.sum()), "fn": int(c.misses.sum()),
            "fp": int(c.false_positives.sum()), "idsw": int(c.switches.sum())}


def test_posetrack_events_sum_to_poseval_with_switches_and_empty_frames(runs) -> None:
    bench = run_benchmark(runs["PoseTrack"])
    seq = next(iter(per_sequence(runs["PoseTrack"])))
    gt = read_posetrack_json(bench.dataset.annotation_dir / f"{seq}.json")
    pred = bench.read(runs["PoseTrack"] / "data", seq)
    people = [list(p) for p in pred.people]
    scored = evaluated_frames(gt)
    people[scored[2]] = []  # an empty frame: poseval's dummy miss and false positive per joint
    for k in scored[5:]:  # swap the first two identities from the sixth scored frame on
        if len(people[k]) >= 2:
            a, b = people[k][:2]
            people[k][:2] = [dataclasses.replace(a, track_id=b.track_id),
                             dataclasses.replace(b, track_id=a.track_id)]
    pred = dataclasses.replace(pred, people=people)
    for drop in (True, False):
        rows = posetrack_sequence_events(seq, gt, pred, drop_last_frame=drop)
        assert counts(rows) == pose_totals(gt, pred, drop)
    dummy = [i for i, f in enumerate(rows.columns["frame"]) if f == scored[2] + 1]
    assert len(dummy) == 30 and all(np.isnan(rows.columns["gt_id"][i]) for i in dummy)
    idsw = [i for i, k in enumerate(rows.columns["type"]) if k == "idsw"]
    assert idsw and all(rows.columns["prev_track_id"][i] != rows.columns["track_id"][i]
                        for i in idsw)


def test_posetrack_run_events_and_real_fixture(runs, shared_data: Path) -> None:
    df = load_events(runs["PoseTrack"])
    for seq, values in per_sequence(runs["PoseTrack"]).items():
        got = event_counts(df)[seq]
        assert got.get("idsw", 0) == values["IDSW"]
        assert (got["fn"], got["fp"]) == (values["num_misses"], values["num_false_positives"])
        assert got["tp"] + got["fn"] == values["num_objects"]
    assert df.loc[df["type"] == "tp", "distance"].between(0, 0.5).all()
    folder = shared_data / "PoseTrack2018" / "posetrack_data" / "annotations" / "val"
    for path in sorted(folder.glob("*.json")):
        gt = read_posetrack_json(path)
        rng = np.random.default_rng(0)
        pred = dataclasses.replace(gt, people=[[dataclasses.replace(
            p, keypoints=p.keypoints + np.r_[rng.normal(0, 8, 2), 0] * (p.keypoints[:, 2:] > 0))
            for p in people] for people in gt.people])
        rows = posetrack_sequence_events(path.stem, gt, pred, drop_last_frame=False)
        assert counts(rows) == {k: v for k, v in pose_totals(gt, pred, False).items() if v}
        assert counts(rows)["tp"] > 0


# ---------------------------------------------------------------------------- VIS
def ap_101(scores: np.ndarray, tp: np.ndarray, num_gt: int) -> float:
    """COCO's 101-point interpolated AP (as TrackEval's TrackMAP computes it)."""
    order = np.argsort(-scores, kind="mergesort")
    tps, fps = np.cumsum(tp[order]), np.cumsum(~tp[order])
    recall = tps / num_gt
    precision = np.maximum.accumulate((tps / np.maximum(tps + fps, 1))[::-1])[::-1]
    idx = np.searchsorted(recall, np.linspace(0, 1, 101), side="left")
    return float(np.mean([precision[i] if i < len(precision) else 0.0 for i in idx]))


def test_vis_events_give_back_trackeval_ap50(runs: dict[str, Path]) -> None:
    df = load_events(runs["VIS"])
    assert set(df["type"]) <= {"tp", "fp", "fn", "ignored"} and (df["type"] == "fp").any()
    for seq, values in per_sequence(runs["VIS"]).items():
        ev = df[df["sequence"] == seq]
        aps = []
        for _, cls in ev.groupby("object"):
            tracks = cls[cls["type"].isin(["tp", "fp"])].drop_duplicates("track_id")
            num_gt = cls.loc[cls["type"].isin(["tp", "fn"]), "gt_id"].nunique()
            if num_gt:
                aps.append(ap_101(tracks["score"].to_numpy(),
                                  (tracks["type"] == "tp").to_numpy(), num_gt))
        assert np.mean(aps) == pytest.approx(values["AP50"], abs=1e-9), seq
        tp = ev[ev["type"] == "tp"]
        assert (tp["track_iou"] >= 0.5).all() and tp["iou"].between(0, 1).all()


def test_events_command_accepts_the_new_tasks(runs: dict[str, Path], capsys) -> None:
    for name, kind in (("MOTS", "idsw"), ("PoseTrack", "idsw"), ("VIS", "fp")):
        assert main(["events", str(runs[name]), "--type", kind, "--format", "csv"]) == 0
        lines = capsys.readouterr().out.strip().splitlines()
        assert len(lines) > 1 and all(f",{kind}," in line for line in lines[1:]), name


def test_report_shows_timelines_of_the_new_tasks(runs: dict[str, Path], tmp_path: Path) -> None:
    from unitrack_env.evaluation.report.build import build_report

    page = build_report([runs["MOTS"], runs["PoseTrack"], runs["VIS"]], tmp_path).read_text()
    for name in ("MOTS", "PoseTrack", "VIS"):
        for seq in per_sequence(runs[name]):
            section = page.split(f'data-sequence="{seq}">', 2)[-1].split("</section>")[0]
            assert '<svg class="timeline"' in section, seq
    assert 'class="ev-idsw"' in page and "IoU of tp tracks" in page
    # masks (MOTS) and joints (PoseTrack) are pictured on their frames, found by the benchmark
    assert 'src="img0-' in page and 'src="img1-' in page


def test_compare_refuses_a_task_whose_metrics_are_not_frame_means(runs) -> None:
    from unitrack_env.evaluation.analysis.intervals import compare_runs

    for name, reason in (("MOTS", "not recomputed"), ("PoseTrack", "per-joint"),
                         ("VIS", "whole tracks")):
        with pytest.raises(ValueError, match=f"cannot compare .* runs: .*{reason}"):
            compare_runs(runs[name], runs[name])

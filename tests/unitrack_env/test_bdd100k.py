"""Issue 40: BDD100K box-track JSON scored per class and combined exactly as TrackEval does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.benchmarks.bdd100k import BDD100KBenchmark
from unitrack_env.errors import DataFormatError

SEQ = "track_sample_anns"


def _trackeval_flavour(path: Path, out: Path) -> None:
    """The Scalabel file in the JSON TrackEval's BDD100K class reads (index, int ids, Crowd)."""
    ids: dict[str, int] = {}
    frames = []
    for frame in sorted(json.loads(path.read_text()), key=lambda f: f["frameIndex"]):
        frames.append({"index": frame["frameIndex"], "labels": [
            {"id": ids.setdefault(lab["id"], len(ids)), "category": lab["category"],
             "box2d": lab["box2d"],
             "attributes": {"Crowd": lab.get("attributes", {}).get("crowd", False)}}
            for lab in frame["labels"]]})
    out.write_text(json.dumps(frames))


def trackeval_direct(gt_file: Path, result_file: Path, tmp: Path) -> dict:
    """TrackEval's own Evaluator with its BDD100K dataset: COMBINED_SEQ per class and groups."""
    import trackeval

    gt, data = tmp / "gt", tmp / "trackers" / "mine" / "data"
    gt.mkdir(parents=True)
    data.mkdir(parents=True)
    _trackeval_flavour(gt_file, gt / f"{SEQ}.json")
    _trackeval_flavour(result_file, data / f"{SEQ}.json")
    config = {**trackeval.Evaluator.get_default_eval_config(), "USE_PARALLEL": False,
              "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
              "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
              "DISPLAY_LESS_PROGRESS": True}
    dataset = trackeval.datasets.BDD100K({
        "GT_FOLDER": str(gt), "TRACKERS_FOLDER": str(tmp / "trackers"),
        "OUTPUT_FOLDER": str(tmp / "out"), "PRINT_CONFIG": False})
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    results, _ = trackeval.Evaluator(config).evaluate([dataset], metrics)
    return results["BDD100K"]["mine"]["COMBINED_SEQ"]


def _perturbed(gt_file: Path, out: Path) -> None:
    """Every 7th box dropped, two car tracks' ids swapped from frame 100, a score per box."""
    frames = json.loads(gt_file.read_text())
    first, second = [lab["id"] for lab in frames[100]["labels"] if lab["category"] == "car"][:2]
    swap = {first: second, second: first}
    k = 0
    for frame in frames:
        kept = []
        for lab in frame["labels"]:
            k += 1
            if k % 7 == 0:
                continue
            lab = dict(lab, score=0.5 + (k % 5) / 10)
            lab.pop("attributes", None)
            if frame["frameIndex"] >= 100:
                lab["id"] = swap.get(lab["id"], lab["id"])
            kept.append(lab)
        frame["labels"] = kept
    out.write_text(json.dumps(frames))


@pytest.fixture
def bdd(shared_data: Path) -> tuple[BDD100KBenchmark, Path]:
    root = shared_data / "BDD100K"
    return BDD100KBenchmark.build(root), root / "labels" / "box_track_20" / "val" / f"{SEQ}.json"


def test_ground_truth_given_back_scores_hota_100(bdd, tmp_path):
    bench, gt = bdd
    (tmp_path / "res").mkdir()
    (tmp_path / "res" / f"{SEQ}.json").write_bytes(gt.read_bytes())
    combined = bench.score_folder(tmp_path / "res").combined
    assert combined["HOTA"] == 1.0 and combined["IDF1"] == 1.0
    for group in ("car", "pedestrian", "rider", "bus", "truck", "motorcycle", "VEHICLE",
                  "HUMAN", "BIKE", "cls_comb_det_av"):
        assert combined[f"{group}/HOTA"] == 1.0, group


def test_perturbed_results_score_as_trackeval_per_class(bdd, tmp_path):
    bench, gt = bdd
    (tmp_path / "res").mkdir()
    _perturbed(gt, tmp_path / "res" / f"{SEQ}.json")
    ours = bench.score_folder(tmp_path / "res").scores["per_class"]
    theirs = trackeval_direct(gt, tmp_path / "res" / f"{SEQ}.json", tmp_path / "te")
    assert set(ours) == set(theirs) - {"all"}
    checked = 0
    for group, values in ours.items():
        for name, value in values.items():
            expected = next((theirs[group][m][name] for m in ("HOTA", "CLEAR", "Identity", "Count")
                             if name in theirs[group][m]), None)
            assert expected is not None, (group, name)
            assert value == (float(np.mean(expected)) if np.ndim(expected)
                             else float(expected)), (group, name)  # every digit
            checked += 1
    assert checked > 400
    assert 0.5 < ours["cls_comb_det_av"]["HOTA"] < 1.0  # the perturbation shows
    assert ours["cls_comb_det_av"]["IDSW"] >= 2


def test_rows_written_and_read_back_score_the_same(bdd, tmp_path):
    bench, gt = bdd
    rows = bench.read(gt.parent, SEQ)
    assert rows.shape == (3241, 8)
    bench.write(tmp_path, SEQ, rows)
    np.testing.assert_array_equal(bench.read(tmp_path, SEQ), rows)
    assert bench.score_sequence(SEQ, rows)["HOTA"] == 1.0


@pytest.mark.parametrize(("label", "message"), [
    ({"id": "1", "category": "plane", "box2d": {"x1": 0, "y1": 0, "x2": 1, "y2": 1}},
     "frame [0].labels[0].category: 'plane' is not one of"),
    ({"id": "1", "category": "car", "box2d": {"x1": 0, "y1": "a", "x2": 1, "y2": 1}},
     "frame [0].labels[0].box2d.y1: a finite number is required"),
])
def test_a_bad_result_label_is_named(bdd, tmp_path, label, message):
    bench, _ = bdd
    (tmp_path / f"{SEQ}.json").write_text(json.dumps([{"frameIndex": 0, "labels": [label]}]))
    with pytest.raises(DataFormatError, match=message.replace("[", r"\[").replace("]", r"\]")):
        bench.score_folder(tmp_path)


def test_a_result_frame_beyond_the_sequence_is_named(bdd, tmp_path):
    bench, _ = bdd
    (tmp_path / f"{SEQ}.json").write_text(json.dumps([{"frameIndex": 202, "labels": []}]))
    with pytest.raises(DataFormatError, match="202 is beyond the sequence's 202 frames"):
        bench.score_folder(tmp_path)


def test_a_root_without_the_split_folder_is_named(tmp_path):
    with pytest.raises(DataFormatError, match="box_track_20"):
        BDD100KBenchmark.build(tmp_path)


def test_crowd_boxes_are_ignore_regions_not_misses(bdd, tmp_path):
    bench, gt = bdd
    frames = json.loads(gt.read_text())
    crowd = sum(lab["attributes"]["crowd"] for f in frames for lab in f["labels"])
    for frame in frames:  # results without the 132 crowd boxes: nothing is missed
        frame["labels"] = [lab for lab in frame["labels"] if not lab["attributes"]["crowd"]]
    (tmp_path / f"{SEQ}.json").write_text(json.dumps(frames))
    combined = bench.score_folder(tmp_path).combined
    assert crowd == 132
    assert combined["car/HOTA"] == 1.0 and combined["car/MOTA"] == 1.0

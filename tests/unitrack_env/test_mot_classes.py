"""Issue 40 item 3: per-class scoring of MOTChallenge-layout data with a class map."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.benchmarks import benchmark_for
from unitrack_env.datasets.mot_classes import ClassMap, ClassMapError, class_map
from unitrack_env.errors import DataFormatError
from unitrack_env.evaluation.cli import main

ENV = "UniTrack/MOTChallenge-v0"
#: gt ids: 1 and 2 pedestrians, 3 cars, 7 a distractor (static person), 9 ignored (occluder).
CLASSES = {"car": [3], "pedestrian": [1, 2]}
MAP = {"classes": CLASSES, "distractors": [7], "ignore": [9]}
W, H, FRAMES = 160, 96, 24
SEQINFO = ("[Sequence]\nname={name}\nimDir=img1\nframeRate=10\nseqLength={n}\nimWidth={w}\n"
           "imHeight={h}\nimExt=.jpg\n")


def _objects(seed: int) -> list[tuple[int, int, np.ndarray]]:
    """``(id, class, (FRAMES, 4) boxes)`` of one synthetic sequence: moving, crossing."""
    rng = np.random.default_rng(seed)
    out = []
    for ident, cls in enumerate((1, 1, 2, 3, 3, 7, 9), start=1):
        w, h = (30.0, 16.0) if cls == 3 else (10.0, 24.0)
        start = rng.uniform([2, 2], [W - w - 40, H - h - 2])
        step = rng.uniform(-1.5, 1.5, 2) if cls != 7 else np.zeros(2)
        xy = start + np.arange(FRAMES)[:, None] * step
        xy = np.clip(xy, 1, [W - w - 1, H - h - 1])
        out.append((ident, cls, np.column_stack([xy, np.full(FRAMES, w), np.full(FRAMES, h)])))
    return out


def make_folder(root: Path, sequences=("CAM-01", "CAM-02")) -> Path:
    """A custom MOTChallenge folder with two classes (gt.txt and det.txt carry class ids)."""
    from PIL import Image

    for k, name in enumerate(sequences):
        seq = root / "train" / name
        for sub in ("img1", "det", "gt"):
            (seq / sub).mkdir(parents=True)
        (seq / "seqinfo.ini").write_text(SEQINFO.format(name=name, n=FRAMES, w=W, h=H))
        for t in range(1, FRAMES + 1):
            Image.fromarray(np.full((H, W, 3), 30 + 5 * t, np.uint8)).save(
                seq / "img1" / f"{t:06d}.jpg")
        gt, det = [], []
        for ident, cls, boxes in _objects(k):
            for t, (x, y, w, h) in enumerate(boxes, start=1):
                flag = 0 if (ident == 2 and t > FRAMES - 4) else 1  # a zero-marked stretch
                gt.append(f"{t},{ident},{x:.2f},{y:.2f},{w:.2f},{h:.2f},{flag},{cls},1\n")
                if (t + ident) % 7:  # some misses
                    det.append(f"{t},-1,{x + 0.5:.2f},{y - 0.5:.2f},{w:.2f},{h:.2f},0.9,{cls},"
                               "-1,-1\n")
        det.append("3,-1,120,60,12,20,0.8,1,-1,-1\n")  # a false positive
        (seq / "gt" / "gt.txt").write_text("".join(gt))
        (seq / "det" / "det.txt").write_text("".join(det))
    return root


def perturbed_results(root: Path, out: Path) -> Path:
    """Results from the ground truth with errors of every kind, each row with its class."""
    out.mkdir(parents=True)
    for seq in sorted((root / "train").iterdir()):
        gt = np.loadtxt(seq / "gt" / "gt.txt", delimiter=",")
        rows = []
        for f, i, x, y, w, h, _, cls, _ in gt:
            if cls == 9 or (i == 4 and f % 5 == 0):  # ignored object; a car missed at times
                continue
            ident = i + 100 if (i == 1 and f > 12) else i  # an id switch
            label = 1 if cls == 7 else (2 if cls == 2 and f > 20 else cls)  # on the distractor
            rows.append([f, ident, x + (f % 3), y, w, h, 1, label, -1, -1])
        rows.append([5, 77, 2, 2, 20, 20, 1, 3, -1, -1])  # a false car
        rows.append([6, 78, 60, 50, 10, 20, 1, 1, -1, -1])  # a false pedestrian
        np.savetxt(out / f"{seq.name}.txt", np.array(rows), fmt="%g", delimiter=",")
    return out


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return make_folder(tmp_path_factory.mktemp("two-classes"))


def trackeval_direct(root: Path, results: Path, tmp: Path) -> dict:
    """TrackEval's own Evaluator, each class on a MOTChallenge folder of its own.

    Class ``c``'s folder: its gt ids as pedestrians (1), the distractor ids as distractors
    (8), other ids as occluders (9); its result rows (class column -1).
    """
    import trackeval

    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    config = {**trackeval.Evaluator.get_default_eval_config(), "USE_PARALLEL": False,
              "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
              "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
              "DISPLAY_LESS_PROGRESS": True}
    seqs = sorted(p.name for p in (root / "train").iterdir())
    per_class = {}
    for cls, ids in CLASSES.items():
        gt_dir, trk = tmp / cls / "gt", tmp / cls / "trackers" / "mine" / "data"
        trk.mkdir(parents=True)
        for seq in seqs:
            gt = np.loadtxt(root / "train" / seq / "gt" / "gt.txt", delimiter=",")
            gt[:, 7] = np.where(np.isin(gt[:, 7], ids), 1, np.where(gt[:, 7] == 7, 8, 9))
            (gt_dir / seq / "gt").mkdir(parents=True)
            np.savetxt(gt_dir / seq / "gt" / "gt.txt", gt, fmt="%.17g", delimiter=",")
            res = np.loadtxt(results / f"{seq}.txt", delimiter=",", ndmin=2)
            res = res[np.isin(res[:, 7], ids)]
            res[:, 7] = -1
            np.savetxt(trk / f"{seq}.txt", res, fmt="%.17g", delimiter=",")
        dataset = trackeval.datasets.MotChallenge2DBox({
            "GT_FOLDER": str(gt_dir), "TRACKERS_FOLDER": str(tmp / cls / "trackers"),
            "OUTPUT_FOLDER": str(tmp / cls / "out"), "BENCHMARK": "MOT17",
            "SKIP_SPLIT_FOL": True, "SEQ_INFO": {s: FRAMES for s in seqs},
            "PRINT_CONFIG": False})
        out, _ = trackeval.Evaluator(config).evaluate([dataset], metrics)
        per_class[cls] = out["MotChallenge2DBox"]["mine"]
    theirs = {seq: {cls: per_class[cls][seq]["pedestrian"] for cls in CLASSES}
              for seq in [*seqs, "COMBINED_SEQ"]}
    combined = theirs["COMBINED_SEQ"]
    for key, how in (("cls_comb_cls_av", "combine_classes_class_averaged"),
                     ("cls_comb_det_av", "combine_classes_det_averaged")):
        combined[key] = {m.get_name(): getattr(m, how)(
            {c: combined[c][m.get_name()] for c in CLASSES}) for m in metrics}
    return theirs


def assert_parity(ours: dict[str, float], theirs: dict) -> int:
    """Every prefixed metric of ``ours`` equals TrackEval's to every digit."""
    checked = 0
    for key, value in ours.items():
        group, _, name = key.rpartition("/")
        if not group or group not in theirs:
            continue
        for metric in ("HOTA", "CLEAR", "Identity"):
            if name in theirs[group][metric]:
                expected = theirs[group][metric][name]
                expected = float(np.mean(expected)) if np.ndim(expected) else float(expected)
                assert value == expected, (key, value, expected)
                checked += 1
    return checked


def test_per_class_scores_equal_a_direct_trackeval_run(folder, tmp_path):
    results = perturbed_results(folder, tmp_path / "res")
    bench = benchmark_for(ENV, root=str(folder), **MAP)
    report = bench.score_folder(results)
    theirs = trackeval_direct(folder, results, tmp_path / "te")
    assert assert_parity(report.combined, theirs["COMBINED_SEQ"]) >= 24
    for seq in ("CAM-01", "CAM-02"):
        assert assert_parity(report.per_sequence[seq], theirs[seq]) >= 12
        events = bench.sequence_events(results, seq).columns  # each names its class
        for cls in CLASSES:
            kinds = [k for k, c in zip(events["type"], events["class"], strict=True)
                     if c == cls]
            clear = theirs[seq][cls]["CLEAR"]
            assert [kinds.count(k) for k in ("tp", "fp", "fn", "idsw", "frag")] == [
                clear[k] for k in ("CLR_TP", "CLR_FP", "CLR_FN", "IDSW", "Frag")], (seq, cls)
    c = report.combined  # unprefixed: the detection average, as KITTI's
    assert c["HOTA"] == c["cls_comb_det_av/HOTA"]
    assert 0.3 < c["car/HOTA"] < 1 and 0.3 < c["pedestrian/HOTA"] < 1
    assert c["car/HOTA"] != c["pedestrian/HOTA"]
    assert c["pedestrian/IDSW"] >= 1  # the id switch of object 1 counts


def test_a_pedestrian_map_gives_mot17s_own_numbers(folder, tmp_path):
    """The MOT17 rules as a class map: pedestrians 1, its distractors, the rest ignored."""
    results = perturbed_results(folder, tmp_path / "res")
    peds = tmp_path / "peds"
    peds.mkdir()
    for path in results.glob("*.txt"):
        rows = np.loadtxt(path, delimiter=",")
        rows = rows[np.isin(rows[:, 7], [1])]
        np.savetxt(peds / path.name, rows, fmt="%g", delimiter=",")
        rows[:, 7] = -1
        np.savetxt(tmp_path / path.name, rows, fmt="%g", delimiter=",")
    mapped = benchmark_for(ENV, root=str(folder), classes={"pedestrian": [1]},
                           distractors=[2, 7, 8, 12], ignore=[3, 9]).score_folder(peds)
    plain = tmp_path / "plain"
    plain.mkdir()
    for path in tmp_path.glob("*.txt"):
        path.rename(plain / path.name)
    default = benchmark_for(ENV, root=str(folder)).score_folder(plain)
    for name in ("HOTA", "MOTA", "IDF1", "IDSW", "DetA", "AssA"):
        assert mapped.combined[f"pedestrian/{name}"] == default.combined[name], name


def test_class_map_arguments_are_checked_naming_the_field(tmp_path):
    cases = [({"car": 3}, (), (), r"classes\['car'\]: must be a list"),
             ([3], (), (), "classes: must map class names"),
             ({"car": [3], "ped": [3]}, (), (), r"classes\['ped'\]: class id 3 is also in "
                                                r"classes\['car'\]"),
             ({"car": [3]}, [3], (), "distractors: class id 3 is also in"),
             ({"car": [0]}, (), (), "integers >= 1"),
             ({"a/b": [1]}, (), (), "not a usable class name"),
             ({"cls_comb_det_av": [1]}, (), (), "not a usable class name"),
             ({"car": []}, (), (), "lists no class id")]
    for classes, distractors, ignore, message in cases:
        with pytest.raises(ClassMapError, match=message):
            ClassMap.parse(classes, distractors, ignore)
    with pytest.raises(ClassMapError, match="distractors/ignore: given without classes"):
        class_map(tmp_path, None, [7])
    (tmp_path / "classes.json").write_text(json.dumps({"classes": CLASSES, "ignored": [9]}))
    with pytest.raises(DataFormatError, match="classes.json, field 'ignored': unknown key"):
        class_map(tmp_path)
    (tmp_path / "classes.json").write_text(json.dumps({"classes": {"car": [3, 3]}}))
    with pytest.raises(DataFormatError, match=r"field 'classes\['car'\]': repeats"):
        class_map(tmp_path)


def test_data_the_map_does_not_cover_is_refused_at_reset(folder, tmp_path):
    from unitrack_env.datasets.motchallenge import read_detections, read_ground_truth

    env = gym.make(ENV, root=str(folder), classes=CLASSES, distractors=[7])
    with pytest.raises(DataFormatError, match=r"det.txt, line \d+, field 'class': detection "
                                              "class 9 is not in the class map"):
        env.reset()
    env.close()
    gt = folder / "train" / "CAM-01" / "gt" / "gt.txt"
    with pytest.raises(DataFormatError, match=r"gt.txt, line \d+, field 'class': ground truth "
                                              r"class 9 is not in the class map \(car: 3; "
                                              r"pedestrian: 1, 2; distractors: 7\)"):
        read_ground_truth(gt, "MOT17", class_map=ClassMap.parse(CLASSES, [7]))
    (tmp_path / "det.txt").write_text("1,-1,1,1,10,20,0.9\n")
    with pytest.raises(DataFormatError, match="det.txt, line 1, field 'class': 7 columns: with "
                                              "a class map each detection carries its class"):
        read_detections(tmp_path / "det.txt", class_map=ClassMap.parse(CLASSES))
    results = perturbed_results(folder, tmp_path / "res")
    with pytest.raises(DataFormatError, match=r"CAM-01/gt/gt.txt, line \d+, field 'class': "
                                              "ground truth class 9 is not in the class map"):
        benchmark_for(ENV, root=str(folder), classes=CLASSES, distractors=[7]).score_folder(
            results)  # scoring alone (unitrack score) checks the ground truth as well
    text = (results / "CAM-01.txt").read_text().replace(",1,-1,-1\n", ",-1,-1,-1\n", 1)
    (results / "CAM-01.txt").write_text(text)
    bench = benchmark_for(ENV, root=str(folder), **MAP)
    with pytest.raises(DataFormatError, match="CAM-01.txt, line 1, field 'class': result "
                                              "class -1 is not in the class map"):
        bench.score_folder(results)


def test_the_env_plays_scored_classes_and_its_return_is_the_detection_average_mota(folder):
    env = gym.make(ENV, root=str(folder), sequences=["CAM-01"], **MAP)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert set(obs["classes"][:obs["num_detections"]]) <= {1, 2, 3}  # 7 and 9 not observed
    total, done = 0.0, False
    while not done:
        n = int(obs["num_detections"])
        ids = np.arange(1, n + 1)  # fresh ids per detection slot: a poor but valid tracker
        obs, reward, done, _, info = env.step({"ids": ids, "boxes": obs["boxes"][:n]})
        total += reward
    rows = env.unwrapped.episode_results()
    assert set(np.unique(rows[:, 7])) <= {1, 2, 3} and len(np.unique(rows[:, 7])) == 3
    m = info["metrics"]
    gt = m["CLR_TP"] + m["CLR_FN"]
    assert total / gt == pytest.approx(m["MOTA"]) and m["MOTA"] == m["cls_comb_det_av/MOTA"]
    assert {"car/HOTA", "pedestrian/HOTA", "cls_comb_cls_av/HOTA"} <= set(m)
    env.close()


def test_without_a_map_the_custom_env_scores_pedestrians_as_before(folder):
    env = gym.make(ENV, root=str(folder), sequences=["CAM-01"])
    obs, _ = env.reset(seed=0)
    assert "classes" not in obs and env.unwrapped.scoring.columns[:3] == (
        "HOTA", "IDF1", "MOTA")
    env.close()


def test_cli_evaluate_and_score_print_and_store_each_class(folder, tmp_path, capsys):
    out = tmp_path / "run"
    args = ["--env", ENV, "--root", str(folder), "--env-arg", f"classes={CLASSES}",
            "--env-arg", "distractors=[7]", "--env-arg", "ignore=[9]"]
    assert main(["evaluate", *args, "--agent", "iou", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "car/HOTA" in table and "pedestrian/HOTA" in table
    ours = json.loads((out / "metrics.json").read_text())
    assert 0 < ours["combined"]["car/HOTA"] <= 1 and 0 < ours["combined"]["pedestrian/HOTA"] <= 1
    theirs = trackeval_direct(folder, out / "data", tmp_path / "te")
    assert assert_parity(ours["combined"], theirs["COMBINED_SEQ"]) >= 24
    capsys.readouterr()  # TrackEval's printing
    assert main(["score", *args, "--results", str(out / "data"), "--format", "json"]) == 0
    scored = json.loads(capsys.readouterr().out)
    assert scored["combined"] == ours["combined"]
    with pytest.raises(DataFormatError, match="give the data's class map"):  # no map given
        benchmark_for(ENV, root=str(folder)).score_folder(out / "data")
    assert main(["events", str(out), "--format", "csv"]) == 0
    events = capsys.readouterr().out
    assert "class" in events.splitlines()[0] and ",car" in events and ",pedestrian" in events
    assert main(["report", str(out), "--out", str(tmp_path / "report")]) == 0
    page = (tmp_path / "report" / "index.html").read_text()
    assert "car/HOTA" in page and "pedestrian/HOTA" in page


def test_compare_recomputes_each_class_and_the_detection_average(folder, tmp_path):
    from unitrack_env.evaluation.analysis.intervals import compare_runs

    out = tmp_path / "run"
    assert main(["evaluate", "--env", ENV, "--root", str(folder), "--env-arg",
                 f"classes={CLASSES}", "--env-arg", "distractors=[7]", "--env-arg",
                 "ignore=[9]", "--agent", "iou", "--out", str(out), "--quiet"]) == 0
    ours = json.loads((out / "metrics.json").read_text())
    rows = compare_runs(out, out).rows
    for key in ("HOTA", "MOTA", "IDF1", "car/HOTA", "car/MOTA", "pedestrian/HOTA",
                "pedestrian/IDF1", "pedestrian/AssA"):
        assert rows["COMBINED"][key].a == pytest.approx(ours["combined"][key], abs=1e-12), key
        assert rows["CAM-01"][key].a == pytest.approx(ours["per_sequence"]["CAM-01"][key],
                                                      abs=1e-12), key


def test_a_classes_json_beside_the_data_declares_the_map(folder, tmp_path):
    import shutil

    root = shutil.copytree(folder, tmp_path / "data")
    (root / "classes.json").write_text(json.dumps(MAP))
    results = perturbed_results(folder, tmp_path / "res")
    declared = benchmark_for(ENV, root=str(root)).score_folder(results)
    given = benchmark_for(ENV, root=str(folder), **MAP).score_folder(results)
    assert declared.combined == given.combined and "car/HOTA" in declared.combined
    only_cars = benchmark_for(ENV, root=str(root), classes={"car": [3]},
                              distractors=[7], ignore=[1, 2, 9])  # arguments win
    assert only_cars.columns[:3] == ("HOTA", "car/HOTA", "cls_comb_cls_av/HOTA")
    cars = only_cars.score_folder(results).combined  # rows of ignored ids: not scored
    assert cars["car/HOTA"] == given.combined["car/HOTA"] == cars["HOTA"]


def test_empty_frames_and_files_score_as_nothing(folder, tmp_path):
    cmap = ClassMap.parse(**MAP)
    gt, mine = cmap.pedestrian_rows("car", np.zeros((0, 9)), np.zeros((0, 6)))
    assert gt.shape == (0, 9) and mine.shape == (0, 10)
    results = perturbed_results(folder, tmp_path / "res")
    (results / "CAM-02.txt").write_text("")  # a tracker that output nothing there
    report = benchmark_for(ENV, root=str(folder), **MAP).score_folder(results)
    assert report.per_sequence["CAM-02"]["car/HOTA"] == 0
    assert report.per_sequence["CAM-02"]["CLR_FN"] > 0

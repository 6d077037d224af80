"""Issue 40 item 1: DanceTrack and SportsMOT, the MOTChallenge layout with their own splits.

Their embedded synthetic defaults are in each data set's exact layout; scores equal
TrackEval's own Evaluator run as the benchmarks' kits run it (``MotChallenge2DBox`` under
their ``BENCHMARK`` names, the split folder, its seqmap, ``SKIP_SPLIT_FOL``).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.benchmarks import benchmark_for
from unitrack_env.datasets.synthetic.cache import ensure_synthetic
from unitrack_env.datasets.synthetic.dance_sports import KIND
from unitrack_env.errors import DataFormatError
from unitrack_env.evaluation.cli import main

DANCE, SPORTS = "UniTrack/DanceTrack-v0", "UniTrack/SportsMOT-v0"
#: (env id, benchmark, split folder below the root, seqmap of a split, the val sequence)
CASES = [(DANCE, "DanceTrack", "{split}", "{split}_seqmap.txt", "dancetrack0004"),
         (SPORTS, "SportsMOT", "dataset/{split}", "splits_txt/{split}.txt",
          "v_SYNTHsports_c002")]


def synthetic_root(benchmark: str) -> Path:
    return ensure_synthetic(benchmark, KIND)


def copy_without_detections(benchmark: str, to: Path) -> Path:
    root = shutil.copytree(synthetic_root(benchmark), to, symlinks=True)
    shutil.rmtree(root / "detections")
    return root


def trackeval_direct(benchmark: str, split_dir: Path, names: list[str], results: Path,
                     tmp: Path) -> dict:
    """TrackEval's own Evaluator, configured as DanceTrack's README runs it.

    Its seqmap has TrackEval's ``name`` header (DanceTrack's have it; SportsMOT's
    ``splits_txt`` files do not, its kit's ``sportsmot-val.txt`` seqmaps do).
    """
    import trackeval

    seqmap = tmp / "seqmap.txt"
    tmp.mkdir(parents=True, exist_ok=True)
    seqmap.write_text("".join(f"{n}\n" for n in ["name", *names]))
    config = {**trackeval.Evaluator.get_default_eval_config(), "USE_PARALLEL": False,
              "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
              "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
              "DISPLAY_LESS_PROGRESS": True}
    dataset = trackeval.datasets.MotChallenge2DBox({
        "GT_FOLDER": str(split_dir), "SEQMAP_FILE": str(seqmap), "SKIP_SPLIT_FOL": True,
        "BENCHMARK": benchmark, "SPLIT_TO_EVAL": "val", "TRACKERS_FOLDER": str(results.parent),
        "TRACKERS_TO_EVAL": [results.name], "TRACKER_SUB_FOLDER": "",
        "OUTPUT_FOLDER": str(tmp / "out"), "PRINT_CONFIG": False})
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    out, _ = trackeval.Evaluator(config).evaluate([dataset], metrics)
    return out["MotChallenge2DBox"][results.name]


def assert_parity(ours: dict[str, float], theirs: dict) -> None:
    checked = 0
    for metric in ("HOTA", "CLEAR", "Identity"):
        for name, expected in theirs["pedestrian"][metric].items():
            if name in ours and not isinstance(expected, dict):
                value = float(np.mean(expected)) if np.ndim(expected) else float(expected)
                assert ours[name] == value, (name, ours[name], value)  # every digit
                checked += 1
    assert checked >= 20


@pytest.mark.parametrize(("env_id", "benchmark", "split", "seqmap", "seq"), CASES)
def test_the_synthetic_default_has_the_exact_layout(env_id, benchmark, split, seqmap, seq):
    root = synthetic_root(benchmark)
    digits = 8 if benchmark == "DanceTrack" else 6
    for where in ("train", "val"):
        folder = root / split.format(split=where)
        names = [n for n in (root / seqmap.format(split=where)).read_text().split()
                 if n != "name"]
        assert where == "train" or names == [seq]
        seq_dir = folder / names[0]
        assert (seq_dir / "img1" / f"{1:0{digits}d}.jpg").is_file()
        assert (seq_dir / "gt" / "gt.txt").is_file() and (seq_dir / "seqinfo.ini").is_file()
        assert not (seq_dir / "det").exists()  # no public detections in these layouts
        assert (root / "detections" / where / f"{names[0]}.txt").is_file()
        rows = np.loadtxt(seq_dir / "gt" / "gt.txt", delimiter=",")
        assert (rows[:, 6:9] == 1).all()  # the READMEs' "..., 1, 1, 1" rows
    header = (root / seqmap.format(split="val")).read_text().splitlines()[0]
    assert (header == "name") == (benchmark == "DanceTrack")  # DanceTrack's seqmaps have one
    test_seq = next(p for p in (root / split.format(split="test")).iterdir())
    assert not (test_seq / "gt").exists()
    env = gym.make(env_id)
    assert env.unwrapped.sequence_names == [seq]  # the val split, by default
    env.close()


def test_dancers_wear_one_costume_and_players_two_kits():
    import itertools

    import cv2

    for benchmark, kits in (("DanceTrack", 1), ("SportsMOT", 2)):
        env = gym.make(f"UniTrack/{benchmark}-v0", split="train")
        base = env.unwrapped
        _, info = env.reset()
        seq = base.dataset.load(info["sequence"])
        rows = seq.ground_truth.rows(1)
        image = cv2.imread(str(seq.info.frame_path(1)))[:, :, ::-1].astype(float)
        colours = []
        for x, y, w, h in seq.ground_truth.boxes[rows]:
            x0, y0 = int(x - 1 + w * 0.4), int(y - 1 + h * 0.45)
            patch = image[y0:y0 + int(h * 0.3), x0:x0 + max(2, int(w * 0.2))]
            if patch.size:
                colours.append(patch.reshape(-1, 3).mean(0))
        gaps = [np.abs(a - b).max() for a, b in itertools.combinations(colours, 2)]
        alike = sum(gap < 40 for gap in gaps) / len(gaps)
        assert alike > (0.9 if kits == 1 else 0.3), (benchmark, alike)
        env.close()


@pytest.mark.parametrize(("env_id", "benchmark", "split", "seqmap", "seq"), CASES)
def test_without_detections_make_refuses_naming_the_expected_path(
        env_id, benchmark, split, seqmap, seq, tmp_path):
    root = copy_without_detections(benchmark, tmp_path / benchmark)
    with pytest.raises(DataFormatError) as caught:
        gym.make(env_id, root=str(root))
    message = str(caught.value)
    assert f"detections/val/{seq}.txt" in message
    assert f"{benchmark} ships no public detections" in message and "detections=" in message
    env = gym.make(env_id, root=str(root),
                   detections=str(synthetic_root(benchmark) / "detections" / "val"))
    _, info = env.reset()
    assert info["sequence"] == seq and not info["synthetic"]
    env.close()


def test_the_cli_refuses_before_writing_anything(tmp_path, capsys):
    root = copy_without_detections("DanceTrack", tmp_path / "DanceTrack")
    out = tmp_path / "run"
    assert main(["evaluate", "--env", DANCE, "--root", str(root), "--agent", "iou",
                 "--out", str(out), "--quiet"]) == 2
    assert "detections/val/dancetrack0004.txt" in capsys.readouterr().err
    assert not (out / "data").exists()


def test_the_seqmap_lists_the_split(tmp_path):
    root = shutil.copytree(synthetic_root("SportsMOT"), tmp_path / "SportsMOT", symlinks=True)
    seqmap = root / "splits_txt" / "val.txt"
    seqmap.unlink()
    seqmap.write_text("v_SYNTHsports_c002\nv_SYNTHsports_c009\n")
    with pytest.raises(DataFormatError, match=r"val.txt, line 2: lists 'v_SYNTHsports_c009'"):
        gym.make(SPORTS, root=str(root))


@pytest.mark.parametrize(("env_id", "benchmark", "split", "seqmap", "seq"), CASES)
def test_iou_plays_and_scores_as_trackeval(env_id, benchmark, split, seqmap, seq, tmp_path,
                                           capsys):
    out = tmp_path / "run"
    assert main(["evaluate", "--env", env_id, "--agent", "iou", "--out", str(out),
                 "--quiet"]) == 0
    ours = json.loads((out / "metrics.json").read_text())
    assert ours["benchmark"] == benchmark
    root = synthetic_root(benchmark)
    val = root / split.format(split="val")
    theirs = trackeval_direct(benchmark, val, [seq], out / "data", tmp_path)
    assert_parity(ours["per_sequence"][seq], theirs[seq])
    assert_parity(ours["combined"], theirs["COMBINED_SEQ"])
    # A perturbed copy of the ground truth, given back through `unitrack score`.
    rng = np.random.default_rng(0)
    gt = np.loadtxt(val / seq / "gt" / "gt.txt", delimiter=",")
    keep = gt[rng.uniform(size=len(gt)) > 0.1]
    keep[:, 2:6] += rng.normal(0, 3, (len(keep), 4))
    keep[keep[:, 0] > 20, 1] += 100 * (keep[keep[:, 0] > 20, 1] % 2)  # half switch ids
    results = tmp_path / "perturbed" / "mine"
    results.mkdir(parents=True)
    np.savetxt(results / f"{seq}.txt", np.c_[keep[:, :6], np.ones((len(keep), 4)) * -1],
               delimiter=",", fmt="%.3f")
    capsys.readouterr()
    assert main(["score", "--env", env_id, "--results", str(results), "--format",
                 "json"]) == 0
    scored = json.loads(capsys.readouterr().out)
    theirs = trackeval_direct(benchmark, val, [seq], results, tmp_path / "p")
    assert_parity(scored["combined"], theirs["COMBINED_SEQ"])
    assert 0.5 < scored["combined"]["HOTA"] < 0.95 and scored["combined"]["IDSW"] > 0


@pytest.mark.parametrize("env_id", [DANCE, SPORTS])
def test_unitrack_plays_to_the_official_metrics(env_id):
    from unitrack_env.agents import make_agent

    env = gym.make(env_id)
    agent = make_agent("unitrack", input_size=(272, 152), num_threads=1)  # small: fast
    observation, info = env.reset()
    agent.reset(observation, info)
    terminated = False
    while not terminated:
        observation, _, terminated, _, info = env.step(agent.act(observation))
    assert 0.3 < info["metrics"]["HOTA"] <= 1.0 and info["metrics"]["IDF1"] > 0.3
    env.close()


@pytest.mark.parametrize(("env_id", "submission"), [
    (DANCE, "tracker/dancetrack0003.txt"), (SPORTS, "v_SYNTHsports_c003.txt")])
def test_the_test_split_writes_the_servers_layout(env_id, submission, tmp_path):
    out = tmp_path / "run"
    assert main(["evaluate", "--env", env_id, "--split", "test", "--agent", "iou", "--out",
                 str(out), "--quiet"]) == 0
    written = sorted(str(p.relative_to(out / "data")) for p in (out / "data").rglob("*.txt"))
    assert written == [submission]
    rows = np.loadtxt(out / "data" / submission, delimiter=",")
    assert rows.shape[1] == 10 and (rows[:, 7:] == -1).all()
    assert "note" in json.loads((out / "metrics.json").read_text())  # nothing to score
    bench = benchmark_for(env_id, split="test")
    assert bench.read(out / "data", Path(submission).stem).shape == rows.shape


@pytest.mark.parametrize(("env_id", "benchmark", "split", "seqmap", "seq"), CASES)
def test_their_data_under_another_rule_set_name_the_id_to_use(
        env_id, benchmark, split, seqmap, seq, tmp_path):
    root = tmp_path / "custom"
    (root / "train").mkdir(parents=True)
    (root / "train" / seq).symlink_to(synthetic_root(benchmark) / split.format(split="val")
                                      / seq)
    with pytest.raises(DataFormatError, match=f"named like a {benchmark} sequence.*use "
                                              f"{env_id}"):
        gym.make("UniTrack/MOTChallenge-v0", root=str(root))

"""NfS (30 / 240 fps) and UAV123's sub-sequences and UAV20L split: readers, envs, got10k parity.

The ``got10k`` package (the test extra's parity reference) reads NfS and UAV123 with its own
``datasets.NfS`` / ``datasets.UAV123`` and scores NfS by ``ExperimentNfS`` (the OTB rules).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import unitrack_env  # noqa: F401 - registers the ids
from unitrack_env.benchmarks import benchmark_class, benchmark_for
from unitrack_env.datasets.nfs import NfSDataset, write_synthetic_nfs
from unitrack_env.datasets.uav123 import UAV123_SUBSEQUENCES, UAV123Dataset, subsequence_range
from unitrack_env.errors import DataFormatError


@pytest.fixture(scope="module")
def nfs_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("nfs")
    write_synthetic_nfs(root)
    return root


@pytest.mark.parametrize("variant", ["30", "240"])
def test_nfs_id_passes_check_env_and_plays_its_synthetic_default(variant):
    env = gym.make("UniTrack/NfS-v0", variant=variant)
    assert env.unwrapped.synthetic
    check_env(env.unwrapped, skip_render_check=True)
    observation, info = env.reset(options={"sequence": "synwalk_1"})
    assert info["seq_length"] == (11 if variant == "30" else 81)
    terminated = False
    while not terminated:
        observation, _, terminated, _, info = env.step(observation["init_box"])
    assert set(info["metrics"]) == {"AUC", "Precision@20px", "AverageOverlap"}
    env.close()
    assert type(benchmark_for("UniTrack/NfS-v0")) is benchmark_class("UniTrack/NfS-v0")


@pytest.mark.parametrize("fps", [30, 240])
def test_nfs_frames_and_boxes_match_got10k_reader(got10k_experiments, nfs_root, fps, monkeypatch):
    from got10k.datasets import NfS, nfs

    monkeypatch.setattr(nfs.six, "string_types", str, raising=False)  # a stub six may lack it

    reference, ours = NfS(str(nfs_root), fps=fps), NfSDataset(nfs_root, str(fps))
    assert ours.sequence_names == sorted(reference.seq_names)
    for name in ours.sequence_names:
        files, anno = reference[name]
        sequence = ours.load(name)
        assert [str(p) for p in sequence.frame_paths] == files
        assert np.array_equal(sequence.boxes, anno)


def test_nfs_30fps_keeps_every_eighth_240fps_row_and_drops_a_leftover_image(nfs_root):
    full = NfSDataset(nfs_root, "240").load("synball_2")
    thirty = NfSDataset(nfs_root, "30").load("synball_2")
    # 72 rows at 240 fps, 10 images at 30 fps: rows 1, 9, ..., 65 and the first 9 images.
    images = list((nfs_root / "synball_2" / "30" / "synball_2").iterdir())
    assert thirty.num_frames == 9 and len(images) == 10
    assert np.array_equal(thirty.boxes, full.boxes[::8])


def test_nfs_scores_match_got10k_experiment(got10k_experiments, nfs_root, tmp_path):
    from got10k.experiments import ExperimentNfS

    bench = benchmark_for("UniTrack/NfS-v0", root=str(nfs_root))
    runner = ExperimentNfS.__new__(ExperimentNfS)
    runner.nbins_iou, runner.nbins_ce = 21, 51
    rng = np.random.default_rng(5)
    for name in bench.sequence_names:
        gt = bench.load(name).boxes
        pred = gt + rng.normal(0, 6, gt.shape)
        pred[:, 2:] = np.abs(pred[:, 2:]) + 1
        bench.write(tmp_path, name, pred)
        pred = bench.read(tmp_path, name).copy()
        ours = bench.score_files(tmp_path, [name]).per_sequence[name]
        pred[0] = gt[0]
        succ, prec = runner._calc_curves(*runner._calc_metrics(pred, gt))
        assert ours["AUC"] == pytest.approx(np.mean(succ), abs=1e-6)
        assert ours["Precision@20px"] == pytest.approx(prec[20], abs=1e-6)


def test_bad_nfs_annotations_are_named(nfs_root, tmp_path):
    import shutil

    shutil.copytree(nfs_root, tmp_path / "n")
    anno = tmp_path / "n" / "synwalk_1" / "30" / "synwalk_1.txt"
    lines = anno.read_text().splitlines(keepends=True)
    anno.write_text(lines[0] + "1 10 x 30 40 2 0 0 0 \"person\"\n" + "".join(lines[2:]))
    with pytest.raises(DataFormatError, match=r"synwalk_1.txt.*line 2.*ymin.*not a number"):
        NfSDataset(tmp_path / "n").load("synwalk_1")
    anno.write_text("1 10 20 30\n")
    with pytest.raises(DataFormatError, match=r"line 1.*expected track_id"):
        NfSDataset(tmp_path / "n").load("synwalk_1")
    anno.write_text("".join(lines[:40]))  # neither 8x nor 1 row away from the 11 images
    with pytest.raises(DataFormatError, match="40 rows but the frame folder holds 11"):
        NfSDataset(tmp_path / "n").load("synwalk_1")
    with pytest.raises(ValueError, match="NfS variant '60'"):
        NfSDataset(tmp_path / "n", "60")


def _uav_tree(root: Path, folder: str, names: dict[str, int], frames: dict[str, int]) -> None:
    image = np.zeros((8, 8, 3), np.uint8)
    for video, count in frames.items():
        path = root / "data_seq" / folder / video
        path.mkdir(parents=True)
        for i in range(1, count + 1):
            cv2.imwrite(str(path / f"{i:06d}.jpg"), image)
    for name, rows in names.items():
        anno = root / "anno" / ("UAV20L" if name.endswith("L") else folder)
        anno.mkdir(parents=True, exist_ok=True)
        (anno / f"{name.removesuffix('L')}.txt").write_text("2,2,3,3\n" * rows)


def test_uav123_sub_sequences_play_their_configseqs_frame_ranges(tmp_path):
    # 10 fps truck4: truck4_1 is frames 1-193, truck4_2 frames 193-421 (30 fps 577-1261).
    _uav_tree(tmp_path, "UAV123_10fps", {"truck4_1": 193, "truck4_2": 229}, {"truck4": 421})
    data = UAV123Dataset(tmp_path)
    assert data.sequence_names == ["truck4_1", "truck4_2"]
    second = data.load("truck4_2")
    assert second.frame_numbers[0] == 193 and second.frame_paths[-1].name == "000421.jpg"
    env = gym.make("UniTrack/UAV123-v0", root=str(tmp_path))
    assert env.reset(options={"sequence": "truck4_2"})[1]["frame_index"] == 193
    env.close()
    (tmp_path / "anno" / "UAV123_10fps" / "truck4_2.txt").write_text("2,2,3,3\n" * 228)
    with pytest.raises(DataFormatError, match="228 rows but the sub-sequence is frames 193-421"):
        UAV123Dataset(tmp_path).load("truck4_2")
    (tmp_path / "anno" / "UAV123_10fps" / "person12_1.txt").write_text("2,2,3,3\n")
    with pytest.raises(DataFormatError, match="person12_1.txt.*no frame folder.*person12"):
        UAV123Dataset(tmp_path)


def test_uav123_sub_sequence_table_is_got10ks_and_10fps_ranges_are_the_toolkits(got10k_experiments):
    meta = json.loads((Path(got10k_experiments.__file__).parents[1] / "datasets" / "uav123.json")
                      .read_text())
    parts = {name: (m["start_frame"], m["end_frame"]) for name, m in meta["UAV123"].items()
             if m["folder_name"] != name}
    ours = {f"{folder}_{k}": r for folder, ranges in UAV123_SUBSEQUENCES.items()
            for k, r in enumerate(ranges, start=1)}
    assert ours == parts
    for name, (first, last) in {"person12_2": (201, 541), "uav1_3": (825, 1157),
                                "bird1_2": (259, 493), "car6_5": (1309, 1621)}.items():
        assert subsequence_range(name, "UAV123_10fps")[1] == range(first, last + 1)
        assert subsequence_range(name, "UAV123")[1] == range(parts[name][0], parts[name][1] + 1)


def test_uav20l_is_a_split_reading_uav123_frames(tmp_path):
    _uav_tree(tmp_path, "UAV123", {"car9": 5, "car9L": 5}, {"car9": 5})
    data = UAV123Dataset(tmp_path, split="UAV20L")
    assert data.sequence_names == ["car9"] and data.load("car9").benchmark == "UAV20L"
    with pytest.raises(ValueError, match="UAV20L has no 10 fps release"):
        UAV123Dataset(tmp_path, variant="10fps", split="UAV20L")
    with pytest.raises(ValueError, match="UAV123 split 'UAV30'"):
        UAV123Dataset(tmp_path, split="UAV30")
    env = gym.make("UniTrack/UAV123-v0", root=str(tmp_path), split="UAV20L")
    assert env.reset()[1]["benchmark"] == "UAV123"
    env.close()

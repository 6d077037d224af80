"""Issue 40: data of another MOT benchmark are refused at the door, naming the id to use."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import gymnasium as gym
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.datasets.mot_signatures import SIGNATURES, check_signature, gt_class_ids
from unitrack_env.errors import DataFormatError
from unitrack_env.evaluation.cli import main


def test_mot15_rules_on_mot17_data_are_refused_by_the_cli(mot17_root: Path, tmp_path, capsys):
    # The issue's case: this exited 0, scoring MOT17 under MOT15's rules.
    code = main(["evaluate", "--env", "UniTrack/MOT15-v0", "--root", str(mot17_root),
                 "--agent", "iou", "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "MOT17-02-FRCNN: named like a MOT17 sequence" in err
    assert "use UniTrack/MOT17-v0" in err
    assert not (tmp_path / "out" / "data").exists()  # refused before the first frame


@pytest.mark.parametrize(("rule_set", "root", "looks"), [
    ("MOT17", "mot15_root", "UniTrack/MOT15-v0"),
    ("MOT16", "mot17_root", "UniTrack/MOT17-v0"),
    ("MOT20", "mot17_root", "UniTrack/MOT17-v0"),
])
def test_named_like_another_benchmark(rule_set, root, looks, request):
    with pytest.raises(DataFormatError, match=f"use {looks}"):
        gym.make(f"UniTrack/{rule_set}-v0", root=str(request.getfixturevalue(root)))


def test_class_columns_under_mot15_are_refused_whatever_the_names(mot17_root, tmp_path):
    (tmp_path / "train").mkdir()
    shutil.copytree(mot17_root / "train" / "MOT17-05-FRCNN", tmp_path / "train" / "cam5")
    assert gt_class_ids(tmp_path / "train" / "cam5" / "gt" / "gt.txt") == [1, 2, 3, 4, 8, 9]
    with pytest.raises(DataFormatError, match="cam5/gt/gt.txt: 9 columns with class ids"):
        gym.make("UniTrack/MOT15-v0", root=str(tmp_path))
    gym.make("UniTrack/MOTChallenge-v0", root=str(tmp_path)).close()  # the id it names


def test_score_with_a_benchmark_and_a_gt_folder_is_refused_too(mot17_root, tmp_path, capsys):
    code = main(["score", "--benchmark", "MOT15", "--gt", str(mot17_root / "train"),
                 "--results", str(tmp_path)])
    assert code == 2
    assert "use UniTrack/MOT17-v0" in capsys.readouterr().err


@pytest.mark.parametrize(("env_id", "root"), [("UniTrack/MOT15-v0", "mot15_root"),
                                              ("UniTrack/MOT17-v0", "mot17_root")])
def test_each_benchmark_opens_its_own_data_without_a_word(env_id, root, request):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, root=str(request.getfixturevalue(root)), decode_frames=False)
        env.reset()
        env.close()


def test_every_rule_set_names_its_own_sequences():
    official = {"MOT15": "PETS09-S2L1", "MOT16": "MOT16-02", "MOT17": "MOT17-02-FRCNN",
                "MOT20": "MOT20-01"}
    for rule_set, name in official.items():
        assert [s.benchmark for s in SIGNATURES.values() if s.names_match(name)] == [rule_set]
        check_signature(rule_set, Path("/nonexistent"), [name])  # its own: accepted
    assert not any(s.names_match("SYN-01") for s in SIGNATURES.values())  # custom names

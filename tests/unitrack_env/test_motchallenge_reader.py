from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.datasets.motchallenge import (
    MOTChallengeDataset,
    read_detections,
    read_ground_truth,
    read_seqinfo,
)
from unitrack_env.errors import DataFormatError, UnknownSequenceError

SEQINFO = """[Sequence]
name=S1
imDir=img1
frameRate=25
seqLength=3
imWidth=64
imHeight=48
imExt=.jpg
"""


def make_sequence(root: Path, name: str = "S1", frames: int = 3, gt: str | None = None,
                  det: str = "1,-1,1,1,10,20,0.9\n") -> Path:
    import cv2

    seq = root / "train" / name
    (seq / "img1").mkdir(parents=True)
    (seq / "det").mkdir()
    (seq / "seqinfo.ini").write_text(SEQINFO.replace("name=S1", f"name={name}"))
    for t in range(1, frames + 1):
        cv2.imwrite(str(seq / "img1" / f"{t:06d}.jpg"), np.full((48, 64, 3), 40 * t, np.uint8))
    (seq / "det" / "det.txt").write_text(det)
    if gt is not None:
        (seq / "gt").mkdir()
        (seq / "gt" / "gt.txt").write_text(gt)
    return seq


def test_reads_real_mot17_clips_with_seven_column_unsorted_detections(mot17_root: Path):
    dataset = MOTChallengeDataset(mot17_root, "MOT17")
    assert dataset.sequence_names == [
        "MOT17-02-FRCNN", "MOT17-04-FRCNN", "MOT17-05-FRCNN", "MOT17-11-FRCNN"]
    raw = np.loadtxt(mot17_root / "train/MOT17-04-FRCNN/det/det.txt", delimiter=",")
    assert raw.shape[1] == 7 and np.any(np.diff(raw[:, 0]) < 0), "fixture should be unsorted"
    seq = dataset.load("MOT17-04-FRCNN")
    assert seq.info.length == 8 and (seq.info.width, seq.info.height) == (1920, 1080)
    assert len(seq.detections) == len(raw)
    assert np.all(np.diff(seq.detections.frames) >= 0)
    # Every row of frame 3 in the file is served for frame 3, with its box and score.
    rows = seq.detections.rows(3)
    expected = raw[raw[:, 0] == 3]
    got = np.column_stack([seq.detections.boxes[rows], seq.detections.scores[rows]])
    np.testing.assert_allclose(np.sort(got, axis=0), np.sort(expected[:, 2:7], axis=0))
    gt = seq.ground_truth
    assert gt is not None and set(np.unique(gt.classes)) >= {1, 7}
    assert gt.visibility.max() <= 1.0


def test_reads_real_pets_in_mot15_layout(mot15_root: Path):
    seq = MOTChallengeDataset(mot15_root, "MOT15").load("PETS09-S2L1")
    assert seq.info.length == 400 and seq.info.frame_rate == 7
    assert len(seq.ground_truth) == 2396 and len(seq.detections) == 2905
    assert np.all(seq.ground_truth.classes == 1)  # MOT15 has no class column
    assert seq.detections.scores.max() > 1.0  # unbounded detector scores are kept
    assert len(np.unique(seq.ground_truth.ids)) == 10
    assert seq.ground_truth.count_per_frame(400).min() >= 1


def test_ten_and_seven_column_detections_agree(tmp_path: Path):
    ten = tmp_path / "ten.txt"
    seven = tmp_path / "seven.txt"
    ten.write_text("2,-1,5,6,7,8,0.5,-1,-1,-1\n1,-1,1,2,3,4,0.9,-1,-1,-1\n")
    seven.write_text("2,-1,5,6,7,8,0.5\n1,-1,1,2,3,4,0.9\n")
    a, b = read_detections(ten), read_detections(seven)
    np.testing.assert_array_equal(a.boxes, b.boxes)
    np.testing.assert_array_equal(a.frames, [1, 2])
    assert a.rows(2) == slice(1, 2) and a.rows(9) == slice(0, 0)


@pytest.mark.parametrize(
    ("text", "line", "field", "what"),
    [
        ("1,-1,1,1,10,20,0.9\n1,-1,1,x,10,20,0.9\n", 2, "y", "not a number"),
        ("1,-1,1,1,10,20\n", 1, None, "expected at least 7"),
        ("1,-1,1,1,10,20,0.9\n\n4,-1,1,1,10,20,0.9\n", 3, "frame", "not a frame"),
        ("1,-1,1,1,-10,20,0.9\n", 1, "w", "negative"),
        ("1,-1,1,1,nan,20,0.9\n", 1, "w", "finite"),
        ("1,-1,1,1,10,20,0.9\n1,-1,1,1,10,20,0.9,1\n", 2, None, "columns"),
    ],
)
def test_malformed_detections_name_file_line_and_field(tmp_path, text, line, field, what):
    path = tmp_path / "det.txt"
    path.write_text(text)
    with pytest.raises(DataFormatError) as info:
        read_detections(path, length=3)
    err = info.value
    assert err.path == path and err.line == line and err.field == field
    assert what in str(err) and str(path) in str(err)


def test_ground_truth_needs_class_columns_except_mot15(tmp_path: Path):
    path = tmp_path / "gt.txt"
    path.write_text("1,1,1,1,10,20,1,-1,-1,-1\n")
    assert read_ground_truth(path, "MOT15").classes.tolist() == [1]
    path.write_text("1,1,1,1,10,20,1\n")
    with pytest.raises(DataFormatError, match="expected at least 9"):
        read_ground_truth(path, "MOT17")
    path.write_text("1,1.5,1,1,10,20,1,1,1\n")
    with pytest.raises(DataFormatError, match="not an integer"):
        read_ground_truth(path, "MOT17")


def test_seqinfo_errors_name_the_field(tmp_path: Path):
    seq = make_sequence(tmp_path)
    info = read_seqinfo(seq)
    assert (info.length, info.width, info.height, info.frame_rate) == (3, 64, 48, 25.0)
    (seq / "seqinfo.ini").write_text(SEQINFO.replace("seqLength=3", "seqLength=three"))
    with pytest.raises(DataFormatError, match="field 'seqLength'"):
        read_seqinfo(seq)
    (seq / "seqinfo.ini").write_text(SEQINFO.replace("imExt=.jpg\n", ""))
    with pytest.raises(DataFormatError, match="field 'imExt'.*missing"):
        read_seqinfo(seq)
    (seq / "seqinfo.ini").unlink()
    with pytest.raises(DataFormatError, match="seqinfo.ini: missing"):
        read_seqinfo(seq)


def test_missing_frame_and_unknown_sequence(tmp_path: Path):
    seq = make_sequence(tmp_path)
    dataset = MOTChallengeDataset(tmp_path, "MOT17")
    assert dataset.load("S1").ground_truth is None  # test-split style: no gt
    (seq / "img1" / "000002.jpg").unlink()
    with pytest.raises(DataFormatError, match="000002.jpg: missing frame 2 of 3"):
        dataset.load("S1")
    for frame in (seq / "img1").iterdir():  # PNG frames, seqinfo.ini still says .jpg
        frame.rename(frame.with_suffix(".png"))
    with pytest.raises(DataFormatError, match="folder holds 000001.png: is seqinfo.ini imExt"):
        dataset.load("S1")
    with pytest.raises(UnknownSequenceError, match="available: S1"):
        dataset.load("S9")


def test_root_without_split_folder_explains(tmp_path: Path):
    make_sequence(tmp_path)
    with pytest.raises(DataFormatError, match="split folder missing.*found: train"):
        MOTChallengeDataset(tmp_path, "MOT17", split="test")


def test_a_root_one_level_off_says_where_to_point(tmp_path: Path):
    make_sequence(tmp_path / "MOT17")
    with pytest.raises(DataFormatError, match=f"did you mean root={tmp_path / 'MOT17'}\\?"):
        MOTChallengeDataset(tmp_path, "MOT17")  # the folder holding the benchmarks
    with pytest.raises(DataFormatError, match=f"it is a split folder, pass its parent "
                                              f"{tmp_path / 'MOT17'}$"):
        MOTChallengeDataset(tmp_path / "MOT17" / "train", "MOT17")


def test_user_detection_folder(tmp_path: Path):
    make_sequence(tmp_path)
    dets = tmp_path / "mydets"
    dets.mkdir()
    (dets / "S1.txt").write_text("2,-1,3,3,5,5,0.4\n")
    seq = MOTChallengeDataset(tmp_path, "MOT17", detections=dets).load("S1")
    assert seq.detections.frames.tolist() == [2]
    shutil.rmtree(dets)
    dets.mkdir()
    with pytest.raises(DataFormatError, match="no detection file for sequence 'S1'"):
        MOTChallengeDataset(tmp_path, "MOT17", detections=dets).load("S1")
    (dets / "S1.txt").write_text("2,-1,3,3,5,5,0.4\n")
    (dets / "S2-typo.txt").write_text("2,-1,3,3,5,5,0.4\n")
    with pytest.warns(UserWarning, match="S2-typo.txt match no sequence of"):
        MOTChallengeDataset(tmp_path, "MOT17", detections=dets)
    with pytest.raises(DataFormatError, match="detections folder not found"):
        MOTChallengeDataset(tmp_path, "MOT17", detections=tmp_path / "nope").load("S1")


def test_corrupt_frame_is_reported_by_the_env(tmp_path: Path):
    import gymnasium as gym

    seq = make_sequence(tmp_path, det="1,-1,1,1,10,20,0.9\n2,-1,1,1,10,20,0.9\n")
    (seq / "img1" / "000002.jpg").write_bytes(b"\xff\xd8 not really a jpeg")
    env = gym.make("UniTrack/MOTChallenge-v0", root=tmp_path)
    # Refused at reset, before a frame is played (the file has no JPEG end marker).
    with pytest.raises(DataFormatError, match="000002.jpg: truncated image"):
        env.reset()
    # A complete file that still does not decode is reported when decoded.
    (seq / "img1" / "000002.jpg").write_bytes(b"\xff\xd8 not really a jpeg \xff\xd9")
    observation, _ = env.reset()
    assert observation["frame"].shape == (48, 64, 3)
    with pytest.raises(DataFormatError, match="000002.jpg: not a decodable image"):
        env.step({"ids": np.zeros(0, int), "boxes": np.zeros((0, 4))})

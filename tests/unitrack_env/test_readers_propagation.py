"""Readers for the propagation benchmarks: OTB (+ LaSOT, GOT-10k), DAVIS-2017, JHMDB."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from unitrack_env.datasets import davis, jhmdb, lasot, otb
from unitrack_env.errors import DataFormatError, UnknownSequenceError

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"


def _data(name: str) -> Path:
    root = DATA / name
    if not root.is_dir():
        pytest.skip(f"shared {name} fixture missing")
    return root


def _images(folder: Path, numbers, digits: int = 4, ext: str = ".jpg", size=(8, 6)) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for n in numbers:
        cv2.imwrite(str(folder / f"{n:0{digits}d}{ext}"), np.zeros((size[1], size[0], 3), np.uint8))


# --------------------------------------------------------------------------- OTB


def test_otb100_table_facts():
    specs = {s.name: s for s in otb.OTB100_SEQUENCES}
    assert len(specs) == 100
    # OTB-2015 has 59,040 annotated frames; Tiger1's 5 omitted frames leave 59,035 tracked.
    assert sum(s.end_frame - s.start_frame + 1 for s in specs.values()) == 59040
    assert sum(s.num_frames for s in specs.values()) == 59035
    assert (specs["David"].start_frame, specs["David"].end_frame) == (300, 770)
    assert (specs["BlurCar1"].start_frame, specs["BlurCar1"].end_frame) == (247, 988)
    assert specs["Tiger1"].init_omit == 5
    assert specs["Jogging.2"].folder == "Jogging"
    assert specs["Jogging.2"].gt_file == "groundtruth_rect.2.txt"
    assert specs["Human4.2"].gt_file == "groundtruth_rect.2.txt"
    assert otb.canonical_otb_name("Jogging-1") == "Jogging.1"
    assert otb.canonical_otb_name("Car24") == "Car24"


def test_real_otb_fixture():
    root = _data("OTB")
    ds = otb.OTBDataset(root)
    assert ds.sequence_names == ["Crossing", "Human3"]
    crossing = ds.load("crossing")  # case-insensitive
    assert crossing.num_frames == 120 and crossing.image_size == (360, 240)
    np.testing.assert_array_equal(crossing.boxes[0], [205, 151, 17, 50])  # tab-separated file
    assert crossing.frame_numbers[0] == 1 and crossing.frame_paths[-1].name == "0120.jpg"
    assert not crossing.absent.any() and crossing.has_ground_truth
    with pytest.warns(UserWarning, match="199 of the 1698"):
        human3 = ds.load("Human3")
    assert human3.num_frames == 199 and human3.image_size == (480, 640)
    last_line = (root / "Human3" / "groundtruth_rect.txt").read_text().split("\n")[-1]
    np.testing.assert_array_equal(human3.boxes[-1], [float(v) for v in last_line.split(",")])
    with pytest.raises(UnknownSequenceError, match="available: Crossing, Human3"):
        ds.load("Basketball")


def test_box_file_separators_and_errors(tmp_path):
    f = tmp_path / "gt.txt"
    f.write_text("1,2,3,4\n5\t6\t7\t8\n9 10, 11\t12,\nNaN,NaN,NaN,NaN")
    boxes = otb.read_box_file(f)
    np.testing.assert_array_equal(boxes[:3], [[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12]])
    assert np.isnan(boxes[3]).all()
    f.write_text("1,2,3,4\n1,2,x,4\n")
    with pytest.raises(DataFormatError, match=r"line 2, field 'w'"):
        otb.read_box_file(f)
    f.write_text("1,2,3,4\n\n1,2,3,4\n")
    with pytest.raises(DataFormatError, match="line 2.*blank line"):
        otb.read_box_file(f)
    f.write_text("1,2,3\n")
    with pytest.raises(DataFormatError, match="expected 4 numbers"):
        otb.read_box_file(f)


def test_otb_special_sequences(tmp_path):
    # David: images numbered from 300, three rows of a trimmed copy.
    _images(tmp_path / "David" / "img", range(300, 304))
    (tmp_path / "David" / "groundtruth_rect.txt").write_text("1,1,5,5\n2,2,5,5\n3,3,5,5\n")
    # Tiger1: first 5 annotated frames omitted.
    _images(tmp_path / "Tiger1" / "img", range(1, 8))
    (tmp_path / "Tiger1" / "groundtruth_rect.txt").write_text(
        "".join(f"{i},1,5,5\n" for i in range(1, 8)))
    # Jogging: two targets in one folder.
    _images(tmp_path / "Jogging" / "img", range(1, 3))
    (tmp_path / "Jogging" / "groundtruth_rect.1.txt").write_text("1,1,2,2\n1,1,2,2")
    (tmp_path / "Jogging" / "groundtruth_rect.2.txt").write_text("5,5,2,2\n5,5,2,2")
    # Board: five-digit frame names; a folder unknown to the table starting at frame 5.
    _images(tmp_path / "Board" / "img", range(1, 3), digits=5)
    (tmp_path / "Board" / "groundtruth_rect.txt").write_text("1,1,2,2\n1,1,2,2\n")
    _images(tmp_path / "MyClip" / "img", range(5, 9), ext=".png")
    (tmp_path / "MyClip" / "groundtruth_rect.txt").write_text("1,1,2,2\n1,1,2,2\n")
    ds = otb.OTBDataset(tmp_path)
    assert ds.sequence_names == ["Board", "David", "Jogging.1", "Jogging.2", "MyClip", "Tiger1"]
    with pytest.warns(UserWarning, match="trimmed"):
        david = ds.load("David")
    assert david.frame_numbers == (300, 301, 302)
    assert david.frame_paths[0].name == "0300.jpg"
    with pytest.warns(UserWarning):
        tiger = ds.load("Tiger1")
    assert tiger.frame_numbers == (6, 7) and tiger.boxes[:, 0].tolist() == [6.0, 7.0]
    with pytest.warns(UserWarning):
        jog = ds.load("Jogging_2")
    assert jog.name == "Jogging.2" and jog.init_box.tolist() == [5, 5, 2, 2]
    with pytest.warns(UserWarning):
        assert ds.load("Board").frame_paths[0].name == "00001.jpg"
    clip = ds.load("MyClip")
    assert clip.frame_numbers == (5, 6) and clip.image_size == (8, 6)


def test_otb_named_folders_with_other_ground_truth_files_are_not_dropped(tmp_path):
    # Jogging with one plain file (the toolkit defines .1 and .2): read as a custom folder.
    _images(tmp_path / "Jogging" / "img", range(1, 3))
    (tmp_path / "Jogging" / "groundtruth_rect.txt").write_text("1,1,2,2\n1,1,2,2\n")
    # Crossing with two targets (the toolkit defines one file): read as a custom folder.
    _images(tmp_path / "Crossing" / "img", range(1, 3))
    for k in (1, 2):
        (tmp_path / "Crossing" / f"groundtruth_rect.{k}.txt").write_text("1,1,2,2\n" * 2)
    # Skating2 holds its two files and one more: that one is named, the others read.
    _images(tmp_path / "Skating2" / "img", range(1, 3))
    for name in ("groundtruth_rect.1.txt", "groundtruth_rect.2.txt", "groundtruth_rect.txt"):
        (tmp_path / "Skating2" / name).write_text("1,1,2,2\n" * 2)
    with pytest.warns(UserWarning) as caught:
        ds = otb.OTBDataset(tmp_path)
    messages = "\n".join(str(w.message) for w in caught)
    assert "Jogging: named like the OTB-100 sequence Jogging" in messages
    assert "holds groundtruth_rect.1.txt, groundtruth_rect.2.txt" in messages
    assert "Skating2: groundtruth_rect.txt ignored" in messages
    assert ds.sequence_names == ["Crossing.1", "Crossing.2", "Jogging", "Skating2.1",
                                 "Skating2.2"]
    assert ds.load("Jogging").frame_numbers == (1, 2)


def test_otb_errors(tmp_path):
    _images(tmp_path / "Deer" / "img", range(1, 3))
    (tmp_path / "Deer" / "groundtruth_rect.txt").write_text("1,1,2,2\n" * 72)
    ds = otb.OTBDataset(tmp_path)
    with pytest.raises(DataFormatError, match="72 rows but OTB-2015 annotates frames 1-71"):
        ds.load("Deer")
    (tmp_path / "Deer" / "groundtruth_rect.txt").write_text("1,1,2,2\n" * 3)
    with pytest.warns(UserWarning), pytest.raises(DataFormatError, match="missing frame 3"):
        ds.load("Deer")
    with pytest.raises(DataFormatError, match="no sequence folders"):
        otb.OTBDataset(tmp_path / "Deer" / "img")


def test_lasot_reader(tmp_path):
    seq = tmp_path / "airplane" / "airplane-1"
    _images(seq / "img", range(1, 4), digits=8)
    (seq / "groundtruth.txt").write_text("1,2,3,4\n2,3,4,5\n3,4,5,6\n")
    (seq / "full_occlusion.txt").write_text("0,1,0")
    (seq / "out_of_view.txt").write_text("0,0,1")
    split = tmp_path / "testing_set.txt"
    split.write_text("airplane-1\n")
    ds = lasot.LaSOTDataset(tmp_path, split=split)
    s = ds.load("airplane-1")
    assert s.benchmark == "LaSOT" and s.num_frames == 3
    assert s.absent.tolist() == [False, True, True]
    (seq / "out_of_view.txt").write_text("0,0")
    with pytest.raises(DataFormatError, match="2 flags, expected 3"):
        ds.load("airplane-1")


def test_got10k_reader(tmp_path):
    val = tmp_path / "val" / "GOT-10k_Val_000001"
    _images(val, range(1, 4), digits=8)
    (val / "groundtruth.txt").write_text("1,2,3,4\n2,3,4,5\n3,4,5,6\n")
    (val / "absence.label").write_text("0\n0\n1\n")
    test = tmp_path / "test" / "GOT-10k_Test_000001"
    _images(test, range(1, 4), digits=8)
    (test / "groundtruth.txt").write_text("1,2,3,4\n")
    s = lasot.GOT10kDataset(tmp_path, "val").load("GOT-10k_Val_000001")
    assert s.absent.tolist() == [False, False, True] and s.has_ground_truth
    t = lasot.GOT10kDataset(tmp_path, "test").load("GOT-10k_Test_000001")
    assert t.num_frames == 3 and not t.has_ground_truth
    assert t.init_box.tolist() == [1, 2, 3, 4] and np.isnan(t.boxes[1:]).all()


# --------------------------------------------------------------------------- DAVIS


def test_davis_palette_is_the_voc_colour_map_and_matches_the_fixture():
    palette = davis.DAVIS_PALETTE
    assert palette.shape == (256, 3) and palette.dtype == np.uint8
    assert palette[:5].tolist() == [[0, 0, 0], [128, 0, 0], [0, 128, 0], [128, 128, 0],
                                    [0, 0, 128]]
    assert palette[255].tolist() == [224, 224, 192]  # the void colour
    assert len({tuple(c) for c in palette.tolist()}) == 256
    root = _data("DAVIS")
    for seq in ("tennis", "blackswan"):
        fixture = davis.read_png_palette(root / "Annotations" / "480p" / seq / "00000.png")
        np.testing.assert_array_equal(fixture, palette)


def test_real_davis_fixture():
    root = _data("DAVIS")
    val = davis.DAVISDataset(root, "val")
    assert val.sequence_names == ["blackswan", "dog"]
    swan = val.load("blackswan")
    assert swan.num_frames == 50 and swan.image_size == (854, 480)
    assert swan.object_ids == (1,) and swan.has_ground_truth
    tennis = davis.DAVISDataset(root, "train").load("tennis")
    assert tennis.object_ids == (1, 2)  # 255 (void) is not an object
    labels = tennis.read_annotations()
    assert labels.shape == (2, 480, 854) and labels.dtype == np.uint8
    assert set(np.unique(labels).tolist()) == {0, 1, 2, 255}
    # Why Pillow: OpenCV expands the palette to colours instead of returning indices.
    bgr = cv2.imread(str(tennis.annotation_paths[0]), cv2.IMREAD_UNCHANGED)
    assert bgr.ndim == 3
    assert davis.DAVISDataset(root, None).sequence_names == ["blackswan", "dog", "tennis"]
    with pytest.raises(DataFormatError, match="splits found: train, val"):
        davis.DAVISDataset(root, "test-dev")
    with pytest.raises(UnknownSequenceError, match="available: blackswan, dog"):
        val.load("tennis")


def test_davis_result_round_trip(tmp_path):
    root = _data("DAVIS")
    tennis = davis.DAVISDataset(root, "train").load("tennis")
    labels = tennis.read_annotation(1).copy()
    labels[labels == davis.DAVIS_VOID_LABEL] = 0
    path = davis.write_davis_result(tmp_path, tennis, 1, labels)
    assert path == tmp_path / "tennis" / "00001.png"
    np.testing.assert_array_equal(davis.read_label_png(path), labels)
    np.testing.assert_array_equal(davis.read_png_palette(path), davis.DAVIS_PALETTE)
    assert [p.name for p in (tmp_path / "tennis").iterdir()] == ["00001.png"]  # no temp left
    with pytest.raises(ValueError, match="frame is"):
        davis.write_davis_result(tmp_path, tennis, 1, labels[:10])
    rgb = tmp_path / "rgb.png"
    cv2.imwrite(str(rgb), np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(DataFormatError, match="not a label map"):
        davis.read_label_png(rgb)


def test_davis_missing_first_annotation(tmp_path):
    _images(tmp_path / "JPEGImages" / "480p" / "clip", range(2), digits=5)
    (tmp_path / "Annotations" / "480p" / "clip").mkdir(parents=True)
    with pytest.raises(DataFormatError, match="first-frame annotation missing"):
        davis.DAVISDataset(tmp_path, None).load("clip")
    davis.write_label_png(tmp_path / "Annotations" / "480p" / "clip" / "00000.png",
                          np.zeros((6, 8), np.uint8))
    with pytest.raises(DataFormatError, match="no object in the first annotation"):
        davis.DAVISDataset(tmp_path, None).load("clip")


def test_davis_labels_that_are_not_one_to_n_warn(tmp_path):
    _images(tmp_path / "JPEGImages" / "480p" / "clip", range(2), digits=5)
    labels = np.zeros((6, 8), np.uint8)
    labels[1:3, 1:3] = 38  # what convert("L") makes of palette index 1
    davis.write_label_png(tmp_path / "Annotations" / "480p" / "clip" / "00000.png", labels)
    with pytest.warns(UserWarning, match=r"labels \[38\] are not 1..1; the DAVIS evaluation "
                                         r"counts objects 1..38"):
        clip = davis.DAVISDataset(tmp_path, None).load("clip")
    assert clip.object_ids == (38,)


# --------------------------------------------------------------------------- JHMDB


def test_real_jhmdb_fixture():
    from scipy.io import loadmat

    root = _data("JHMDB")
    ds = jhmdb.JHMDBDataset(root)
    name = "catch/Goal_Keeping_Tips_catch_f_cm_np1_fr_med_2"
    assert ds.sequence_names == [name]
    seq = ds.load(name)
    assert seq.num_frames == 40 and seq.image_size == (320, 240)
    assert seq.action == "catch" and seq.frame_paths[0].name == "00001.png"
    pos = loadmat(str(root / "joint_positions" / name / "joint_positions.mat"))["pos_img"]
    np.testing.assert_array_equal(seq.keypoints[7, 3], pos[:, 3, 7] - 1.0)  # 0-based
    np.testing.assert_array_equal(
        jhmdb.read_joint_positions(root / "joint_positions" / name / "joint_positions.mat",
                                   zero_based=False)[0],
        pos[:, :, 0].T,
    )
    assert len(jhmdb.JHMDB_JOINT_NAMES) == 15 == seq.keypoints.shape[1]
    assert {j for pair in jhmdb.JHMDB_SKELETON for j in pair} == set(range(15))
    with pytest.raises(DataFormatError, match="test_split1"):
        jhmdb.JHMDBDataset(root, split="test")  # the fixture ships no split files


def test_jhmdb_split_files(tmp_path):
    root = _data("JHMDB")
    for sub in ("Rename_Images", "joint_positions"):
        shutil.copytree(root / sub, tmp_path / sub)
    splits = tmp_path / "splits"
    splits.mkdir()
    (splits / "catch_test_split1.txt").write_text(
        "Goal_Keeping_Tips_catch_f_cm_np1_fr_med_2.avi 2 \nother_video.avi 1 \n")
    assert len(jhmdb.JHMDBDataset(tmp_path, split="test")) == 1
    with pytest.raises(DataFormatError, match="no <action>"):
        jhmdb.JHMDBDataset(tmp_path, split="train")
    (splits / "catch_test_split1.txt").write_text("broken line here\n")
    with pytest.raises(DataFormatError, match="line 1"):
        jhmdb.JHMDBDataset(tmp_path, split="test")


def test_written_mat_files_do_not_depend_on_the_clock(monkeypatch):
    """scipy stamps the time into a MAT header; the same joints must give the same bytes."""
    import time

    from unitrack_env.datasets.synthetic.jhmdb import joint_positions_mat

    joints = np.arange(2 * 15 * 2, dtype=np.float64).reshape(2, 15, 2)
    first = joint_positions_mat(joints)
    monkeypatch.setattr(time, "asctime", lambda *args: "Thu Jan  1 00:00:00 2099")
    assert joint_positions_mat(joints) == first

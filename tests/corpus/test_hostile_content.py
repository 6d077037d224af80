"""Hostile content (issue 43, "content is checked where it is trusted" and "limits at the
door"): swapped, damaged or NaN-filled feature-cache entries; NaN or all-zero checkpoints;
runs paired across different ground truth or edited after scoring; damaged event files;
frames, annotation files and JSON built to cost before a limit refuses them.

Each case gives one clear message naming the file (or a correct result); docs/bad-inputs.md
("Hostile content") lists them with their messages.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from bad_input_cases import (  # the same folder (pytest prepends it)
    POSE_SEQ,
    clone,
    open_env,
    own,
    synthetic,
    write,
)

from unitrack_env.agents.appearance import (
    AppearanceModel,
    CachedAppearanceModel,
    FeatureCacheWarning,
    ResNet,
    content_key,
)
from unitrack_env.errors import CheckpointError, DataFormatError
from unitrack_env.evaluation.analysis.events import events_path
from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import run

MOT = "UniTrack/MOT17-v0"
SEQ = "SYN-01"


def _cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.err.strip()


def _error_line(err: str) -> str:
    """The one ``error:`` line the CLI printed (no traceback)."""
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    return lines[0]


# ------------------------------------------------------------------------ feature cache
@pytest.fixture
def warm_cache(tmp_path: Path) -> tuple[CachedAppearanceModel, np.ndarray, list[str], Path]:
    model = AppearanceModel("random", seed=0)
    frames = np.random.default_rng(0).integers(0, 256, (4, 24, 32, 3), dtype=np.uint8)
    keys = [content_key(f) for f in frames]
    cached = CachedAppearanceModel(model, tmp_path / "cache")
    cached.features(frames, keys=keys)
    return cached, frames, keys, tmp_path / "cache"


def test_swapped_cache_entries_are_recomputed_not_served(warm_cache) -> None:
    cached, frames, keys, root = warm_cache
    truth = cached.features(frames, keys=keys)
    paths = [cached.cache.path(cached.key((24, 32), k)) for k in keys]
    data = [p.read_bytes() for p in paths]
    for i, path in enumerate(paths):  # every entry now holds its neighbour's (valid) features
        path.write_bytes(data[(i + 1) % len(paths)])
    fresh = CachedAppearanceModel(cached.model, root)
    with pytest.warns(FeatureCacheWarning) as caught:
        served = fresh.features(frames, keys=keys)
    torch.testing.assert_close(served, truth)
    assert fresh.cache.stats.hits == 0 and fresh.cache.stats.corrupt == 4
    messages = [str(w.message) for w in caught]
    assert len(messages) == 4 and all(str(p) in m for p, m in zip(paths, messages, strict=True))
    assert all("another key (swapped or copied entry)" in m for m in messages)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # replaced: served again without a word
        torch.testing.assert_close(CachedAppearanceModel(cached.model, root).features(
            frames, keys=keys), truth)


def test_nan_filled_cache_entries_are_named_not_served(warm_cache) -> None:
    cached, frames, keys, root = warm_cache
    truth = cached.features(frames, keys=keys)
    path = cached.cache.path(cached.key((24, 32), keys[2]))
    shape = cached.model.feature_shape(24, 32)
    np.save(path, np.full(shape, np.nan, np.float16))  # what a hostile user writes
    fresh = CachedAppearanceModel(cached.model, root)
    with pytest.warns(FeatureCacheWarning, match="corrupt feature-cache entry") as caught:
        served = fresh.features(frames, keys=keys)
    assert len(caught) == 1 and str(path) in str(caught[0].message)
    assert torch.isfinite(served).all()  # (recomputed alone: float16 rounding may differ)
    torch.testing.assert_close(served, truth, rtol=2e-3, atol=2e-3)


# -------------------------------------------------------------------------- checkpoints
@pytest.mark.parametrize("fill", ["nan", "zero"])
def test_wiped_checkpoints_are_refused_naming_the_tensors(tmp_path: Path, fill: str) -> None:
    state = ResNet("resnet18").state_dict()
    value = float("nan") if fill == "nan" else 0.0
    wiped = {k: (torch.full_like(v, value) if v.is_floating_point() else v)
             for k, v in state.items()}
    path = tmp_path / f"{fill}.pth"
    torch.save(wiped, path)
    with pytest.raises(CheckpointError) as info:
        AppearanceModel(path, arch="resnet18")
    text = str(info.value)
    assert text.startswith(str(path)) and "conv1.weight" in text and "more)" in text, text


# ------------------------------------------------------------------------- runs: compare
@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Run A on the synthetic MOT17 copy; run B the same agent on a copy whose SYN-01 gt.txt
    lost every other row; run C the same as A (same data)."""
    base = tmp_path_factory.mktemp("hostile-runs")
    full = clone(synthetic("motchallenge", "MOT17"), base / "full")
    halved = clone(synthetic("motchallenge", "MOT17"), base / "halved")
    gt = own(halved / "train" / SEQ / "gt" / "gt.txt")
    gt.write_text("".join(gt.read_text().splitlines(keepends=True)[::2]))
    runs = {}
    for name, root, agent in (("a", full, "iou"), ("b", halved, "iou"), ("c", full, "fresh-ids")):
        runs[name] = base / name
        run(MOT, agent, out=runs[name], progress=False,
            env_kwargs={"root": str(root), "decode_frames": False})
    runs["full"], runs["halved"] = full, halved
    return runs


def test_compare_refuses_runs_scored_against_different_ground_truth(two_runs, capsys) -> None:
    code, err = _cli(["compare", str(two_runs["a"]), str(two_runs["b"])], capsys)
    line = _error_line(err)
    assert code == 2 and "were scored against different data for SYN-01" in line, line
    assert "needs the same ground truth" in line and str(two_runs["halved"]) in line


def test_compare_of_runs_on_the_same_data_still_works(two_runs, capsys) -> None:
    code, _ = _cli(["compare", str(two_runs["a"]), str(two_runs["c"])], capsys)
    assert code == 0


def _copy_run(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def test_a_result_file_edited_after_scoring_is_refused(two_runs, tmp_path: Path,
                                                       capsys) -> None:
    edited = _copy_run(two_runs["a"], tmp_path / "edited")
    result = edited / "data" / f"{SEQ}.txt"
    rows = result.read_text().splitlines(keepends=True)
    result.write_text("".join(rows[: len(rows) // 2]))
    code, err = _cli(["compare", str(edited), str(two_runs["c"])], capsys)
    line = _error_line(err)
    assert code == 2 and f"the result files of {SEQ} were changed after they were scored" \
        in line, line
    out = tmp_path / "report"
    code, err = _cli(["report", str(edited), str(two_runs["c"]), "--out", str(out)], capsys)
    line = _error_line(err)
    assert code == 2 and str(edited) in line and "metrics.json does not describe them" in line
    assert not (out / "index.html").exists()
    # The cure the message names: the same command again replays the edited sequence.
    run(MOT, "iou", out=edited, progress=False,
        env_kwargs={"root": str(two_runs["full"]), "decode_frames": False})
    assert result.read_text() == (two_runs["a"] / "data" / f"{SEQ}.txt").read_text()
    assert _cli(["compare", str(edited), str(two_runs["c"])], capsys)[0] == 0


def test_data_changed_after_scoring_is_refused(two_runs, tmp_path: Path, capsys) -> None:
    root = clone(two_runs["full"], tmp_path / "data")
    scored = tmp_path / "run"
    run(MOT, "iou", out=scored, progress=False,
        env_kwargs={"root": str(root), "decode_frames": False})
    gt = own(root / "train" / SEQ / "gt" / "gt.txt")
    gt.write_text("".join(gt.read_text().splitlines(keepends=True)[::3]))
    code, err = _cli(["report", str(scored), "--out", str(tmp_path / "report")], capsys)
    line = _error_line(err)
    assert code == 2 and f"data files (ground truth, annotations) of {SEQ}" in line, line
    assert "changed after the run was scored" in line


def test_report_of_runs_on_different_data_says_why_it_does_not_compare(two_runs,
                                                                       tmp_path: Path) -> None:
    out = tmp_path / "report"
    assert main(["report", str(two_runs["a"]), str(two_runs["b"]), "--out", str(out),
                 "--thumbnails", "1"]) == 0
    page = (out / "index.html").read_text()
    assert "Not compared:" in page and "different data for SYN-01" in page
    assert 'id="compare-table"' not in page


# ------------------------------------------------------------------------ events files
@pytest.mark.parametrize("damage", ["truncated", "not-gzip", "empty"])
def test_a_damaged_events_file_is_one_sentence(two_runs, tmp_path: Path, capsys,
                                               damage: str) -> None:
    copy = _copy_run(two_runs["a"], tmp_path / "run")
    path = events_path(copy, SEQ)
    data = path.read_bytes()
    path.write_bytes({"truncated": data[: len(data) // 2], "not-gzip": b"hello\n",
                      "empty": b""}[damage])
    code, err = _cli(["events", str(copy)], capsys)
    line = _error_line(err)
    assert code == 2 and line.startswith(f"error: {path}: damaged events file (") \
        and f"`unitrack events {copy}` to rebuild it" in line, line
    for word in ("EOFError", "Not a gzipped file", "No columns to parse"):
        assert word not in err
    json.loads((copy / "metrics.json").read_text())  # nothing else touched


# ---------------------------------------------------------------------- limits at the door
def _tiff_bomb(width: int, height: int) -> bytes:
    """A little-endian TIFF header whose first directory says ``width`` x ``height``."""
    import struct

    entries = b"".join(struct.pack("<HHII", tag, 4, 1, value)
                       for tag, value in ((256, width), (257, height)))
    return b"II*\x00" + struct.pack("<IH", 8, 2) + entries + b"\0" * 4 + b"\0" * 70_000


def test_a_tiff_frame_declaring_20000x20000_is_refused_before_decoding(tmp_path: Path) -> None:
    root = clone(synthetic("motchallenge", "MOT17"), tmp_path / "MOT17")
    seq = root / "train" / SEQ
    info = own(seq / "seqinfo.ini")
    info.write_text(info.read_text().replace("imExt=.jpg", "imExt=.tif"))
    import cv2

    for frame in sorted((seq / "img1").glob("*.jpg")):
        image = cv2.imread(str(frame))
        frame.unlink()
        cv2.imwrite(str(frame.with_suffix(".tif")), image)
    bomb = seq / "img1" / "000003.tif"
    write(bomb, _tiff_bomb(20000, 20000))
    with pytest.raises(DataFormatError) as info_:
        open_env(MOT, root, SEQ)
    text = str(info_.value)
    assert text.startswith(str(bomb)) and "header says 20000x20000 pixels" in text, text
    assert "refused before decoding" in text


def test_a_300_mb_gt_file_is_refused_before_it_is_read(tmp_path: Path) -> None:
    root = clone(synthetic("motchallenge", "MOT17"), tmp_path / "MOT17")
    gt = root / "train" / SEQ / "gt" / "gt.txt"
    gt.unlink()
    with gt.open("wb") as handle:  # sparse: 300 MB on paper, nothing on disk
        handle.truncate(300 * 10**6)
    with pytest.raises(DataFormatError) as info:
        open_env(MOT, root, SEQ)
    assert str(info.value) == (f"{gt}: 300,000,000 bytes, more than the 256 MiB a MOTChallenge "
                               "table may hold (unitrack_env.datasets.limits); refused before "
                               "reading it: split it")


def test_a_700_mb_posetrack_file_is_refused_before_it_is_read(tmp_path: Path) -> None:
    root = clone(synthetic("posetrack", "PoseTrack2018"), tmp_path / "PoseTrack")
    path = root / "posetrack_data" / "annotations" / "val" / f"{POSE_SEQ}.json"
    path.unlink()
    with path.open("wb") as handle:
        handle.truncate(700 * 10**6)
    with pytest.raises(DataFormatError, match=r"700,000,000 bytes, more than the 64 MiB a "
                                              "PoseTrack file may hold"):
        open_env("UniTrack/PoseTrack-v0", root, POSE_SEQ)


@pytest.mark.parametrize("reader", ["posetrack", "vis"])
def test_json_nested_100000_deep_is_one_line_naming_the_file(tmp_path: Path, reader: str) -> None:
    deep = "[" * 100_000 + "]" * 100_000
    if reader == "posetrack":
        root = clone(synthetic("posetrack", "PoseTrack2018"), tmp_path / "PoseTrack")
        path = root / "posetrack_data" / "annotations" / "val" / f"{POSE_SEQ}.json"
        env_id, sequence = "UniTrack/PoseTrack-v0", POSE_SEQ
    else:
        root = clone(synthetic("youtube_vis", "YouTube-VIS-2019"), tmp_path / "VIS")
        path = next(p for p in root.rglob("*.json"))
        env_id, sequence = "UniTrack/VIS-v0", "syn-01"
    write(path, deep)
    with pytest.raises(DataFormatError) as info:
        open_env(env_id, root, sequence)
    text = str(info.value)
    assert text.startswith(f"{path}: JSON nested more than about") and "\n" not in text, text

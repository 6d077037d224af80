"""Hostile folders (issue 43, items 1-2): paths read from files, links where we write, deletion.

Every case builds what a hostile (or careless) user could hand over: a split list, a JSON
file name, a manifest or a metrics file naming a path outside its folder, a symbolic link
where a tool writes, a folder that is not a cache given to ``cache clear``. Each asserts the
refusal (or the warning) names the file and the value, and that the victim files, outside
the folders the tool was given, keep their bytes. docs/bad-inputs.md ("Hostile folders")
lists them with their messages.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
from pathlib import Path

import pytest
from bad_input_cases import (
    POSE_SEQ,
    CLIFailed,
    cli,
    clone,
    edit_json,
    synthetic,
    write,
)

DAVIS_SEQ = "syn-occluded"


def victims(folder: Path, count: int = 3) -> dict[Path, bytes]:
    """``count`` files of the user's own under ``folder``; returns their bytes."""
    folder.mkdir(parents=True, exist_ok=True)
    files = {}
    for k in range(count):
        path = folder / f"{k:05d}.png"
        path.write_bytes(f"the user's own file {k}\n".encode())
        files[path] = path.read_bytes()
    return files


def unchanged(files: dict[Path, bytes]) -> None:
    for path, data in files.items():
        assert not path.is_symlink() and path.is_file(), f"{path} was removed or replaced"
        assert path.read_bytes() == data, f"{path} was changed"


def refused(run, scratch: Path, *fragments: str, error: type = Exception) -> str:
    """Run ``run(scratch)``; it must raise ``error`` holding every fragment. The message."""
    with pytest.raises(error) as caught:
        run(scratch)
    message = " ".join(str(caught.value).split())
    missing = [f for f in fragments if f not in message]
    assert not missing, f"{missing} not in: {message}"
    return message


def quiet(*argv: str) -> tuple[int, str]:
    """``unitrack <argv>``: its exit status and what it printed."""
    from unitrack_env.evaluation.cli import main

    printed = io.StringIO()
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100000"
    try:
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
            code = main([str(a) for a in argv])
    finally:
        if saved is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved
    return code, " ".join(printed.getvalue().split())


# ------------------------------------------------------------- 1. names read from files
def _davis_with_line(scratch: Path, line: str) -> Path:
    root = clone(synthetic("davis", "DAVIS-2017"), scratch / "DAVIS")
    write(root / "ImageSets" / "2017" / "val.txt", f"syn-crossing\n{line}\n")
    return root


@pytest.mark.parametrize("where", ["absolute", "dotdot"])
def test_davis_split_name_outside_root_is_refused(tmp_path: Path, where: str):
    """A val.txt line naming another folder: its annotations were overwritten by results."""
    other = tmp_path / "other" / DAVIS_SEQ
    source = synthetic("davis", "DAVIS-2017")
    shutil.copytree(source / "JPEGImages" / "480p" / DAVIS_SEQ, other)
    for png in (source / "Annotations" / "480p" / DAVIS_SEQ).iterdir():
        shutil.copyfile(png, other / png.name)
    before = {p: p.read_bytes() for p in other.iterdir()}
    line = str(other) if where == "absolute" else f"../../../other/{DAVIS_SEQ}"
    run = cli("evaluate", "--env", "UniTrack/DAVIS-v0", "--root", "{data}", "--agent",
              "repeat-mask", "--out", "{out}", "--quiet",
              data=lambda scratch: _davis_with_line(scratch, line))
    message = refused(run, tmp_path, "val.txt, line 2", repr(line), "refused", error=CLIFailed)
    assert "exit 2" in message
    unchanged(before)
    assert sorted(before) == sorted(other.iterdir())


def test_got10k_list_name_outside_root_is_refused(tmp_path: Path):
    from unitrack_env.datasets.lasot import GOT10kDataset

    (tmp_path / "val").mkdir()
    write(tmp_path / "val" / "list.txt", "GOT-10k_Val_000001\n/etc\n")
    refused(lambda _: GOT10kDataset(tmp_path), tmp_path, "list.txt, line 2", "'/etc'",
            "absolute path")


def _posetrack_file_name(scratch: Path, name: str) -> None:
    from bad_input_cases import open_env

    root = clone(synthetic("posetrack", "PoseTrack2018"), scratch / "PoseTrack")

    def hostile(data: dict) -> None:
        data["images"][1]["file_name"] = name

    edit_json(root / "posetrack_data" / "annotations" / "val" / f"{POSE_SEQ}.json", hostile)
    open_env("UniTrack/PoseTrack-v0", root, POSE_SEQ)


@pytest.mark.parametrize("where", ["absolute", "dotdot"])
def test_posetrack_file_name_outside_root_is_refused(tmp_path: Path, where: str):
    secret = victims(tmp_path / "secret", 1)
    (path,) = secret
    name = str(path) if where == "absolute" else "../../secret/00000.png"
    refused(lambda scratch: _posetrack_file_name(scratch, name), tmp_path,
            f"{POSE_SEQ}.json, field 'images[1].file_name'", repr(name), "refused")
    unchanged(secret)


@pytest.mark.parametrize("where", ["absolute", "dotdot"])
def test_vis_file_names_outside_root_are_refused(tmp_path: Path, where: str):
    from bad_input_cases import open_env

    secret = victims(tmp_path / "secret", 1)
    root = clone(synthetic("youtube_vis", "YouTube-VIS-2019"), tmp_path / "VIS")
    name = f"{tmp_path}/secret/00000.png" if where == "absolute" else "../../../secret/00000.png"

    def hostile(data: dict) -> None:
        data["videos"][0]["file_names"][2] = name

    edit_json(root / "train.json", hostile)
    refused(lambda _: open_env("UniTrack/VIS-v0", root, "syn-01"), tmp_path,
            "train.json, field 'videos[0].file_names[2]'", repr(name), "refused")
    unchanged(secret)

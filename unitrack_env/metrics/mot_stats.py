"""Per-frame sufficient statistics of MOTA, IDF1 and HOTA, and the metrics on reweighted frames.

:mod:`unitrack_env.evaluation.analysis.compare` recomputes the metrics on many resamples (frame
weights: how often each frame is drawn); the tables are built once and a ``(B, frames)`` weight
matrix is evaluated with a few matrix products. At unit weights every metric is TrackEval's;
what is exact on a resample is in docs/report.md. IDF1's optimal id assignment is solved again
per resample (minimising IDFN + IDFP is maximising the matched pair count). HOTA's per-frame
matching is made once, with the whole sequence's alignment scores, and not redone with a
resample's (it would change only where two assignments score nearly equal).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import linear_sum_assignment

from unitrack_env.metrics.clear_stream import StreamingClear
from unitrack_env.metrics.mot_preprocess import EPS, MATCH_IOU_THRESHOLD, PreprocessedFrame

#: HOTA's localisation thresholds (TrackEval's ``array_labels``: 0.05, 0.10, ..., 0.95).
ALPHAS: np.ndarray = np.arange(0.05, 0.99, 0.05)

#: Metrics that :func:`weighted_metrics` returns.
MOT_STAT_METRICS: tuple[str, ...] = ("HOTA", "DetA", "AssA", "IDF1", "MOTA")


@dataclass
class MotStats:
    """Per-frame tables of one sequence (``F`` frames).

    ``clear`` is ``(F, 4)`` tp, fp, fn, idsw; ``gt_det``/``trk_det`` mark present ids;
    ``id_match`` (sparse ``(F, P)``) marks IoU >= 0.5 of the ``id_pairs``; ``hota_match`` (one
    per alpha) marks HOTA matches of the ``hota_pairs``; ``hota_tp`` is ``(F, A)``.
    """

    clear: np.ndarray
    gt_det: np.ndarray
    trk_det: np.ndarray
    id_pairs: np.ndarray
    id_match: sparse.csc_matrix
    hota_pairs: np.ndarray
    hota_match: list[sparse.csc_matrix]
    hota_tp: np.ndarray

    @property
    def num_frames(self) -> int:
        """``F``."""
        return int(self.clear.shape[0])


def _index(frames: Sequence[PreprocessedFrame]) -> tuple[dict[int, int], dict[int, int]]:
    gts = sorted({int(g) for f in frames for g in f.gt_ids})
    trks = sorted({int(k) for f in frames for k in f.tracker_ids})
    return {g: i for i, g in enumerate(gts)}, {k: i for i, k in enumerate(trks)}


def _hota_alignment(frames: Sequence[PreprocessedFrame], gi: dict[int, int],
                    ki: dict[int, int]) -> np.ndarray:
    """HOTA's global alignment score between every gt id and track id (TrackEval's rule)."""
    pot = np.zeros((len(gi), len(ki)))
    g_count, k_count = np.zeros((len(gi), 1)), np.zeros((1, len(ki)))
    for f in frames:
        g = np.array([gi[int(x)] for x in f.gt_ids], dtype=np.int64)
        k = np.array([ki[int(x)] for x in f.tracker_ids], dtype=np.int64)
        sim = f.iou
        denom = sim.sum(0)[None, :] + sim.sum(1)[:, None] - sim
        norm = np.zeros_like(sim)
        ok = denom > EPS
        norm[ok] = sim[ok] / denom[ok]
        pot[g[:, None], k[None, :]] += norm
        g_count[g, 0] += 1
        k_count[0, k] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return pot / (g_count + k_count - pot)


def _pair_table(entries: list[tuple[int, int, int]], num_frames: int,
                depth: int = 1) -> tuple[np.ndarray, list[sparse.csc_matrix]]:
    """``(pairs, depth x sparse (F, P) indicators)`` from ``(layer * F + frame, g, k)``."""
    pairs = sorted({(g, k) for _, g, k in entries})
    where = {p: i for i, p in enumerate(pairs)}
    slots = np.array([e[0] for e in entries], dtype=np.int64)
    cols = np.array([where[(g, k)] for _, g, k in entries], dtype=np.int64)
    tables = []
    for layer in range(depth):
        sel = slots // num_frames == layer
        tables.append(sparse.csc_matrix(
            (np.ones(int(sel.sum())), (slots[sel] % num_frames, cols[sel])),
            shape=(num_frames, len(pairs))))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), tables


def mot_stats(frames: Sequence[PreprocessedFrame]) -> MotStats:
    """The per-frame tables of one preprocessed sequence (see :class:`MotStats`)."""
    n = len(frames)
    gi, ki = _index(frames)
    align = _hota_alignment(frames, gi, ki)
    clear = StreamingClear()
    counts = np.zeros((n, 4))
    gt_det, trk_det = np.zeros((n, len(gi))), np.zeros((n, len(ki)))
    hota_tp = np.zeros((n, len(ALPHAS)))
    id_entries: list[tuple[int, int, int]] = []
    hota_entries: list[tuple[int, int, int]] = []
    for t, f in enumerate(frames):
        c = clear.update(f.gt_ids, f.gt_boxes, f.tracker_ids, f.tracker_boxes, iou=f.iou)
        counts[t] = (c.tp, c.fp, c.fn, c.idsw)
        g = np.array([gi[int(x)] for x in f.gt_ids], dtype=np.int64)
        k = np.array([ki[int(x)] for x in f.tracker_ids], dtype=np.int64)
        gt_det[t, g] = 1.0
        trk_det[t, k] = 1.0
        if not (len(g) and len(k)):
            continue
        for r, col in zip(*np.nonzero(f.iou >= MATCH_IOU_THRESHOLD), strict=True):
            id_entries.append((t, int(g[r]), int(k[col])))
        rows, cols = linear_sum_assignment(-(align[g[:, None], k[None, :]] * f.iou))
        sim = f.iou[rows, cols]
        for a, alpha in enumerate(ALPHAS):
            ok = sim >= alpha - EPS
            hota_tp[t, a] = ok.sum()
            hota_entries += [(a * n + t, int(g[r]), int(k[col]))
                             for r, col in zip(rows[ok], cols[ok], strict=True)]
    id_pairs, id_match = _pair_table(id_entries, n)
    hota_pairs, hota_match = _pair_table(hota_entries, n, len(ALPHAS))
    return MotStats(counts, gt_det, trk_det, id_pairs, id_match[0], hota_pairs, hota_match,
                    hota_tp)


def _dot(w: np.ndarray, table: sparse.csc_matrix) -> np.ndarray:
    """``w @ table`` for a dense ``(B, F)`` and a sparse ``(F, P)``, dense ``(B, P)``."""
    return np.asarray((table.T @ w.T).T)


#: Sums that combine over sequences (TrackEval's combine_sequences for these metrics).
SUM_FIELDS: tuple[str, ...] = ("tp", "fp", "fn", "idsw", "idtp", "n_gt", "n_trk")


def weighted_sums(stats: MotStats, weights: np.ndarray) -> dict[str, np.ndarray]:
    """Summable statistics for each row of ``weights`` (``(B, F)``).

    Returns ``{field: (B,)}`` for :data:`SUM_FIELDS`, plus ``hota_tp``, ``hota_ass`` (the
    TP-weighted association sum) as ``(B, A)``.
    """
    w = np.asarray(weights, dtype=np.float64)
    clear = w @ stats.clear
    gtc, trkc = w @ stats.gt_det, w @ stats.trk_det
    out = {"tp": clear[:, 0], "fp": clear[:, 1], "fn": clear[:, 2], "idsw": clear[:, 3],
           "n_gt": gtc.sum(1), "n_trk": trkc.sum(1)}
    pm = _dot(w, stats.id_match)
    idtp = np.zeros(len(w))
    if pm.shape[1]:
        g, k = stats.id_pairs[:, 0], stats.id_pairs[:, 1]
        for b in range(len(w)):
            mat = np.zeros((gtc.shape[1], trkc.shape[1]))
            mat[g, k] = pm[b]
            r, c = linear_sum_assignment(-mat)
            idtp[b] = mat[r, c].sum()
    out["idtp"] = idtp
    out["hota_tp"] = w @ stats.hota_tp
    ass = np.zeros((len(w), len(ALPHAS)))
    if stats.hota_pairs.size:
        g, k = stats.hota_pairs[:, 0], stats.hota_pairs[:, 1]
        base = gtc[:, g] + trkc[:, k]
        for a in range(len(ALPHAS)):
            mc = _dot(w, stats.hota_match[a])
            ass[:, a] = (mc * mc / np.maximum(1.0, base - mc)).sum(1)
    out["hota_ass"] = ass
    return out


def metrics_from_sums(sums: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """MOTA, IDF1, HOTA, DetA, AssA (fractions) from (possibly combined) sums."""
    n_gt, n_trk = sums["n_gt"], sums["n_trk"]
    tp_a = sums["hota_tp"]
    det_a = tp_a / np.maximum(1.0, n_gt[:, None] + n_trk[:, None] - tp_a)
    ass_a = sums["hota_ass"] / np.maximum(1.0, tp_a)
    return {
        "HOTA": np.sqrt(det_a * ass_a).mean(1),
        "DetA": det_a.mean(1),
        "AssA": ass_a.mean(1),
        "IDF1": 2 * sums["idtp"] / np.maximum(1.0, n_gt + n_trk),
        "MOTA": (sums["tp"] - sums["fp"] - sums["idsw"]) / np.maximum(1.0, sums["tp"] + sums["fn"]),
    }


def add_sums(parts: Sequence[dict[str, np.ndarray]],
             counts: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Combine per-sequence sums; ``counts`` ``(B, S)`` repeats sequence ``s`` that often."""
    out: dict[str, np.ndarray] = {}
    for key in parts[0]:
        stack = np.stack([p[key] for p in parts])  # (S, B[, A])
        if counts is None:
            out[key] = stack.sum(0)
        else:
            c = counts.T.reshape(counts.shape[1], counts.shape[0], *([1] * (stack.ndim - 2)))
            out[key] = (stack * c).sum(0)
    return out

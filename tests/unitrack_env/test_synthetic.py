"""Tests of the embedded synthetic data sets: scene engine, MOTChallenge writer, cache."""

from __future__ import annotations

import configparser
import dataclasses
import os
import time
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from unitrack_env.datasets.synthetic import (
    DEFAULT_SPEC,
    DetectionNoise,
    MotChallengeSpec,
    ObjectRole,
    SceneConfig,
    SequenceSpec,
    cache,
    ensure_synthetic,
    render_scene,
    simulate_detections,
    write_motchallenge,
)
from unitrack_env.geometry import box_iou

SMALL = SceneConfig(width=160, height=120, num_frames=12, num_objects=3, num_crossings=1,
                    object_height_range=(40.0, 60.0), seed=5)
SMALL_SPEC = MotChallengeSpec(sequences=(
    SequenceSpec("A", "train", SMALL, frame_rate=10),
    SequenceSpec("B", "test", dataclasses.replace(SMALL, seed=6), frame_rate=12),
))


def _annotations(video):
    return [frame.objects for frame in video]


def _tracks(annotations):
    """id -> {frame: annotation}."""
    tracks: dict[int, dict[int, object]] = {}
    for t, objects in enumerate(annotations):
        for obj in objects:
            tracks.setdefault(obj.id, {})[t] = obj
    return tracks


def _crossings(video, annotations, min_iou=0.3):
    """Pairs of differently textured pedestrians whose x order swaps and whose boxes overlap."""
    tracks = _tracks(annotations)
    walkers = [o for o in video.objects if o.role is ObjectRole.PEDESTRIAN]
    found = []
    for i, a in enumerate(walkers):
        for b in walkers[i + 1:]:
            common = sorted(set(tracks[a.id]) & set(tracks[b.id]))
            if len(common) < 2:
                continue
            dx = [tracks[a.id][t].box[0] + tracks[a.id][t].box[2] / 2
                  - tracks[b.id][t].box[0] - tracks[b.id][t].box[2] / 2 for t in common]
            ious = [box_iou(np.array([tracks[a.id][t].box]), np.array([tracks[b.id][t].box]))[0, 0]
                    for t in common]
            if min(dx) < 0 < max(dx) and max(ious) >= min_iou and a.texture != b.texture:
                t_best = common[int(np.argmax(ious))]
                found.append((a.id, b.id, t_best, max(ious)))
    return found


def _read_table(path: Path) -> np.ndarray:
    rows = [line.split(",") for line in path.read_text().splitlines()]
    assert len({len(r) for r in rows}) == 1, f"{path}: ragged rows"
    return np.array(rows, dtype=np.float64)


def _seqinfo(path: Path) -> dict[str, str]:
    parser = configparser.ConfigParser()
    parser.optionxform = str  # keep MOTChallenge's camelCase keys
    parser.read(path)
    return dict(parser["Sequence"])


@pytest.fixture(scope="module")
def mot17_root(tmp_path_factory):
    """The default synthetic MOT17 data set, generated through the cache (timed)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("UNITRACK_CACHE", str(tmp_path_factory.mktemp("cache")))
        start = time.perf_counter()
        root = ensure_synthetic("MOT17")
        seconds = time.perf_counter() - start
    files = [p for p in root.rglob("*") if p.is_file()]
    size = sum(p.stat().st_size for p in files) / 2**20
    print(f"\nsynthetic MOT17: generated in {seconds:.2f} s, {len(files)} files, {size:.1f} MB")
    return root


# ----------------------------------------------------------------------------- scene engine

def test_render_is_deterministic_and_order_independent():
    first, second = render_scene(SMALL), render_scene(SMALL)
    assert first.objects == second.objects
    late = second.frame(9)  # render out of order first
    for t in range(SMALL.num_frames):
        a, b = first.frame(t), second.frame(t)
        assert np.array_equal(a.image, b.image)
        assert np.array_equal(a.instance_map, b.instance_map)
        assert a.objects == b.objects
    assert np.array_equal(first.frame(9).image, late.image)
    other = render_scene(dataclasses.replace(SMALL, seed=99))
    assert not np.array_equal(other.frame(0).image, first.frame(0).image)


def test_frame_contract_boxes_masks_visibility():
    video = render_scene(DEFAULT_SPEC.sequences[0].scene)
    checked_tight = 0
    for frame in video:
        assert frame.image.shape == (video.height, video.width, 3)
        assert frame.image.dtype == np.uint8 and frame.instance_map.dtype == np.int32
        ids = [o.id for o in frame.objects]
        assert ids == sorted(ids)
        assert set(np.unique(frame.instance_map)) <= {0, *ids}
        for obj in frame.objects:
            pixels = frame.instance_map == obj.id
            assert obj.visible_pixels == int(pixels.sum())
            assert 0.0 <= obj.visibility <= 1.0
            assert obj.visibility == pytest.approx(obj.visible_pixels / obj.area)
            x, y, w, h = obj.box
            if obj.visibility == 1.0:  # fully visible: the mask's bbox is the box
                rows, cols = np.flatnonzero(pixels.any(1)), np.flatnonzero(pixels.any(0))
                assert (cols[0], rows[0], cols[-1] + 1 - cols[0], rows[-1] + 1 - rows[0]) == (
                    x, y, w, h)
                checked_tight += 1
            if obj.role is not ObjectRole.OCCLUDER:
                assert h > 1.8 * w  # pedestrian-shaped
    assert checked_tight > 100


@pytest.mark.parametrize("seq", DEFAULT_SPEC.sequences, ids=lambda s: s.name)
def test_default_scenes_have_textured_crossings_with_occlusion(seq):
    video = render_scene(seq.scene)
    annotations = _annotations(video)
    crossings = _crossings(video, annotations)
    forced = {(2 * k + 1, 2 * k + 2) for k in range(seq.scene.num_crossings)}
    assert seq.scene.num_crossings >= 2
    assert forced <= {(a, b) for a, b, _, _ in crossings}
    for a_id, b_id, t, iou in crossings:
        a, b = video.object(a_id), video.object(b_id)
        # Similar sizes: IoU cannot tell them apart; textures differ in colour.
        assert abs(a.base_size[1] - b.base_size[1]) <= 0.2 * max(a.base_size[1], b.base_size[1])
        colour_gap = np.abs(np.subtract(a.texture.colour_a, b.texture.colour_a)).sum()
        assert colour_gap >= 40 or a.texture.pattern != b.texture.pattern
        # The farther one is (partly) hidden while they overlap.
        farther = a if (a.depth, a.id) > (b.depth, b.id) else b
        vis = {o.id: o.visibility for o in annotations[t]}
        assert vis[farther.id] < 1.0, (a_id, b_id, t, iou)


def test_crossing_pair_is_told_apart_by_appearance():
    """Mean colours of the two walkers of a crossing differ far more than within a walker."""
    video = render_scene(DEFAULT_SPEC.sequences[0].scene)
    a_id, b_id, t, _ = _crossings(video, _annotations(video))[0]

    def mean_colour(frame, object_id):
        return frame.image[frame.instance_map == object_id].astype(float).mean(0)

    early, late = video.frame(max(t - 15, 0)), video.frame(min(t + 15, video.num_frames - 1))
    same = np.linalg.norm(mean_colour(early, a_id) - mean_colour(late, a_id))
    different = np.linalg.norm(mean_colour(early, a_id) - mean_colour(early, b_id))
    assert different > 3 * same and different > 25


def test_objects_enter_and_leave_and_occluder_hides_someone():
    video = render_scene(DEFAULT_SPEC.sequences[0].scene)
    annotations = _annotations(video)
    tracks = _tracks(annotations)
    last = video.num_frames - 1
    walkers = [o.id for o in video.objects if o.role is ObjectRole.PEDESTRIAN]
    assert any(min(tracks[i]) > 0 for i in walkers), "nobody enters"
    assert any(max(tracks[i]) < last for i in walkers), "nobody leaves"
    roles = {o.role for o in video.objects}
    assert roles == {ObjectRole.PEDESTRIAN, ObjectRole.STATIC_PERSON, ObjectRole.OCCLUDER}
    occluder = next(o for o in video.objects if o.role is ObjectRole.OCCLUDER)
    assert all(tracks[occluder.id][t].visibility == 1.0 for t in tracks[occluder.id])
    hidden = [
        o for objs in annotations for o in objs
        if o.role is ObjectRole.PEDESTRIAN and o.visibility < 0.9 and box_iou(
            np.array([o.box]), np.array([tracks[occluder.id][0].box]))[0, 0] > 0
    ]
    assert hidden, "the occluder never hides a walker"


def test_scene_config_validation_names_the_field():
    with pytest.raises(ValueError, match="num_crossings"):
        SceneConfig(num_objects=3, num_crossings=2)
    with pytest.raises(ValueError, match="speed_range"):
        SceneConfig(speed_range=(3.0, 1.0))


def test_render_speed_of_default_scenes():
    start = time.perf_counter()
    for seq in DEFAULT_SPEC.sequences:
        for _ in render_scene(seq.scene):
            pass
    print(f"\nrendered the default scenes in {time.perf_counter() - start:.2f} s")


# ------------------------------------------------------------------------------ detections

def test_noiseless_detections_are_the_clipped_person_boxes():
    video = render_scene(SMALL)
    annotations = _annotations(video)
    exact = DetectionNoise(miss_rate=0, occlusion_miss_weight=0, position_jitter=0,
                           size_jitter=0, false_positives_per_frame=0, clutter_rate=0,
                           min_size=0)
    dets = simulate_detections(annotations, (SMALL.width, SMALL.height), exact,
                               np.random.default_rng(0))
    expected = []
    for t, objects in enumerate(annotations):
        for o in objects:
            if o.role in (ObjectRole.PEDESTRIAN, ObjectRole.STATIC_PERSON):
                x, y, w, h = o.box
                x0, y0 = max(x, 0), max(y, 0)
                x1, y1 = min(x + w, SMALL.width), min(y + h, SMALL.height)
                expected.append((t, o.id, x0, y0, x1 - x0, y1 - y0))
    rows = zip(dets.frames, dets.sources, dets.boxes, strict=True)
    got = [(int(t), int(s), *b) for t, s, b in rows]
    assert got == [tuple(float(v) if i > 1 else v for i, v in enumerate(e)) for e in expected]
    assert np.all((dets.scores > 0) & (dets.scores < 1))


def test_simulated_noise_has_misses_and_false_positives():
    video = render_scene(DEFAULT_SPEC.sequences[0].scene)
    annotations = _annotations(video)
    dets = simulate_detections(annotations, (video.width, video.height), DetectionNoise(),
                               np.random.default_rng(1))
    persons = [o for objs in annotations for o in objs
               if o.role in (ObjectRole.PEDESTRIAN, ObjectRole.STATIC_PERSON)]
    detected = {(int(t), int(s)) for t, s in zip(dets.frames, dets.sources, strict=True) if s > 0}
    missed_visible = [o for t, objs in enumerate(annotations) for o in objs
                      if o in persons and o.visibility > 0.9 and (t, o.id) not in detected]
    missed_hidden = [o for t, objs in enumerate(annotations) for o in objs
                     if o in persons and o.visibility < 0.5 and (t, o.id) not in detected]
    n_visible = sum(o.visibility > 0.9 for o in persons)
    n_hidden = sum(o.visibility < 0.5 for o in persons)
    assert n_hidden > 0
    assert len(missed_hidden) / n_hidden > 2 * len(missed_visible) / n_visible
    assert (dets.sources == -1).sum() > 0
    fp_scores = dets.scores[dets.sources == -1]
    tp_scores = dets.scores[dets.sources > 0]
    assert tp_scores.mean() > fp_scores.mean() + 0.2


# --------------------------------------------------------------------------- MOTChallenge

def test_layout_seqinfo_and_columns_mot17(mot17_root):
    root = mot17_root
    assert sorted(p.name for p in root.iterdir() if p.is_dir()) == ["test", "train"]
    for seq in DEFAULT_SPEC.sequences:
        seq_dir = root / seq.split / seq.name
        info = _seqinfo(seq_dir / "seqinfo.ini")
        assert info == {
            "name": seq.name, "imDir": "img1", "frameRate": str(seq.frame_rate),
            "seqLength": str(seq.scene.num_frames), "imWidth": str(seq.scene.width),
            "imHeight": str(seq.scene.height), "imExt": ".jpg",
        }
        images = sorted(p.name for p in (seq_dir / "img1").iterdir())
        assert images == [f"{i:06d}.jpg" for i in range(1, seq.scene.num_frames + 1)]
        first = cv2.imread(str(seq_dir / "img1" / images[0]))
        assert first.shape == (seq.scene.height, seq.scene.width, 3)
        det = _read_table(seq_dir / "det" / "det.txt")
        assert det.shape[1] == 10 and np.all(det[:, 1] == -1) and np.all(det[:, 7:] == -1)
        assert np.all(np.diff(det[:, 0]) >= 0)
        assert det[:, 0].min() >= 1 and det[:, 0].max() <= seq.scene.num_frames
        assert np.all((det[:, 6] >= 0) & (det[:, 6] <= 1))
        assert np.all(det[:, 2] >= 1) and np.all(det[:, 2] + det[:, 4] <= seq.scene.width + 1)
        assert (seq_dir / "gt" / "gt.txt").exists() == (seq.split == "train")


def test_gt_rows_match_the_scene_mot17(mot17_root):
    seq = DEFAULT_SPEC.sequences[0]
    gt = _read_table(mot17_root / "train" / seq.name / "gt" / "gt.txt")
    assert gt.shape[1] == 9
    order = np.lexsort((gt[:, 0], gt[:, 1]))
    assert np.array_equal(order, np.arange(len(gt))), "gt not sorted by id, then frame"
    assert {(int(f), int(c)) for f, c in gt[:, 6:8]} == {(1, 1), (0, 7), (0, 9)}
    assert np.all((gt[:, 8] >= 0) & (gt[:, 8] <= 1)) and gt[:, 8].min() < 0.5
    video = render_scene(seq.scene)
    frame = video.frame(10)
    rows = gt[gt[:, 0] == 11]
    assert len(rows) == len(frame.objects)
    for obj in frame.objects:
        (row,) = rows[rows[:, 1] == obj.id]
        assert tuple(row[2:6]) == (obj.box[0] + 1, obj.box[1] + 1, obj.box[2], obj.box[3])
        assert row[8] == pytest.approx(obj.visibility, abs=1e-5)
    # The JPEG on disk is the rendered RGB frame stored as BGR.
    disk = cv2.imread(str(mot17_root / "train" / seq.name / "img1" / "000011.jpg"))
    assert np.abs(disk[:, :, ::-1].astype(int) - frame.image).mean() < 4


def test_detection_rates_on_disk(mot17_root):
    """Match det to gt persons at IoU >= 0.5; measure miss and false-positive rates."""
    gt_persons = missed = dets_total = false_pos = frames = 0
    missed_by_vis = {"vis>=0.9": [0, 0], "vis<0.5": [0, 0]}
    for seq in DEFAULT_SPEC.sequences:
        if seq.split != "train":
            continue
        frames += seq.scene.num_frames
        gt = _read_table(mot17_root / "train" / seq.name / "gt" / "gt.txt")
        gt = gt[np.isin(gt[:, 7], (1, 7))]
        det = _read_table(mot17_root / "train" / seq.name / "det" / "det.txt")
        for t in range(1, seq.scene.num_frames + 1):
            g, d = gt[gt[:, 0] == t], det[det[:, 0] == t]
            iou = box_iou(g[:, 2:6], d[:, 2:6])
            rows, cols = linear_sum_assignment(-iou) if iou.size else ([], [])
            matched = {r for r, c in zip(rows, cols, strict=True) if iou[r, c] >= 0.5}
            gt_persons += len(g)
            missed += len(g) - len(matched)
            dets_total += len(d)
            false_pos += len(d) - len(matched)
            for r in range(len(g)):
                key = "vis>=0.9" if g[r, 8] >= 0.9 else "vis<0.5" if g[r, 8] < 0.5 else None
                if key:
                    missed_by_vis[key][0] += r not in matched
                    missed_by_vis[key][1] += 1
    miss_rate, fp_rate = missed / gt_persons, false_pos / dets_total
    by_vis = {k: m / n for k, (m, n) in missed_by_vis.items()}
    print(f"\ndet vs gt (IoU>=0.5): miss rate {miss_rate:.3f}, false-positive share {fp_rate:.3f},"
          f" per frame {false_pos / frames:.2f}; miss rate by visibility {by_vis}")
    assert 0.05 < miss_rate < 0.35
    assert 0.03 < fp_rate < 0.3
    assert by_vis["vis<0.5"] > 3 * by_vis["vis>=0.9"]


def test_mot15_columns_and_scores(tmp_path):
    write_motchallenge(tmp_path, "MOT15", spec=SMALL_SPEC)
    gt = _read_table(tmp_path / "train" / "A" / "gt" / "gt.txt")
    assert gt.shape[1] == 10 and np.all(gt[:, 6] == 1) and np.all(gt[:, 7:] == -1)
    assert np.all(np.diff(gt[:, 0]) >= 0), "MOT15 gt sorted by frame"
    video = render_scene(SMALL)
    persons = {o.id for o in video.objects if o.role is not ObjectRole.OCCLUDER}
    assert set(gt[:, 1].astype(int)) <= persons  # occluders are not MOT15 ground truth
    det = _read_table(tmp_path / "test" / "B" / "det" / "det.txt")
    assert det.shape[1] == 10 and det[:, 6].max() > 1.0  # PETS-like 0-100 scores
    assert not (tmp_path / "test" / "B" / "gt").exists()
    assert _seqinfo(tmp_path / "test" / "B" / "seqinfo.ini")["frameRate"] == "12"


@pytest.mark.parametrize("benchmark", ["MOT16", "MOT20"])
def test_other_class_benchmarks_have_nine_gt_columns(tmp_path, benchmark):
    write_motchallenge(tmp_path, benchmark, spec=SMALL_SPEC)
    assert _read_table(tmp_path / "train" / "A" / "gt" / "gt.txt").shape[1] == 9


def test_writer_is_byte_deterministic(tmp_path):
    write_motchallenge(tmp_path / "a", "MOT17", spec=SMALL_SPEC)
    write_motchallenge(tmp_path / "b", "MOT17", spec=SMALL_SPEC)
    files_a = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*")
                     if p.is_file())
    files_b = sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*")
                     if p.is_file())
    assert files_a == files_b and len(files_a) == 2 * 12 + 5
    for rel in files_a:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel


def test_writer_rejects_unknown_benchmark(tmp_path):
    with pytest.raises(ValueError, match="MOT15, MOT16, MOT17, MOT20"):
        write_motchallenge(tmp_path, "MOT18", spec=SMALL_SPEC)


def test_reader_accepts_the_synthetic_layout(mot17_root):
    reader = pytest.importorskip("unitrack_env.datasets.motchallenge")
    dataset = reader.MOTChallengeDataset(mot17_root, "MOT17", "train")
    assert dataset.sequence_names == ["SYN-01", "SYN-02"]
    seq = dataset.load("SYN-01")
    gt_lines = (mot17_root / "train" / "SYN-01" / "gt" / "gt.txt").read_text().splitlines()
    assert len(seq.ground_truth) == len(gt_lines)
    assert reader.MOTChallengeDataset(mot17_root, "MOT17", "test").load("SYN-03").ground_truth \
        is None


# ----------------------------------------------------------------------------------- cache

@pytest.fixture
def fake_writer(monkeypatch, tmp_path):
    """Replace the real writer by a fast one that records its calls."""
    monkeypatch.setenv("UNITRACK_CACHE", str(tmp_path / "cache"))
    calls: list[Path] = []

    def writer(root: Path, benchmark: str) -> None:
        calls.append(root)
        (root / "train").mkdir()
        (root / "train" / "data.txt").write_text(f"{benchmark} #{len(calls)}")

    monkeypatch.setattr(cache, "KINDS", MappingProxyType(
        {"motchallenge": dataclasses.replace(cache.KINDS["motchallenge"], write=writer)}))
    return calls


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


def test_cache_generates_once_with_marker(fake_writer, tmp_path):
    root = ensure_synthetic("MOT17")
    expected = tmp_path / "cache" / "synthetic" / f"motchallenge-MOT17-v{cache.GENERATOR_VERSION}"
    assert root == expected and cache.is_complete(root)
    assert (root / "train" / "data.txt").read_text() == "MOT17 #1"
    assert ensure_synthetic("MOT17") == root and len(fake_writer) == 1
    assert fake_writer[0].parent == root.parent and fake_writer[0] != root  # temp sibling
    assert _leftovers(root.parent) == []


def test_cache_regenerates_without_marker(fake_writer):
    root = ensure_synthetic("MOT17")
    (root / cache.MARKER_NAME).unlink()  # half-written / damaged
    (root / "stray.txt").write_text("junk")
    assert ensure_synthetic("MOT17") == root
    assert len(fake_writer) == 2 and not (root / "stray.txt").exists()
    assert (root / "train" / "data.txt").read_text() == "MOT17 #2"
    assert _leftovers(root.parent) == []


def test_cache_ignores_interrupted_temp_dirs(fake_writer):
    parent = cache.synthetic_path("MOT17").parent
    parent.mkdir(parents=True)
    name = cache.synthetic_path("MOT17").name
    fresh, stale = parent / f".{name}.tmp-fresh", parent / f".{name}.tmp-stale"
    for d in (fresh, stale):
        (d / "train").mkdir(parents=True)
        (d / "train" / "partial.txt").write_text("interrupted")
    old = time.time() - 2 * cache.STALE_TEMP_SECONDS
    os.utime(stale, (old, old))
    root = ensure_synthetic("MOT17")
    assert cache.is_complete(root) and not (root / "train" / "partial.txt").exists()
    assert fresh.exists(), "a recent temp dir may belong to a live process"
    assert not stale.exists(), "stale temp dirs are cleaned up"


def test_cache_failed_generation_leaves_nothing(monkeypatch, tmp_path):
    monkeypatch.setenv("UNITRACK_CACHE", str(tmp_path))

    def broken(root: Path, benchmark: str) -> None:
        (root / "half.txt").write_text("x")
        raise RuntimeError("disk full")

    monkeypatch.setattr(cache, "KINDS", MappingProxyType(
        {"motchallenge": dataclasses.replace(cache.KINDS["motchallenge"], write=broken)}))
    with pytest.raises(RuntimeError, match="disk full"):
        ensure_synthetic("MOT17")
    parent = tmp_path / "synthetic"
    assert list(parent.iterdir()) == []


def test_cache_lost_race_keeps_the_winner(monkeypatch, tmp_path):
    monkeypatch.setenv("UNITRACK_CACHE", str(tmp_path))
    final = cache.synthetic_path("MOT17")

    def racing(root: Path, benchmark: str) -> None:
        (root / "mine.txt").write_text("loser")
        final.mkdir()  # another process finishes first
        (final / "theirs.txt").write_text("winner")
        (final / cache.MARKER_NAME).write_text("{}")

    monkeypatch.setattr(cache, "KINDS", MappingProxyType(
        {"motchallenge": dataclasses.replace(cache.KINDS["motchallenge"], write=racing)}))
    assert ensure_synthetic("MOT17") == final
    assert (final / "theirs.txt").exists() and not (final / "mine.txt").exists()
    assert _leftovers(final.parent) == []


def test_cache_errors_and_default_location(monkeypatch):
    with pytest.raises(ValueError, match="valid: MOT15, MOT16, MOT17, MOT20"):
        cache.synthetic_path("KITTI")
    with pytest.raises(ValueError, match="valid: motchallenge"):
        cache.synthetic_path("MOT17", kind="nope")
    monkeypatch.delenv("UNITRACK_CACHE", raising=False)
    import platformdirs

    assert cache.cache_root() == Path(platformdirs.user_cache_dir("unitrack-env"))

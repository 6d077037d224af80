"""Appearance-model runtimes: choice, identity, and agreement of every runtime with torch."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from unitrack_env.agents.appearance import AppearanceModel, letterbox
from unitrack_env.agents.appearance import runtime as rt
from unitrack_env.provenance import recording_runtimes

COMPILED = ("openvino", "onnxruntime")
COSINE_FLOOR = 0.9999


def _cosine(a: torch.Tensor, b: torch.Tensor) -> float:
    a, b = a.double().flatten(), b.double().flatten()
    return float(a @ b / (a.norm() * b.norm()))


@pytest.fixture(scope="module")
def torch_model() -> AppearanceModel:
    return AppearanceModel(runtime="torch")


def _compiled(name: str, cache: Path, **kwargs) -> AppearanceModel:
    pytest.importorskip(name)
    pytest.importorskip("onnx")
    return AppearanceModel(runtime=name, runtime_cache=cache, num_threads=2, **kwargs)


# ---------------------------------------------------------------------- choice
def test_default_is_auto_unless_the_environment_says_otherwise(monkeypatch):
    monkeypatch.delenv(rt.RUNTIME_ENV, raising=False)
    assert rt.resolve_runtime(None) == rt.resolve_runtime("auto")
    assert rt.is_auto(None) and not rt.is_auto("openvino")
    monkeypatch.setenv(rt.RUNTIME_ENV, "torch")
    assert rt.resolve_runtime(None) == "torch" and not rt.is_auto(None)
    monkeypatch.setenv(rt.RUNTIME_ENV, "nonsense")
    with pytest.raises(ValueError, match="valid"):
        rt.resolve_runtime(None)


def test_auto_picks_the_first_installed_in_preference_order():
    chosen = rt.resolve_runtime("auto")
    assert chosen == next(r for r in rt.AUTO_ORDER if rt.runtime_installed(r))
    assert rt.resolve_runtime("auto", "cuda") == "torch"  # only torch runs on CUDA
    assert "torch" in rt.available_runtimes()


def test_errors_name_the_valid_choices_and_the_extra(monkeypatch):
    with pytest.raises(ValueError, match="valid"):
        rt.resolve_runtime("tensorrt")
    with pytest.raises(ValueError, match="CPU only"):
        rt.resolve_runtime("openvino", "cuda")
    monkeypatch.setitem(rt._IMPORT_NAMES, "openvino", ("no_such_module_here",))
    with pytest.raises(ImportError, match=r"unitrack-env\[openvino\]"):
        rt.resolve_runtime("openvino")
    assert rt.resolve_runtime("auto") in ("onnxruntime", "torch")


def test_features_note_the_runtime_that_computed_them_also_from_the_cache(torch_model,
                                                                           tmp_path):
    from unitrack_env.agents.appearance.cached_model import CachedAppearanceModel

    frame = np.zeros((40, 48, 3), np.uint8)
    with recording_runtimes() as outer, recording_runtimes() as inner:
        torch_model.features(frame)
    assert outer == inner == {"torch"}
    cached = CachedAppearanceModel(torch_model, tmp_path)
    cached.features(frame)
    with recording_runtimes() as seen:  # a hit: the cache key's runtime computed it
        cached.features(frame)
    assert cached.cache.stats.hits == 1 and seen == {"torch"}
    with recording_runtimes() as seen:
        pass
    assert seen == set()


def test_identity_keeps_runtimes_apart_and_torch_keys_unchanged(torch_model):
    ident = torch_model.identity
    assert ident.runtime == "torch" and torch_model.describe()["runtime"] == "torch"
    legacy = f"{ident.arch}|{ident.layer}|{ident.digest}|{ident.mean}|{ident.std}"
    assert ident.key() == hashlib.sha256(legacy.encode()).hexdigest()[:len(ident.key())]
    from dataclasses import replace

    keys = {replace(ident, runtime=name).key() for name in rt.RUNTIMES}
    assert len(keys) == len(rt.RUNTIMES)


# ---------------------------------------------------------------------- agreement
@pytest.mark.parametrize("name", COMPILED)
def test_compiled_features_match_torch_on_synthetic_batches(torch_model, name, tmp_path):
    model = _compiled(name, tmp_path)
    assert model.runtime == name and model.identity.runtime == name
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (3, 72, 100, 3), dtype=np.uint8)  # odd sizes: SAME padding
    ref = torch_model.features(images)
    out = model.features(images)
    assert out.shape == ref.shape == (3, 112, 9, 13) and out.dtype == torch.float32
    assert _cosine(out, ref) >= COSINE_FLOOR
    assert torch.allclose(out, ref, atol=1e-3, rtol=1e-3)
    one = model.features(images[1])  # another batch size of the same input size
    assert _cosine(one, ref[1:2]) >= COSINE_FLOOR


@pytest.mark.parametrize("name", COMPILED)
def test_a_compiled_runtime_leaves_the_callers_cpu_affinity_alone(name, tmp_path):
    # OpenVINO pinned the calling thread to core 0 while it inferred: two one-thread pool
    # workers then shared one core (the synthetic scorecard with --workers 2 ran at 1.05 cores).
    caller = threading.get_native_id()
    before = os.sched_getaffinity(caller)
    if len(before) < 2:
        pytest.skip("needs 2 CPUs to see a thread pinned to one")
    pytest.importorskip(name)
    pytest.importorskip("onnx")
    model = AppearanceModel(runtime=name, runtime_cache=tmp_path, num_threads=1)
    frames = np.zeros((1, 320, 320, 3), np.uint8)
    model.features(frames)  # compiled and warm
    seen: set[frozenset[int]] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.add(frozenset(os.sched_getaffinity(caller)))
            time.sleep(0.001)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        for _ in range(20):
            model.features(frames)
    finally:
        done.set()
        watcher.join()
    assert seen == {frozenset(before)}


def test_two_processes_compile_into_one_openvino_cache(tmp_path):
    # OpenVINO writes its blob cache unlocked: two pool workers compiling the same model
    # failed 3 times in 4 ("cannot set permissions: No such file or directory" on the blob).
    pytest.importorskip("openvino")
    pytest.importorskip("onnx")
    script = ("import sys, numpy as np\n"
              "from unitrack_env.agents.appearance import AppearanceModel\n"
              "m = AppearanceModel(weights='random', runtime='openvino', "
              "runtime_cache=sys.argv[1], num_threads=1)\n"
              "for size in [(96, 128), (128, 96), (160, 160), (200, 120)]:\n"
              "    m.features(np.zeros((3, *size, 3), np.uint8))\n")
    for attempt in range(2):
        cache = tmp_path / str(attempt)
        runs = [subprocess.Popen([sys.executable, "-c", script, str(cache)],
                                 stderr=subprocess.PIPE, text=True) for _ in range(2)]
        errors = [run.communicate(timeout=300)[1] for run in runs]
        assert [run.returncode for run in runs] == [0, 0], errors


@pytest.mark.parametrize("name", COMPILED)
def test_exported_graph_is_cached_on_disk_and_reused(name, tmp_path):
    model = _compiled(name, tmp_path)
    model.features(np.zeros((40, 48, 3), np.uint8))
    graphs = sorted(tmp_path.glob("*.onnx"))
    assert len(graphs) == 1 and "40x48" in graphs[0].name
    assert not list(tmp_path.glob("*.tmp"))
    stamp = graphs[0].stat().st_mtime_ns
    again = _compiled(name, tmp_path)
    again.features(np.zeros((40, 48, 3), np.uint8))
    assert graphs[0].stat().st_mtime_ns == stamp  # reused, not exported again
    other = _compiled(name, tmp_path, layer="stage3")  # other network: its own file
    other.features(np.zeros((40, 48, 3), np.uint8))
    assert len(list(tmp_path.glob("*.onnx"))) == 2


@pytest.mark.parametrize("name", COMPILED)
def test_auto_checks_each_size_once_records_it_and_falls_back_to_torch(name, tmp_path,
                                                                       monkeypatch):
    model = _compiled(name, tmp_path, weights="random", arch="resnet18")
    rng = np.random.default_rng(0)
    with recording_runtimes() as seen:  # what a run record names, as the model runs
        model.features(rng.integers(0, 255, (64, 96, 3), np.uint8))
    assert seen == {name}
    model._compiled.verify = True
    with recording_runtimes() as seen:
        model.features(rng.integers(0, 255, (64, 96, 3), np.uint8))
    assert seen == {f"{name} (auto, checked against torch)"}
    records = list(tmp_path.glob(f"*.{name}.check.json"))
    assert len(records) == 1 and json.loads(records[0].read_text())["cosine"] >= rt.MIN_COSINE
    network, model._compiled.network = model._compiled.network, None
    assert model._compiled.check(64, 96) >= rt.MIN_COSINE  # the record is read, not recomputed
    model._compiled.network = network
    monkeypatch.setattr(rt, "MIN_COSINE", 1.5)  # another size that no runtime can pass
    frame = rng.integers(0, 255, (32, 48, 3), np.uint8)
    with pytest.warns(UserWarning, match="runs in eager torch"), recording_runtimes() as seen:
        ours = model.features(frame)
    assert model._compiled.fallbacks == {(32, 48)}
    assert seen == {f"torch (auto: {name} differed)"}
    reference = AppearanceModel("random", arch="resnet18", runtime="torch").features(frame)
    assert torch.equal(ours, reference)


@pytest.mark.parametrize("name", COMPILED)
def test_compiled_hypercolumn_matches_torch(name, tmp_path):
    reference = AppearanceModel(layer="stage3+stage5", runtime="torch")
    model = _compiled(name, tmp_path, layer="stage3+stage5")
    image = np.random.default_rng(1).integers(0, 256, (64, 80, 3), dtype=np.uint8)
    assert _cosine(model.features(image), reference.features(image)) >= COSINE_FLOOR


@pytest.mark.parametrize("name", COMPILED)
def test_compiled_features_match_torch_on_real_frames(torch_model, name, shared_data,
                                                      tmp_path):
    model = _compiled(name, tmp_path)
    davis = shared_data / "DAVIS" / "JPEGImages" / "480p" / "blackswan" / "00000.jpg"
    mot = shared_data / "MOT17" / "train" / "MOT17-02-FRCNN" / "img1" / "000001.jpg"
    for path, boxed in ((davis, False), (mot, True)):
        frame = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        image = letterbox(frame).image if boxed else frame
        cosine = _cosine(model.features(image), torch_model.features(image))
        assert cosine >= COSINE_FLOOR, (path.name, cosine)


# ---------------------------------------------------------------------- episodes
GOLDENS = Path(__file__).resolve().parents[1] / "goldens"
GOLDEN_TOLERANCE = 2e-3  # as the propagation heads' goldens


@pytest.mark.parametrize("name", COMPILED)
@pytest.mark.parametrize(("env_id", "agent", "sequence", "options"), [
    ("UniTrack/DAVIS-v0", "unitrack-vos", "syn-occluded", {}),
    ("UniTrack/JHMDB-v0", "unitrack-pose", "run/SYN_run_f_cm_np1_ri_med_1", {}),
    # Not the SOT goldens: on the 15-frame SynLateStart, success AUC moves in steps of
    # 1/315 (one threshold of one frame) and unitrack-dcf's episode is chaotic (boxes within
    # 0.08 px of torch's, then a different peak wins; AUC -0.16 with OpenVINO, measured).
])
def test_episode_metrics_unchanged_with_a_compiled_runtime(episode_regression, name, env_id,
                                                           agent, sequence, options,
                                                           tmp_path, monkeypatch):
    pytest.importorskip(name)
    pytest.importorskip("onnx")
    monkeypatch.setenv(rt.CACHE_ENV, str(tmp_path))
    env_name = env_id.split("/")[1].split("-")[0]
    golden = GOLDENS / f"{agent}-{env_name}-{sequence.replace('/', '__')}.json"
    episode_regression.check(
        env_id, agent=agent, sequence=sequence, golden=golden, tolerance=GOLDEN_TOLERANCE,
        agent_kwargs={"num_threads": 1, "runtime": name, **options},
    )

"""``unitrack evaluate --backend ray``: the same files and metrics as a local run, on a local
Ray cluster started on the loopback address."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.run.runner import RunFailed, run

ENV = "UniTrack/MOT17-v0"
FIXTURES = Path(__file__).resolve().parents[3] / "shared" / "data" / "MOT17"


@pytest.fixture(scope="module")
def ray_cluster():
    ray = pytest.importorskip("ray")
    if not FIXTURES.is_dir():
        pytest.skip(f"no MOT17 fixtures at {FIXTURES}")
    ray.init(num_cpus=2, _node_ip_address="127.0.0.1", include_dashboard=False,
             log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


def _files(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted((out / "data").rglob("*"))
            if p.is_file()}


@pytest.mark.slow
def test_ray_writes_the_local_bytes_and_metrics_and_resumes(ray_cluster, tmp_path, capsys):
    env_kwargs = {"root": str(FIXTURES)}
    local = run(ENV, "iou", out=tmp_path / "local", env_kwargs=env_kwargs, progress=False)
    assert main(["evaluate", "--env", ENV, "--root", str(FIXTURES), "--agent", "iou",
                 "--backend", "ray", "--out", str(tmp_path / "ray"), "--quiet"]) == 0
    assert _files(tmp_path / "ray") == _files(tmp_path / "local")
    assert len(_files(tmp_path / "local")) == 4
    on_ray = json.loads((tmp_path / "ray" / "metrics.json").read_text())
    here = json.loads((tmp_path / "local" / "metrics.json").read_text())
    assert on_ray["combined"] == here["combined"] == json.loads(json.dumps(
        local.scores.combined))
    assert on_ray["per_sequence"] == here["per_sequence"]
    manifest = json.loads((tmp_path / "ray" / "manifest.json").read_text())
    assert not manifest.get("playing")  # every claim settled
    for name in _files(tmp_path / "ray"):
        assert any(name in str(f) for f in manifest["files"]), name
    again = run(ENV, "iou", out=tmp_path / "ray", env_kwargs=env_kwargs, progress=False,
                backend="ray")
    assert sorted(again.skipped) == sorted(here["per_sequence"])  # resumed: nothing played


@pytest.mark.slow
def test_a_failed_sequence_fails_alone_on_ray(ray_cluster, tmp_path):
    root = tmp_path / "MOT17"
    shutil.copytree(FIXTURES, root)
    frame = sorted((root / "train" / "MOT17-05-FRCNN" / "img1").iterdir())[0]
    frame.write_bytes(frame.read_bytes()[:200])  # a truncated JPEG
    out = tmp_path / "run"
    with pytest.raises(RunFailed) as failed:
        run(ENV, "iou", out=out, env_kwargs={"root": str(root)}, progress=False,
            backend="ray")
    assert list(failed.value.failures) == ["MOT17-05-FRCNN"]
    assert str(frame.name) in failed.value.failures["MOT17-05-FRCNN"]
    kept = sorted(p.stem for p in (out / "sequences").glob("*.json"))
    assert kept == ["MOT17-02-FRCNN", "MOT17-04-FRCNN", "MOT17-11-FRCNN"]


def test_address_goes_with_ray(tmp_path):
    with pytest.raises(ValueError, match="--address goes with --backend ray"):
        run(ENV, "iou", out=tmp_path, address="auto")

from pathlib import Path

import numpy as np
import pytest
import torch

from unitrack_env.agents.appearance import (
    CIFAR_MEAN,
    DEFAULT_REMAPS,
    DEFAULT_WEIGHT_LOADERS,
    AppearanceModel,
    CheckpointError,
    KeyRemap,
    ResNet,
    WeightsSource,
    infer_resnet_arch,
)

IMAGE = np.random.default_rng(0).integers(0, 256, (40, 48, 3), dtype=np.uint8)


def _resnet_state(arch: str, seed: int) -> dict[str, torch.Tensor]:
    torch.manual_seed(seed)
    net = ResNet(arch)
    # Non-trivial batch-norm statistics, so a load that skipped them would show.
    for name, buf in net.named_buffers():
        if name.endswith("running_mean"):
            buf.normal_(0, 0.1)
        elif name.endswith("running_var"):
            buf.uniform_(0.5, 1.5)
    return net.state_dict()


@pytest.fixture(scope="module")
def r18_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, torch.Tensor]]:
    state = _resnet_state("resnet18", 1)
    path = tmp_path_factory.mktemp("ckpt") / "resnet18.pth"
    torch.save(state, path)
    return path, state


def _assert_same_features(actual: torch.Tensor, expected: torch.Tensor) -> None:
    """Equal up to float32 rounding on any x86-64: the same network and weights, but oneDNN
    picks other convolution kernels on other CPUs (on an AVX-512 machine the model's path
    and the plain forward differ by up to 2e-5 on a few of these layer3 values)."""
    torch.testing.assert_close(actual, expected, rtol=1e-4, atol=1e-4)


def _reference_features(state: dict[str, torch.Tensor], layer: str = "layer3") -> torch.Tensor:
    net = ResNet("resnet18").eval()
    net.load_state_dict(state)
    x = torch.from_numpy(IMAGE).permute(2, 0, 1).float().div(255)[None]
    x = (x - torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)) / torch.tensor(
        [0.229, 0.224, 0.225]
    ).view(1, 3, 1, 1)
    with torch.no_grad():
        return net.forward_features(x, layer)


def test_torchvision_layout_file_round_trips(r18_file: tuple[Path, dict]) -> None:
    path, state = r18_file
    model = AppearanceModel(path)
    report = model.load_report
    assert model.arch == "resnet18" and model.layer == "layer3"
    assert report is not None and report.complete and report.remap == "torchvision"
    assert sorted(report.matched) == sorted(state)
    assert not report.missing and not report.unexpected and not report.mismatched
    _assert_same_features(model.features(IMAGE), _reference_features(state))
    assert model.identity.weights == str(path)
    assert "122 matched" in model.describe()["load"]


def test_resnet50_file_into_resnet18_fails_loudly(tmp_path: Path) -> None:
    path = tmp_path / "r50.pth"
    torch.save(_resnet_state("resnet50", 0), path)
    with pytest.raises(CheckpointError) as info:
        AppearanceModel(path, arch="resnet18")
    message = str(info.value)
    assert str(path) in message
    assert "layer1.0.conv1.weight" in message  # first offending key is named
    assert "allow_partial" in message
    # Without arch= the depth is inferred and the file loads.
    assert AppearanceModel(path).arch == "resnet50"


def test_deeper_basic_resnet_into_resnet18_fails(tmp_path: Path) -> None:
    path = tmp_path / "r34.pth"
    torch.save(_resnet_state("resnet34", 0), path)
    with pytest.raises(CheckpointError, match="layer1.2"):
        AppearanceModel(path, arch="resnet18")
    assert infer_resnet_arch(list(_resnet_state("resnet34", 0))) == "resnet34"


@pytest.mark.parametrize("content", [b"", b"this is not a checkpoint at all", None])
def test_corrupt_files_give_a_clear_error(
    tmp_path: Path, r18_file: tuple[Path, dict], content: bytes | None
) -> None:
    path = tmp_path / "broken.pth"
    if content is None:  # a real checkpoint cut in half
        data = r18_file[0].read_bytes()
        content = data[: len(data) // 2]
    path.write_bytes(content)
    with pytest.raises(CheckpointError, match="not a readable PyTorch checkpoint") as info:
        AppearanceModel(path, arch="resnet18")
    assert str(path) in str(info.value) and f"({len(content):,} bytes;" in str(info.value)


def test_pickled_objects_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "pickle.pth"
    torch.save({"state_dict": _resnet_state("resnet18", 0), "args": Path("x")}, path)
    with pytest.raises(CheckpointError, match="weights_only"):
        AppearanceModel(path, arch="resnet18")


def test_missing_file_is_named() -> None:
    with pytest.raises(ValueError, match="no/such/file.pth"):
        AppearanceModel("no/such/file.pth")


def test_moco_checkpoint_loads_through_the_remap_table(
    tmp_path: Path, r18_file: tuple[Path, dict]
) -> None:
    _, state = r18_file
    other = _resnet_state("resnet18", 5)
    ckpt = {
        "epoch": 200,
        "arch": "resnet18",
        "state_dict": {
            **{f"module.encoder_q.{k}": v for k, v in state.items()},
            **{f"module.encoder_k.{k}": v for k, v in other.items()},
            "module.queue": torch.randn(128, 16),
        },
    }
    path = tmp_path / "moco.pth.tar"
    torch.save(ckpt, path)
    for remap in ("auto", "moco"):
        model = AppearanceModel(path, remap=remap)
        assert model.load_report is not None and model.load_report.remap == "moco"
        assert len(model.load_report.matched) == len(state)
        assert len(model.load_report.unexpected) == len(other) + 1  # encoder_k + queue
        _assert_same_features(model.features(IMAGE), _reference_features(state))


def test_one_gpu_moco_keys_load_and_the_architecture_is_inferred(
    tmp_path: Path, r18_file: tuple[Path, dict]
) -> None:
    _, state = r18_file  # MoCo trained without DataParallel: 'encoder_q.' without 'module.'
    path = tmp_path / "moco-1gpu.pth"
    torch.save({"state_dict": {f"encoder_q.{k}": v for k, v in state.items()}}, path)
    model = AppearanceModel(path)
    assert model.arch == "resnet18" and model.load_report.remap == "moco"
    assert len(model.load_report.matched) == len(state)


def test_an_efficientnet_lite0_state_dict_needs_no_arch(tmp_path: Path) -> None:
    from unitrack_env.agents.appearance.efficientnet_lite import EfficientNetLite0

    path = tmp_path / "lite0.pth"
    torch.save({f"module.{k}": v for k, v in EfficientNetLite0().state_dict().items()}, path)
    assert AppearanceModel(path).arch == "efficientnet-lite0"


def test_a_foreign_prefix_is_named(tmp_path: Path, r18_file: tuple[Path, dict]) -> None:
    _, state = r18_file
    path = tmp_path / "wrapped.pth"
    # ("backbone." is no longer foreign: the DINO remap strips it, as DINO's checkpoints need.)
    torch.save({f"net.{k}": v for k, v in state.items()}, path)
    with pytest.raises(CheckpointError, match=f"Every key starts with 'net.' and "
                                              f"{len(state)} keys fit the backbone without it"):
        AppearanceModel(path, arch="resnet18")


def test_crw_remap_sets_cifar_normalisation(tmp_path: Path, r18_file: tuple[Path, dict]) -> None:
    _, state = r18_file
    path = tmp_path / "crw.pth"
    torch.save({"model": {f"encoder.model.{k}": v for k, v in state.items()}, "epoch": 3}, path)
    model = AppearanceModel(path)
    assert model.load_report is not None and model.load_report.remap == "crw"
    assert model.mean == CIFAR_MEAN
    assert AppearanceModel(path, mean=(0.5, 0.5, 0.5)).mean == (0.5, 0.5, 0.5)


def test_timecycle_5d_kernels_are_squeezed(tmp_path: Path, r18_file: tuple[Path, dict]) -> None:
    _, state = r18_file
    five_d = {
        f"module.encoderVideo.{k}": (v.unsqueeze(2) if v.ndim == 4 else v)
        for k, v in state.items()
    }
    path = tmp_path / "timecycle.pth"
    torch.save({"state_dict": five_d}, path)
    model = AppearanceModel(path, arch="resnet18", remap="timecycle")
    _assert_same_features(model.features(IMAGE), _reference_features(state))


def test_partial_checkpoints(tmp_path: Path, r18_file: tuple[Path, dict]) -> None:
    _, state = r18_file
    no_layer3 = {k: v for k, v in state.items() if not k.startswith("layer3.")}
    path = tmp_path / "partial.pth"
    torch.save(no_layer3, path)
    with pytest.raises(CheckpointError, match="layer3.0.conv1.weight"):
        AppearanceModel(path, arch="resnet18")
    model = AppearanceModel(path, arch="resnet18", allow_partial=True)
    report = model.load_report
    assert report is not None and not report.complete
    assert "layer3.0.conv1.weight" in report.critical_missing
    # layer4 is not needed for layer3 features: its absence is reported, not fatal.
    no_layer4 = {k: v for k, v in state.items() if not k.startswith(("layer4.", "fc."))}
    torch.save(no_layer4, path)
    model = AppearanceModel(path, arch="resnet18")
    assert model.load_report is not None and model.load_report.complete
    assert "layer4.0.conv1.weight" in model.load_report.missing
    with pytest.raises(CheckpointError, match="layer4"):
        AppearanceModel(path, arch="resnet18", layer="layer4")


def test_old_files_without_num_batches_tracked_load(
    tmp_path: Path, r18_file: tuple[Path, dict]
) -> None:
    _, state = r18_file
    path = tmp_path / "old.pth"
    torch.save({k: v for k, v in state.items() if not k.endswith("num_batches_tracked")}, path)
    model = AppearanceModel(path)
    assert model.load_report is not None and model.load_report.complete
    assert model.load_report.missing  # reported all the same


def test_user_remaps_and_loaders(tmp_path: Path, r18_file: tuple[Path, dict]) -> None:
    _, state = r18_file
    path = tmp_path / "custom.pth"
    torch.save({"net": {f"backbone.{k}": v for k, v in state.items()}}, path)
    mine = KeyRemap("mine", containers=("net",), strip_prefixes=("backbone.",))
    remaps = {**DEFAULT_REMAPS, "mine": mine}
    model = AppearanceModel(path, remaps=remaps, remap="mine", arch="resnet18")
    assert model.load_report is not None and model.load_report.remap == "mine"
    assert AppearanceModel(path, remap=mine, arch="resnet18").load_report.complete
    with pytest.raises(CheckpointError, match="unknown remap 'nope'"):
        AppearanceModel(path, remap="nope", arch="resnet18")
    assert "mine" not in DEFAULT_REMAPS  # defaults are read-only and unchanged
    with pytest.raises(TypeError):
        DEFAULT_REMAPS["x"] = mine  # type: ignore[index]

    loaders = {
        **DEFAULT_WEIGHT_LOADERS,
        "my-r18": lambda: WeightsSource("my-r18", arch="resnet18", path=str(path), remap="mine"),
    }
    named = AppearanceModel("my-r18", loaders=loaders, remaps=remaps)
    assert named.identity.weights == "my-r18"
    _assert_same_features(named.features(IMAGE), _reference_features(state))


def test_digest_tracks_the_weights(tmp_path: Path, r18_file: tuple[Path, dict]) -> None:
    path, state = r18_file
    a = AppearanceModel(path)
    changed = dict(state)
    changed["layer3.1.conv2.weight"] = state["layer3.1.conv2.weight"] * 1.01
    other = tmp_path / "changed.pth"
    torch.save(changed, other)
    b = AppearanceModel(other)
    assert a.identity.digest != b.identity.digest
    changed_fc = dict(state)
    changed_fc["fc.bias"] = state["fc.bias"] + 1  # not used by layer3 features
    torch.save(changed_fc, other)
    assert AppearanceModel(other).identity.digest == a.identity.digest

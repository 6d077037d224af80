"""Published ViT checkpoint layouts load strictly; wrong architectures are refused."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import torch
from test_vit import official_state, with_layerscale  # the same folder (pytest prepends it)

from unitrack_env.agents.appearance.model import AppearanceModel
from unitrack_env.agents.appearance.resnet import ResNet
from unitrack_env.agents.appearance.vit import VIT_SPECS
from unitrack_env.errors import CheckpointError

S16 = "vit_small_patch16"


def _prefixed(state: dict[str, torch.Tensor], prefix: str) -> dict[str, torch.Tensor]:
    return {prefix + k: v for k, v in state.items()}


def _dino_teacher(s: dict[str, torch.Tensor]) -> object:
    head = {"head.mlp.0.weight": torch.zeros(8, 384), "head.last_layer.weight_g": torch.ones(4, 1)}
    return {"teacher": _prefixed(s, "backbone.") | head, "epoch": 100,
            "student": _prefixed(s, "module.backbone.") | _prefixed(head, "module.")}


def _dino_student(s: dict[str, torch.Tensor]) -> object:
    return {"student": _prefixed(s, "module.backbone.")
            | {"module.head.mlp.0.weight": torch.zeros(8, 384)}}


def _mae_pretrain(s: dict[str, torch.Tensor]) -> object:
    decoder = {"mask_token": torch.zeros(1, 1, 512), "decoder_embed.weight": torch.zeros(512, 384),
               "decoder_pos_embed": torch.zeros(1, 197, 512),
               "decoder_blocks.0.attn.qkv.weight": torch.zeros(1536, 512),
               "decoder_norm.weight": torch.ones(512), "decoder_pred.weight": torch.zeros(768, 512)}
    return {"model": s | decoder}


def _mae_finetuned(s: dict[str, torch.Tensor]) -> object:
    tuned = {("fc_norm." + k[5:] if k.startswith("norm.") else k): v for k, v in s.items()}
    head = {"head.weight": torch.zeros(1000, 384), "head.bias": torch.zeros(1000)}
    return {"model": tuned | head}


def _timm(s: dict[str, torch.Tensor]) -> object:
    return s | {"head.weight": torch.zeros(1000, 384), "head.bias": torch.zeros(1000)}


# layout -> (arch, file content, the remap "auto" picks). A plain file reads the same under
# every plain rule, so the first in the table wins ("torchvision"; "dino" drops a timm head).
LAYOUTS: dict[str, tuple[str, Callable[[dict[str, torch.Tensor]], object], str]] = {
    "dino-release": (S16, dict, "torchvision"),
    "dino-teacher": (S16, _dino_teacher, "dino"),
    "dino-student": (S16, _dino_student, "dino"),
    "mae-pretrain": (S16, _mae_pretrain, "mae"),
    "mae-finetuned": (S16, _mae_finetuned, "mae"),
    "timm": (S16, _timm, "dino"),
}


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_published_layouts_load(tmp_path: Path, layout: str) -> None:
    arch, wrap, remap = LAYOUTS[layout]
    state = official_state(arch, 2)
    path = tmp_path / f"{layout}.pth"
    torch.save(wrap(state), path)
    model = AppearanceModel(path, layer="block1")  # arch inferred, remap auto
    assert model.arch == arch
    assert model.load_report is not None and model.load_report.remap == remap
    assert model.load_report.complete and not model.load_report.unexpected, \
        model.load_report.summary()
    loaded = model.module.state_dict()
    for key, value in state.items():
        assert torch.equal(loaded[key], value), key
    assert all(torch.equal(v, torch.ones_like(v)) for k, v in loaded.items()
               if k.endswith((".ls1.gamma", ".ls2.gamma")))


@pytest.mark.parametrize("arch", ["vit_small_patch14", "vit_small_patch14_reg4"])
def test_dinov2_layouts_load(tmp_path: Path, arch: str) -> None:
    state = with_layerscale(official_state(arch, 3), VIT_SPECS[arch].depth)
    path = tmp_path / "dinov2.pth"
    torch.save(state, path)
    model = AppearanceModel(path, layer="block1")
    assert model.arch == arch and model.load_report is not None
    assert model.load_report.remap == "dinov2" and not model.load_report.unexpected
    loaded = model.module.state_dict()
    assert all(torch.equal(loaded[k], v) for k, v in state.items() if k != "mask_token")
    teacher = tmp_path / "dinov2-teacher.pth"
    torch.save({"teacher": _prefixed(state, "backbone.")
                | {"dino_head.mlp.0.weight": torch.zeros(4, 384)}}, teacher)
    again = AppearanceModel(teacher, layer="block1")
    assert again.identity.digest == model.identity.digest


def test_wrong_arch_is_refused_with_the_keys(tmp_path: Path) -> None:
    path = tmp_path / "dino-s16.pth"
    torch.save(official_state(S16, 4), path)
    with pytest.raises(CheckpointError, match=r"shape mismatches.*patch_embed\.proj\.weight"):
        AppearanceModel(path, arch="vit_small_patch14", layer="block1")
    with pytest.raises(CheckpointError, match=r"\('cls_token', \(1, 1, 384\), \(1, 1, 768\)\)"):
        AppearanceModel(path, arch="vit_base_patch16", layer="block1")
    with pytest.raises(CheckpointError, match=r"missing keys: conv1\.weight"):
        AppearanceModel(path, arch="resnet18")
    registers = tmp_path / "dinov2-s16-reg4.pth"
    torch.save(official_state(f"{S16}_reg4", 4), registers)
    with pytest.raises(CheckpointError, match=r"does not have.*: register_tokens"):
        AppearanceModel(registers, arch=S16, layer="block1")  # not run without its registers
    resnet = tmp_path / "r18.pth"
    torch.save(ResNet("resnet18").state_dict(), resnet)
    with pytest.raises(CheckpointError, match=r"missing keys: cls_token, pos_embed"):
        AppearanceModel(resnet, arch=S16)


def test_truncated_vit_is_refused(tmp_path: Path) -> None:
    state = official_state(S16, 5)
    del state["blocks.11.mlp.fc2.weight"]
    path = tmp_path / "cut.pth"
    torch.save(state, path)
    with pytest.raises(CheckpointError, match=r"blocks\.11\.mlp\.fc2\.weight"):
        AppearanceModel(path, arch=S16, layer="block1")  # strict whatever the layer


@pytest.mark.parametrize("fill", ["nan", "inf", "zero"])
def test_nan_or_zero_vit_weights_are_refused_naming_the_tensors(tmp_path: Path,
                                                                fill: str) -> None:
    state = official_state(S16, 6)
    value = {"nan": float("nan"), "inf": float("inf"), "zero": 0.0}[fill]
    state = {k: torch.full_like(v, value) for k, v in state.items()}
    path = tmp_path / f"{fill}.pth"
    torch.save(state, path)
    with pytest.raises(CheckpointError) as info:
        AppearanceModel(path, arch=S16, layer="block12")
    text = str(info.value)
    assert str(path) in text and "cls_token" in text and "more)" in text, text
    assert ("NaN or infinite" if fill != "zero" else "every weight tensor is zero") in text


def test_one_nan_tensor_is_named_and_a_clean_file_still_loads_exactly(tmp_path: Path) -> None:
    state = official_state(S16, 7)
    clean = tmp_path / "clean.pth"
    torch.save(state, clean)
    model = AppearanceModel(clean, arch=S16, layer="block12")
    loaded = model.module.state_dict()
    assert all(torch.equal(loaded[k], v) for k, v in state.items() if k in loaded)
    state["blocks.3.attn.qkv.weight"][0, 0] = float("nan")
    broken = tmp_path / "one-nan.pth"
    torch.save(state, broken)
    with pytest.raises(CheckpointError, match=r"1 of \d+ tensors hold NaN or infinite values: "
                                              r"blocks\.3\.attn\.qkv\.weight\."):
        AppearanceModel(broken, arch=S16, layer="block12")

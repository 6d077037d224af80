"""ViT backbones: the forward against an independent functional reference, the published
checkpoint layouts (built here with the official key names and shapes), strides."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from unitrack_env.agents.appearance.model import AppearanceModel
from unitrack_env.agents.appearance.vit import VIT_SPECS, VisionTransformer, infer_vit_arch
from unitrack_env.agents.base import make_agent
from unitrack_env.agents.heads.vos import UniTrackVOSConfig
from unitrack_env.agents.primitives.box_propagation import (
    BoxPropagationConfig,
    BoxPropagator,
    BoxState,
    XCorrHead,
)
from unitrack_env.agents.primitives.label_propagation import LabelPropagationConfig
from unitrack_env.evaluation.scorecard.plan import ModelSpec

LN_EPS = 1e-6


def official_state(arch: str, seed: int) -> dict[str, torch.Tensor]:
    """Random tensors under the key names and shapes DINO/DINOv2/timm release (timm layout)."""
    spec = VIT_SPECS[arch]
    g = torch.Generator().manual_seed(seed)
    d, p, hidden = spec.dim, spec.patch, spec.dim * 4

    def rnd(*shape: int, scale: float = 0.05) -> torch.Tensor:
        return torch.randn(*shape, generator=g) * scale

    state = {"cls_token": rnd(1, 1, d, scale=1), "pos_embed": rnd(1, 1 + spec.pos_grid ** 2, d),
             "patch_embed.proj.weight": rnd(d, 3, p, p), "patch_embed.proj.bias": rnd(d),
             "norm.weight": 1 + rnd(d), "norm.bias": rnd(d)}
    if spec.registers:
        state["register_tokens"] = rnd(1, spec.registers, d, scale=1)
    for i in range(spec.depth):
        b = f"blocks.{i}."
        state |= {b + "norm1.weight": 1 + rnd(d), b + "norm1.bias": rnd(d),
                  b + "attn.qkv.weight": rnd(3 * d, d), b + "attn.qkv.bias": rnd(3 * d),
                  b + "attn.proj.weight": rnd(d, d), b + "attn.proj.bias": rnd(d),
                  b + "norm2.weight": 1 + rnd(d), b + "norm2.bias": rnd(d),
                  b + "mlp.fc1.weight": rnd(hidden, d), b + "mlp.fc1.bias": rnd(hidden),
                  b + "mlp.fc2.weight": rnd(d, hidden), b + "mlp.fc2.bias": rnd(d)}
    return state


def with_layerscale(state: dict[str, torch.Tensor], depth: int) -> dict[str, torch.Tensor]:
    """DINOv2's extra keys: layer scale per block and the (unused) mask token."""
    d = state["cls_token"].shape[-1]
    g = torch.Generator().manual_seed(7)
    out = dict(state, mask_token=torch.zeros(1, d))
    for i in range(depth):
        out[f"blocks.{i}.ls1.gamma"] = torch.rand(d, generator=g) + 0.5
        out[f"blocks.{i}.ls2.gamma"] = torch.rand(d, generator=g) + 0.5
    return out


# ----------------------------------------------------------------- independent reference
def _layer_norm(x: torch.Tensor, w: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    mu = x.mean(-1, keepdim=True)
    var = ((x - mu) ** 2).mean(-1, keepdim=True)
    return (x - mu) / torch.sqrt(var + LN_EPS) * w + b


def reference_tokens(state: dict[str, torch.Tensor], image: torch.Tensor, patch: int,
                     heads: int, blocks: int) -> torch.Tensor:
    """Patch tokens after ``blocks`` blocks and the final norm, with explicit matmuls.

    ``image`` (3, H, W) must be a multiple of the patch and exactly the trained grid, so no
    interpolation is involved; float64 throughout."""
    s = {k: v.double() for k, v in state.items()}
    c, h, w = image.shape
    gh, gw = h // patch, w // patch
    patches = image.double().reshape(c, gh, patch, gw, patch).permute(1, 3, 0, 2, 4)
    x = patches.reshape(gh * gw, -1) @ s["patch_embed.proj.weight"].reshape(
        s["patch_embed.proj.weight"].shape[0], -1).T + s["patch_embed.proj.bias"]
    x = torch.cat([s["cls_token"][0], x]) + s["pos_embed"][0]
    n_reg = s["register_tokens"].shape[1] if "register_tokens" in s else 0
    if n_reg:
        x = torch.cat([x[:1], s["register_tokens"][0], x[1:]])
    d = x.shape[1]
    hd = d // heads
    for i in range(blocks):
        p = f"blocks.{i}."
        y = _layer_norm(x, s[p + "norm1.weight"], s[p + "norm1.bias"])
        qkv = y @ s[p + "attn.qkv.weight"].T + s[p + "attn.qkv.bias"]
        outs = []
        for head in range(heads):
            q = qkv[:, head * hd:(head + 1) * hd]
            k = qkv[:, d + head * hd:d + (head + 1) * hd]
            v = qkv[:, 2 * d + head * hd:2 * d + (head + 1) * hd]
            a = torch.exp(q @ k.T / math.sqrt(hd))
            outs.append((a / a.sum(1, keepdim=True)) @ v)
        y = torch.cat(outs, 1) @ s[p + "attn.proj.weight"].T + s[p + "attn.proj.bias"]
        x = x + y * s.get(p + "ls1.gamma", torch.ones(d, dtype=torch.float64))
        y = _layer_norm(x, s[p + "norm2.weight"], s[p + "norm2.bias"])
        y = y @ s[p + "mlp.fc1.weight"].T + s[p + "mlp.fc1.bias"]
        y = 0.5 * y * (1 + torch.erf(y / math.sqrt(2)))
        y = y @ s[p + "mlp.fc2.weight"].T + s[p + "mlp.fc2.bias"]
        x = x + y * s.get(p + "ls2.gamma", torch.ones(d, dtype=torch.float64))
    x = _layer_norm(x[1 + n_reg:], s["norm.weight"], s["norm.bias"])
    return x.T.reshape(d, gh, gw)


def _features(model: AppearanceModel, image: torch.Tensor) -> torch.Tensor:
    return model.features(image[None])[0].double()


@pytest.mark.parametrize("arch, layerscale", [("vit_small_patch16", False),
                                              ("vit_small_patch14_reg4", True)])
def test_forward_matches_reference(tmp_path: Path, arch: str, layerscale: bool) -> None:
    spec = VIT_SPECS[arch]
    state = official_state(arch, 1)
    if layerscale:
        state = with_layerscale(state, spec.depth)
    path = tmp_path / "vit.pth"
    torch.save(state, path)
    model = AppearanceModel(path, layer="block2")  # arch inferred from the keys
    assert model.arch == arch and model.stride == spec.patch
    side = spec.pos_grid * spec.patch
    image = torch.randn(3, side, side, generator=torch.Generator().manual_seed(3))
    got = _features(model, image)
    want = reference_tokens(state, image, spec.patch, spec.heads, blocks=2)
    assert got.shape == want.shape
    assert torch.allclose(got, want, atol=2e-4), (got - want).abs().max()


def test_position_embedding_resized_bicubically() -> None:
    net = VisionTransformer("vit_small_patch16").eval()
    pos = net.position_embedding(14, 14)
    assert torch.equal(pos, net.pos_embed)  # the trained grid is used as is
    grid = net.pos_embed[:, 1:].reshape(1, 14, 14, -1).permute(0, 3, 1, 2)
    want = torch.nn.functional.interpolate(grid, size=(5, 9), mode="bicubic")
    got = net.position_embedding(5, 9)[:, 1:].reshape(1, 5, 9, -1).permute(0, 3, 1, 2)
    assert torch.allclose(got, want) and torch.equal(net.position_embedding(5, 9)[:, 0],
                                                     net.pos_embed[:, 0])


def test_any_input_size_pads_to_whole_patches() -> None:
    model = AppearanceModel("random", arch="vit_small_patch14", layer="block1")
    image = np.random.default_rng(0).integers(0, 256, (45, 71, 3), dtype=np.uint8)
    assert model.features(image).shape == (1, 384, 4, 6)  # ceil(45/14), ceil(71/14)
    assert model.feature_shape(45, 71) == (384, 4, 6)


@pytest.mark.parametrize("stride, mode", [("8", "overlap"), ("8-upsample", "upsample")])
def test_stride_option(stride: str, mode: str) -> None:
    model = AppearanceModel("random", arch="vit_small_patch14", layer="block1", stride=stride)
    image = np.random.default_rng(0).integers(0, 256, (45, 71, 3), dtype=np.uint8)
    assert model.stride == 8 and model.features(image).shape == (1, 384, 6, 9)
    assert model.identity.layer == f"block1@stride8-{mode}"
    native = AppearanceModel("random", arch="vit_small_patch14", layer="block1")
    assert native.identity.key() != model.identity.key()


def test_stride_option_errors() -> None:
    with pytest.raises(ValueError, match="exceeds its patch"):
        AppearanceModel("random", arch="vit_small_patch8", stride=14)
    with pytest.raises(ValueError, match="ViT architectures only"):
        AppearanceModel("random", arch="resnet18", stride=8)
    with pytest.raises(ValueError, match="8-upsample"):
        AppearanceModel("random", arch="vit_small_patch14", stride="8-bogus")
    with pytest.raises(ValueError, match="block1 .. block12"):
        AppearanceModel("random", arch="vit_small_patch14", layer="layer3")


def test_intermediate_layers_and_hypercolumn() -> None:
    net = VisionTransformer("vit_small_patch16").eval()
    x = torch.randn(1, 3, 32, 48)
    with torch.no_grad():
        b3, b12 = net.forward_layers(x, ("block3", "block12"))
        assert torch.equal(b3, net.forward_features(x, "block3"))
        assert not torch.allclose(b3, b12)
    model = AppearanceModel("random", arch="vit_small_patch16", layer="block6+block12")
    assert model.channels == 768


def test_infer_arch_from_shapes() -> None:
    with torch.device("meta"):
        for arch in ("vit_base_patch8", "vit_large_patch14_reg4", "vit_small_patch16"):
            assert infer_vit_arch(VisionTransformer(arch).state_dict()) == arch
    assert infer_vit_arch({"conv1.weight": torch.zeros(64, 3, 7, 7)}) is None


@pytest.mark.parametrize("runtime", ["openvino", "onnxruntime"])
@pytest.mark.parametrize("arch", ["vit_small_patch14", "vit_small_patch14_reg4"])
def test_exported_runtime_matches_torch(tmp_path: Path, runtime: str, arch: str) -> None:
    """ViT-S/14 (the last block, the default) through each compiled runtime = torch."""
    for module in (runtime, "onnx"):
        pytest.importorskip(module)
    import onnx

    image = np.random.default_rng(1).integers(0, 256, (2, 60, 90, 3), dtype=np.uint8)
    eager = AppearanceModel("random", arch=arch)
    compiled = AppearanceModel("random", arch=arch, runtime=runtime, runtime_cache=tmp_path)
    a, b = eager.features(image), compiled.features(image)
    assert a.shape == b.shape == (2, 384, 5, 7)
    assert torch.nn.functional.cosine_similarity(a, b, dim=1).min() >= 0.9999
    # the position embedding resized to the 5 x 7 grid is a constant of the graph: OpenVINO
    # would otherwise constant-fold the bicubic resize when compiling (minutes at 10k tokens)
    (graph,) = tmp_path.glob("*.onnx")
    assert "Resize" not in {node.op_type for node in onnx.load(str(graph)).graph.node}


def test_frozen_positions_are_the_resized_embedding() -> None:
    net = VisionTransformer("vit_small_patch16").eval()
    x = torch.randn(1, 3, 50, 70)
    want = net.forward_features(x, "block2")
    with net.frozen_positions(50, 70):
        assert torch.equal(net.position_embedding(4, 5), net._frozen_positions[1])
        assert net.position_embedding(5, 5).shape[1] == 26  # another grid: resized as usual
        assert torch.equal(net.forward_features(x, "block2"), want)
    assert net._frozen_positions is None


def test_heads_keep_their_reach_in_pixels_at_another_stride() -> None:
    config = LabelPropagationConfig()
    assert config.for_stride(8) is config
    s14 = config.for_stride(14)
    assert s14.radius == pytest.approx(12 * 8 / 14) and s14.first_frame_radius is None
    assert s14.for_stride(14) is s14 and s14.for_stride(8).radius == pytest.approx(12)
    assert LabelPropagationConfig(radius_stride=None).for_stride(14).radius == 12
    assert UniTrackVOSConfig(radius=6).propagation_config(16).radius == 3
    head = XCorrHead(BoxPropagationConfig(method="xcorr"))
    for size, side in ((65, 14), (38, 8), (33, 7)):  # strides 8, 14, 16 of a 520 crop
        head.init(torch.zeros(1, 4, size, size))
        assert head.template is not None and head.template.shape[-1] == side


def test_scorecard_model_option_stride() -> None:
    spec = ModelSpec.parse("random,arch=vit_small_patch14,layer=block9,stride=8-upsample")
    assert spec.agent_kwargs() == {"weights": "random", "arch": "vit_small_patch14",
                                   "layer": "block9", "stride": "8-upsample"}
    assert spec.name == "random+vit_small_patch14+block9+s8-upsample"
    vos = make_agent("unitrack-vos", weights="random", arch="vit_small_patch16", layer="block1")
    assert vos.model.stride == 16 and vos.propagator.config.radius == pytest.approx(6)


def _cell_pixels(stride: int):
    """Appearance-free features laid out like a ViT map of ``stride``: the normalised colour of
    each 2 x 2 sub-block of every cell (cell ``j`` covers pixels ``[s j, s j + s)``)."""
    def features(crops: np.ndarray) -> torch.Tensor:
        x = torch.from_numpy(np.ascontiguousarray(crops)).permute(0, 3, 1, 2).float() / 255
        x = (x - x.mean((2, 3), keepdim=True)) / (x.std((2, 3), keepdim=True) + 1e-6)
        gh, gw = math.ceil(x.shape[2] / stride), math.ceil(x.shape[3] / stride)
        x = torch.nn.functional.pad(x, (0, gw * stride - x.shape[3], 0, gh * stride - x.shape[2]))
        x = torch.nn.functional.interpolate(x, size=(2 * gh, 2 * gw), mode="area")
        return torch.nn.functional.pixel_unshuffle(x, 2)
    return features


@pytest.mark.parametrize("method", ["xcorr", "dcf"])
@pytest.mark.parametrize("stride", [8, 14, 16])
def test_box_propagation_finds_a_known_shift_at_any_stride(method: str, stride: int) -> None:
    """The SOT heads' geometry at the ViT strides: a textured frame moved by (+19, -11) px."""
    import cv2

    rng = np.random.default_rng(0)
    image = cv2.resize(rng.integers(0, 256, (45, 60, 3), dtype=np.uint8), (480, 360),
                       interpolation=cv2.INTER_CUBIC)
    shift = (19.0, -11.0)
    moved = cv2.warpAffine(image, np.array([[1, 0, shift[0]], [0, 1, shift[1]]]), (480, 360),
                           borderMode=cv2.BORDER_REFLECT)
    tracker = BoxPropagator(_cell_pixels(stride), BoxPropagationConfig(method=method),
                            stride=stride)
    tracker.reset(image, BoxState(240.0, 180.0, 60.0, 60.0))
    state = tracker.step(moved)
    cell = stride * 60 * 4.5 / 520  # image pixels per feature cell
    assert abs(state.cx - 240 - shift[0]) < cell and abs(state.cy - 180 - shift[1]) < cell


def test_vos_labels_sit_on_the_cells_that_cover_them() -> None:
    """Stride 16 on a 40 x 50 frame: 3 x 4 cells covering 48 x 64 pixels, not 40 x 50."""
    vos = make_agent("unitrack-vos", weights="random", arch="vit_small_patch16", layer="block1")
    vos._size = (40, 50)
    vos._lookup = np.array([0, 1], np.uint8)
    soft = torch.zeros(2, 3, 4)
    soft[1, 1, 1] = 1.0
    soft[0] = 1.0 - soft[1]
    rows, cols = np.nonzero(vos.decode(soft))
    assert set(rows) == set(range(16, 32)) and set(cols) == set(range(16, 32))
    onehot = torch.zeros(2, 40, 50)
    onehot[1, 16:32, 16:32] = 1.0
    onehot[0] = 1.0 - onehot[1]
    canvas = vos._grid_canvas(onehot)
    assert canvas.shape == (2, 48, 64) and torch.equal(canvas[:, :40, :50], onehot)
    assert canvas[0, 40:].eq(1).all() and canvas[1, :, 50:].eq(0).all()
    assert vos.model.map_extent(40, 50) == (48, 64)
    assert AppearanceModel("random", arch="resnet18").map_extent(40, 50) == (40, 50)
    upsampled = AppearanceModel("random", arch="vit_small_patch14", layer="block1",
                                stride="8-upsample")
    assert upsampled.map_extent(40, 50) == (42, 56)

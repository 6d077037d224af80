"""Vision transformers (ViT-S/B/L, patch 8, 14 or 16, optional registers) as feature backbones.

The architecture is Dosovitskiy et al., "An Image is Worth 16x16 Words" (ICLR 2021), in the
parameter layout that DINO, DINOv2, MAE and timm publish (``cls_token``, ``pos_embed``,
``patch_embed.proj``, ``blocks.<i>.{norm1, attn.qkv, attn.proj, ls1.gamma, norm2, mlp.fc1,
mlp.fc2, ls2.gamma}``, ``norm``), with DINOv2's layer scale (``ls1``/``ls2``, ones when a
checkpoint has none) and register tokens (Darcet et al., ICLR 2024: inserted after the
class token, after the position embedding is added).

As a backbone: the image is cut into patches (zero-padded: ``ceil(H / s) x ceil(W / s)``
tokens), the position embedding is interpolated bicubically to the token grid (as DINO
does), and the patch tokens of ``layer="block<k>"`` (1-based; default the last), through the
final ``norm``, become a ``(B, dim, h, w)`` map. Its stride is the patch size unless
``stride`` asks otherwise: ``"overlap"`` runs the patch embedding with that stride (denser
tokens, attention cost grows with their square), ``"upsample"`` resizes the map bilinearly
(cheap, no new detail); costs in ``docs/evaluate-your-representation.md``. Attention is
``scaled_dot_product_attention`` (fused; the ``N x N`` matrix is never held whole). For
export, :meth:`VisionTransformer.frozen_positions` makes the resized position embedding a
constant: left as a bicubic resize, OpenVINO constant-folded it for minutes per input size.
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import torch
import torch.nn.functional as F
from torch import nn

LN_EPS: float = 1e-6
"""Layer-norm epsilon of DINO, DINOv2, MAE and timm ViTs."""

MLP_RATIO: int = 4
"""Hidden width of each block's MLP over the embedding width."""

REGISTERS: int = 4
"""Register tokens of the ``_reg4`` variants (DINOv2 with registers)."""

STRIDE_MODES: tuple[str, ...] = ("overlap", "upsample")
"""How a ``stride`` smaller than the patch is obtained (see the module docstring)."""

_SIZES: Mapping[str, tuple[int, int, int]] = MappingProxyType({
    "small": (384, 12, 6), "base": (768, 12, 12), "large": (1024, 24, 16),
})
"""Embedding width, depth and attention heads of ViT-S, ViT-B and ViT-L."""


@dataclass(frozen=True)
class ViTSpec:
    """One ViT variant.

    Attributes:
        name: Architecture name, e.g. ``"vit_small_patch14_reg4"``.
        patch: Patch size (8, 14 or 16).
        dim: Embedding width.
        depth: Number of blocks.
        heads: Attention heads.
        registers: Register tokens (0 or :data:`REGISTERS`).
    """

    name: str
    patch: int
    dim: int
    depth: int
    heads: int
    registers: int = 0

    @property
    def pos_grid(self) -> int:
        """Side of the trained position-embedding grid.

        37 for patch 14 (DINOv2's 518 px), else 224 / patch (DINO, MAE, timm at 224 px).
        """
        return 37 if self.patch == 14 else 224 // self.patch

    @property
    def layers(self) -> tuple[str, ...]:
        """Output layer names: ``block1`` .. ``block<depth>``."""
        return tuple(f"block{k}" for k in range(1, self.depth + 1))


VIT_SPECS: Mapping[str, ViTSpec] = MappingProxyType({
    f"vit_{size}_patch{patch}{'_reg4' if reg else ''}": ViTSpec(
        f"vit_{size}_patch{patch}{'_reg4' if reg else ''}", patch, *dims, registers=reg)
    for size, dims in _SIZES.items() for patch in (8, 14, 16) for reg in (0, REGISTERS)
})
"""Every ViT architecture the appearance model can build (read-only)."""


@dataclass(frozen=True)
class StrideOption:
    """A feature stride other than the patch size, and how it is obtained.

    Attributes:
        stride: Pixels per feature cell (at most the patch size).
        mode: ``"overlap"`` (patch embedding with this stride) or ``"upsample"``.
    """

    stride: int
    mode: str = "overlap"

    @classmethod
    def parse(cls, value: int | str | StrideOption | None) -> StrideOption | None:
        """``8``, ``"8"``, ``"8-overlap"`` or ``"8-upsample"`` (None: the patch size)."""
        if value is None or isinstance(value, StrideOption):
            return value
        match = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\w+))?\s*", str(value))
        if not match or int(match[1]) < 1 or (match[2] or "overlap") not in STRIDE_MODES:
            raise ValueError(f"stride {value!r}: give pixels per feature cell, optionally with "
                             f"a mode, e.g. 8, '8-overlap' or '8-upsample' ({STRIDE_MODES})")
        return cls(int(match[1]), match[2] or "overlap")

    def __str__(self) -> str:
        return f"{self.stride}-{self.mode}"


class Attention(nn.Module):
    """Multi-head self-attention with one ``qkv`` projection (timm/DINO layout)."""

    def __init__(self, dim: int, heads: int) -> None:
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, dim * 3)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        b, n, d = x.shape
        q, k, v = self.qkv(x).reshape(b, n, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        out = F.scaled_dot_product_attention(q, k, v)
        return self.proj(out.transpose(1, 2).reshape(b, n, d))


class LayerScale(nn.Module):
    """Per-channel scale of a residual branch (DINOv2's ``ls1``/``ls2``; ones otherwise)."""

    def __init__(self, dim: int) -> None:
        super().__init__()
        self.gamma = nn.Parameter(torch.ones(dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        return x * self.gamma


class Mlp(nn.Module):
    """Two linear layers with an exact GELU between them."""

    def __init__(self, dim: int, hidden: int) -> None:
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden)
        self.fc2 = nn.Linear(hidden, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        return self.fc2(F.gelu(self.fc1(x)))


class Block(nn.Module):
    """Pre-norm transformer block: ``x + ls1(attn(norm1 x))``, then ``+ ls2(mlp(norm2 x))``."""

    def __init__(self, dim: int, heads: int) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=LN_EPS)
        self.attn = Attention(dim, heads)
        self.ls1 = LayerScale(dim)
        self.norm2 = nn.LayerNorm(dim, eps=LN_EPS)
        self.mlp = Mlp(dim, dim * MLP_RATIO)
        self.ls2 = LayerScale(dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        x = x + self.ls1(self.attn(self.norm1(x)))
        return x + self.ls2(self.mlp(self.norm2(x)))


class PatchEmbed(nn.Module):
    """Patches to tokens: one convolution (kernel = patch, stride = patch or smaller)."""

    def __init__(self, patch: int, dim: int) -> None:
        super().__init__()
        self.proj = nn.Conv2d(3, dim, patch, stride=patch)


class VisionTransformer(nn.Module):
    """A ViT with named block outputs as stride-``s`` feature maps.

    Args:
        arch: One of :data:`VIT_SPECS`.
        stride: A :class:`StrideOption` (or its text), or None for the patch size.

    Example:
        >>> net = VisionTransformer("vit_small_patch14").eval()
        >>> net.forward_features(torch.zeros(1, 3, 56, 70), "block12").shape
        torch.Size([1, 384, 4, 5])
    """

    def __init__(self, arch: str = "vit_small_patch14", *,
                 stride: int | str | StrideOption | None = None) -> None:
        super().__init__()
        if arch not in VIT_SPECS:
            raise ValueError(f"unknown ViT architecture {arch!r}; valid: {list(VIT_SPECS)}")
        self.spec = spec = VIT_SPECS[arch]
        self.stride_option = StrideOption.parse(stride)
        if self.stride_option is not None and self.stride_option.stride > spec.patch:
            raise ValueError(f"stride {self.stride_option.stride} of {arch} exceeds its patch "
                             f"size {spec.patch}; give a stride <= {spec.patch}")
        device = torch.empty(0).device  # "meta" when probing shapes
        with torch.device("meta"):  # allocate once, initialise once (below)
            self.cls_token = nn.Parameter(torch.zeros(1, 1, spec.dim))
            self.pos_embed = nn.Parameter(torch.zeros(1, 1 + spec.pos_grid ** 2, spec.dim))
            if spec.registers:
                self.register_tokens = nn.Parameter(torch.zeros(1, spec.registers, spec.dim))
            self.patch_embed = PatchEmbed(spec.patch, spec.dim)
            self.blocks = nn.ModuleList(Block(spec.dim, spec.heads) for _ in range(spec.depth))
            self.norm = nn.LayerNorm(spec.dim, eps=LN_EPS)
        self.to_empty(device=device)
        if device.type != "meta":
            self._init_weights()
        self._frozen_positions: tuple[tuple[int, int], torch.Tensor] | None = None

    def _init_weights(self) -> None:
        """The usual random ViT initialisation.

        Linear weights and position embedding ~ N(0, 0.02^2) (timm's
        ``trunc_normal_(std=.02)`` truncates at +-2, i.e. never), zero biases, class token and
        registers ~ N(0, 1e-6^2), unit norms and layer scales, the patch convolution as
        torch's default (uniform, bound ``1/sqrt(fan_in)``).
        """
        nn.init.normal_(self.pos_embed, std=0.02)
        nn.init.normal_(self.cls_token, std=1e-6)
        if self.spec.registers:
            nn.init.normal_(self.register_tokens, std=1e-6)
        bound = 1 / math.sqrt(3 * self.spec.patch ** 2)
        nn.init.uniform_(self.patch_embed.proj.weight, -bound, bound)
        nn.init.uniform_(self.patch_embed.proj.bias, -bound, bound)
        for m in self.modules():
            if isinstance(m, nn.Linear):
                nn.init.normal_(m.weight, std=0.02)
                nn.init.zeros_(m.bias)
            elif isinstance(m, nn.LayerNorm):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)
            elif isinstance(m, LayerScale):
                nn.init.ones_(m.gamma)

    @property
    def embed_stride(self) -> int:
        """Stride of the patch embedding convolution."""
        option = self.stride_option
        return option.stride if option is not None and option.mode == "overlap" else self.spec.patch

    def layer_channels(self, layer: str) -> int:
        """Channels of every block's map: the embedding width."""
        self._block_index(layer)
        return self.spec.dim

    def layer_stride(self, layer: str) -> int:
        """Pixels per feature cell of ``layer`` (the patch size, or the stride option's)."""
        self._block_index(layer)
        return self.spec.patch if self.stride_option is None else self.stride_option.stride

    def required_prefixes(self, layer: str) -> tuple[str, ...]:
        """The whole encoder: a ViT checkpoint must fit every block, whatever the layer.

        ``register_tokens`` even without registers: a ``_reg4`` file is refused, not run
        without its registers.
        """
        self._block_index(layer)
        return ("cls_token", "pos_embed", "register_tokens", "patch_embed.", "blocks.", "norm.")

    def _block_index(self, layer: str) -> int:
        if layer not in self.spec.layers:
            raise ValueError(f"unknown {self.spec.name} layer {layer!r}; valid: block1 .. "
                             f"block{self.spec.depth} (the k-th block's output)")
        return int(layer.removeprefix("block"))

    def token_grid(self, height: int, width: int) -> tuple[int, int]:
        """Rows and columns of patch tokens of a ``height`` x ``width`` input."""
        step = self.embed_stride
        return math.ceil(height / step), math.ceil(width / step)

    def map_extent(self, height: int, width: int) -> tuple[int, int]:
        """Pixels from the top-left the feature map spans: whole patches (or stride cells).

        ``stride="8-upsample"`` resizes the native map, so it spans the native patches.
        """
        option = self.stride_option
        step = option.stride if option is not None and option.mode == "overlap" \
            else self.spec.patch
        return math.ceil(height / step) * step, math.ceil(width / step) * step

    @contextlib.contextmanager
    def frozen_positions(self, height: int, width: int) -> Iterator[None]:
        """Within: the position embedding of ``height`` x ``width`` inputs is a constant.

        For export: a traced graph then holds the resized embedding itself instead of the
        bicubic resize of the trained one, which OpenVINO constant-folds when it compiles
        (measured: 232 s for a 76 x 136 grid, ViT-S/8 at 1088 x 608, vs 1.2 s).
        """
        grid = self.token_grid(height, width)
        with torch.inference_mode(False), torch.no_grad():
            self._frozen_positions = (grid, self.position_embedding(*grid).detach().clone())
        try:
            yield
        finally:
            self._frozen_positions = None

    def position_embedding(self, grid_h: int, grid_w: int) -> torch.Tensor:
        """Position embedding ``(1, 1 + grid_h * grid_w, dim)`` of a token grid.

        The class position, then the patch grid resized bicubically from the trained grid
        (unchanged when the sizes agree; a constant within :meth:`frozen_positions`).
        """
        frozen = self._frozen_positions
        if frozen is not None and frozen[0] == (grid_h, grid_w):
            return frozen[1]
        side = self.spec.pos_grid
        cls_pos, patch_pos = self.pos_embed[:, :1], self.pos_embed[:, 1:]
        if (grid_h, grid_w) != (side, side):
            grid = patch_pos.reshape(1, side, side, -1).permute(0, 3, 1, 2)
            grid = F.interpolate(grid, size=(grid_h, grid_w), mode="bicubic", align_corners=False)
            patch_pos = grid.permute(0, 2, 3, 1).reshape(1, grid_h * grid_w, -1)
        return torch.cat([cls_pos, patch_pos], 1)

    def tokens(self, x: torch.Tensor) -> tuple[torch.Tensor, int, int]:
        """Image ``(B, 3, H, W)`` -> tokens ``(B, 1 + registers + h * w, dim)``, ``h``, ``w``.

        The image is zero-padded so that the patches at stride ``s`` cover it with
        ``ceil(H / s)`` rows; overlapping patches are centred on their stride-``s`` cell.
        """
        patch, step = self.spec.patch, self.embed_stride
        height, width = x.shape[-2:]
        grid_h, grid_w = self.token_grid(height, width)
        lead = (patch - step) // 2
        pad_h = (grid_h - 1) * step + patch - height - lead
        pad_w = (grid_w - 1) * step + patch - width - lead
        x = F.pad(x, (lead, pad_w, lead, pad_h))
        t = F.conv2d(x, self.patch_embed.proj.weight, self.patch_embed.proj.bias, stride=step)
        t = t.flatten(2).transpose(1, 2)
        t = torch.cat([self.cls_token.expand(t.shape[0], -1, -1), t], 1)
        t = t + self.position_embedding(grid_h, grid_w)
        if self.spec.registers:
            regs = self.register_tokens.expand(t.shape[0], -1, -1)
            t = torch.cat([t[:, :1], regs, t[:, 1:]], 1)
        return t, grid_h, grid_w

    def forward_features(self, x: torch.Tensor, layer: str = "block12") -> torch.Tensor:
        """Run the network up to ``layer`` and return that feature map."""
        return self.forward_layers(x, (layer,))[0]

    def forward_layers(self, x: torch.Tensor, layers: tuple[str, ...]) -> list[torch.Tensor]:
        """Run the blocks once, up to the deepest of ``layers``; their normed patch-token maps."""
        wanted = {self._block_index(layer) for layer in layers}
        height, width = x.shape[-2:]
        t, grid_h, grid_w = self.tokens(x)
        skip = 1 + self.spec.registers
        out = {}
        for k, block in enumerate(self.blocks[: max(wanted)], start=1):
            t = block(t)
            if k in wanted:
                fmap = self.norm(t[:, skip:]).transpose(1, 2)
                out[k] = fmap.reshape(x.shape[0], self.spec.dim, grid_h, grid_w)
        maps = [out[self._block_index(layer)] for layer in layers]
        option = self.stride_option
        if option is not None and option.mode == "upsample":
            size = (math.ceil(height / option.stride), math.ceil(width / option.stride))
            maps = [F.interpolate(m, size=size, mode="bilinear", align_corners=False)
                    for m in maps]
        return maps


def infer_vit_arch(state: Mapping[str, torch.Tensor]) -> str | None:
    """The ViT architecture of timm-layout keys.

    Width and patch from ``patch_embed.proj.weight``, depth from the ``blocks.<i>`` keys,
    registers from ``register_tokens``. None when no :data:`VIT_SPECS` entry matches.
    """
    proj = state.get("patch_embed.proj.weight")
    if proj is None or proj.ndim != 4 or proj.shape[-1] != proj.shape[-2]:
        return None
    depth = 1 + max((int(k.split(".")[1]) for k in state
                     if k.startswith("blocks.") and k.split(".")[1].isdigit()), default=-1)
    regs = state.get("register_tokens")
    registers = 0 if regs is None else int(regs.shape[1])
    for spec in VIT_SPECS.values():
        if (spec.dim, spec.patch, spec.depth, spec.registers) == (
                proj.shape[0], proj.shape[-1], depth, registers):
            return spec.name
    return None

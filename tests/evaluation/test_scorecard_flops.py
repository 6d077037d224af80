"""The GFLOP table of the scorecard's first ETA agrees with the networks' own count."""

from __future__ import annotations

import pytest
import torch

from unitrack_env.agents.appearance.architectures import (
    DEFAULT_LAYERS,
    build_network,
    network_gflops,
)
from unitrack_env.agents.appearance.vit import VIT_SPECS
from unitrack_env.agents.appearance.weights import DEFAULT_WEIGHT_LOADERS, resolve_weights
from unitrack_env.evaluation.scorecard.eta import LITE0_GFLOP_PER_MP, megapixel_gflops
from unitrack_env.evaluation.scorecard.flops import (
    CNN_MACS,
    DEFAULT_CNN_LAYERS,
    NAMED_ARCHS,
    REFERENCE_SIZE,
    estimated_megapixel_gflops,
    reference_macs,
    vit_shape,
)
from unitrack_env.evaluation.scorecard.plan import TASKS


def _counted(arch: str, layer: str, stride: str | None = None) -> float:
    """``network_gflops`` at the reference size, on the meta device (shapes only: cheap)."""
    with torch.device("meta"):
        module = build_network(arch, tuple(layer.split("+")), 0, stride)
        return network_gflops(module, tuple(layer.split("+")),
                              [(REFERENCE_SIZE, REFERENCE_SIZE)])[0]


@pytest.mark.parametrize("arch", list(CNN_MACS))
def test_every_cnn_entry_is_the_networks_own_count(arch):
    for layer in CNN_MACS[arch]:
        assert 2e-9 * reference_macs(arch, layer)[0] == pytest.approx(_counted(arch, layer),
                                                                     rel=1e-12), layer


# Every size, patch and register option (the closed form is per block: one depth each, and
# block1 once), and the stride options (overlap adds tokens, upsample does not).
VITS = [("vit_small_patch8", "block12", None), ("vit_small_patch14_reg4", "block12", None),
        ("vit_base_patch16", "block12", None), ("vit_base_patch8_reg4", "block12", None),
        ("vit_large_patch14", "block24", None), ("vit_large_patch16_reg4", "block24", None),
        ("vit_small_patch16", "block1", None), ("vit_small_patch16", "block12", "8"),
        ("vit_base_patch14_reg4", "block3+block12", "7-overlap"),
        ("vit_small_patch8", "block12", "4-upsample")]


def test_the_vit_closed_form_is_the_networks_own_count():
    for arch, layer, stride in VITS:
        pixels, pixels2 = reference_macs(arch, layer, stride)
        assert 2e-9 * (pixels + pixels2) == pytest.approx(_counted(arch, layer, stride),
                                                          rel=1e-12), (arch, layer, stride)


def test_named_weights_and_default_layers_are_the_models():
    assert set(NAMED_ARCHS) == set(DEFAULT_WEIGHT_LOADERS)
    for name, arch in NAMED_ARCHS.items():
        assert resolve_weights(name).arch == arch
    assert DEFAULT_CNN_LAYERS == {a: DEFAULT_LAYERS[a] for a in CNN_MACS}
    for arch in VIT_SPECS:  # the ViT default, the last block, is implied
        assert reference_macs(arch, None) == reference_macs(arch, DEFAULT_LAYERS[arch])


def test_every_vit_is_read_from_its_name_as_the_network_builds_it():
    for arch, spec in VIT_SPECS.items():
        parsed = vit_shape(arch)
        assert parsed == (spec.dim, spec.patch, spec.registers, spec.depth), arch


def test_the_estimate_per_task_is_what_the_scorecard_counts_later():
    tasks = list(TASKS)
    with torch.device("meta"):
        module = build_network("vit_small_patch16", ("block12",), 0, "8")
        counted = megapixel_gflops(module, ("block12",), tasks)
    estimated = estimated_megapixel_gflops("random", "vit_small_patch16", None, "8", tasks)
    assert estimated == pytest.approx(counted, rel=1e-12)
    assert estimated_megapixel_gflops("imagenet-lite0", None, None, None, ["sot"])["sot"] == \
        pytest.approx(LITE0_GFLOP_PER_MP, abs=0.1)


def test_unknown_architectures_fall_back_to_lite0():
    for weights, arch, layer in (("mine.pth", None, None), ("random", "resnet18", "layer1"),
                                 ("imagenet-lite0", None, "stage9")):
        assert estimated_megapixel_gflops(weights, arch, layer, None, ["vos"]) == \
            {"vos": LITE0_GFLOP_PER_MP}

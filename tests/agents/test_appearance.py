import math

import cv2
import numpy as np
import pytest
import torch

from unitrack_env.agents.appearance import (
    DEFAULT_WEIGHT_LOADERS,
    AppearanceModel,
    EfficientNetLite0,
    ResNet,
    letterbox,
)
from unitrack_env.agents.appearance.efficientnet_lite import (
    LITE0_CROP_FRACTION,
    LITE0_INPUT_SIZE,
    LITE0_MEAN,
    LITE0_STD,
)

skimage_data = pytest.importorskip("skimage.data")

IMAGENET_CAT_CLASSES = range(281, 286)  # tabby, tiger cat, Persian, Siamese, Egyptian cat
IMAGENET_COFFEE_CLASSES = (967, 968)  # espresso, cup


@pytest.fixture(scope="module")
def lite0() -> AppearanceModel:
    return AppearanceModel()


def _classification_input(image: np.ndarray) -> torch.Tensor:
    """Resize the short side to 224 / 0.875 (bicubic), centre-crop 224, normalise."""
    short = round(LITE0_INPUT_SIZE / LITE0_CROP_FRACTION)
    h, w = image.shape[:2]
    s = short / min(h, w)
    image = cv2.resize(image, (round(w * s), round(h * s)), interpolation=cv2.INTER_CUBIC)
    h, w = image.shape[:2]
    y0, x0 = (h - LITE0_INPUT_SIZE) // 2, (w - LITE0_INPUT_SIZE) // 2
    crop = image[y0:y0 + LITE0_INPUT_SIZE, x0:x0 + LITE0_INPUT_SIZE]
    x = torch.from_numpy(crop).permute(2, 0, 1).float().div(255)[None]
    mean = torch.tensor(LITE0_MEAN).view(1, 3, 1, 1)
    std = torch.tensor(LITE0_STD).view(1, 3, 1, 1)
    return (x - mean) / std


def test_default_weights_classify_cat_and_coffee() -> None:
    # The native-stride network (stage3 output) holds the same, fully loaded weights; its
    # classifier is the one the weights were trained with.
    model = AppearanceModel(layer="stage3")
    net = model.module
    assert isinstance(net, EfficientNetLite0) and not net.stride8
    assert model.load_report is not None and len(model.load_report.matched) == 296
    batch = torch.cat([
        _classification_input(skimage_data.chelsea()),
        _classification_input(skimage_data.coffee()),
    ])
    with torch.inference_mode():
        probs = net(batch).softmax(dim=1)
    cat, coffee = probs
    assert int(cat.argmax()) in IMAGENET_CAT_CLASSES
    assert float(cat[list(IMAGENET_CAT_CLASSES)].sum()) > 0.8
    assert int(coffee.argmax()) in IMAGENET_COFFEE_CLASSES
    assert float(coffee[list(IMAGENET_COFFEE_CLASSES)].sum()) > 0.8


def test_default_model_is_the_offline_lite0(lite0: AppearanceModel) -> None:
    assert lite0.identity.arch == "efficientnet-lite0"
    assert lite0.identity.layer == "stage5"
    assert lite0.identity.weights == "imagenet-lite0"
    assert lite0.channels == 112 and lite0.stride == 8
    assert lite0.module.stride8  # stage4's stride set to 1
    assert lite0.mean == LITE0_MEAN and lite0.std == LITE0_STD
    report = lite0.load_report
    assert report is not None and report.complete
    assert len(report.matched) == len(lite0.module.state_dict())
    assert not report.missing and not report.unexpected
    assert "imagenet-lite0" in DEFAULT_WEIGHT_LOADERS
    assert lite0.describe()["digest"] == lite0.identity.digest


@pytest.mark.parametrize("height,width", [(37, 53), (64, 96), (41, 8)])
def test_feature_maps_have_stride_8(lite0: AppearanceModel, height: int, width: int) -> None:
    image = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
    expected = (math.ceil(height / 8), math.ceil(width / 8))
    out = lite0.features(image)
    assert out.shape == (1, 112, *expected) and out.dtype == torch.float32
    native = AppearanceModel(layer="stage3")
    assert not native.module.stride8
    assert native.features(image).shape == (1, 40, *expected)
    for arch, channels in (("resnet18", 256), ("resnet50", 1024)):
        model = AppearanceModel("random", arch=arch)
        assert model.features(image).shape == (1, channels, *expected)
    assert model.feature_shape(height, width) == (1024, *expected)


def test_layer4_and_later_efficientnet_stages_keep_stride_8() -> None:
    image = np.zeros((64, 80, 3), np.uint8)
    r18 = AppearanceModel("random", arch="resnet18", layer="layer4")
    assert r18.features(image).shape == (1, 512, 8, 10)
    head = AppearanceModel(layer="head")
    assert head.module.stride8
    assert head.features(image).shape == (1, 1280, 8, 10)
    assert head.load_report is not None and head.load_report.complete


@pytest.mark.parametrize("arch,layer", [("resnet18", "layer1"), ("efficientnet-lite0", "stage2")])
def test_layers_that_are_not_stride_8_are_refused(arch: str, layer: str) -> None:
    weights = "random" if arch.startswith("resnet") else "imagenet-lite0"
    with pytest.raises(ValueError, match="stride"):
        AppearanceModel(weights, arch=arch, layer=layer)


def test_hypercolumn_is_the_normalised_layers_side_by_side(lite0: AppearanceModel) -> None:
    image = np.random.default_rng(4).integers(0, 255, (64, 80, 3), dtype=np.uint8)
    both = AppearanceModel(layer="stage3+stage5")
    assert both.layers == ("stage3", "stage5") and both.channels == 40 + 112
    assert both.identity.layer == "stage3+stage5"  # feature caches keep them apart
    stage3 = AppearanceModel(layer="stage3").features(image)
    stage5 = lite0.features(image)
    feats = both.features(image)
    unit = torch.nn.functional.normalize
    torch.testing.assert_close(feats[:, :40], unit(stage3, dim=1) / math.sqrt(2))
    torch.testing.assert_close(feats[:, 40:], unit(stage5, dim=1) / math.sqrt(2))
    torch.testing.assert_close(feats.norm(dim=1), torch.ones(1, 8, 10))
    r18 = AppearanceModel("random", layer="layer2+layer3")
    assert r18.features(image).shape == (1, 128 + 256, 8, 10)
    for bad in ("stage3+", "stage5+stage5", "stage2+stage5"):
        with pytest.raises(ValueError, match="layer"):
            AppearanceModel(layer=bad)


def test_input_forms_agree(lite0: AppearanceModel) -> None:
    rng = np.random.default_rng(1)
    images = [rng.integers(0, 256, (24, 40, 3), dtype=np.uint8) for _ in range(2)]
    from_list = lite0.features(images)
    from_array = lite0.features(np.stack(images))
    single = lite0.features(images[1])
    normalised = lite0.preprocess(images)
    from_tensor = lite0.features(normalised)
    assert from_list.shape == (2, 112, 3, 5)
    torch.testing.assert_close(from_list, from_array)
    torch.testing.assert_close(from_list, from_tensor)
    torch.testing.assert_close(from_list[1:], single, atol=1e-5, rtol=1e-4)
    # Normalisation is (rgb / 255 - mean) / std.
    expected = (images[0][0, 0] / 255.0 - np.array(LITE0_MEAN)) / np.array(LITE0_STD)
    np.testing.assert_allclose(normalised[0, :, 0, 0].numpy(), expected, rtol=1e-5)


def test_bad_inputs_are_explained(lite0: AppearanceModel) -> None:
    with pytest.raises(ValueError, match="same size"):
        lite0.features([np.zeros((8, 8, 3), np.uint8), np.zeros((16, 8, 3), np.uint8)])
    with pytest.raises(ValueError, match="uint8 or float32"):
        lite0.features(np.zeros((8, 8, 3), np.float64))
    with pytest.raises(ValueError, match="uint8"):
        lite0.features(np.zeros((8, 8), np.uint8))


def test_float32_pixel_values_are_the_uint8_image(lite0: AppearanceModel) -> None:
    """The SOT heads' exact crops are float32 pixel values: integral ones give the uint8
    image's features, and the caller's array is left as it was (not normalised in place)."""
    image = np.random.default_rng(5).integers(0, 256, (2, 24, 40, 3), dtype=np.uint8)
    pixels = image.astype(np.float32)
    assert torch.equal(lite0.features(pixels), lite0.features(image))
    np.testing.assert_array_equal(pixels, image)


def test_num_threads_is_applied_only_during_the_pass() -> None:
    before = torch.get_num_threads()
    model = AppearanceModel("random", num_threads=1)
    seen = []
    original = model.module.forward_layers

    def spy(x: torch.Tensor, layers: tuple[str, ...]) -> list[torch.Tensor]:
        seen.append(torch.get_num_threads())
        return original(x, layers)

    model.module.forward_layers = spy  # type: ignore[method-assign]
    model.features(np.zeros((16, 16, 3), np.uint8))
    assert seen == [1]
    assert torch.get_num_threads() == before
    with pytest.raises(ValueError, match="num_threads"):
        AppearanceModel("random", num_threads=0)


def test_random_init_is_seeded_and_leaves_global_rng_alone() -> None:
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    a = AppearanceModel("random", seed=7)
    after = torch.rand(3)
    torch.testing.assert_close(after, expected)
    b = AppearanceModel("random", seed=7)
    c = AppearanceModel("random", seed=8)
    assert a.identity.arch == "resnet18"  # the paper's random baseline
    assert a.load_report is None
    assert a.identity.digest == b.identity.digest != c.identity.digest
    image = np.random.default_rng(2).integers(0, 256, (32, 32, 3), dtype=np.uint8)
    torch.testing.assert_close(a.features(image), b.features(image))


def test_user_normalisation_and_unknown_weights() -> None:
    model = AppearanceModel("random", mean=(0.1, 0.2, 0.3), std=(1.0, 1.0, 1.0))
    assert model.mean == (0.1, 0.2, 0.3)
    assert model.identity.key() != AppearanceModel("random").identity.key()
    with pytest.raises(ValueError, match="imagenet-lite0"):
        AppearanceModel("no-such-weights")
    with pytest.raises(ValueError, match="arch"):
        AppearanceModel(arch="resnet18")  # lite0 weights do not fit a ResNet
    with pytest.raises(ValueError, match="unknown arch"):
        AppearanceModel("random", arch="vgg16")


def test_torchvision_weights_need_torchvision() -> None:
    try:
        import torchvision  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="torchvision"):
            AppearanceModel("torchvision:ResNet18_Weights.IMAGENET1K_V1")
    else:  # pragma: no cover - torchvision is not installed in this project's environment
        pytest.skip("torchvision is installed; its download path is not exercised offline")


def test_letterbox_keeps_aspect_and_maps_boxes() -> None:
    image = np.zeros((1080, 1920, 3), np.uint8)
    image[100:300, 400:500] = 255  # a white block: x 400..500, y 100..300
    lb = letterbox(image)
    assert lb.image.shape == (608, 1088, 3)
    ratio = 608 / 1080
    assert lb.scale == pytest.approx((round(1920 * ratio) / 1920, ratio))
    assert lb.offset == ((1088 - round(1920 * ratio)) // 2, 0)
    assert (lb.image[:, : lb.offset[0]] == 128).all()  # padding
    box = np.array([[400, 100, 500, 300]], float)
    x1, y1, x2, y2 = lb.boxes_to_input(box)[0]
    inner = lb.image[int(y1) + 2:int(y2) - 2, int(x1) + 2:int(x2) - 2]
    assert inner.min() > 200  # the block lands where the box says
    assert lb.image[int(y2) + 3, int(x1):int(x2)].max() < 50
    np.testing.assert_allclose(lb.boxes_to_frame(lb.boxes_to_input(box)), box)
    np.testing.assert_allclose(lb.boxes_to_features(box), lb.boxes_to_input(box) / 8)
    tall = letterbox(np.zeros((400, 100, 3), np.uint8))
    assert tall.image.shape == (608, 1088, 3) and tall.offset == ((1088 - 152) // 2, 0)
    with pytest.raises(ValueError, match="uint8"):
        letterbox(np.zeros((10, 10), np.uint8))


def test_architectures_in_torchvision_layout() -> None:
    r18 = ResNet("resnet18").state_dict()
    assert "layer3.0.downsample.0.weight" in r18 and "fc.weight" in r18
    assert r18["conv1.weight"].shape == (64, 3, 7, 7)
    assert len(r18) == 122  # torchvision's resnet18 state dict has 122 entries
    assert len(ResNet("resnet50").state_dict()) == 320  # and resnet50 320
    r50 = ResNet("resnet50")
    assert sum(p.numel() for p in r50.parameters()) == 25_557_032  # torchvision R50 params
    assert sum(p.numel() for p in ResNet("resnet18").parameters()) == 11_689_512
    assert sum(p.numel() for p in EfficientNetLite0().parameters()) == 4_652_008


def test_letterbox_layout_matches_letterbox_geometry():
    from unitrack_env.agents.appearance import letterbox, letterbox_layout

    for shape in ((1080, 1920, 3), (480, 640, 3), (100, 37, 3)):
        full = letterbox(np.zeros(shape, np.uint8))
        layout = letterbox_layout(shape[0], shape[1])
        assert layout.image is None
        assert (layout.scale, layout.offset, layout.original_size) == (
            full.scale, full.offset, full.original_size)


@pytest.mark.parametrize("arch", ["efficientnet-lite0", "resnet18", "vit_small_patch14"])
def test_network_gflops_agree_with_torchs_flop_counter(arch: str) -> None:
    from torch.utils.flop_counter import FlopCounterMode

    from unitrack_env.agents.appearance.architectures import network_gflops
    from unitrack_env.agents.appearance.vit import Attention
    from unitrack_env.agents.appearance.weights import load_weights

    loaded = load_weights("random", arch=arch)
    sizes = [(224, 224), (448, 448)]
    ours = network_gflops(loaded.module, loaded.layers, sizes)
    blocks = [m.proj.in_features for m in loaded.module.modules() if isinstance(m, Attention)]
    for (height, width), count in zip(sizes, ours, strict=True):
        counter = FlopCounterMode(display=False)
        with counter, torch.no_grad():
            loaded.module.forward_layers(torch.zeros(1, 3, height, width), loaded.layers)
        # torch's counter skips the CPU's fused attention: 4 n^2 d per block (n tokens + CLS)
        tokens = height * width // 14**2 + 1
        attention = sum(4 * tokens**2 * dim for dim in blocks)
        expected = (counter.get_total_flops() + attention) / 1e9
        assert count == pytest.approx(expected, rel=0.01)

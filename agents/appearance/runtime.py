"""Compiled CPU runtimes for the appearance model: OpenVINO and ONNX Runtime.

:class:`~unitrack_env.agents.appearance.AppearanceModel` runs its network in eager torch by
default. With ``runtime="openvino"`` or ``"onnxruntime"`` the same network (any
architecture, layer or hypercolumn, with the loaded weights) is exported to ONNX once per
input size and run by that engine; preprocessing stays in torch and features come back as
torch tensors, so the heads see no difference (measured at 1088 x 608 on 2 threads: OpenVINO
~3.9x, ONNX Runtime ~2.6x eager torch, ``benchmarks/runtime.py``).

* Export: traced per input ``(H, W)`` (EfficientNet's "SAME" padding is size-specific) with
  a dynamic batch axis, cached atomically as ``<identity key>-<H>x<W>-<torch>.onnx`` in
  ``$UNITRACK_RUNTIME_CACHE`` (else ``$XDG_CACHE_HOME/unitrack_env/runtime``, else
  ``~/.cache/unitrack_env/runtime``); needs the package ``onnx``.
* Precision: float32. OpenVINO would pick bfloat16 by itself on AVX512-BF16 CPUs (2x faster,
  but features cosine ~0.9993); ``INFERENCE_PRECISION_HINT=f32`` is pinned (cosine 1.0000000).
* Threads: each engine gets the model's ``num_threads`` (no oversubscription).
* Choice: :func:`resolve_runtime` maps None to ``$UNITRACK_RUNTIME`` (default ``"auto"``) and
  ``"auto"`` to the fastest installed engine (``AUTO_ORDER``), torch on CUDA. An engine
  picked by ``"auto"`` is trusted per model and input size only once its features of a fixed
  input match torch's (cosine >= ``MIN_COSINE``; the verdict is stored beside the graph);
  a size that fails runs in torch, with a warning.
* Warm processes: compiled engines are kept per process, so a worker building the same model
  again neither re-exports nor recompiles; OpenVINO's blobs are cached on disk too.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from .cache_files import file_lock

TORCH: str = "torch"
OPENVINO: str = "openvino"
ONNXRUNTIME: str = "onnxruntime"
AUTO: str = "auto"

RUNTIMES: tuple[str, ...] = (TORCH, OPENVINO, ONNXRUNTIME)
"""Runtimes the appearance model can run on (plus ``"auto"``)."""

AUTO_ORDER: tuple[str, ...] = (OPENVINO, ONNXRUNTIME, TORCH)
"""Preference of ``runtime="auto"``: fastest first, as measured on the project's CPU
(``benchmarks/runtime.py``: EfficientNet-Lite0 stage5 at 1088 x 608, 2 threads)."""

RUNTIME_ENV: str = "UNITRACK_RUNTIME"
"""Environment variable read when no runtime is given (``runtime=None``)."""

CACHE_ENV: str = "UNITRACK_RUNTIME_CACHE"
"""Environment variable naming the directory of exported ONNX files."""

RUNTIME_EXTRAS: dict[str, str] = {OPENVINO: "openvino", ONNXRUNTIME: "onnxruntime"}
"""The ``unitrack-env`` extra that installs each optional runtime."""

ONNX_OPSET: int = 17
"""ONNX opset of the exported graphs."""

MIN_COSINE: float = 0.9999
"""Least cosine between a compiled runtime's and eager torch's features for ``"auto"`` to use
it (measured: OpenVINO and ONNX Runtime give 1.0000000 on every architecture here)."""

_ENGINES: dict[tuple[Any, ...], Any] = {}
"""Compiled engines of this process, kept across models (warm workers)."""

_IMPORT_NAMES: dict[str, tuple[str, ...]] = {
    OPENVINO: ("openvino", "onnx"), ONNXRUNTIME: ("onnxruntime", "onnx"), TORCH: (),
}


def runtime_installed(name: str) -> bool:
    """Whether the packages runtime ``name`` needs are importable (torch always is)."""
    if name not in _IMPORT_NAMES:
        raise ValueError(f"unknown runtime {name!r}; valid: {RUNTIMES}")
    return all(importlib.util.find_spec(module) is not None for module in _IMPORT_NAMES[name])


def available_runtimes() -> tuple[str, ...]:
    """The installed runtimes, in :data:`RUNTIMES` order."""
    return tuple(name for name in RUNTIMES if runtime_installed(name))


def resolve_runtime(name: str | None, device: torch.device | str = "cpu") -> str:
    """The concrete runtime for an option value.

    Args:
        name: ``"torch"``, ``"openvino"``, ``"onnxruntime"``, ``"auto"`` (the fastest
            installed, :data:`AUTO_ORDER`) or None (``$UNITRACK_RUNTIME``, default auto).
        device: The model's device; only torch runs on a non-CPU device.

    Raises:
        ValueError: Unknown name, or a compiled runtime asked for on a non-CPU device.
        ImportError: The named runtime is not installed (the message names the extra).
    """
    if name is None:
        name = os.environ.get(RUNTIME_ENV, "").strip() or AUTO
    device = torch.device(device)
    if name == AUTO:
        if device.type != "cpu":
            return TORCH
        return next(r for r in AUTO_ORDER if runtime_installed(r))
    if name not in RUNTIMES:
        raise ValueError(f"unknown runtime {name!r}; valid: {(*RUNTIMES, AUTO)} "
                         f"(or set ${RUNTIME_ENV})")
    if name != TORCH and device.type != "cpu":
        raise ValueError(f"runtime {name!r} runs on the CPU only; device is {device}; "
                         f"use runtime='torch' on {device.type}")
    if not runtime_installed(name):
        missing = [m for m in _IMPORT_NAMES[name] if importlib.util.find_spec(m) is None]
        raise ImportError(
            f"runtime={name!r} needs {', '.join(missing)}: pip install "
            f"'unitrack-env[{RUNTIME_EXTRAS[name]}]'"
        )
    return name


def is_auto(name: str | None) -> bool:
    """Whether the option value leaves the choice to :func:`resolve_runtime` (checked)."""
    if name is None:
        name = os.environ.get(RUNTIME_ENV, "").strip() or AUTO
    return name == AUTO


def default_cache_dir() -> Path:
    """Where exported ONNX graphs are kept (see the module docstring)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "unitrack_env" / "runtime"


class FeatureNetwork(nn.Module):
    """``images -> features`` as one module: the layers' maps, or their hypercolumn.

    Args:
        module: A backbone with ``forward_layers(x, layers)``.
        layers: The output layers (one, or the parts of a hypercolumn).
        combine: Turns the list of layer maps into the output map (the appearance model's
            hypercolumn rule).
    """

    def __init__(self, module: nn.Module, layers: tuple[str, ...],
                 combine: Callable[[list[torch.Tensor]], torch.Tensor]) -> None:
        super().__init__()
        self.module = module
        self.layers = layers
        self.combine = combine
        # the wrapper takes the backbone's mode: torch.onnx.export puts every submodule back
        # into the wrapper's mode afterwards (a fresh module is in training mode)
        self.train(module.training)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Normalised images ``(B, 3, H, W)`` -> features ``(B, C, h, w)``."""
        return self.combine(self.module.forward_layers(x, self.layers))

    def export_scope(self, height: int, width: int) -> contextlib.AbstractContextManager[Any]:
        """The context to trace one input size in: the backbone's ``frozen_positions``, if any.

        (A ViT's resized position embedding then enters the graph as a constant.)
        """
        frozen = getattr(self.module, "frozen_positions", None)
        return frozen(height, width) if frozen is not None else contextlib.nullcontext()


def export_onnx(network: nn.Module, height: int, width: int, path: Path) -> Path:
    """Export ``network`` for ``(B, 3, height, width)`` inputs (dynamic B) to ``path``.

    Written to a temporary file in the same folder and renamed, so concurrent processes
    exporting the same graph never see a partial file. An existing file is reused.
    """
    if path.is_file():
        return path
    if importlib.util.find_spec("onnx") is None:
        raise ImportError("exporting the appearance model needs the PyPI package 'onnx': "
                          "pip install 'unitrack-env[openvino]' (or [onnxruntime])")
    path.parent.mkdir(parents=True, exist_ok=True)
    example = torch.zeros(1, 3, height, width)
    handle, tmp = tempfile.mkstemp(prefix=path.stem, suffix=".onnx.tmp", dir=path.parent)
    os.close(handle)
    try:
        scope = getattr(network, "export_scope", None)
        with warnings.catch_warnings(), torch.inference_mode(False), torch.no_grad(), \
                (scope(height, width) if scope is not None else contextlib.nullcontext()):
            # Sizes computed in Python (SAME padding) trace as constants: intended, the
            # graph is per input size.
            warnings.simplefilter("ignore")
            torch.onnx.export(
                network, (example,), tmp, dynamo=False, opset_version=ONNX_OPSET,
                input_names=["images"], output_names=["features"],
                dynamic_axes={"images": {0: "batch"}, "features": {0: "batch"}},
            )
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
    return path


class CompiledBackbone:
    """A network exported to ONNX and run by a compiled engine, per input size.

    Args:
        runtime: ``"openvino"`` or ``"onnxruntime"``.
        network: The torch network (``images -> features``), in eval mode on the CPU.
        key: Identity key of the network (weights digest, layer, ...): part of file names.
        num_threads: Engine threads (None: ``torch.get_num_threads()`` now).
        cache_dir: Directory of exported graphs (None: :func:`default_cache_dir`).
        verify: Check each input size against eager torch once (``runtime="auto"``); a size
            whose features differ (cosine < :data:`MIN_COSINE`) runs in eager torch.

    Attributes:
        fallbacks: Input sizes ``(H, W)`` that failed the check and run in eager torch.
    """

    def __init__(self, runtime: str, network: nn.Module, key: str, *,
                 num_threads: int | None = None,
                 cache_dir: str | os.PathLike[str] | None = None, verify: bool = False) -> None:
        if runtime not in (OPENVINO, ONNXRUNTIME):
            raise ValueError(f"CompiledBackbone runs {OPENVINO!r} or {ONNXRUNTIME!r}, "
                             f"not {runtime!r}")
        self.runtime = runtime
        self.network = network
        self.key = key
        self.num_threads = num_threads or torch.get_num_threads()
        self.cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        self.verify = verify
        self.fallbacks: set[tuple[int, int]] = set()
        self._checked: set[tuple[int, int]] = set()

    def graph_path(self, height: int, width: int) -> Path:
        """The cached ONNX file of one input size."""
        version = torch.__version__.split("+")[0]
        return self.cache_dir / f"{self.key}-{height}x{width}-torch{version}.onnx"

    def _engine(self, shape: tuple[int, int, int, int]) -> Any:
        batch, _, height, width = shape
        path = self.graph_path(height, width)
        memo = (self.runtime, str(path), shape if self.runtime == OPENVINO else (height, width),
                self.num_threads)
        engine = _ENGINES.get(memo)
        if engine is None:
            export_onnx(self.network, height, width, path)
            # OpenVINO writes its blob cache unlocked: two pool workers compiling one model
            # at once failed with "cannot set permissions: No such file" on the blob.
            with file_lock(self.cache_dir / "openvino.lock"):
                engine = _ENGINES[memo] = _compile(self.runtime, path, shape, self.num_threads,
                                                   self.cache_dir / "openvino")
        return engine

    def _run(self, array: np.ndarray) -> torch.Tensor:
        engine = self._engine(tuple(array.shape))
        if self.runtime == OPENVINO:
            out = engine(array)[engine.outputs[0]]
        else:
            out = engine.run(None, {"images": array})[0]
        return torch.from_numpy(np.array(out, dtype=np.float32, copy=True))

    def check(self, height: int, width: int) -> float:
        """Cosine between this engine's and eager torch's features of a fixed input.

        Computed once per model and size; the verdict is stored beside the graph and read back
        afterwards. A size below :data:`MIN_COSINE` joins :attr:`fallbacks` (with a warning).
        """
        record = self.graph_path(height, width).with_suffix(f".{self.runtime}.check.json")
        try:
            cosine = float(json.loads(record.read_text())["cosine"])
        except (OSError, ValueError, KeyError, TypeError):
            generator = torch.Generator().manual_seed(0)
            x = torch.randn(1, 3, height, width, generator=generator)
            with torch.inference_mode():
                reference = self.network(x).float().flatten()
            ours = self._run(x.numpy()).flatten()
            cosine = float(torch.nn.functional.cosine_similarity(reference, ours, dim=0))
            text = json.dumps({"cosine": cosine, "min_cosine": MIN_COSINE,
                               "runtime": self.runtime, "size": [height, width]})
            with contextlib.suppress(OSError):
                _write_atomic(record, text)
        self._checked.add((height, width))
        if cosine < MIN_COSINE:
            self.fallbacks.add((height, width))
            warnings.warn(f"runtime {self.runtime!r} differs from torch on this model at "
                          f"{height}x{width} (feature cosine {cosine:.6f} < {MIN_COSINE}); "
                          "that size runs in eager torch", UserWarning, stacklevel=3)
        return cosine

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """Features of normalised images ``(B, 3, H, W)`` (float32 CPU tensor)."""
        size = (int(x.shape[2]), int(x.shape[3]))
        if self.verify and size not in self._checked:
            self.check(*size)
        if size in self.fallbacks:
            return self.network(x).float().contiguous()
        return self._run(np.ascontiguousarray(x.detach().to("cpu", torch.float32).numpy()))


def _compile(runtime: str, path: Path, shape: tuple[int, int, int, int], threads: int,
             blobs: Path) -> Any:
    """An engine for the graph at ``path``: OpenVINO for the full ``shape``, else ORT.

    OpenVINO keeps its compiled blobs in ``blobs`` (its model cache), so another process
    (a pool worker) loads them instead of compiling again.
    """
    if runtime == OPENVINO:
        # lazy: optional dependency (openvino)
        import openvino as ov

        core = ov.Core()
        with contextlib.suppress(Exception):  # an optional speed-up; compiling still works
            core.set_property({"CACHE_DIR": str(blobs)})
        model = core.read_model(str(path))
        model.reshape({model.inputs[0].any_name: ov.PartialShape(list(shape))})
        return core.compile_model(model, "CPU", {
            "INFERENCE_PRECISION_HINT": "f32",
            "PERFORMANCE_HINT": "LATENCY",
            "INFERENCE_NUM_THREADS": threads,
            # OpenVINO pins its threads, the caller's included, from core 0 up: two pool
            # workers of one thread each then share core 0 (measured: 2 workers ran at 1.05
            # cores). A library must not pin its user's threads.
            "ENABLE_CPU_PINNING": False,
        })
    # lazy: optional dependency (onnxruntime)
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def _write_atomic(path: Path, text: str) -> None:
    handle, tmp = tempfile.mkstemp(prefix=path.stem, suffix=".tmp", dir=path.parent)
    with os.fdopen(handle, "w") as stream:
        stream.write(text)
    os.replace(tmp, path)

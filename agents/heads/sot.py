"""The UniTrack SOT heads: box propagation with the shared appearance model.

Agents ``unitrack-xcorr`` (SiamFC cross-correlation, fixed first-frame template) and
``unitrack-dcf`` (DCFNet correlation filter with online update), both from
:class:`~unitrack_env.agents.primitives.box_propagation.BoxPropagator` (UniTrack paper, section 2.3
and appendix B.1). Per frame one backbone call: the three scale crops, plus, for the DCF head,
the previous frame's update crop (at the box found there), whose filter update is applied
before this frame's response, as if it had run last frame.

Boxes come and go in the environment's OTB convention: ``(x, y, w, h)`` with 1-based pixels
(the top-left pixel is ``(1, 1)``), converted to continuous coordinates by subtracting
``pixel_origin``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
import torch

from ..appearance.model import AppearanceModel, torch_threads
from ..appearance.spec import AppearanceSpec
from ..base import Agent
from ..primitives.box_propagation import (
    BoxPropagationConfig,
    BoxPropagator,
    BoxState,
)
from .vos import build_model

OTB_PIXEL_ORIGIN: float = 1.0
"""OTB boxes are 1-based: ``x - 1`` is the left edge in continuous 0-based coordinates."""


@dataclass(frozen=True)
class UniTrackSOTConfig(AppearanceSpec, BoxPropagationConfig):
    """Options of ``unitrack-xcorr`` / ``unitrack-dcf``, flat: ``name = default`` [paper].

    Appearance: weights, arch, layer, remap, device, runtime, stride, num_threads
    (:class:`AppearanceSpec`). Propagation (:class:`BoxPropagationConfig`, appendix B.1):
    ``crop_size = 520`` [520], ``context = 4.5`` [4.5], ``num_scales = 3`` [3],
    ``scale_step = 1.0275``, ``scale_penalty = 0.985``, ``min_size_factor = 0.2``,
    ``max_size_factor = 5.0``, ``feature_window = True`` [Hann], ``template_window = 1.5``
    (DCF's training window in target sizes; None: the crop's), ``template_size = 14``
    [XCorr 14 x 14], ``dcf_lambda = 1e-4``, ``dcf_interp = 0.01``, ``dcf_sigma_factor =
    0.1``, ``subpixel = True``. ``pixel_origin = 1.0``: the first pixel of boxes [OTB 1].
    The method is the agent's (``unitrack-xcorr`` or ``unitrack-dcf``), not an option.
    """

    method: str = field(default="dcf", init=False)
    pixel_origin: float = OTB_PIXEL_ORIGIN

    def propagation_config(self, method: str) -> BoxPropagationConfig:
        """The propagator's :class:`BoxPropagationConfig` for ``method``."""
        return BoxPropagationConfig(method=method, **{
            f.name: getattr(self, f.name) for f in fields(BoxPropagationConfig)
            if f.name != "method"})


class _UniTrackSOTAgent(Agent):
    """Shared body of the two SOT heads (``method`` set by the subclass)."""

    config_class = UniTrackSOTConfig

    method: str = "dcf"

    def __init__(self, *, appearance_model: AppearanceModel | None = None,
                 **options: Any) -> None:
        self.config = UniTrackSOTConfig.from_options(self.name, options)
        self.model = build_model(self.config, appearance_model)
        self.propagator = BoxPropagator(self.model.features,
                                        self.config.propagation_config(self.method),
                                        stride=self.model.stride)
        self._first_answer: np.ndarray | None = None

    def reset(self, observation: dict[str, Any], info: dict[str, Any]) -> None:
        """Initialise the template / filter on the first frame and ``init_box``."""
        x, y, w, h = (float(v) for v in np.asarray(observation["init_box"], np.float64))
        left, top = x - self.config.pixel_origin, y - self.config.pixel_origin
        with torch_threads(self.config.num_threads), torch.inference_mode():
            self.propagator.reset(observation["frame"],
                                  BoxState(left + w / 2, top + h / 2, w, h))
        self._first_answer = np.array([x, y, w, h], np.float32)

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """The box ``(x, y, w, h)`` (float32, 1-based pixels) of the current frame."""
        if self._first_answer is not None:  # the first step answers the reset frame
            answer, self._first_answer = self._first_answer, None
            return answer
        if self.propagator.state is None:
            raise RuntimeError("call reset() with the first observation before act()")
        with torch_threads(self.config.num_threads), torch.inference_mode():
            st = self.propagator.step(observation["frame"])
        origin = self.config.pixel_origin
        return np.array([st.cx - st.w / 2 + origin, st.cy - st.h / 2 + origin, st.w, st.h],
                        np.float32)


class UniTrackXCorrAgent(_UniTrackSOTAgent, name="unitrack-xcorr", tasks=("sot",)):
    """UniTrack SOT with the cross-correlation (SiamFC) head.

    Args:
        appearance_model: A ready model to share (then the model options are ignored).
        **options: Fields of :class:`UniTrackSOTConfig`.
    """

    method = "xcorr"


class UniTrackDCFAgent(_UniTrackSOTAgent, name="unitrack-dcf", tasks=("sot",)):
    """UniTrack SOT with the correlation-filter (DCFNet) head.

    Args:
        appearance_model: A ready model to share (then the model options are ignored).
        **options: Fields of :class:`UniTrackSOTConfig`.
    """

    method = "dcf"

"""What names an appearance model: one dataclass that every head's config extends.

The options stay flat (``--agent-arg weights=...``) while the model is built in one place.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    # lazy: start-up cost (torch, via .model)
    from .model import AppearanceModel

SpecT = TypeVar("SpecT", bound="AppearanceSpec")


@dataclass(frozen=True)
class AppearanceSpec:
    """The appearance model of a head.

    Fields are :class:`~unitrack_env.agents.appearance.model.AppearanceModel`'s arguments of
    the same names (``num_threads`` applies while the agent acts).
    """

    weights: str = "imagenet-lite0"
    arch: str | None = None
    layer: str | None = None
    remap: str = "auto"
    device: str = "cpu"
    num_threads: int | None = None
    runtime: str | None = None
    stride: int | str | None = None

    @classmethod
    def from_options(cls: type[SpecT], agent: str, options: Mapping[str, Any]) -> SpecT:
        """The config ``cls(**options)`` of ``agent``; TypeError lists the valid options."""
        try:
            return cls(**options)
        except TypeError as exc:
            valid = ", ".join(f.name for f in fields(cls))
            raise TypeError(f"{agent}: {exc}; valid options: {valid}") from None

    @classmethod
    def configure(
        cls: type[SpecT], agent: str, options: Mapping[str, Any],
        model: AppearanceModel | None = None,
    ) -> tuple[SpecT, AppearanceModel]:
        """A head's config and its model: ``model`` when shared, else built."""
        config = cls.from_options(agent, options)
        return config, model if model is not None else config.build()

    def appearance(self) -> AppearanceSpec:
        """This config's appearance fields alone (a plain :class:`AppearanceSpec`)."""
        return AppearanceSpec(**{f.name: getattr(self, f.name) for f in fields(AppearanceSpec)})

    def build(self, **extra: Any) -> AppearanceModel:
        """The :class:`AppearanceModel` this spec names (``extra``: further model options)."""
        # lazy: start-up cost (torch, via .model)
        from .model import AppearanceModel

        spec = self.appearance()
        return AppearanceModel(spec.weights, arch=spec.arch, layer=spec.layer, remap=spec.remap,
                               device=spec.device, num_threads=spec.num_threads,
                               runtime=spec.runtime, stride=spec.stride, **extra)

"""What every technique is: the :class:`Technique` protocol, and the registry the CLI and the plan look techniques
up in."""

from __future__ import annotations

from typing import ClassVar, Protocol

from warpsky.errors import UsageError
from warpsky.layer import Layer
from warpsky.resources import MemoryEstimate, WorkItem
from warpsky.scene.model import Scene


class Technique(Protocol):
    """A renderer of the scene's voxel media: built once per frame from its settings, it draws one :class:`Layer`.

    Capabilities are class attributes every technique declares:

    - ``traces_air``: the technique carries the atmosphere itself (as a participating medium, with the sun's disk),
      so no sky pass runs around its layer and its media see unreddened sunlight.
    - ``renders_layers``: the technique can run next to the stratiform pass (it renders the voxel media without the
      ground, which the lowest stratiform layer draws).
    - ``traces_layers`` (optional, default False): the technique traces the stratiform layers itself, voxelised
      (:mod:`warpsky.techniques.path_tracer.layer_media`), so no stratiform pass runs.
    """

    name: ClassVar[str]
    Settings: ClassVar[type]
    traces_air: ClassVar[bool]
    renders_layers: ClassVar[bool]
    settings: object
    device: str

    def resolved_settings(self, scene: Scene) -> object:
        """The settings with every ``auto`` value filled in for ``scene``; settings that hold no ``auto`` value are
        returned as they are."""
        ...

    def render(self, scene: Scene, width: int, height: int) -> Layer:
        """Render ``scene`` at ``width`` x ``height`` pixels (the camera conformed to that aspect ratio)."""
        ...

    def memory_estimate(self, scene: Scene, width: int, height: int) -> MemoryEstimate:
        """Bytes a render of ``scene`` at ``width`` x ``height`` allocates on the host and the device, by part, as
        an upper bound, without allocating anything (:mod:`warpsky.resources`)."""
        ...

    def work_estimate(self, scene: Scene, width: int, height: int) -> list[WorkItem]:
        """Worst-case kernel iterations of that render, by kind, with the settings that set them."""
        ...

#: The technique ``warpsky render`` uses unless told otherwise: exact single scattering plus denoised, path-traced
#: multiple scattering, rendered to a target error (``hybrid``). ``slicing`` is the interactive technique (Riley
#: 2004's half-angle slicing), ``single_scatter`` and ``path_tracer`` the references.
DEFAULT_TECHNIQUE = "hybrid"

_REGISTRY: dict[str, str] = {
    "single_scatter": "warpsky.techniques.single_scatter.technique:SingleScatter",
    "path_tracer": "warpsky.techniques.path_tracer.technique:PathTracer",
    "slicing": "warpsky.techniques.slicing.technique:Slicing",
    "hybrid": "warpsky.techniques.hybrid.technique:Hybrid",
}

def technique_names() -> list[str]:
    return sorted(_REGISTRY)

def technique_class(name: str) -> type[Technique]:
    """Import and return the technique class registered under ``name``."""
    import importlib

    try:
        target = _REGISTRY[name]
    except KeyError:
        raise UsageError(f"unknown technique {name!r}; available: {', '.join(technique_names())}") from None
    module_name, class_name = target.split(":")
    return getattr(importlib.import_module(module_name), class_name)

"""Every technique and pass warpsky knows, by name: the one place a new one is registered.

A technique (:class:`~warpsky.techniques.technique.Technique`) is registered under its name in :data:`TECHNIQUES`; a
pass (:class:`~warpsky.passes.render_pass.Pass`) joins :data:`PASSES`, the frame's passes in the order they run. Entries
are ``module:Class`` paths, imported on first use, so that importing the registry loads no kernels. Nothing else in
warpsky names a technique or a pass: the plan, the frame, the command line and the first-compile notice read the
registered classes' names, settings and capabilities.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Mapping

from warpsky.core.errors import UsageError

#: The technique ``warpsky render`` uses unless told otherwise: exact single scattering plus denoised, path-traced
#: multiple scattering, rendered to a target error (``hybrid``). ``slicing`` is the interactive technique (Riley
#: 2004's half-angle slicing), ``single_scatter`` and ``path_tracer`` the references.
DEFAULT_TECHNIQUE = "hybrid"

TECHNIQUES: dict[str, str] = {
    "single_scatter": "warpsky.techniques.single_scatter.single_scatter:SingleScatter",
    "path_tracer": "warpsky.techniques.path_tracer.path_tracer:PathTracer",
    "slicing": "warpsky.techniques.slicing.slicing:Slicing",
    "hybrid": "warpsky.techniques.hybrid.hybrid:Hybrid",
}

#: The passes of a frame in the order they run; the chosen technique runs in the ``media`` pass.
PASSES: tuple[str, ...] = (
    "warpsky.passes.surfaces.surfaces:SurfacesPass",
    "warpsky.passes.media:MediaPass",
    "warpsky.passes.stratiform.stratiform:StratiformPass",
    "warpsky.passes.deck.deck:DeckPass",
    "warpsky.passes.fog.fog:FogPass",
    "warpsky.passes.sky.sky:SkyPass",
)


def _load(target: str):
    module_name, class_name = target.split(":")
    return getattr(importlib.import_module(module_name), class_name)


def technique_names() -> list[str]:
    return sorted(TECHNIQUES)


def technique_class(name: str):
    """The technique class registered under ``name`` (imported on first use)."""
    try:
        target = TECHNIQUES[name]
    except KeyError:
        raise UsageError(f"unknown technique {name!r}; available: {', '.join(technique_names())}") from None
    return _load(target)


def technique_classes() -> list:
    """Every registered technique class, the default first."""
    return [technique_class(name) for name in [DEFAULT_TECHNIQUE, *(n for n in technique_names()
                                                                     if n != DEFAULT_TECHNIQUE)]]


@functools.cache
def _pass_classes(targets: tuple[str, ...]) -> tuple:
    return tuple(_load(target) for target in targets)


def pass_classes() -> tuple:
    """The registered pass classes, in the order a frame runs them."""
    return _pass_classes(PASSES)


def aov_components() -> dict[str, str]:
    """Every AOV some registered technique writes, name -> components (what a RenderVar may name besides the
    frame's own outputs)."""
    out: dict[str, str] = {}
    for cls in technique_classes():
        out.update(cls.aovs)
    return out


class AovComponents(Mapping):
    """:func:`aov_components` as a mapping that imports the techniques on first use: a stage without RenderProducts
    never reads it, and its frame loads only its own technique (each technique's module defines its kernels)."""

    @functools.cached_property
    def _all(self) -> dict[str, str]:
        return aov_components()

    def __getitem__(self, name: str) -> str:
        return self._all[name]

    def __iter__(self):
        return iter(self._all)

    def __len__(self) -> int:
        return len(self._all)


def aov_producers(name: str) -> list[str]:
    """Names of the registered techniques whose layers hold the AOV ``name``."""
    return [cls.name for cls in technique_classes() if name in cls.aovs]

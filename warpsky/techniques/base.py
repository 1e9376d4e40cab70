"""What every technique returns, and the registry the CLI and the plan look techniques up in."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from warpsky.errors import UsageError


@dataclass
class Layer:
    """One technique's image of what it renders, ready to composite front to back.

    Attributes:
        radiance: (H, W, 3) float32 radiance reaching the eye [sun irradiance units / sr].
        transmittance: (H, W, 3) float32 fraction of the light from behind the layer that passes through it
            (0 where an opaque surface such as the ground is hit).
        depth: (H, W) float32 representative camera-space depth along the view axis [m]: the opacity-weighted
            mean depth of what the layer shows; the camera's far clipping distance where it shows nothing.
        stats: Figures about the render (lookups, seconds, settings) for metadata and benchmarks.
        aovs: Extra per-pixel outputs by name, e.g. ``variance`` (H, W, 3) of a Monte Carlo pixel mean.
    """

    radiance: np.ndarray
    transmittance: np.ndarray
    depth: np.ndarray
    stats: dict = field(default_factory=dict)
    aovs: dict = field(default_factory=dict)


#: The technique ``warpsky render`` uses unless told otherwise: half-angle slicing (Riley 2004), one sweep with
#: multiple-scattering phase functions; ``single_scatter`` and ``path_tracer`` remain for comparison and reference.
DEFAULT_TECHNIQUE = "slicing"

_REGISTRY: dict[str, str] = {
    "single_scatter": "warpsky.techniques.single_scatter.technique:SingleScatter",
    "path_tracer": "warpsky.techniques.path_tracer.technique:PathTracer",
    "slicing": "warpsky.techniques.slicing.technique:Slicing",
}


def technique_names() -> list[str]:
    return sorted(_REGISTRY)


def technique_class(name: str):
    """Import and return the technique class registered under ``name``."""
    import importlib

    try:
        target = _REGISTRY[name]
    except KeyError:
        raise UsageError(f"unknown technique {name!r}; available: {', '.join(technique_names())}") from None
    module_name, class_name = target.split(":")
    return getattr(importlib.import_module(module_name), class_name)


def parse_settings(cls, values: dict[str, str] | None):
    """Build the settings dataclass ``cls`` from ``{name: text}`` pairs, converting each to its field's type."""
    values = dict(values or {})
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, text in values.items():
        if key not in fields:
            raise UsageError(f"unknown setting {key!r} for {cls.technique}; known: {', '.join(sorted(fields))}")
        if isinstance(text, str) and text.strip().lower() in ("", "auto", "none"):
            kwargs[key] = None
            continue
        try:
            kwargs[key] = float(text)
        except ValueError:
            raise UsageError(f"setting {key}: expected a number, got {text!r}") from None
    return cls(**kwargs)

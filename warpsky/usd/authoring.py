"""Authoring the warpsky attributes the shipped stages share (for the tools that write them)."""

from __future__ import annotations

from warpsky.model.scene import EARTH_AIR_ATTRIBUTES


def earth_air_lines(indent: str = "        ") -> str:
    """The Earth's air (:data:`~warpsky.model.scene.EARTH_AIR_ATTRIBUTES`) as ``.usda`` attribute lines, for a
    stage in metres."""
    lines = []
    for name, value in EARTH_AIR_ATTRIBUTES.items():
        if isinstance(value, tuple):
            colour = ", ".join(f"{v:.10g}" for v in value)
            lines.append(f"{indent}custom color3f warpsky:atmosphere:{name} = ({colour})")
        else:
            lines.append(f"{indent}custom float warpsky:atmosphere:{name} = {value:.10g}")
    return "\n".join(lines)


def author_earth_air(prim) -> None:
    """Author the Earth's air on the Usd ``prim`` (an atmosphere Scope of a stage in metres)."""
    from pxr import Gf, Sdf

    for name, value in EARTH_AIR_ATTRIBUTES.items():
        if isinstance(value, tuple):
            prim.CreateAttribute(f"warpsky:atmosphere:{name}", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))
        else:
            prim.CreateAttribute(f"warpsky:atmosphere:{name}", Sdf.ValueTypeNames.Float).Set(float(value))

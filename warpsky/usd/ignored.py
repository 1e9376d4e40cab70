"""What a stage holds that warpsky does not render, named in one ``warning:`` line per prim instead of left out
silently (a stage made for another renderer keeps its key light or its proxy spheres, and the TD should hear that
they are not in the picture).

Warned about, when visible (lights) or visible and of a rendered purpose (geometry):

- a ``DomeLight`` after the first visible one (only that one lights the scene);
- every other light: ``RectLight``, ``SphereLight``, ``DiskLight``, ``CylinderLight``, ``PortalLight``, ... (any
  prim with UsdLux's ``LightAPI`` but the ``DistantLight`` suns and the dome), and a ``Mesh`` with
  ``MeshLightAPI`` (its emission; the mesh itself renders as a surface);
- gprims other than ``Mesh``, ``Plane`` and ``Volume`` (``Cube``, ``Sphere``, ``Cylinder``, ``Cone``, ``Capsule``,
  ``Points``, ``BasisCurves``, ...), unless they carry a ``warpsky:kind``, and a ``Plane`` after the first (the
  first is the ground); a ``PointInstancer``.

Inside instances a prim is warned about once, at its first instance. Past :data:`WARNED_PER_TYPE` prims of one
type, the rest are counted in one line (a grid of a hundred spheres gives six lines, not a hundred). pxr is
imported inside the methods.
"""

from __future__ import annotations

from warpsky.usd.prims import StagePrims

#: Lines naming prims of one type; the rest of that type are counted in one more line.
WARNED_PER_TYPE = 5
#: What warpsky renders, for the messages.
RENDERED_LIGHTS = "DistantLight suns and the first visible DomeLight"
RENDERED_GEOMETRY = "Mesh surfaces, one ground Plane and Volumes"


class IgnoredReading(StagePrims):
    """The stage reader's warnings about prims it does not render."""

    def warn_ignored(self, time=None) -> None:
        """One ``warning:`` line (once per reader) for every prim at ``time`` that looks rendered but is not."""
        tc = self._time(time)
        first: dict[str, str] = {}  # "dome" / "plane" -> the path of the one that is used
        prototypes = set()
        named: dict[str, int] = {}  # prim type -> lines so far
        more: dict[str, list[str]] = {}  # prim type -> the paths past WARNED_PER_TYPE
        for prim in self._traverse():
            reason = self._light_reason(prim, tc, first) or self._geometry_reason(prim, tc, first)
            if reason is None:
                continue
            if prim.IsInstanceProxy():
                key = prim.GetPrimInPrototype().GetPath()
                if key in prototypes:
                    continue
                prototypes.add(key)
                reason += " (and in every other instance of its prototype)"
            kind = prim.GetTypeName() or "typeless"
            named[kind] = named.get(kind, 0) + 1
            if named[kind] > WARNED_PER_TYPE:
                more.setdefault(kind, []).append(str(prim.GetPath()))
            else:
                self._warn(reason)
        for kind, paths in more.items():
            self._warn(f"{len(paths)} more {kind} prims ignored as the {WARNED_PER_TYPE} above ({paths[0]} .. "
                       f"{paths[-1]})")

    def _light_reason(self, prim, tc, first: dict[str, str]) -> str | None:
        from pxr import UsdGeom, UsdLux

        if not prim.HasAPI(UsdLux.LightAPI) or prim.IsA(UsdLux.DistantLight) or not self._visible(prim, tc):
            return None
        path = str(prim.GetPath())
        if prim.IsA(UsdLux.DomeLight):
            used = first.setdefault("dome", path)
            return None if used == path else (f"DomeLight {path} ignored: only the first visible DomeLight ({used}) "
                                              "lights the scene")
        if prim.IsA(UsdGeom.Mesh):
            return (f"Mesh {path}: its light (MeshLightAPI) is ignored, warpsky's lights are {RENDERED_LIGHTS}; the "
                    "mesh renders as an unlit surface")
        kind = prim.GetTypeName() or "light"
        return f"{kind} {path} ignored: warpsky renders {RENDERED_LIGHTS}"

    def _geometry_reason(self, prim, tc, first: dict[str, str]) -> str | None:
        from pxr import UsdGeom, UsdVol

        if not (prim.IsA(UsdGeom.Gprim) or prim.IsA(UsdGeom.PointInstancer)):
            return None
        if prim.IsA(UsdGeom.Mesh) or not self._rendered(prim, tc):
            return None
        path = str(prim.GetPath())
        if prim.IsA(UsdVol.Volume):
            return self._volume_reason(UsdVol.Volume(prim), path)
        if prim.IsA(UsdGeom.Plane):
            used = first.setdefault("plane", path)
            return None if used == path else (f"Plane {path} ignored: the first rendered Plane ({used}) is the only "
                                              "ground")
        kind_attr = prim.GetAttribute("warpsky:kind")
        if kind_attr and kind_attr.HasAuthoredValue():  # read by its kind (a stratiform layer, a fog, ...)
            return None
        kind = prim.GetTypeName()
        return f"{kind} {path} ignored: warpsky renders {RENDERED_GEOMETRY}; make it a Mesh to render it"

    @staticmethod
    def _volume_reason(volume, path: str) -> str | None:
        """Why a Volume is not rendered: it has no field warpsky renders (a procedural volume its material makes);
        None when it has one."""
        from warpsky.usd.volumes import RENDERED_FIELDS

        fields = sorted(str(name) for name in volume.GetFieldPaths())
        if any(name in RENDERED_FIELDS for name in fields):
            return None
        what = f"fields {', '.join(fields)} but none warpsky renders" if fields else "no fields"
        expected = ", ".join(f"field:{n}" for n in RENDERED_FIELDS)
        return f"Volume {path} ignored: it has {what} ({expected}; a volume made by its material is not rendered)"

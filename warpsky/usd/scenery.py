"""Terrain and the analytic media of a stage: ``UsdGeomMesh`` prims (opaque Lambertian surfaces such as terrain),
prims with ``warpsky:kind = "heightFieldClouds"`` (Max 1986) and prims with ``warpsky:kind = "analyticFog"``
(Biri et al. 2002).

The attributes each kind carries are documented on its reader: :func:`warpsky.model.terrain.read_mesh`,
:func:`warpsky.model.deck.read_decks`, :func:`warpsky.model.fog.read_analytic_fog`.
pxr is imported inside the methods (a heavy import).
"""

from __future__ import annotations

from warpsky.core.errors import SceneError
from warpsky.usd.prims import StagePrims

DECK_KIND = "heightFieldClouds"
FOG_KIND = "analyticFog"
#: Attribute namespaces that only make sense on a prim of the given kind.
_NAMESPACES = {DECK_KIND: ("warpsky:hf:", "warpsky:haze:"), FOG_KIND: ("warpsky:fog:",)}


class SceneryReading(StagePrims):
    """The stage reader's meshes, height-field clouds and analytic fogs."""

    def _time_s(self, time) -> float:
        return 0.0 if time is None else float(time) / float(self.stage.GetTimeCodesPerSecond())

    def read_meshes(self, time=None) -> tuple:
        """Every rendered ``UsdGeomMesh`` at ``time`` as a :class:`~warpsky.model.terrain.TerrainMesh`
        (:func:`~warpsky.model.terrain.read_meshes`)."""
        from warpsky.model.terrain import read_meshes

        return read_meshes(self, time)

    def _kind_prims(self, kind: str, tc) -> list:
        """Rendered prims with ``warpsky:kind = kind``; a prim carrying the kind's attributes under another kind is
        an error naming the attribute."""
        prims = []
        for prim in self._traverse():
            attr = prim.GetAttribute("warpsky:kind")
            found = str(attr.Get(tc)) if attr and attr.HasAuthoredValue() else None
            if found == kind:
                if self._rendered(prim, tc):
                    prims.append(prim)
                continue
            stray = sorted(a.GetName() for a in prim.GetAttributes() if a.GetName().startswith(_NAMESPACES[kind]))
            if stray:
                raise SceneError(f"{prim.GetPath()}: has {stray[0]} but warpsky:kind is {found!r}; expected uniform "
                                 f"token warpsky:kind = \"{kind}\" on that prim")
        return prims

    def read_decks(self, time=None) -> tuple:
        """Prims with ``warpsky:kind = "heightFieldClouds"`` as
        :class:`~warpsky.model.deck.CloudDeck` at ``time``."""
        tc = self._time(time)
        prims = self._kind_prims(DECK_KIND, tc)
        if not prims:
            return ()
        if len(prims) > 1:
            raise SceneError(f"stage {self.path}: {len(prims)} prims with warpsky:kind = \"{DECK_KIND}\" "
                             f"({', '.join(str(p.GetPath()) for p in prims)}); one cloud deck per stage is rendered")
        from warpsky.model.deck import read_decks

        return tuple(read_decks(self, prim, tc) for prim in prims)

    def read_fogs(self, time=None) -> tuple:
        """Prims with ``warpsky:kind = "analyticFog"`` as :class:`~warpsky.model.fog.AnalyticFog` at
        ``time``."""
        tc = self._time(time)
        prims = self._kind_prims(FOG_KIND, tc)
        if not prims:
            return ()
        from warpsky.model.fog import read_analytic_fog

        return tuple(read_analytic_fog(self, prim, tc, self._time_s(time)) for prim in prims)

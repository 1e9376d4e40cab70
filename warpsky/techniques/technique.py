"""What every technique is: the :class:`Technique` base class, its capabilities and what it estimates.

A technique renders the scene's voxel media (and, as far as its capabilities say, what lies around them) into one
:class:`~warpsky.core.image.ImageLayer`. The frame runs it in its ``media`` pass (:mod:`warpsky.passes.media`) next to
the other passes. Nothing outside a technique's folder and :mod:`warpsky.render.registry` names a technique: the plan,
the passes, the command line and the output checks read the capabilities below.
"""

from __future__ import annotations

import functools
from typing import ClassVar

from warpsky.core.image import ImageLayer
from warpsky.core.resources import MemoryEstimate, WorkItem
from warpsky.core.settings import Settings
from warpsky.model.scene import Scene
from warpsky.optics.prepare import TableNeed
from warpsky.optics.tables import phase_table


class Technique:
    """A renderer of the scene's voxel media: built once per frame from its settings, it draws one :class:`ImageLayer`.

    Capabilities (class attributes):

    - ``traces_air``: the technique carries the atmosphere itself (as a participating medium, with the sun's disk),
      so no sky pass runs around its layer and its media see the sun above the air.
    - ``renders_layers``: the technique can run next to the stratiform pass (it renders the voxel media without
      the ground, which the lowest stratiform layer draws).
    - ``traces_layers``: it traces the stratiform layers itself, voxelised, so no stratiform pass runs.
    - ``traces_decks``: it traces height-field cloud decks and their haze itself, so no deck pass runs.
    - ``traces_fog``: it traces analytic fog itself as a participating medium, so no fog pass runs.
    - ``traces_dome``: a dome's light is path traced exactly (else it is an ambient light of the marching models).
    - ``traces_meshes``: it traces the scene's triangle meshes itself (light bounces between them, the media and
      the ground), so no surfaces pass runs: it draws the ground plane and the meshes in its own layer.
    - ``scatters_scenery``: next to the fog, height-field and surfaces passes (which draw the fog's, the deck's and
      the meshes' single scattering: the sun once) it path traces the light those scatter more than once, and the
      sky's and the dome's light on them (:meth:`scenery_paths`), so the media pass runs in a frame of fog, a deck
      or meshes even without voxel media; under stratiform layers its paths also carry the layers' light onto
      them (the stratiform pass draws the layers and leaves the ground to the surfaces pass).
    - ``aovs``: the extra outputs its layer holds, name -> components (``variance``: ``RGB``), which RenderVars
      may name.
    - ``kernel_modules``: the modules whose kernel factories it launches (the first-compile notice checks Warp's
      cache for them).
    - ``settings_notes``: what ``render --help`` adds below its settings table.

    Settings are resolved once per frame: the plan calls :meth:`resolve`, and the estimates and the render read
    :meth:`settings_for`, which resolves again only for a technique used outside a plan.
    """

    name: ClassVar[str]
    Settings: ClassVar[type[Settings]]
    traces_air: ClassVar[bool] = False
    renders_layers: ClassVar[bool] = True
    traces_layers: ClassVar[bool] = False
    traces_decks: ClassVar[bool] = False
    traces_fog: ClassVar[bool] = False
    traces_dome: ClassVar[bool] = False
    traces_meshes: ClassVar[bool] = False
    scatters_scenery: ClassVar[bool] = False
    aovs: ClassVar[dict[str, str]] = {}
    kernel_modules: ClassVar[tuple[str, ...]] = ()
    settings_notes: ClassVar[str] = ""

    def __init__(self, settings: Settings | None = None, *, device: str = "cpu"):
        self.settings = settings if settings is not None else self.Settings()
        self.device = device
        self._resolved: Settings | None = None

    def resolved_settings(self, scene: Scene) -> Settings:
        """The settings with every ``auto`` value filled in for ``scene`` (settings without one are returned as
        they are)."""
        return self.settings

    def resolve(self, scene: Scene) -> Technique:
        """Resolve the settings for ``scene`` once; later estimates and renders use them as they are."""
        self._resolved = self.settings = self.resolved_settings(scene)
        return self

    def settings_for(self, scene: Scene) -> Settings:
        """The resolved settings: those of :meth:`resolve`, else resolved now for ``scene``."""
        return self._resolved if self._resolved is not None else self.resolved_settings(scene)

    def with_settings(self, settings: Settings) -> Technique:
        """A technique of the same class on the same device with ``settings``, resolved when this one is (they
        must then be resolved settings too)."""
        other = type(self)(settings, device=self.device)
        if self._resolved is not None:
            other._resolved = settings
        return other

    def for_extra_light(self) -> Technique:
        """The technique that renders the frame again for each extra light (light adds up): itself, unless some
        light of its own (a uniform environment) must count once."""
        return self

    def scenery_paths(self, scene: Scene) -> bool:
        """Whether its render of ``scene`` path traces the fog's, the deck's and the meshes' light beyond the sun's
        single scattering, the sky's and the dome's included (then the fog and deck passes leave out their
        ambient terms and the surfaces pass its sky light); False unless ``scatters_scenery``."""
        return False

    def render(self, scene: Scene, width: int, height: int) -> ImageLayer:
        """Render ``scene`` at ``width`` x ``height`` pixels (the camera conformed to that aspect ratio)."""
        raise NotImplementedError

    def memory_estimate(self, scene: Scene, width: int, height: int) -> MemoryEstimate:
        """Bytes a render of ``scene`` at ``width`` x ``height`` allocates on the host and the device, by part, as
        an upper bound, without allocating anything (:mod:`warpsky.core.resources`)."""
        raise NotImplementedError

    def work_estimate(self, scene: Scene, width: int, height: int) -> list[WorkItem]:
        """Worst-case kernel iterations of that render, by kind, with the settings that set them."""
        return []

    def tables(self, scene: Scene) -> list[TableNeed]:
        """The optics tables a render of ``scene`` loads (built before a batch's frames when missing): a phase
        table per species."""
        return [TableNeed(name, "phase", functools.partial(phase_table, name)) for name in scene.species]

    def features(self, scene: Scene, width: int, height: int, features: dict[str, str]) -> dict[str, str]:
        """``warpsky info``'s lines, given those the plan and the passes wrote: changed where the technique
        renders something differently (a voxelised layer), else as they are."""
        return features

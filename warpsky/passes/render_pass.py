"""What every pass of a frame is: the :class:`Pass` base class.

A frame is the chosen technique plus a declared tuple of passes (:data:`warpsky.render.registry.PASSES`, run in that
order by :func:`warpsky.passes.frame.render_layers`); the technique itself runs in the ``media`` pass. A pass declares
when it runs, what it costs and what it draws, with the same kind of typed settings as a technique
(:mod:`warpsky.core.settings`, reached by ``--set PREFIX.NAME=VALUE``). Adding one is a folder under ``passes/`` and a
line in the registry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np

from warpsky.core.image import ImageLayer
from warpsky.core.resources import MemoryEstimate, WorkItem
from warpsky.core.settings import Settings


class Pass:
    """One part of a frame besides the technique (or, for the ``media`` pass, the technique's place in it).

    Class attributes:

    - ``name``: what ``warpsky info`` calls it (``passes surfaces -> media -> sky -> composite``).
    - ``Settings``: its settings class (prefix ``name.``), or None.
    - ``wraps``: it draws the air around everything else: its :meth:`render` returns two layers, the air in
      front of what the other passes drew and the air behind it; a frame with such a pass lights its media,
      layers and scenery through that air (:class:`~warpsky.light.frame.FrameLight`). Every other pass's layers
      are merged by depth (:func:`~warpsky.passes.composite.merge_by_depth`).
    - ``ground_rank``: it can draw the ground plane; of the passes that run, the one with the lowest rank does
      (None: it never does).
    - ``ground_note``: what ``warpsky info`` adds to the ground's line when this pass draws it.
    - ``runs_technique``: this is the pass the frame's technique renders in.
    - ``draws``: the :class:`~warpsky.model.scene.Scene` fields it draws, which the technique then does not see
      (the stratiform pass's ``layers``).
    - ``kernel_modules``: modules of its kernel factories (the first-compile notice).
    - ``shades_air``: its :meth:`shadow` also shades the air in front of the eye
      (:mod:`~warpsky.passes.sky.shadowed_air`); not a stratiform layer's, below which the air is lit by the
      layer's own diffuse light, which nothing draws into the air.
    """

    name: ClassVar[str]
    Settings: ClassVar[type[Settings] | None] = None
    wraps: ClassVar[bool] = False
    ground_rank: ClassVar[int | None] = None
    ground_note: ClassVar[str] = ""
    draws: ClassVar[tuple[str, ...]] = ()
    runs_technique: ClassVar[bool] = False
    kernel_modules: ClassVar[tuple[str, ...]] = ()
    shades_air: ClassVar[bool] = False

    def __init__(self, settings: Settings | None = None, *, device: str = "cpu", technique=None):
        if settings is None and self.Settings is not None:
            settings = self.Settings()
        self.settings = settings
        self.device = device
        self.technique = technique

    def draws_ground(self, scene) -> bool:
        """Whether the pass would draw the scene's ground plane in a frame of ``scene`` (of the running passes
        that would, the one of lowest ``ground_rank`` does)."""
        return self.ground_rank is not None

    def own_layer(self, frame) -> ImageLayer | None:
        """The layer this pass draws in ``frame``, where another pass needs it before this pass's turn: drawn once
        and kept in ``frame.kept`` (:meth:`keep`); None for a pass that offers none."""
        return None

    def keep(self, frame, draw: Callable[[], ImageLayer]) -> ImageLayer:
        """``draw()`` the first time this pass asks in ``frame``, the kept layer after that."""
        if self.name not in frame.kept:
            frame.kept[self.name] = draw()
        return frame.kept[self.name]

    def shadow(self, scene) -> Callable[[np.ndarray], np.ndarray] | None:
        """The shadow of what this pass draws, for the passes that light surfaces: a function of world points
        (N, 3) [m] giving the (N, 3) RGB transmittance of the sunlight from them towards the sun; None when it casts
        none."""
        return None

    @classmethod
    def runs(cls, scene, technique) -> bool:
        """Whether the pass runs in a frame of ``scene`` rendered by ``technique`` (the plan's built technique, or
        a technique class)."""
        raise NotImplementedError

    @classmethod
    def refusal(cls, scene, technique) -> tuple[str, list[str]] | None:
        """(what, prim names) when the pass would run and ``technique`` cannot render next to it (the plan refuses
        the frame naming them); None when it can."""
        return None

    @classmethod
    def describe(cls, scene, technique, settings) -> dict[str, str]:
        """``warpsky info``'s lines about what the pass draws in ``scene`` (with ``settings``), or why it does not
        run."""
        return {}

    def memory_estimate(self, scene, width: int, height: int) -> MemoryEstimate:
        """Bytes the pass allocates at ``width`` x ``height`` (an upper bound, nothing allocated)."""
        return MemoryEstimate()

    def work_estimate(self, scene, width: int, height: int) -> list[WorkItem]:
        """Its worst-case kernel iterations (none counted by default: one light launch per frame)."""
        return []

    def tables(self, scene) -> list:
        """The optics tables (:class:`~warpsky.optics.prepare.TableNeed`) it loads."""
        return []

    def header(self, parts: list[dict]) -> dict:
        """Values for the EXR header (``warpsky/<key>``) from the stats of the frame's merged layer's ``parts``
        (none by default)."""
        return {}

    def render(self, frame) -> list[ImageLayer]:
        """The pass's layers for ``frame`` (:class:`~warpsky.passes.frame.FrameState`), front to back in its own
        order; a wrapping pass returns [front, back]."""
        raise NotImplementedError

"""How to render a frame, as the command line, the Python API or a batch driver gives it: :class:`RenderOptions`."""

from __future__ import annotations

from dataclasses import dataclass, field

from warpsky.output.color import DEFAULT_COLORSPACE
from warpsky.output.deep_bins import DEEP_SAMPLES
from warpsky.output.png import DEFAULT_VIEW
from warpsky.output.products import FULL_WINDOW, OutputVar, default_outputs, required_channels
from warpsky.render.motion import DEFAULT_SAMPLES
from warpsky.render.registry import DEFAULT_TECHNIQUE


@dataclass
class RenderOptions:
    """How to render, as given on the command line (or by a batch driver).

    Attributes:
        technique: Registered technique name.
        settings: Settings as ``{name: text or value}`` (``PREFIX.NAME`` for a pass's); unknown names are an
            error. The plan parses them once (:func:`~warpsky.render.plan.make_plan`); what runs reads the plan's
            typed settings.
        resolution: (width, height or None) or None for the stage's render settings / default.
        device: Warp device name, already resolved (``cpu``, ``cuda:0``).
        camera: Camera prim path, or None for the default camera.
        half: Write RGBA as half floats (False: 32-bit float).
        png: Also write a tone-mapped PNG preview next to the EXR.
        deep: Also write a deep scanline EXR next to it (:mod:`warpsky.output.deep`).
        deep_product: The output is itself a deep scanline EXR (a ``deepRaster`` RenderProduct): no flat frame.
        deep_samples: Volume samples per pixel of each volume layer (voxel media, analytic fog) in a deep image,
            1..64 (:mod:`warpsky.output.deep_bins`).
        shutter: (open, close) [frames] overriding the camera's shutter (:mod:`warpsky.render.motion`); None: the
            camera's.
        motion_samples: Sub-frames of a frame whose shutter is open (:mod:`warpsky.render.motion`).
        exposure: Preview exposure in stops on top of the sun-based normalisation (a white surface facing the sun ->
            1); None: automatic, from the frame's luminance (:func:`~warpsky.output.png.auto_exposure`).
        view: The preview's display view (:mod:`warpsky.output.png`).
        max_memory: Most bytes a frame may allocate on the host and on the device each (None: what is free).
        work_limit: Refuse frames whose worst-case work exceeds :mod:`warpsky.core.resources`' bounds.
        outputs: The channels to write (a RenderProduct's vars), or None for warpsky's default channels.
        pixel_aspect: Width / height of a pixel as displayed (RenderSettings ``pixelAspectRatio``).
        data_window: The part of the image written, (xmin, ymin, xmax, ymax) in NDC (``dataWindowNDC``).
        colorspace: The primaries the EXR's colours are written in (:mod:`warpsky.output.color`).
        stage: How the stage is composed (:class:`~warpsky.usd.composition.StageOptions`; None: defaults).
    """

    technique: str = DEFAULT_TECHNIQUE
    settings: dict = field(default_factory=dict)
    resolution: tuple[int, int | None] | None = None
    device: str = "cpu"
    camera: str | None = None
    half: bool = True
    png: bool = False
    deep: bool = False
    deep_product: bool = False
    deep_samples: int = DEEP_SAMPLES
    shutter: tuple[float, float] | None = None
    motion_samples: int = DEFAULT_SAMPLES
    exposure: float | None = None
    view: str = DEFAULT_VIEW
    max_memory: int | None = None
    work_limit: bool = True
    outputs: tuple[OutputVar, ...] | None = None
    pixel_aspect: float = 1.0
    data_window: tuple[float, float, float, float] = FULL_WINDOW
    colorspace: str = DEFAULT_COLORSPACE
    stage: object = None

    @property
    def required_channels(self) -> tuple[str, ...]:
        """Channels every frame written with these options holds (AOVs left out of the default set)."""
        return required_channels(self.outputs or default_outputs())

    @property
    def deep_output(self) -> bool:
        """Whether a frame rendered with these options keeps deep samples (a deep EXR beside it, or as it)."""
        return self.deep or self.deep_product

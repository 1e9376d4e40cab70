"""One time of a cloud model's output on a regular grid: what the CM1 and WRF readers return and the stage writer
takes (:mod:`warpsky.usd.weather.author`).

Axes are the meteorological ones, which the written stage keeps (``upAxis = "Z"``, metres): x east, y north, z up.
Arrays are indexed ``[x, y, z]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.model.water_optics import species_extinction

#: The species fields a weather stage has, in this order (:data:`~warpsky.model.scene.FIELD_SPECIES`).
SPECIES_ORDER = ("cloud", "rain", "ice", "snow")


@dataclass
class Terrain:
    """The ground under a model's domain.

    Attributes:
        height: Terrain height [m] at the grid's horizontal cell centres, shape (nx, ny).
    """

    height: np.ndarray


@dataclass
class WeatherState:
    """A model's hydrometeors, air and wind at one time, on a regular grid.

    ============= ============ ===================================================================================
    attribute     unit         meaning
    ============= ============ ===================================================================================
    source        –            the file it was read from
    time          s            time since the simulation began
    label         –            the file's own name for the time (WRF's ``Times``), else ``t=<seconds>s``
    origin        m            (x, y, z) of the centre of cell [0, 0, 0]
    spacing       m            (dx, dy, dz) cell size
    water         kg/m³        hydrometeor name (``cloud``, ``rain``, ``ice``, ``snow``, ``graupel``) -> water
                               content, shape (nx, ny, nz); 0 under the ground and outside the model's levels
    radius        m            hydrometeor name -> effective radius per cell, where the file gives one
    number        1/m³         hydrometeor name -> number concentration per cell, where a two-moment scheme
                               gives one
    velocity      m/s          (nx, ny, nz, 3) wind (east, north, up) at the cell centres, or None
    terrain       –            :class:`Terrain`, or None (flat ground at z = 0)
    ============= ============ ===================================================================================
    """

    source: str
    time: float
    label: str
    origin: np.ndarray
    spacing: np.ndarray
    water: dict[str, np.ndarray]
    radius: dict[str, np.ndarray] = field(default_factory=dict)
    number: dict[str, np.ndarray] = field(default_factory=dict)
    velocity: np.ndarray | None = None
    terrain: Terrain | None = None

    def __post_init__(self):
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        self.spacing = np.asarray(self.spacing, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(self.spacing)) or np.any(self.spacing <= 0.0):
            raise SceneError(f"{self.source}: grid spacing must be > 0 m on every axis, got {self.spacing.tolist()}")
        if not self.water:
            raise SceneError(f"{self.source}: no hydrometeor mixing ratio to render")
        shapes = {name: grid.shape for name, grid in self.water.items()}
        if len(set(shapes.values())) != 1:
            raise SceneError(f"{self.source}: hydrometeor grids differ in shape: {shapes}")

    @property
    def shape(self) -> tuple[int, int, int]:
        """Cells along x, y, z."""
        return next(iter(self.water.values())).shape

    def cell_centres(self, axis: int) -> np.ndarray:
        """Coordinates [m] of the cell centres along ``axis`` (0 x, 1 y, 2 z)."""
        return self.origin[axis] + self.spacing[axis] * np.arange(self.shape[axis])

    def extinction(self, hydrometeors=None) -> dict[str, np.ndarray]:
        """Extinction [1/m] per warpsky species (``cloud``, ``rain``, ``ice``, ``snow``), float32, indexed
        [x, y, z] (:func:`~warpsky.model.water_optics.species_extinction`)."""
        beta = species_extinction(self.water, self.radius, hydrometeors, self.number)
        return {name: grid.astype(np.float32) for name, grid in beta.items()}

"""The solver's state as the frames warpsky renders: per-species extinction NanoVDB grids, a velocity grid and a USD
stage with their time samples.

The solver's axes (x, up, z) are written as the meteorological ones the weather stage uses (x east, y north,
z up; ``upAxis = "Z"``): its z is north. The water becomes extinction through
:mod:`warpsky.model.water_optics` (mixing ratio x dry-air density -> water content -> extinction), the conversion
``warpsky import-weather`` uses for CM1 and WRF output, and the stage is that command's
(:mod:`warpsky.usd.weather`): one Volume with ``field:cloud``, ``rain``, ``ice``, ``snow`` and ``velocity``.

The solver has one condensate and one precipitation category; the frames split both by temperature: condensate
is droplets above 0 C and ice below -20 C, linearly between (the partition of the ice-phase mixed layer in,
e.g., Lord et al. 1984's saturation adjustment), and precipitation is rain or snow by the same weights. The
solver's fall speeds, cold rates and latent heat use the same partition (:func:`.kernels_water.frozen_share`).

Each grid is written to a temporary file and renamed, and the stage is written (the same way) after each frame
with every frame so far: a run stopped part way leaves a stage of the frames it finished. The stage's default
camera is the rainbow shot of :mod:`.shot` (``/World/RainbowCam``, following the rain shaft, the sun at its back);
``/World/Camera`` frames everything cloudy so far.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpsky.core.errors import OutputError
from warpsky.core.files import atomic_write
from warpsky.model.water_optics import dry_air_density, species_water, water_content
from warpsky.simulate.kernels_water import ALL_ICE, ALL_LIQUID
from warpsky.simulate.shot import Shaft, author_shot, find_shaft, shot_sun
from warpsky.usd.weather.weather_state import SPECIES_ORDER, WeatherState

#: The velocity is written only this many cells around the media (what motion blur moves), which keeps its grids
#: sparse: the environment's wind fills the whole domain (a dense 128 x 128 x 64 grid is 12 MB per frame).
VELOCITY_MARGIN = 2
#: Fields each frame writes.
FIELDS = (*SPECIES_ORDER, "velocity")


def ice_fraction(temperature: np.ndarray) -> np.ndarray:
    """The share of condensate and precipitation that is ice at ``temperature`` [K] (module docstring): the
    solver's :func:`.kernels_water.frozen_share` on the host, between the same temperatures."""
    return np.clip((ALL_LIQUID - temperature) / (ALL_LIQUID - ALL_ICE), 0.0, 1.0)


def weather_state(fields: dict[str, np.ndarray], base, spacing: tuple[float, float], time: float,
                  domain_speed: tuple[float, float] = (0.0, 0.0)) -> WeatherState:
    """One frame of the solver (``CloudSolver.fields()``, its ``base`` state, (dx, dy) [m]) as a WeatherState
    (water contents [kg/m^3] on meteorological axes), where a grid moving at ``domain_speed`` (u, v) [m/s] along
    the solver's +x and +z has moved to by ``time`` [s], with that speed added to its wind."""
    dx, dy = spacing
    nx, ny, nz = fields["theta"].shape
    pressure = base.pressure[None, :, None]
    temperature = fields["theta"] * base.exner[None, :, None]
    air = dry_air_density(pressure, temperature, fields["vapour"])
    ice = ice_fraction(temperature)
    contents = {"cloud": water_content(fields["cloud"] * (1.0 - ice), air),
                "rain": water_content(fields["rain"] * (1.0 - ice), air),
                "ice": water_content(fields["cloud"] * ice, air),
                "snow": water_content(fields["rain"] * ice, air)}

    def met(grid):  # (x, up, z) -> (x, north, up)
        return np.ascontiguousarray(np.swapaxes(grid, 1, 2))

    u, v = domain_speed
    velocity = fields["velocity"][..., [0, 2, 1]] + np.array([u, v, 0.0], dtype=np.float32)
    origin = ((0.5 - 0.5 * nx) * dx + u * time, (0.5 - 0.5 * nz) * dx + v * time, 0.5 * dy)
    return WeatherState(source="warpsky simulate", time=float(time), label=f"t={time:.0f}s", origin=origin,
                        spacing=(dx, dx, dy), water={name: met(grid) for name, grid in contents.items()},
                        velocity=met(velocity).astype(np.float32))


def near_media(beta: dict[str, np.ndarray], margin: int) -> np.ndarray:
    """1 in the cells within ``margin`` cells (periodically along x and y, held at the floor and the lid) of one
    with extinction, else 0, as float32."""
    occupied = sum(beta.values()) > 0.0 if beta else np.zeros((1, 1, 1), bool)
    grown = occupied.copy()
    for axis in range(3):
        for _ in range(margin):
            before = grown.copy()
            if axis < 2:
                grown |= np.roll(before, 1, axis=axis) | np.roll(before, -1, axis=axis)
            else:
                grown[..., 1:] |= before[..., :-1]
                grown[..., :-1] |= before[..., 1:]
    return grown.astype(np.float32)


def write_grid(path: Path, grid: np.ndarray, origin: np.ndarray, spacing: np.ndarray) -> Path:
    """``grid`` (scalar or (..., 3)) as a NanoVDB file whose voxel [0, 0, 0] centre is ``origin`` [m], padded with
    a voxel of background (0) on every side so that the grid's edge fades to it; written atomically."""
    import warp as wp

    pad = ((1, 1), (1, 1), (1, 1)) + (((0, 0),) if grid.ndim == 4 else ())
    padded = np.pad(np.asarray(grid, dtype=np.float32), pad)
    background = (0.0, 0.0, 0.0) if grid.ndim == 4 else 0.0
    volume = wp.Volume.load_from_numpy(padded, min_world=tuple(float(v) for v in origin - spacing),
                                       voxel_size=tuple(float(v) for v in spacing), bg_value=background,
                                       device="cpu")
    return atomic_write(path, lambda tmp: volume.save_to_nvdb(str(tmp), codec="zip"))


@dataclass
class FrameWriter:
    """Writes frames into ``folder`` and the stage ``stage`` after each (module docstring)."""

    folder: Path
    stage: Path
    seconds_per_frame: float
    resolution: tuple[int, int] = (384, 256)
    sun: tuple[float, float] = field(default_factory=shot_sun)
    grids: list[dict[str, Path]] = field(default_factory=list)
    shafts: list[Shaft] = field(default_factory=list)
    middles: list[tuple[float, float]] = field(default_factory=list)
    peaks: dict[str, float] = field(default_factory=dict)
    box: tuple[np.ndarray, np.ndarray] | None = None
    water: list[dict[str, tuple[float, float]]] = field(default_factory=list)

    def write(self, state: WeatherState) -> dict[str, Path]:
        """The frame's grids, then the stage with every frame so far; the files written."""
        from warpsky.usd.weather.author import framing

        frame = len(self.grids) + 1
        beta = state.extinction()
        files = {}
        for species in SPECIES_ORDER:
            grid = beta.get(species, np.zeros(state.shape, np.float32))
            self.peaks[species] = max(self.peaks.get(species, 0.0), float(grid.max()))
            files[species] = write_grid(self.folder / f"{species}.{frame:04d}.nvdb", grid, state.origin,
                                        state.spacing)
        near = near_media(beta, VELOCITY_MARGIN)
        files["velocity"] = write_grid(self.folder / f"velocity.{frame:04d}.nvdb", state.velocity * near[..., None],
                                       state.origin, state.spacing)
        lower, upper = framing([state], [beta])
        if self.box is not None and any(p > 0.0 for p in self.peaks.values()):
            lower, upper = np.minimum(lower, self.box[0]), np.maximum(upper, self.box[1])
        self.box = (lower, upper) if float(sum(g.max() for g in beta.values())) > 0.0 else self.box
        self.grids.append(files)
        self.water.append(species_water(state.water, float(np.prod(state.spacing))))
        self.shafts.append(find_shaft(beta, state.origin, state.spacing))
        middle = state.origin + 0.5 * state.spacing * (np.array(state.shape) - 1)
        self.middles.append((float(middle[0]), float(middle[1])))
        self._write_stage(state)
        return files

    def _write_stage(self, state: WeatherState) -> None:
        from warpsky.usd.weather.weather_usd import author_stage

        codes = [float(n) for n in range(1, len(self.grids) + 1)]
        box = self.box or (state.origin, state.origin + state.spacing * (np.array(state.shape) - 1))
        peaks = ", ".join(f"{k} {v:.3g} 1/m" for k, v in self.peaks.items())
        doc = (f"warpsky simulate: {len(self.grids)} frame(s), {self.seconds_per_frame:g} s of storm life apart "
               f"(anelastic cloud solver with Kessler rain and snow; extinction by warpsky.model.water_optics; peaks: "
               f"{peaks}).")
        tmp = self.stage.with_name(f".{self.stage.stem}.tmp.usda")
        try:
            author_stage(tmp, [state], self.grids, codes, 1.0 / self.seconds_per_frame, framing=box, sun=self.sun,
                         resolution=self.resolution, doc=doc, water=self.water)
            author_shot(tmp, self.shafts, self.middles, codes, self.sun)
            os.replace(tmp, self.stage)
        except OSError as exc:
            raise OutputError(f"cannot write {self.stage}: {exc.strerror or exc}") from None
        finally:
            if tmp.exists():
                tmp.unlink()

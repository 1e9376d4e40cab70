"""Writing imported weather: per-species extinction grids (NanoVDB) and a USD stage that renders them.

The stage (``upAxis = "Z"``, metres: x east, y north, z up, the models' own axes) holds

- ``/World/Weather``: a Volume with ``field:cloud``, ``field:rain``, ``field:ice``, ``field:snow`` (those with water
  at some time), each an OpenVDBAsset whose grid is the species' extinction coefficient [1/m]
  (``warpsky:extinctionScale = 1``; :mod:`warpsky.model.water_optics` converts the water; ``warpsky:water:peak``
  [kg/m³] and ``warpsky:water:total`` [kg], time-sampled, record the water it holds), and ``field:velocity``
  (a Vec3f grid [m/s]) when the files give the wind: the velocity blur of a frame rendered with an open shutter.
  Several times become time samples of every ``filePath`` (time code 1 at the first time, one time code per
  shortest interval between times, ``timeCodesPerSecond`` = 1 / that interval: a time-lapse of model seconds);
- ``/World/Camera``: outside the weather, south of it, looking north at the box holding its extinction;
- ``/World/Sun``: a DistantLight at the given elevation and azimuth (clockwise from north);
- ``/World/Atmosphere``: the Earth's air (Riley §4.1 and the round-earth sky: :func:`author_earth_air`);
- ``/World/Ground``: a Plane at the lowest ground, and ``/World/Terrain``, a Mesh of the terrain (WRF's ``HGT``)
  when the file has one;
- ``/Render/Settings``: the camera and resolution.

Each grid is padded with one voxel of zeros on every side, so that the NanoVDB's background (0) continues the
data's edge instead of cutting it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warpsky.core.errors import OutputError
from warpsky.model.water_optics import species_water
from warpsky.usd.weather.weather_state import SPECIES_ORDER, WeatherState
from warpsky.usd.weather.weather_usd import author_stage

#: A cell counts towards the camera's framing when its extinction exceeds this fraction of the maximum.
FRAMING_FRACTION = 1e-2


@dataclass
class ImportedWeather:
    """What :func:`write_weather_stage` wrote.

    Attributes:
        stage: The USD stage.
        grids: Per time: field name (a species or ``velocity``) -> its NanoVDB file.
        peak_extinction: Species -> its largest extinction [1/m] over all times.
        times: Seconds since the simulation began of each time code 1, 2, ...
    """

    stage: Path
    grids: list[dict[str, Path]]
    peak_extinction: dict[str, float]
    times: list[float]


def _write_nvdb(path: Path, grid: np.ndarray, origin: np.ndarray, spacing: np.ndarray) -> Path:
    """``grid`` (indexed [x, y, z], scalar or (..., 3)) as a NanoVDB file whose voxel [0, 0, 0] centre is ``origin``,
    padded with a voxel of background on every side."""
    import warp as wp

    pad = ((1, 1), (1, 1), (1, 1)) + (((0, 0),) if grid.ndim == 4 else ())
    padded = np.pad(np.asarray(grid, dtype=np.float32), pad)
    background = (0.0, 0.0, 0.0) if grid.ndim == 4 else 0.0
    tmp = path.with_suffix(".tmp.nvdb")
    try:
        volume = wp.Volume.load_from_numpy(padded, min_world=tuple(float(v) for v in origin - spacing),
                                           voxel_size=tuple(float(v) for v in spacing), bg_value=background,
                                           device="cpu")
        volume.save_to_nvdb(str(tmp), codec="zip")
        tmp.replace(path)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def write_grids(states: list[WeatherState], folder: Path, hydrometeors=None
                ) -> tuple[list[dict[str, Path]], dict[str, float], list[dict[str, np.ndarray]]]:
    """Every state's species extinction (and velocity) grids as ``folder/<field>.<frame>.nvdb``.

    Returns:
        (files per state, peak extinction per species [1/m], extinction grids per state); a species without
        extinction at any time is left out.
    """
    from warpsky.core.device import init_warp

    init_warp()
    folder.mkdir(parents=True, exist_ok=True)
    betas = [state.extinction(hydrometeors) for state in states]
    peaks = {s: max(float(b[s].max()) for b in betas if s in b) for s in SPECIES_ORDER
             if any(s in b for b in betas)}
    present = [s for s in SPECIES_ORDER if peaks.get(s, 0.0) > 0.0]
    files = []
    for frame, (state, beta) in enumerate(zip(states, betas, strict=True), start=1):
        written = {}
        for species in present:
            grid = beta.get(species, np.zeros(state.shape, np.float32))
            written[species] = _write_nvdb(folder / f"{species}.{frame:04d}.nvdb", grid, state.origin, state.spacing)
        if state.velocity is not None:
            written["velocity"] = _write_nvdb(folder / f"velocity.{frame:04d}.nvdb", state.velocity, state.origin,
                                              state.spacing)
        files.append(written)
    return files, {s: peaks[s] for s in present}, betas


def time_codes(times: list[float]) -> tuple[list[float], float]:
    """Time codes (1 at the first time) and timeCodesPerSecond: one code per shortest interval between times."""
    if len(times) < 2:
        return [1.0], 1.0
    step = min(b - a for a, b in zip(times, times[1:], strict=False))
    return [1.0 + (t - times[0]) / step for t in times], 1.0 / step


def framing(states: list[WeatherState], betas: list[dict[str, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners [m] of the box of cell centres whose total extinction exceeds
    :data:`FRAMING_FRACTION` of its maximum over every time (the whole grid when all is clear)."""
    totals = [sum(beta.values()) if beta else np.zeros(state.shape) for state, beta in zip(states, betas,
                                                                                          strict=True)]
    peak = max(float(np.max(total)) for total in totals)
    lows, highs = [], []
    for state, total in zip(states, totals, strict=True):
        mask = total > FRAMING_FRACTION * peak if peak > 0.0 else np.ones(state.shape, bool)
        if not mask.any():
            continue
        index = np.argwhere(mask)
        lows.append(state.origin + state.spacing * index.min(axis=0))
        highs.append(state.origin + state.spacing * index.max(axis=0))
    return np.min(lows, axis=0), np.max(highs, axis=0)


def write_weather_stage(states: list[WeatherState], out: Path, *, name: str = "weather", hydrometeors=None,
                        sun: tuple[float, float] = (35.0, 225.0), resolution: tuple[int, int] = (384, 256),
                        sources: list[str] | None = None) -> ImportedWeather:
    """Write the grids under ``out/<name>/`` and the stage ``out/<name>.usda``.

    Args:
        states: The times, in time order (:func:`~warpsky.usd.weather.read_weather`).
        out: Folder for the stage and its grids.
        name: The stage's file name without ``.usda`` and its grids' folder.
        hydrometeors: The water-to-extinction table (default :data:`~warpsky.model.water_optics.HYDROMETEORS`).
        sun: (elevation, azimuth clockwise from north) [degrees].
        resolution: The RenderSettings' resolution [pixels].
        sources: The files read, for the stage's documentation.
    """
    out = Path(out)
    grids, peaks, betas = write_grids(states, out / name, hydrometeors)
    stage_path = out / f"{name}.usda"
    codes, per_second = time_codes([s.time for s in states])
    water = [species_water(s.water, float(np.prod(s.spacing)), hydrometeors) for s in states]
    author_stage(stage_path, states, grids, codes, per_second, framing=framing(states, betas), sun=sun,
                 resolution=resolution, doc=_documentation(states, peaks, sources or []), water=water)
    return ImportedWeather(stage_path, grids, peaks, [s.time for s in states])


def _documentation(states: list[WeatherState], peaks: dict[str, float], sources: list[str]) -> str:
    files = ", ".join(os.path.basename(s) for s in sources) or ", ".join(sorted({s.source for s in states}))
    times = ", ".join(s.label for s in states[:6]) + (", ..." if len(states) > 6 else "")
    species = ", ".join(f"{k} (peak {v:.3g} 1/m)" for k, v in peaks.items())
    return (f"warpsky import-weather: {files}; {len(states)} time(s): {times}. Fields are extinction [1/m] per "
            f"species: {species} (warpsky.model.water_optics: mixing ratio x dry-air density -> water content -> "
            "extinction; graupel renders as snow).")

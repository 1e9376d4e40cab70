"""Cloud-model output (CM1, WRF netCDF) to warpsky stages: readers of the models' files (:mod:`.cm1`, :mod:`.wrf`)
returning :class:`~warpsky.usd.weather.weather_state.WeatherState` s on regular grids, and the writer of their
per-species extinction grids and a USD stage (:mod:`.author`). The water-to-extinction conversion is
:mod:`warpsky.model.water_optics`.
"""

from __future__ import annotations

from pathlib import Path

from warpsky.core.errors import SceneError
from warpsky.usd.weather.weather_state import WeatherState


def read_weather_file(path: str | Path, *, dz: float | None = None) -> list[WeatherState]:
    """Every time of one CM1 or WRF output file (told apart by their variables), on a regular grid."""
    from warpsky.usd.weather import netcdf
    from warpsky.usd.weather.cm1 import is_cm1, read_cm1
    from warpsky.usd.weather.wrf import is_wrf, read_wrf

    ds = netcdf.open_dataset(path)
    try:
        if is_wrf(ds):
            return read_wrf(path, ds, dz=dz)
        if is_cm1(ds):
            return read_cm1(path, ds, dz=dz)
        raise SceneError(f"{path}: neither CM1 output (variables 'xh' and 'th') nor a wrfout file (variable 'PHB', "
                         "dimension 'bottom_top_stag')")
    finally:
        ds.close()


def read_weather(paths, *, dz: float | None = None) -> list[WeatherState]:
    """Every time of every file, in time order; two states at the same time are refused."""
    states = [state for path in paths for state in read_weather_file(path, dz=dz)]
    if not states:
        raise SceneError("no weather-model file given")
    states.sort(key=lambda s: s.time)
    for before, after in zip(states, states[1:], strict=False):
        if after.time == before.time:
            raise SceneError(f"{after.source} ({after.label}) and {before.source} ({before.label}) are both at "
                             f"t = {after.time:g} s; give each time once")
    return states

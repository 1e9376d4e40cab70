"""Opening a cloud model's netCDF output and taking variables from it, with one-line errors that name the file and
the variable or dimension at fault (:class:`~warpsky.core.errors.SceneError`, exit code 2 from the command line).

xarray and netCDF4 are the ``weather`` extra (``pip install 'warpsky[weather]'``) and load here, not with warpsky.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpsky.core.errors import SceneError, UsageError

#: Metres per unit of the length units CM1 and WRF write (CM1's ``units`` attribute is ``km`` or ``meters``).
LENGTH_UNITS = {"km": 1000.0, "kilometers": 1000.0, "kilometres": 1000.0, "m": 1.0, "meters": 1.0, "metres": 1.0}
#: Seconds per unit of a time variable's units (the first word of e.g. ``minutes since 2004-05-13``).
TIME_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "min": 60.0, "minute": 60.0, "minutes": 60.0,
              "h": 3600.0, "hour": 3600.0, "hours": 3600.0}


def open_dataset(path: str | Path):
    """The file as an xarray Dataset (times left undecoded); a SceneError when it is missing or not netCDF."""
    try:
        import xarray as xr
    except ImportError:
        raise UsageError("reading CM1 and WRF output needs xarray and netCDF4: pip install 'warpsky[weather]'") \
            from None
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: no such file")
    try:
        return xr.open_dataset(path, decode_times=False, mask_and_scale=True, engine="netcdf4")
    except (OSError, ValueError) as exc:
        raise SceneError(f"{path}: not a readable netCDF file ({str(exc).splitlines()[0]})") from None


def require(ds, path, name: str, what: str):
    """Variable ``name`` of ``ds``; a SceneError naming the file, the variable and what it is for when missing."""
    if name not in ds.variables:
        raise SceneError(f"{path}: missing variable {name!r} ({what})")
    return ds[name]


def values(ds, path, name: str, dims: tuple[str, ...], what: str) -> np.ndarray:
    """Variable ``name`` as float64, its dimensions checked against ``dims`` (a leading time dimension, when the
    variable has one more dimension than ``dims``, is kept first); missing values read as 0."""
    var = require(ds, path, name, what)
    found = tuple(var.dims)
    core = found[1:] if len(found) == len(dims) + 1 else found
    if core != tuple(dims):
        raise SceneError(f"{path}: variable {name!r} has dimensions {found}, expected {tuple(dims)} after an optional "
                         "time dimension")
    data = np.asarray(var.values, dtype=np.float64)
    return np.nan_to_num(data, nan=0.0, posinf=0.0, neginf=0.0)


def at_time(data: np.ndarray, ndim: int, index: int) -> np.ndarray:
    """``data``'s slice at time ``index`` when it has a leading time axis (more than ``ndim`` axes), else itself."""
    return data[index] if data.ndim > ndim else data


def dimension(ds, path, name: str, what: str) -> int:
    """Size of dimension ``name``; a SceneError naming the file and the dimension when it is missing."""
    if name not in ds.sizes:
        raise SceneError(f"{path}: missing dimension {name!r} ({what})")
    return int(ds.sizes[name])


def length_scale(var, path, default: str = "km") -> float:
    """Metres per unit of a coordinate variable, from its ``units`` attribute (``default`` when unauthored)."""
    unit = str(var.attrs.get("units", default)).strip().lower()
    if unit not in LENGTH_UNITS:
        raise SceneError(f"{path}: variable {var.name!r} has units {unit!r}; expected one of "
                         f"{', '.join(sorted(LENGTH_UNITS))}")
    return LENGTH_UNITS[unit]


def time_scale(var, path) -> float:
    """Seconds per unit of a time variable, from the first word of its ``units`` (seconds when unauthored)."""
    words = str(var.attrs.get("units", "seconds")).strip().lower().split()
    unit = words[0] if words else "seconds"
    if unit not in TIME_UNITS:
        raise SceneError(f"{path}: variable {var.name!r} has time units {unit!r}; expected seconds, minutes or hours")
    return TIME_UNITS[unit]


def uniform_spacing(coords: np.ndarray, path, name: str) -> float:
    """The constant step [same unit] of a 1-D coordinate; a SceneError when it is not increasing or not uniform
    to 0.1 % (the readers resample a stretched vertical axis, not a horizontal one)."""
    coords = np.asarray(coords, dtype=np.float64)
    if coords.size < 2:
        raise SceneError(f"{path}: coordinate {name!r} needs at least 2 points, got {coords.size}")
    steps = np.diff(coords)
    if np.any(steps <= 0.0):
        raise SceneError(f"{path}: coordinate {name!r} must increase")
    if np.ptp(steps) > 1e-3 * steps.mean():
        raise SceneError(f"{path}: coordinate {name!r} is stretched (steps {steps.min():g} to {steps.max():g}); "
                         "only a uniform horizontal grid is read")
    return float(steps.mean())


def water(ds, path, dims: tuple[str, ...], names: dict[str, str], vapour: str):
    """(hydrometeor -> mixing ratio [kg/kg], water vapour [kg/kg] or None) of the variables ``names`` (file name ->
    hydrometeor) the file holds; a SceneError naming the first of them when it holds none."""
    found = {name: hydro for name, hydro in names.items() if name in ds.variables}
    if not found:
        raise SceneError(f"{path}: missing variable {next(iter(names))!r} (no hydrometeor mixing ratio: expected any "
                         f"of {', '.join(names)})")
    ratios = {hydro: values(ds, path, name, dims, "mixing ratio [kg/kg]") for name, hydro in found.items()}
    return ratios, values(ds, path, vapour, dims, "water vapour [kg/kg]") if vapour in ds.variables else None

"""CM1 (Bryan and Fritsch 2002) netCDF output as :class:`~warpsky.usd.weather.weather_state.WeatherState` s.

What is read (CM1's ``writeout_nc.F``; the names of ``output_format = 2`` files):

============== ============================ ========= =============================================================
variable       dimensions                   unit      meaning
============== ============================ ========= =============================================================
``xh, yh``     ``xh``, ``yh``               km or m   scalar-point (cell-centre) coordinates; the ``units``
                                                      attribute says which (``outunits``: km by default)
``zh``         ``zh``                       km or m   nominal height of the scalar levels (``z`` on ``nk`` in files
                                                      of older releases); a stretched axis is resampled
``th``         time, zh, yh, xh             K         potential temperature
``prs``        time, zh, yh, xh             Pa        pressure
``qv``         time, zh, yh, xh             kg/kg     water vapour (optional: refines the dry-air density)
``qc qr qi     time, zh, yh, xh             kg/kg     cloud water, rain, cloud ice, snow, graupel (or hail, when
qs qg``                                               ``ihail = 1``) mixing ratios; those present are read, at
                                                      least one is required
``nci ncr      time, zh, yh, xh             1/kg      number concentrations of a two-moment scheme (Morrison:
ncs ncg``                                             ``ptype = 5``), optional: they set the size distributions
``u, v, w``    on ``xf``, ``yf``, ``zf``    m/s       ground-relative wind on the staggered faces (optional: all
                                                      three give the velocity for motion blur)
``time``       time                         s         time since the simulation began
``umove,       time                         m/s       the domain's motion (``imove = 1``): the grid at time t sits
vmove``                                               umove·t east and vmove·t north of where it began
============== ============================ ========= =============================================================

Without a ``units`` attribute on ``xh`` the coordinates are taken in km, CM1's default. The ground is flat at
z = 0 (CM1's terrain, ``terrain_flag``, is not read).
"""

from __future__ import annotations

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.usd.weather import netcdf
from warpsky.usd.weather.regrid import ColumnWeights, default_spacing, destagger, regular_levels
from warpsky.usd.weather.weather_state import WeatherState

#: CM1 variable -> hydrometeor (:data:`~warpsky.model.water_optics.HYDROMETEORS`).
MIXING_RATIOS = {"qc": "cloud", "qr": "rain", "qi": "ice", "qs": "snow", "qg": "graupel"}
#: CM1 number concentrations [1/kg] of two-moment schemes -> hydrometeor.
NUMBERS = {"nci": "ice", "ncr": "rain", "ncs": "snow", "ncg": "graupel"}


def is_cm1(ds) -> bool:
    """Whether a dataset looks like CM1 output (its scalar-point coordinates)."""
    return "xh" in ds.variables and "th" in ds.variables


def _axes(ds, path) -> tuple[tuple[str, str, str], np.ndarray, np.ndarray, np.ndarray]:
    """(dims of a scalar field as (z, y, x), x [m], y [m], z [m])."""
    xh = netcdf.require(ds, path, "xh", "west-east scalar-point coordinate")
    yh = netcdf.require(ds, path, "yh", "south-north scalar-point coordinate")
    zname = "zh" if "zh" in ds.variables else "z"
    zh = netcdf.require(ds, path, zname, "height of the scalar levels (zh, or z in older releases)")
    scale = netcdf.length_scale(xh, path)
    x, y = np.asarray(xh.values, np.float64) * scale, np.asarray(yh.values, np.float64) * scale
    z = np.asarray(zh.values, np.float64) * netcdf.length_scale(zh, path)
    dims = (zh.dims[0], yh.dims[0], xh.dims[0])
    return dims, x, y, z


def read_cm1(path, ds, *, dz: float | None = None) -> list[WeatherState]:
    """Every time of a CM1 output file, on a regular grid.

    Args:
        path: The file (named in errors).
        ds: Its open xarray Dataset.
        dz: Vertical spacing [m] of the regular grid for a stretched vertical axis (default: its finest step,
            at most 256 levels); a uniform axis keeps its own.
    """
    dims, x, y, z = _axes(ds, path)
    dx = netcdf.uniform_spacing(x, path, "xh")
    dy = netcdf.uniform_spacing(y, path, "yh")
    theta = netcdf.values(ds, path, "th", dims, "potential temperature [K]")
    pressure = netcdf.values(ds, path, "prs", dims, "pressure [Pa]")
    ratios, vapour = netcdf.water(ds, path, dims, MIXING_RATIOS, "qv")
    numbers = {hydro: netcdf.values(ds, path, name, dims, "number concentration [1/kg]")
               for name, hydro in NUMBERS.items() if name in ds.variables and hydro in ratios}
    wind = _staggered_wind(ds, path, dims)
    times, moves = _times(ds, path, theta.ndim > 3, theta.shape[0] if theta.ndim > 3 else 1)
    levels, spacing, weights = _levels(z, dz, (len(x), len(y)))
    states = []
    for index, (seconds, (east, north)) in enumerate(zip(times, moves, strict=True)):
        from warpsky.model.water_optics import dry_air_density, temperature_from_theta, water_content

        p = netcdf.at_time(pressure, 3, index)
        rho = dry_air_density(p, temperature_from_theta(netcdf.at_time(theta, 3, index), p),
                              None if vapour is None else netcdf.at_time(vapour, 3, index))
        water = {hydro: _regular(water_content(netcdf.at_time(q, 3, index), rho), weights)
                 for hydro, q in ratios.items()}
        number = {hydro: _regular(water_content(netcdf.at_time(n, 3, index), rho), weights).astype(np.float32)
                  for hydro, n in numbers.items()}
        velocity = None
        if wind is not None:
            velocity = np.stack([_regular(netcdf.at_time(c, 3, index), weights) for c in wind], axis=-1)
        states.append(WeatherState(
            source=str(path), time=float(seconds), label=f"t={seconds:g}s",
            origin=(x[0] + east, y[0] + north, levels[0]), spacing=(dx, dy, spacing),
            water={k: v.astype(np.float32) for k, v in water.items()}, number=number,
            velocity=None if velocity is None else velocity.astype(np.float32)))
    return states


def _levels(z: np.ndarray, dz: float | None, columns: tuple[int, int]
            ) -> tuple[np.ndarray, float, ColumnWeights | None]:
    """The regular levels (cell centres [m]), their spacing, and where each falls among CM1's levels (the same in
    every one of the ``columns``); CM1's own levels and None when they are uniform and no ``dz`` is asked."""
    steps = np.diff(z)
    if np.any(steps <= 0.0):
        raise SceneError("CM1 scalar levels must increase upwards")
    if dz is None and np.ptp(steps) <= 1e-3 * steps.mean():
        return z.copy(), float(steps.mean()), None
    bottom = max(0.0, z[0] - 0.5 * steps[0])
    top = z[-1] + 0.5 * steps[-1]
    spacing = float(dz) if dz is not None else default_spacing(z, bottom, top)
    levels = regular_levels(bottom, top, spacing)
    weights = ColumnWeights.between(np.broadcast_to(z, (*columns, len(z))), levels, np.zeros(columns))
    return levels, spacing, weights


def _regular(field_zyx: np.ndarray, weights: ColumnWeights | None) -> np.ndarray:
    """A (z, y, x) field as (x, y, z) on the regular levels (CM1's own when ``weights`` is None)."""
    xyz = np.transpose(field_zyx, (2, 1, 0))
    return xyz if weights is None else weights.apply(xyz)


def _staggered_wind(ds, path, dims) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(u, v, w) [m/s] at the scalar points, each (time, z, y, x) or (z, y, x); None unless all three are given."""
    if not all(name in ds.variables for name in ("u", "v", "w")):
        return None
    zdim, ydim, xdim = dims
    zf = "zf" if "zf" in ds.sizes else "nkp1"
    yf = "yf" if "yf" in ds.sizes else "njp1"
    xf = "xf" if "xf" in ds.sizes else "nip1"
    u = netcdf.values(ds, path, "u", (zdim, ydim, xf), "west-east wind on the xf faces [m/s]")
    v = netcdf.values(ds, path, "v", (zdim, yf, xdim), "south-north wind on the yf faces [m/s]")
    w = netcdf.values(ds, path, "w", (zf, ydim, xdim), "vertical wind on the zf faces [m/s]")
    return destagger(u, -1), destagger(v, -2), destagger(w, -3)


def _times(ds, path, has_time: bool, count: int) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Seconds since the simulation began for each time, and the domain's offset [m] east and north then."""
    if "time" in ds.variables:
        var = ds["time"]
        seconds = np.atleast_1d(np.asarray(var.values, np.float64)) * netcdf.time_scale(var, path)
    elif has_time:
        raise SceneError(f"{path}: missing variable 'time' (seconds since the simulation began)")
    else:
        seconds = np.zeros(1)
    if len(seconds) != count:
        raise SceneError(f"{path}: variable 'time' has {len(seconds)} values for {count} output times")
    moves = []
    for index, t in enumerate(seconds):
        offset = []
        for name in ("umove", "vmove"):
            speed = np.atleast_1d(np.asarray(ds[name].values, np.float64)) if name in ds.variables else np.zeros(1)
            offset.append(float(speed[min(index, len(speed) - 1)]) * float(t))
        moves.append((offset[0], offset[1]))
    return seconds, moves

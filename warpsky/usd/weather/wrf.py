"""WRF (Skamarock et al., the ARW) ``wrfout`` files as :class:`~warpsky.usd.weather.weather_state.WeatherState` s.

What is read (the ARW's history variables; dimensions ``Time``, ``bottom_top``, ``south_north``, ``west_east``
and their ``_stag`` versions):

=============================== ===================== ======= =====================================================
variable                        grid                  unit    meaning
=============================== ===================== ======= =====================================================
``P``, ``PB``                   mass points           Pa      perturbation and base-state pressure: p = P + PB
``T``                           mass points           K       perturbation potential temperature: θ = T + 300 K
``PH``, ``PHB``                 w levels (stag)       m²/s²   perturbation and base geopotential: the w levels'
                                                              height z = (PH + PHB) / g, g = 9.81 m/s²
``QCLOUD QRAIN QICE QSNOW       mass points           kg/kg   hydrometeor mixing ratios; those present are read,
QGRAUP``                                                      at least one is required
``QNCLOUD QNICE QNRAIN QNSNOW    mass points           1/kg    number concentrations of two-moment schemes
QNGRAUPEL``                                                   (Morrison, Thompson), optional: they set the size
                                                              distributions
``QVAPOR``                      mass points           kg/kg   water vapour (optional: refines the dry-air density)
``RE_CLOUD``, ``RE_ICE``        mass points           m       effective radii (optional; where > 0 they replace
                                                              the default droplet and ice radii)
``U``, ``V``, ``W``             x, y, z faces         m/s     wind (optional: all three give the motion-blur
                                                              velocity)
``HGT``                         mass points (2-D)     m       terrain height: the terrain mesh and the ground
``XTIME``                       Time                  min     minutes since the simulation began (else 0)
``Times``                       Time, DateStrLen      –       the date of each time (labels)
attributes ``DX``, ``DY``                             m       grid spacing
=============================== ===================== ======= =====================================================

The mass points' heights are the mean of the two w levels around them. Each column of terrain-following levels is
resampled linearly to regular heights (spacing ``dz``) from the lowest terrain up to the top mass level; under the
terrain the water is 0, between the terrain and the lowest mass level it is the lowest level's. The horizontal grid
is taken as flat and Cartesian on the map projection's plane (map-scale factors are not applied), its first mass
point at x = y = 0.
"""

from __future__ import annotations

import numpy as np

from warpsky.core.errors import SceneError
from warpsky.usd.weather import netcdf
from warpsky.usd.weather.regrid import ColumnWeights, default_spacing, destagger, regular_levels
from warpsky.usd.weather.weather_state import Terrain, WeatherState

#: WRF variable -> hydrometeor (:data:`~warpsky.model.water_optics.HYDROMETEORS`).
MIXING_RATIOS = {"QCLOUD": "cloud", "QRAIN": "rain", "QICE": "ice", "QSNOW": "snow", "QGRAUP": "graupel"}
#: WRF number concentrations [1/kg] of two-moment schemes -> hydrometeor.
NUMBERS = {"QNCLOUD": "cloud", "QNICE": "ice", "QNRAIN": "rain", "QNSNOW": "snow", "QNGRAUPEL": "graupel"}
#: WRF's effective-radius diagnostics [m] -> hydrometeor.
RADII = {"RE_CLOUD": "cloud", "RE_ICE": "ice"}
#: Gravity [m/s²] of WRF's geopotential (module_model_constants: g = 9.81).
GRAVITY = 9.81
MASS = ("bottom_top", "south_north", "west_east")
W_LEVELS = ("bottom_top_stag", "south_north", "west_east")


def is_wrf(ds) -> bool:
    """Whether a dataset looks like a wrfout file."""
    return "PHB" in ds.variables or "QCLOUD" in ds.variables or "bottom_top_stag" in ds.sizes


def _spacing(ds, path) -> tuple[float, float]:
    out = []
    for name in ("DX", "DY"):
        if name not in ds.attrs:
            raise SceneError(f"{path}: missing global attribute {name!r} (grid spacing [m])")
        out.append(float(np.asarray(ds.attrs[name]).reshape(-1)[0]))
    return out[0], out[1]


def read_wrf(path, ds, *, dz: float | None = None) -> list[WeatherState]:
    """Every time of a wrfout file, resampled to regular heights.

    Args:
        path: The file (named in errors).
        ds: Its open xarray Dataset.
        dz: Vertical spacing [m] of the regular grid (default: the finest step of the domain-mean column, at most
            256 levels).
    """
    for name, what in zip(MASS, ("vertical mass levels", "south-north mass points", "west-east mass points"),
                          strict=True):
        netcdf.dimension(ds, path, name, what)
    dx, dy = _spacing(ds, path)
    p = netcdf.values(ds, path, "P", MASS, "perturbation pressure [Pa]")
    p = p + netcdf.values(ds, path, "PB", MASS, "base-state pressure [Pa]")
    theta = netcdf.values(ds, path, "T", MASS, "perturbation potential temperature [K]") + 300.0
    geopotential = netcdf.values(ds, path, "PH", W_LEVELS, "perturbation geopotential [m2/s2]")
    geopotential = geopotential + netcdf.values(ds, path, "PHB", W_LEVELS, "base-state geopotential [m2/s2]")
    ratios, vapour = netcdf.water(ds, path, MASS, MIXING_RATIOS, "QVAPOR")
    radii = {hydro: netcdf.values(ds, path, name, MASS, "effective radius [m]")
             for name, hydro in RADII.items() if name in ds.variables}
    numbers = {hydro: netcdf.values(ds, path, name, MASS, "number concentration [1/kg]")
               for name, hydro in NUMBERS.items() if name in ds.variables and hydro in ratios}
    hgt = netcdf.values(ds, path, "HGT", MASS[1:], "terrain height [m]") if "HGT" in ds.variables else None
    wind = _staggered_wind(ds, path)
    seconds, labels = _times(ds, path, p.shape[0] if p.ndim > 3 else 1)
    states = []
    for index, (t, label) in enumerate(zip(seconds, labels, strict=True)):
        stag = np.transpose(netcdf.at_time(geopotential, 3, index), (2, 1, 0)) / GRAVITY  # (x, y, k+1)
        heights = 0.5 * (stag[..., :-1] + stag[..., 1:])
        ground = stag[..., 0] if hgt is None else np.transpose(netcdf.at_time(hgt, 2, index))
        bottom, top = float(ground.min()), float(heights[..., -1].min())
        spacing = float(dz) if dz is not None else default_spacing(heights, bottom, top)
        levels = regular_levels(bottom, top, spacing)
        states.append(_state(path, index, t, label, (dx, dy, spacing), levels, heights, ground,
                             (p, theta, vapour, ratios, radii, numbers, wind)))
    return states


def _state(path, index: int, t: float, label: str, spacing, levels, heights, ground, fields) -> WeatherState:
    """One time's WeatherState: the water, radii and wind of time ``index`` resampled to the regular levels."""
    from warpsky.model.water_optics import dry_air_density, temperature_from_theta, water_content

    p, theta, vapour, ratios, radii, numbers, wind = fields

    def column(data, ndim: int = 3) -> np.ndarray:  # (k, y, x) at this time -> (x, y, k)
        return np.transpose(netcdf.at_time(data, ndim, index), (2, 1, 0))

    pressure = column(p)
    rho = dry_air_density(pressure, temperature_from_theta(column(theta), pressure),
                          None if vapour is None else column(vapour))

    weights = ColumnWeights.between(heights, levels, ground)  # once for every field of this time

    def regular(values: np.ndarray) -> np.ndarray:
        return weights.apply(values).astype(np.float32)

    water = {hydro: regular(water_content(column(q), rho)) for hydro, q in ratios.items()}
    radius = {hydro: regular(column(r)) for hydro, r in radii.items()}
    number = {hydro: regular(water_content(column(n), rho)) for hydro, n in numbers.items()}
    velocity = None
    if wind is not None:
        velocity = np.stack([regular(column(c)) for c in wind], axis=-1)
    return WeatherState(source=str(path), time=float(t), label=label, origin=(0.0, 0.0, levels[0]),
                        spacing=spacing, water=water, radius=radius, number=number, velocity=velocity,
                        terrain=Terrain(np.asarray(ground, dtype=np.float64)))


def _staggered_wind(ds, path) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(U, V, W) [m/s] at the mass points, each (Time, k, y, x); None unless all three are given."""
    if not all(name in ds.variables for name in ("U", "V", "W")):
        return None
    u = netcdf.values(ds, path, "U", ("bottom_top", "south_north", "west_east_stag"), "x wind [m/s]")
    v = netcdf.values(ds, path, "V", ("bottom_top", "south_north_stag", "west_east"), "y wind [m/s]")
    w = netcdf.values(ds, path, "W", W_LEVELS, "vertical wind [m/s]")
    return destagger(u, -1), destagger(v, -2), destagger(w, -3)


def _times(ds, path, count: int) -> tuple[list[float], list[str]]:
    """Seconds since the simulation began (``XTIME``, else 0 for each) and a label per time (``Times``)."""
    if "XTIME" in ds.variables:
        var = ds["XTIME"]
        scale = netcdf.time_scale(var, path) if "units" in var.attrs else 60.0  # WRF writes minutes
        seconds = [float(v) * scale for v in np.atleast_1d(np.asarray(var.values, np.float64))]
    else:
        seconds = [0.0] * count
    if len(seconds) != count:
        raise SceneError(f"{path}: variable 'XTIME' has {len(seconds)} values for {count} output times")
    labels = [f"t={s:g}s" for s in seconds]
    if "Times" in ds.variables:
        raw = np.atleast_1d(np.asarray(ds["Times"].values))
        if raw.ndim == 2:  # (Time, DateStrLen) characters
            raw = np.array([b"".join(np.asarray(row, dtype="S1").tolist()) for row in raw])
        texts = [r.decode("ascii", "replace") if isinstance(r, bytes) else str(r) for r in raw]
        if len(texts) == count:
            labels = [t.strip("\x00 ").strip() or label for t, label in zip(texts, labels, strict=True)]
    return seconds, labels

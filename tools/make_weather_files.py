"""Write small CM1 and WRF netCDF files in the models' documented layouts, for ``warpsky import-weather``'s tests
and as examples.

- CM1 (``writeout_nc.F``, ``output_format = 2``): dimensions ``time, zh, yh, xh`` and the staggered ``xf, yf, zf``;
  coordinates in km (``units = "km"``, CM1's default ``outunits``); ``th`` [K], ``prs`` [Pa], ``qv qc qr qi qs qg``
  [kg/kg] on the scalar points, ``u`` on ``xf``, ``v`` on ``yf``, ``w`` on ``zf`` [m/s]; ``time`` [s]; ``umove``,
  ``vmove`` [m/s].
- WRF ``wrfout``: dimensions ``Time, bottom_top(_stag), south_north(_stag), west_east(_stag), DateStrLen``;
  ``P + PB`` [Pa], ``T`` (θ − 300 K), ``PH + PHB`` (g × height of the w levels), ``QVAPOR QCLOUD QRAIN QICE QSNOW
  QGRAUP`` [kg/kg], ``U V W`` on their faces, ``HGT`` [m], ``XTIME`` [minutes], ``Times``; attributes ``DX, DY``
  [m]. Levels are terrain-following: the w levels sit at z = HGT + (z_top − HGT) η for stretched η in [0, 1].

The sample storm (both files): a cell of cloud water (peak 1.5 g/kg) from 1.5 to 8 km, a rain shaft under it, cloud
ice and snow above 6 km, graupel in the updraft core; an updraft of 10 m/s in the cell and a 5 m/s westerly.
The WRF sample stands it beside an 800 m Gaussian hill.

Run:  python tools/make_weather_files.py [--out data/weather] [--n 24] [--nz 20] [--times 0,900]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GRAVITY = 9.81
R_DRY, CP_DRY = 287.04, 1005.7


def pressure_at(z: np.ndarray, theta0: float = 300.0) -> np.ndarray:
    """Hydrostatic pressure [Pa] at height ``z`` [m] in air of constant potential temperature ``theta0``."""
    return 1.0e5 * (1.0 - GRAVITY * np.asarray(z) / (CP_DRY * theta0)) ** (CP_DRY / R_DRY)


def cm1_dataset(x_km, y_km, z_km, fields: dict, *, times, wind=None, zf_km=None, units: str = "km",
                move=(0.0, 0.0)):
    """A CM1 output Dataset. ``fields``: name -> (time, zh, yh, xh) array; ``wind``: (u on xf, v on yf, w on zf)
    arrays, each with a leading time axis; coordinates in ``units`` (km or meters)."""
    import xarray as xr

    x, y, z = (np.asarray(a, np.float32) for a in (x_km, y_km, z_km))
    data = {name: (("time", "zh", "yh", "xh"), np.asarray(v, np.float32)) for name, v in fields.items()}
    coords = {"xh": ("xh", x, {"units": units, "long_name": "west-east location of scalar grid points"}),
              "yh": ("yh", y, {"units": units}), "zh": ("zh", z, {"units": units}),
              "time": ("time", np.asarray(times, np.float32), {"units": "seconds"})}
    if wind is not None:
        u, v, w = wind
        zf = np.concatenate([[0.0], 0.5 * (z[1:] + z[:-1]), [2 * z[-1] - 0.5 * (z[-1] + z[-2])]]) \
            if zf_km is None else np.asarray(zf_km)
        coords |= {"xf": ("xf", _faces(x), {"units": units}), "yf": ("yf", _faces(y), {"units": units}),
                   "zf": ("zf", zf.astype(np.float32), {"units": units})}
        data |= {"u": (("time", "zh", "yh", "xf"), np.asarray(u, np.float32)),
                 "v": (("time", "zh", "yf", "xh"), np.asarray(v, np.float32)),
                 "w": (("time", "zf", "yh", "xh"), np.asarray(w, np.float32))}
    data |= {"umove": (("time",), np.full(len(times), move[0], np.float32)),
             "vmove": (("time",), np.full(len(times), move[1], np.float32))}
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update({"CM1 version": "cm1r21 layout (warpsky test file)", "x_units": units, "ptype": 5})
    return ds


def _faces(centres: np.ndarray) -> np.ndarray:
    step = float(centres[1] - centres[0])
    return np.concatenate([centres - 0.5 * step, [centres[-1] + 0.5 * step]]).astype(np.float32)


def wrf_dataset(dx: float, dy: float, hgt: np.ndarray, z_stag: np.ndarray, fields: dict, *, pressure, theta,
                minutes, wind=None, dates=None):
    """A wrfout Dataset. ``hgt``: (Time, y, x) [m]; ``z_stag``: (Time, k + 1, y, x) heights of the w levels [m];
    ``fields``: WRF name -> (Time, k, y, x); ``pressure`` [Pa] and ``theta`` [K] on the mass points; ``wind``:
    (U on x faces, V on y faces, W on w levels)."""
    import xarray as xr

    mass = ("Time", "bottom_top", "south_north", "west_east")
    data = {name: (mass, np.asarray(v, np.float32)) for name, v in fields.items()}
    pressure = np.asarray(pressure, np.float64)
    base = np.broadcast_to(pressure.mean(axis=(0, 2, 3), keepdims=True), pressure.shape)
    data |= {"PB": (mass, base.astype(np.float32)), "P": (mass, (pressure - base).astype(np.float32)),
             "T": (mass, (np.asarray(theta) - 300.0).astype(np.float32)),
             "PHB": (("Time", "bottom_top_stag", "south_north", "west_east"),
                     (GRAVITY * np.asarray(z_stag)).astype(np.float32)),
             "PH": (("Time", "bottom_top_stag", "south_north", "west_east"), np.zeros(np.shape(z_stag), np.float32)),
             "HGT": (("Time", "south_north", "west_east"), np.asarray(hgt, np.float32)),
             "XTIME": (("Time",), np.asarray(minutes, np.float32), {"units": "minutes since simulation start"})}
    if wind is not None:
        u, v, w = wind
        data |= {"U": (("Time", "bottom_top", "south_north", "west_east_stag"), np.asarray(u, np.float32)),
                 "V": (("Time", "bottom_top", "south_north_stag", "west_east"), np.asarray(v, np.float32)),
                 "W": (("Time", "bottom_top_stag", "south_north", "west_east"), np.asarray(w, np.float32))}
    dates = dates or [f"2004-05-29_{18 + int(m) // 60:02d}:{int(m) % 60:02d}:00" for m in minutes]
    data["Times"] = (("Time", "DateStrLen"), np.array([list(d) for d in dates], dtype="S1"))
    ds = xr.Dataset(data)
    ds.attrs.update({"DX": np.float32(dx), "DY": np.float32(dy), "TITLE": "OUTPUT FROM WRF V4 (warpsky test file)"})
    return ds


def storm(X, Y, Z, t: float) -> dict[str, np.ndarray]:
    """The sample cell's mixing ratios [kg/kg] at points (X, Y, Z) [m] and time t [s] (centred at x = y = 0)."""
    r = np.hypot(X - 5.0 * t, Y)
    grow = 1.0 + t / 1800.0
    cloud = 1.5e-3 * np.exp(-(r / 3500.0) ** 2) * np.exp(-((Z - 4500.0) / 2500.0) ** 2) * (Z > 1500.0) * grow
    rain = 1.0e-3 * np.exp(-(np.hypot(X - 5.0 * t - 1500.0, Y) / 2500.0) ** 2) * (Z < 4500.0) * grow
    ice = 4.0e-4 * np.exp(-(r / 5000.0) ** 2) * np.exp(-((Z - 8000.0) / 1200.0) ** 2)
    snow = 6.0e-4 * np.exp(-(r / 3000.0) ** 2) * np.exp(-((Z - 6500.0) / 1200.0) ** 2)
    graupel = 5.0e-4 * np.exp(-(r / 1500.0) ** 2) * np.exp(-((Z - 5000.0) / 1500.0) ** 2)
    return {"cloud": cloud, "rain": rain, "ice": ice, "snow": snow, "graupel": graupel}


def sample_cm1(path: Path, n: int = 24, nz: int = 20, times=(0.0, 900.0), dx: float = 1000.0, dz: float = 500.0):
    """The sample storm as CM1 output at ``path``."""
    x = (np.arange(n) - (n - 1) / 2) * dx
    z = (np.arange(nz) + 0.5) * dz
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")  # (zh, yh, xh)
    names = {"cloud": "qc", "rain": "qr", "ice": "qi", "snow": "qs", "graupel": "qg"}
    fields = {name: [] for name in ("th", "prs", "qv", *names.values())}
    for t in times:
        q = storm(X, Y, Z, t)
        for hydro, name in names.items():
            fields[name].append(q[hydro])
        fields["th"].append(np.full(Z.shape, 300.0))
        fields["prs"].append(pressure_at(Z))
        fields["qv"].append(0.012 * np.exp(-Z / 2500.0))
    updraft = [10.0 * np.exp(-(np.hypot(X[:1].repeat(nz + 1, 0) - 5.0 * t, Y[:1].repeat(nz + 1, 0)) / 3000.0) ** 2)
               for t in times]
    wind = ([np.full((nz, n, n + 1), 5.0)] * len(times), [np.zeros((nz, n + 1, n))] * len(times), updraft)
    ds = cm1_dataset(x / 1000.0, x / 1000.0, z / 1000.0, fields, times=times, wind=wind)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.to_netcdf(path, engine="netcdf4")
    return path


def eta_levels(nz: int) -> np.ndarray:
    """nz + 1 stretched w levels η in [0, 1], finer near the ground (as WRF's default levels are)."""
    s = np.linspace(0.0, 1.0, nz + 1)
    return 0.6 * s + 0.4 * s**2


def sample_wrf(path: Path, n: int = 24, nz: int = 20, minutes=(0.0, 15.0), dx: float = 1000.0,
               z_top: float = 12000.0):
    """The sample storm as a wrfout file at ``path``, beside an 800 m hill."""
    x = np.arange(n) * dx
    centre = (n - 1) / 2 * dx
    Yh, Xh = np.meshgrid(x, x, indexing="ij")  # (south_north, west_east)
    hgt = 800.0 * np.exp(-(((Xh - centre - 6000.0) ** 2 + (Yh - centre) ** 2) / 3000.0**2))
    z_stag = hgt[None] + (z_top - hgt[None]) * eta_levels(nz)[:, None, None]  # (k + 1, y, x)
    z_mass = 0.5 * (z_stag[1:] + z_stag[:-1])
    names = {"cloud": "QCLOUD", "rain": "QRAIN", "ice": "QICE", "snow": "QSNOW", "graupel": "QGRAUP"}
    fields = {name: [] for name in ("QVAPOR", *names.values())}
    for m in minutes:
        q = storm(Xh[None] - centre, Yh[None] - centre, z_mass, 60.0 * m)
        for hydro, name in names.items():
            fields[name].append(q[hydro])
        fields["QVAPOR"].append(0.012 * np.exp(-z_mass / 2500.0))
    count = len(minutes)
    wind = ([np.full((nz, n, n + 1), 5.0)] * count, [np.zeros((nz, n + 1, n))] * count,
            [np.zeros((nz + 1, n, n))] * count)
    ds = wrf_dataset(dx, dx, [hgt] * count, [z_stag] * count, fields, pressure=[pressure_at(z_mass)] * count,
                     theta=np.full((count, *z_mass.shape), 300.0), minutes=minutes, wind=wind)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.to_netcdf(path, engine="netcdf4")
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "data" / "weather")
    parser.add_argument("--n", type=int, default=24, help="horizontal cells per side (default 24)")
    parser.add_argument("--nz", type=int, default=20, help="vertical levels (default 20)")
    parser.add_argument("--times", default="0,900", help="output times [s], comma-separated (default 0,900)")
    args = parser.parse_args(argv)
    times = [float(t) for t in args.times.split(",")]
    print(sample_cm1(args.out / "cm1out.nc", args.n, args.nz, times))
    print(sample_wrf(args.out / "wrfout_d01.nc", args.n, args.nz, [t / 60.0 for t in times]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""``warpsky import-weather``: CM1 or WRF netCDF output to per-species extinction grids and a USD stage that
``warpsky render`` renders (:mod:`warpsky.usd.weather`, :mod:`warpsky.model.water_optics`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from warpsky.cli.options import resolution_arg
from warpsky.core.errors import UsageError

DESCRIPTION = """\
Read CM1 or WRF netCDF output (every time in every FILE), convert each hydrometeor's mixing ratio to the
extinction coefficient of the species warpsky renders (mixing ratio x dry-air density from pressure and
temperature -> water content -> extinction from the hydrometeor's size distribution; graupel renders as snow),
and write DIR/NAME/<species>.<frame>.nvdb and the stage DIR/NAME.usda (camera, sun, air, ground or terrain; one
time code per time), ready for 'warpsky render DIR/NAME.usda'. Needs the weather extra:
pip install 'warpsky[weather]'."""


def add_parser(sub) -> None:
    cmd = sub.add_parser("import-weather", help="turn CM1 or WRF netCDF output into a stage of per-species grids",
                         description=DESCRIPTION)
    cmd.add_argument("files", nargs="+", type=Path, metavar="FILE", help="CM1 or WRF (wrfout) netCDF files")
    cmd.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder for the stage and its grids")
    cmd.add_argument("--name", default="weather", help="stage name: DIR/NAME.usda and DIR/NAME/ (default weather)")
    cmd.add_argument("--dz", type=float, default=None, metavar="M",
                     help="vertical spacing [m] of the regular grid WRF's terrain-following levels (and a stretched "
                     "CM1 axis) are resampled to (default: the finest level spacing, at most 256 levels)")
    cmd.add_argument("--cloud-radius", type=float, default=None, metavar="UM",
                     help="effective radius of cloud droplets [um] (default 10; a file's RE_CLOUD wins)")
    cmd.add_argument("--ice-radius", type=float, default=None, metavar="UM",
                     help="effective radius of cloud ice [um] (default 25; a file's RE_ICE wins)")
    cmd.add_argument("--graupel-density", type=float, default=None, metavar="KG_M3",
                     help="bulk density of the graupel category [kg/m^3] (default 400; 900 where it holds hail, as "
                     "CM1's Morrison scheme with ihail = 1)")
    cmd.add_argument("--sun", default="35,225", metavar="ELEV,AZIM",
                     help="sun elevation and azimuth clockwise from north [degrees] (default 35,225: south-west)")
    cmd.add_argument("--res", type=resolution_arg, default=(384, 256), metavar="WxH",
                     help="the stage's render resolution (default 384x256)")


def _sun(text: str) -> tuple[float, float]:
    try:
        elevation, azimuth = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"--sun takes ELEVATION,AZIMUTH in degrees, got {text!r}") from None
    if not -10.0 <= elevation <= 90.0:
        raise UsageError(f"--sun: elevation must lie in [-10, 90] degrees, got {elevation:g}")
    return elevation, azimuth


def _hydrometeors(args):
    """The water-to-extinction table with the radii the options ask for."""
    from warpsky.model.water_optics import HYDROMETEORS

    table = dict(HYDROMETEORS)
    for option, name in ((args.cloud_radius, "cloud"), (args.ice_radius, "ice")):
        if option is not None:
            if not option > 0.0:
                raise UsageError(f"--{name}-radius must be > 0 um, got {option:g}")
            table[name] = replace(table[name], effective_radius=option * 1e-6)
    if args.graupel_density is not None:
        if not args.graupel_density > 0.0:
            raise UsageError(f"--graupel-density must be > 0 kg/m^3, got {args.graupel_density:g}")
        table["graupel"] = replace(table["graupel"], particle_density=args.graupel_density)
    return table


def cmd_import_weather(args) -> int:
    from warpsky.usd.weather import read_weather
    from warpsky.usd.weather.author import write_weather_stage

    if args.dz is not None and not args.dz > 0.0:
        raise UsageError(f"--dz must be > 0 m, got {args.dz:g}")
    sun = _sun(args.sun)
    table = _hydrometeors(args)
    states = read_weather(args.files, dz=args.dz)
    result = write_weather_stage(states, args.out, name=args.name, hydrometeors=table, sun=sun,
                                 resolution=args.res, sources=[str(f) for f in args.files])
    first = states[0]
    print(f"{len(states)} time(s) from {len(args.files)} file(s); grid {'x'.join(map(str, first.shape))} cells of "
          f"{' x '.join(f'{s:g}' for s in first.spacing)} m")
    for species, peak in result.peak_extinction.items():
        print(f"  {species:6s} peak extinction {peak:.3g} 1/m")
    if any("velocity" in g for g in result.grids):
        print("  velocity field written (motion blur with an open shutter, e.g. --shutter 0:0.5)")
    print(result.stage)
    return 0

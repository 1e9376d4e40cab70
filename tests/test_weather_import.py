"""CM1 and WRF netCDF output read into regular grids (warpsky.usd.weather) and written as a stage by
``warpsky import-weather``: the extinction of a hand-made file against the formulas, staggered winds and
terrain-following levels against analytic fields, the one-line errors of bad files, and a render of the stage.

The files follow the models' documented layouts (tools/make_weather_files.py).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
pytest.importorskip("xarray")
pytest.importorskip("netCDF4")
import make_weather_files as mk  # noqa: E402

from warpsky.model.water_optics import (  # noqa: E402
    EPSILON,
    HYDROMETEORS,
    R_DRY,
    extinction,
    temperature_from_theta,
)
from warpsky.usd.weather import read_weather  # noqa: E402


def _air_density(p, theta, qv):
    return p / (R_DRY * temperature_from_theta(theta, p) * (1.0 + qv / EPSILON))


def _uniform_cm1(tmp_path, nz=6, n=5, fields=None, **kwargs) -> Path:
    """A CM1 file on a 1 km x 1 km x 500 m grid (coordinates in km) with constant air."""
    x = (np.arange(n) + 0.5) * 1.0
    z = (np.arange(nz) + 0.5) * 0.5
    shape = (1, nz, n, n)
    base = {"th": np.full(shape, 300.0), "prs": np.full(shape, 9.0e4), "qv": np.full(shape, 0.01),
            "qc": np.zeros(shape)}
    base.update(fields or {})
    path = tmp_path / "cm1out.nc"
    mk.cm1_dataset(x, x, z, base, times=[0.0], **kwargs).to_netcdf(path, engine="netcdf4")
    return path


def test_hand_made_cm1_extinction_matches_the_formulas(tmp_path):
    nz, n = 6, 5
    shape = (1, nz, n, n)
    qc, qr, qs, qg = (np.zeros(shape) for _ in range(4))
    qc[0, 2, 1, 3] = 1.2e-3  # cell z = 1.25 km, y = 1.5 km, x = 3.5 km
    qr[0, 0, 2, 2] = 2.0e-3
    qs[0, 4, 0, 0] = 5.0e-4
    qg[0, 4, 0, 0] = 8.0e-4
    path = _uniform_cm1(tmp_path, fields={"qc": qc, "qr": qr, "qs": qs, "qg": qg})
    (state,) = read_weather([path])
    rho = _air_density(9.0e4, 300.0, 0.01)
    np.testing.assert_allclose(state.origin, [500.0, 500.0, 250.0])
    np.testing.assert_allclose(state.spacing, [1000.0, 1000.0, 500.0])
    beta = state.extinction()
    assert set(beta) == {"cloud", "rain", "snow"}
    # indexed [x, y, z]
    np.testing.assert_allclose(beta["cloud"][3, 1, 2], 3 * 1.2e-3 * rho / (2 * 1000.0 * 10e-6), rtol=1e-5)
    np.testing.assert_allclose(beta["rain"][2, 2, 0], np.pi * 8e6 * (2e-3 * rho / (np.pi * 1000 * 8e6)) ** 0.75,
                               rtol=1e-5)
    expected_snow = extinction(HYDROMETEORS["snow"], 5e-4 * rho) + extinction(HYDROMETEORS["graupel"], 8e-4 * rho)
    np.testing.assert_allclose(beta["snow"][0, 0, 4], expected_snow, rtol=1e-5)
    assert np.count_nonzero(beta["cloud"]) == 1 and np.count_nonzero(beta["rain"]) == 1


def test_two_moment_numbers_set_the_rain_distribution(tmp_path):
    """CM1's ncr [1/kg] times the dry-air density is the rain's number concentration; the extinction follows
    the two-moment form instead of Marshall-Palmer's fixed intercept."""
    shape = (1, 6, 5, 5)
    qr, ncr = np.zeros(shape), np.zeros(shape)
    qr[0, 1, 2, 2], ncr[0, 1, 2, 2] = 2e-3, 400.0  # fewer, larger drops than Marshall-Palmer's
    qr[0, 3, 2, 2] = 1e-3  # no number: Marshall-Palmer
    (state,) = read_weather([_uniform_cm1(tmp_path, fields={"qr": qr, "ncr": ncr})])
    rho = _air_density(9.0e4, 300.0, 0.01)
    beta = state.extinction()["rain"]
    expected = extinction(HYDROMETEORS["rain"], 2e-3 * rho, number=400.0 * rho)
    np.testing.assert_allclose(beta[2, 2, 1], expected, rtol=1e-5)
    assert abs(expected / extinction(HYDROMETEORS["rain"], 2e-3 * rho) - 1.0) > 0.1
    np.testing.assert_allclose(beta[2, 2, 3], extinction(HYDROMETEORS["rain"], 1e-3 * rho), rtol=1e-5)


def test_written_grid_holds_the_extinction_at_the_model_positions(tmp_path):
    """The NanoVDB the stage references gives back each cell's extinction at the cell's own x, y, z [m]."""
    from warpsky.media.voxels.fields import load_field
    from warpsky.usd.weather.author import write_weather_stage

    shape = (1, 6, 5, 5)
    qc = np.zeros(shape)
    qc[0, 2, 1, 3], qc[0, 5, 4, 0] = 1.2e-3, 3e-4
    states = read_weather([_uniform_cm1(tmp_path, fields={"qc": qc})])
    result = write_weather_stage(states, tmp_path / "out")
    grid = load_field(result.grids[0]["cloud"])
    index_from_world = np.linalg.inv(grid.local_from_index)
    beta = states[0].extinction()["cloud"]
    for cell in [(3, 1, 2), (0, 4, 5), (2, 2, 2)]:
        world = states[0].origin + states[0].spacing * np.array(cell)
        ijk = (index_from_world @ np.append(world, 1.0))[:3]
        np.testing.assert_allclose(ijk, np.round(ijk), atol=1e-4)
        i, j, k = np.round(ijk).astype(int)
        np.testing.assert_allclose(grid.values[i, j, k], beta[cell], rtol=1e-6)


def test_cm1_staggered_wind_and_stretched_levels_against_linear_fields(tmp_path):
    """u linear in x on the xf faces and w linear in z on the zf faces average to the same lines at the centres;
    a stretched vertical axis with water linear in height resamples to that line on regular levels."""
    n, nz = 4, 6
    x = (np.arange(n) + 0.5) * 2.0  # km
    zf = np.array([0.0, 0.2, 0.5, 1.0, 1.7, 2.6, 3.8])  # km, stretched
    z = 0.5 * (zf[1:] + zf[:-1])
    Z = np.broadcast_to(z[:, None, None] * 1000.0, (nz, n, n))
    shape = (1, nz, n, n)
    xf = np.concatenate([x - 1.0, [x[-1] + 1.0]])
    u = np.broadcast_to(3.0 + 0.002 * xf * 1000.0, (1, nz, n, n + 1))
    w = np.broadcast_to(1.0 + 0.004 * zf[:, None, None] * 1000.0, (1, nz + 1, n, n))
    v = np.zeros((1, nz, n + 1, n))
    fields = {"th": np.full(shape, 300.0), "prs": np.full(shape, 9.0e4), "qc": (1e-4 + 2e-7 * Z)[None]}
    path = tmp_path / "stretched.nc"
    mk.cm1_dataset(x, x, z, fields, times=[0.0], wind=(u, v, w), zf_km=zf).to_netcdf(path, engine="netcdf4")
    (state,) = read_weather([path], dz=100.0)
    levels = state.cell_centres(2)
    np.testing.assert_allclose(state.spacing[2], 100.0)
    rho = 9.0e4 / (R_DRY * temperature_from_theta(300.0, 9.0e4))
    inside = (levels >= z[0] * 1000) & (levels <= z[-1] * 1000)
    np.testing.assert_allclose(state.water["cloud"][1, 2, inside], rho * (1e-4 + 2e-7 * levels[inside]), rtol=1e-5)
    np.testing.assert_allclose(state.velocity[:, 0, 0, 0], 3.0 + 0.002 * x * 1000.0, rtol=1e-6)
    np.testing.assert_allclose(state.velocity[0, 0, inside, 2], 1.0 + 0.004 * levels[inside], rtol=1e-5)


def test_cm1_domain_motion_and_meters(tmp_path):
    """A moving domain (umove, vmove) sits umove t east at time t; coordinates in meters are read as such."""
    x = (np.arange(3) + 0.5) * 1000.0
    z = (np.arange(4) + 0.5) * 500.0
    shape = (2, 4, 3, 3)
    fields = {"th": np.full(shape, 300.0), "prs": np.full(shape, 9e4), "qr": np.full(shape, 1e-4)}
    path = tmp_path / "moving.nc"
    mk.cm1_dataset(x, x, z, fields, times=[0.0, 600.0], units="meters", move=(12.5, 3.0)).to_netcdf(path)
    first, second = read_weather([path])
    np.testing.assert_allclose(first.origin, [500.0, 500.0, 250.0])
    np.testing.assert_allclose(second.origin, [500.0 + 12.5 * 600, 500.0 + 3.0 * 600, 250.0])
    assert (first.time, second.time) == (0.0, 600.0)


def _wrf_column_file(tmp_path, hill=900.0, n=6, nz=10) -> tuple[Path, np.ndarray, np.ndarray]:
    """A wrfout with constant air, terrain-following levels over a hill and QCLOUD linear in height."""
    x = np.arange(n) * 1000.0
    Y, X = np.meshgrid(x, x, indexing="ij")
    hgt = hill * np.exp(-((X - 2500.0) ** 2 + (Y - 2500.0) ** 2) / 1500.0**2)
    z_stag = hgt[None] + (8000.0 - hgt[None]) * mk.eta_levels(nz)[:, None, None]
    z_mass = 0.5 * (z_stag[1:] + z_stag[:-1])
    fields = {"QCLOUD": [1e-4 + 1e-7 * z_mass], "QVAPOR": [np.full(z_mass.shape, 0.005)]}
    ds = mk.wrf_dataset(1000.0, 1000.0, [hgt], [z_stag], fields, pressure=[np.full(z_mass.shape, 8.5e4)],
                        theta=np.full((1, *z_mass.shape), 295.0), minutes=[30.0])
    path = tmp_path / "wrfout_d01_2004-05-29_18:30:00"
    ds.to_netcdf(path, engine="netcdf4")
    return path, hgt, z_mass


def test_wrf_terrain_following_levels_resample_to_heights(tmp_path):
    path, hgt, z_mass = _wrf_column_file(tmp_path)
    (state,) = read_weather([path], dz=50.0)
    rho = _air_density(8.5e4, 295.0, 0.005)
    levels = state.cell_centres(2)
    assert state.label == "2004-05-29_18:30:00" and state.time == 1800.0
    np.testing.assert_allclose(state.terrain.height, hgt.T, rtol=1e-6)
    water = state.water["cloud"]
    for i, j in [(0, 0), (2, 2), (3, 2), (5, 1)]:
        column = z_mass[:, j, i]
        inside = (levels >= column[0]) & (levels <= column[-1])
        np.testing.assert_allclose(water[i, j, inside], rho * (1e-4 + 1e-7 * levels[inside]), rtol=1e-5)
        under = levels < hgt[j, i]
        assert np.all(water[i, j, under] == 0.0)
        surface = (levels >= hgt[j, i]) & (levels < column[0])
        np.testing.assert_allclose(water[i, j, surface], rho * (1e-4 + 1e-7 * column[0]), rtol=1e-5)
    assert np.count_nonzero(water[2, 2, levels < 800.0] == 0.0) > 0  # the hill top is under the ground


def _import(tmp_path, capsys, *files, name="weather"):
    code, out, err = run_cli(["import-weather", *files, "--out", tmp_path / "out", "--name", name], capsys)
    assert code == 0, err
    return tmp_path / "out" / f"{name}.usda", out


def test_missing_variable_is_one_line_naming_file_and_variable(tmp_path, capsys):
    path = _uniform_cm1(tmp_path)
    import xarray as xr

    ds = xr.open_dataset(path).load().drop_vars("prs")
    broken = tmp_path / "noprs.nc"
    ds.to_netcdf(broken)
    code, _, err = run_cli(["import-weather", broken, "--out", tmp_path / "o"], capsys)
    assert code == 2
    assert err.strip().count("\n") == 0
    assert str(broken) in err and "'prs'" in err and "missing variable" in err


def test_missing_dimension_and_attribute_and_no_hydrometeor(tmp_path, capsys):
    import xarray as xr

    path, _, _ = _wrf_column_file(tmp_path)
    ds = xr.open_dataset(path, decode_times=False).load()
    no_dx = ds.copy()
    no_dx.attrs = {k: v for k, v in ds.attrs.items() if k != "DX"}
    cases = {"dim.nc": (ds.rename_dims({"bottom_top": "levels"}), "missing dimension 'bottom_top'"),
             "nodx.nc": (no_dx, "missing global attribute 'DX'"),
             "noq.nc": (ds.drop_vars(["QCLOUD"]), "missing variable 'QCLOUD'")}
    for name, (broken, message) in cases.items():
        broken.to_netcdf(tmp_path / name)
        code, _, err = run_cli(["import-weather", tmp_path / name, "--out", tmp_path / "o"], capsys)
        assert code == 2, (name, err)
        assert err.strip().count("\n") == 0 and str(tmp_path / name) in err and message in err, err
    code, _, err = run_cli(["import-weather", tmp_path / "absent.nc", "--out", tmp_path / "o"], capsys)
    assert code == 2 and "absent.nc: no such file" in err


@pytest.mark.slow  # its first render builds the rain, ice and snow phase tables (about 40 s in the full suite)
def test_cm1_import_info_and_render(tmp_path, capsys):
    from pxr import Usd, UsdVol

    cm1 = mk.sample_cm1(tmp_path / "cm1out.nc", n=16, nz=14, times=(0.0, 900.0))
    stage_path, out = _import(tmp_path, capsys, cm1)
    assert "cloud" in out and "velocity field written" in out
    stage = Usd.Stage.Open(str(stage_path))
    assert stage.GetTimeCodesPerSecond() == pytest.approx(1.0 / 900.0)
    volume = UsdVol.Volume(stage.GetPrimAtPath("/World/Weather"))
    assert set(volume.GetFieldPaths()) == {"cloud", "rain", "ice", "snow", "velocity"}
    samples = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Weather/cloud")).GetFilePathAttr().GetTimeSamples()
    assert samples == [1.0, 2.0]
    from warpsky.media.voxels.fields import load_vector_field

    velocity = load_vector_field(stage_path.parent / "weather" / "velocity.0002.nvdb").values
    (state,) = [s for s in read_weather([cm1]) if s.time == 900.0]
    np.testing.assert_allclose(velocity[..., 2].max(), state.velocity[..., 2].max(), rtol=1e-6)  # the updraft
    np.testing.assert_allclose(velocity[..., 0].max(), 5.0, rtol=1e-6)  # the westerly
    code, info, err = run_cli(["info", stage_path, "--time", 2], capsys)
    assert code == 0, err
    for species in ("cloud", "rain", "ice", "snow"):
        assert f"/World/Weather:{species}" in info and f"{species} phase table" in info
    exr = tmp_path / "r" / "cm1.####.exr"
    code, _, err = run_cli(["render", stage_path, exr, "--frames", "2", "--res", "32x32", "--set", "spp=8"], capsys)
    assert code == 0, err
    from warpsky.output.exr import read_exr

    image = read_exr(tmp_path / "r" / "cm1.0002.exr")
    rgba, depth = image.rgba(), image.depth()
    assert rgba.shape == (32, 32, 4) and np.all(np.isfinite(rgba))
    # the camera frames the storm: cloud in the middle of the picture (its depth some km), sky above it
    assert depth[16, 16] < 3.0e4 and depth[0].min() > 1.0e5
    assert rgba[16, 16, 1] > 3.0 * rgba[0, 16, 1]


@pytest.mark.slow  # its render builds the rain and ice phase tables (about 40 s) where no earlier test has
def test_wrf_import_with_terrain_renders(tmp_path, capsys):
    from pxr import Usd, UsdGeom

    wrf = mk.sample_wrf(tmp_path / "wrfout_d01.nc", n=12, nz=12, minutes=(0.0,))
    stage_path, out = _import(tmp_path, capsys, wrf, name="wrf")
    stage = Usd.Stage.Open(str(stage_path))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Terrain"))
    points = np.asarray(mesh.GetPointsAttr().Get())
    assert points.shape == (144, 3) and points[:, 2].max() > 700.0
    code, _, err = run_cli(["render", stage_path, tmp_path / "r" / "wrf.####.exr", "--frames", "1", "--res",
                            "32x32", "--set", "spp=8"], capsys)
    assert code == 0, err


def test_column_resampling_matches_numpy_interp_on_random_columns():
    """Every column against np.interp (linear, held below the lowest level down to the ground, 0 under the ground
    and above the top level), on random increasing levels and targets that hit levels exactly."""
    from warpsky.usd.weather.regrid import ColumnWeights

    rng = np.random.default_rng(3)
    heights = np.cumsum(rng.uniform(20.0, 400.0, size=(7, 5, 12)), axis=-1)
    values = rng.normal(size=heights.shape)
    ground = heights[..., 0] - rng.uniform(0.0, 30.0, size=heights.shape[:2])
    levels = np.sort(np.concatenate([rng.uniform(0.0, heights.max() + 200.0, 60), heights[3, 2, [0, 5, 11]]]))
    result = ColumnWeights.between(heights, levels, ground).apply(values)
    for i in range(7):
        for j in range(5):
            expected = np.interp(levels, heights[i, j], values[i, j])
            expected[(levels < ground[i, j]) | (levels > heights[i, j, -1])] = 0.0
            np.testing.assert_allclose(result[i, j], expected, rtol=1e-12, atol=1e-12)


def test_the_written_wind_moves_the_weather_within_a_blurred_frame(tmp_path, capsys):
    """A sub-frame a quarter of a time code (225 s of model time) after the frame sees the cloud carried by the
    file's wind (uniform u = 5, w = 2 m/s on the staggered faces): its centroid 1125 m further east (warpsky's +x)
    and 450 m higher (warpsky's +y), as the velocity blur's one semi-Lagrangian step translates a uniform flow."""
    from warpsky.usd.stage import StageReader

    n, nz = 12, 10
    x = (np.arange(n) + 0.5) * 1.0  # km
    z = (np.arange(nz) + 0.5) * 0.5
    Z, Y, X = np.meshgrid(z, x, x, indexing="ij")
    blob = 1e-3 * np.exp(-((X - 6.0) ** 2 + (Y - 6.0) ** 2 + ((Z - 2.5) * 2.0) ** 2) / 4.0)
    shape = (2, nz, n, n)
    fields = {"th": np.full(shape, 300.0), "prs": np.full(shape, 9e4), "qc": np.stack([blob, blob])}
    wind = (np.full((2, nz, n, n + 1), 5.0), np.zeros((2, nz, n + 1, n)), np.full((2, nz + 1, n, n), 2.0))
    path = tmp_path / "windy.nc"
    mk.cm1_dataset(x, x, z, fields, times=[0.0, 900.0], wind=wind).to_netcdf(path, engine="netcdf4")
    stage_path, _ = _import(tmp_path, capsys, path)
    reader = StageReader(stage_path)

    def centroid(time_code: float) -> np.ndarray:
        with reader.sub_frames_of(1.0):
            (cloud,) = [m for m in reader.read_media(time_code) if m.species == "cloud"]
        index = np.indices(cloud.density.shape).reshape(3, -1)
        world = (cloud.world_from_index @ np.vstack([index, np.ones(index.shape[1])]))[:3]
        weights = cloud.density.reshape(-1).astype(np.float64)
        return world @ weights / weights.sum()

    # measured: 1123.0, 446.3, 0 m (the step's trilinear lookups and the grid's floor trim a little)
    np.testing.assert_allclose(centroid(1.25) - centroid(1.0), [5.0 * 225.0, 2.0 * 225.0, 0.0], atol=10.0)


def test_options_change_the_optics_and_bad_values_exit_2(tmp_path, capsys):
    from warpsky.media.voxels.fields import load_field

    shape = (1, 6, 5, 5)
    qc, qg = np.zeros(shape), np.zeros(shape)
    qc[0, 2, 2, 2], qg[0, 3, 2, 2] = 1e-3, 1e-3
    path = _uniform_cm1(tmp_path, fields={"qc": qc, "qg": qg})
    peaks = {}
    for name, options in (("base", []), ("big", ["--cloud-radius", "20", "--graupel-density", "900"])):
        code, _, err = run_cli(["import-weather", path, "--out", tmp_path / "o", "--name", name, *options], capsys)
        assert code == 0, err
        peaks[name] = {s: float(load_field(tmp_path / "o" / name / f"{s}.0001.nvdb").values.max())
                       for s in ("cloud", "snow")}
    np.testing.assert_allclose(peaks["big"]["cloud"], peaks["base"]["cloud"] / 2.0, rtol=1e-6)
    np.testing.assert_allclose(peaks["big"]["snow"], peaks["base"]["snow"] * (400.0 / 900.0) ** 0.75, rtol=1e-6)
    for bad, message in ((["--dz", "0"], "--dz"), (["--sun", "95,0"], "elevation"), (["--sun", "x"], "--sun"),
                         (["--ice-radius", "-1"], "--ice-radius"), (["--graupel-density", "0"], "--graupel")):
        code, _, err = run_cli(["import-weather", path, "--out", tmp_path / "o", *bad], capsys)
        assert code == 2 and message in err and err.strip().count("\n") == 0, err


def test_info_lists_each_species_water_as_the_import_recorded_it(tmp_path, capsys):
    """The imported stage records each species' peak water content and total water (graupel with snow, as it
    renders), and ``warpsky info`` prints them: mixing ratio x dry-air density, summed over cells of 1 km x 1 km x
    500 m."""
    shape = (1, 6, 5, 5)
    qc, qr, qs, qg = (np.zeros(shape) for _ in range(4))
    qc[0, 2, 1, 3], qc[0, 3, 1, 3] = 1.2e-3, 0.4e-3
    qr[0, 0, 2, 2] = 2.0e-3
    qs[0, 4, 0, 0], qg[0, 4, 0, 0] = 5.0e-4, 8.0e-4
    path = _uniform_cm1(tmp_path, fields={"qc": qc, "qr": qr, "qs": qs, "qg": qg})
    stage_path, _ = _import(tmp_path, capsys, path)
    from warpsky.usd.stage import StageReader

    rho, cell = _air_density(9.0e4, 300.0, 0.01), 1000.0 * 1000.0 * 500.0
    water = {m.species: m.water for m in StageReader(str(stage_path)).read_media(None)}
    np.testing.assert_allclose(water["cloud"], [1.2e-3 * rho, 1.6e-3 * rho * cell], rtol=1e-6)
    np.testing.assert_allclose(water["rain"], [2.0e-3 * rho, 2.0e-3 * rho * cell], rtol=1e-6)
    np.testing.assert_allclose(water["snow"], [1.3e-3 * rho, 1.3e-3 * rho * cell], rtol=1e-6)
    code, out, err = run_cli(["info", stage_path, "--res", "32x32"], capsys)
    assert code == 0, err
    assert out.count("water content: peak") == 3
    assert f"water content: peak {1.2e-3 * rho * 1e3:.3g} g/m³, {1.6e-3 * rho * cell / 1e3:.4g} t in all" in out

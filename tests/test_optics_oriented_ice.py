"""Oriented ice crystals against closed forms the test derives itself: parhelia (Bravais' index), the
circumzenithal arc, the upper tangent arc and the upper suncave Parry arc, a slab's reflectance, and the random
orientation of :mod:`warpsky.optics.ice`.

Reference numbers do not come from the code under test: ice indices at the band centres are Warren & Brandt 2008's
(650 nm 1.3080, 550 nm 1.3110, 450 nm 1.3157).

* Parhelion: a plate's side faces are vertical, so the horizontal projection of a ray refracts with Bravais'
  index n' = sqrt(n^2 - sin^2 e) / cos e and the elevation is kept: the parhelion lies at elevation e, azimuth
  offset 2 asin(n' / 2) - 60° (minimum deviation of the 60° prism in the projection).
* Circumzenithal arc: in through the horizontal top face (horizontal component / n), out through a vertical side
  (vertical component x n): the outgoing ray's vertical component is sqrt(n^2 - cos^2 e), so the arc's elevation
  is asin(sqrt(n^2 - cos^2 e)), and it exists only for n^2 - cos^2 e < 1 (e < 32.2°).
* Upper tangent arc: a ray perpendicular to a horizontal column's c-axis, in the sun's vertical plane, crosses the
  60° prism at minimum deviation 2 asin(n / 2) - 60° directly above the sun.
* Upper suncave Parry arc (c-axis horizontal, two prism faces horizontal): in through the top face at incidence
  90° - e (refraction r = asin(cos e / n)), out through the far lower side face (normal 30° below the horizontal)
  at internal incidence 60° - r: seen at elevation 30° + asin(n sin(60° - r)) above the sun's azimuth.
* Zenith sun over level plates: a parallel slab; light leaves straight through or reflected straight back, the
  reflected share 2R / (1 + R) with R = ((n - 1) / (n + 1))^2 (all orders of internal reflection, no absorption).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from warpsky.core.errors import SceneError
from warpsky.optics.grid import angle_grid, sphere_integral
from warpsky.optics.ice import DIFFRACTED_SHARE, HABITS, diffraction_phase, ice_optics
from warpsky.optics.oriented_ice import (
    IceOrientation,
    SkyBins,
    build_oriented_table,
    diffraction_bins,
    oriented_ice_table,
    oriented_phase,
    oriented_slice,
    parse_orientation,
    slice_cdf,
    sun_frame,
    trace_oriented,
)
from warpsky.optics.spectrum import band_samples

INDEX_AT_CENTRES = (1.3080, 1.3110, 1.3157)
GRID = SkyBins()
ELEVATIONS = GRID.elevation_centres_deg()
AZIMUTHS = GRID.azimuth_centres_deg()
SOLID = GRID.solid_angles()
PHOTONS = 1_000_000


def parhelion_azimuth_deg(n: float, e_deg: float) -> float | None:
    """Azimuth offset [deg] of the parhelion from the sun (Bravais), None when there is none."""
    e = math.radians(e_deg)
    bravais = math.sqrt(n * n - math.sin(e) ** 2) / math.cos(e)
    return None if bravais >= 2.0 else math.degrees(2.0 * math.asin(0.5 * bravais)) - 60.0


def circumzenithal_elevation_deg(n: float, e_deg: float) -> float | None:
    vertical2 = n * n - math.cos(math.radians(e_deg)) ** 2
    return math.degrees(math.asin(math.sqrt(vertical2))) if vertical2 < 1.0 else None


def parry_arc_elevation_deg(n: float, e_deg: float) -> float:
    r = math.asin(math.cos(math.radians(e_deg)) / n)
    return 30.0 + math.degrees(math.asin(n * math.sin(math.radians(60.0) - r)))


def row_of(elevation_deg: float) -> int:
    return int(np.argmin(np.abs(ELEVATIONS - elevation_deg)))


@functools.cache
def _table(kind: str, tilt: float, suns: tuple, device: str, photons: int = PHOTONS, seed: int = 5):
    return build_oriented_table(IceOrientation(kind, tilt), sun_elevations_deg=suns, photons=photons, seed=seed,
                                device=device)


def _plates(device: str):
    return _table("plate", 0.0, (0.0, 20.0, 40.0, 90.0), device)


def _geometric(table, s: int, c: int) -> np.ndarray:
    """(E, A) ray-optics part of slice s, channel c [1/sr]: the table less its diffraction half, renormalised."""
    radius = math.sqrt(table.projected_area[s] / math.pi)
    sun = float(table.sun_elevations_deg[s])
    diffraction = diffraction_bins(radius, band_samples(c)[0], sun, GRID)
    return (table.phase[s, :, :, c] - DIFFRACTED_SHARE * diffraction) / (1.0 - DIFFRACTED_SHARE)


def _inner_edge(row: np.ndarray, lo: float, hi: float) -> float:
    """Centre [deg] of the first azimuth bin in [lo, hi] reaching a quarter of the row's maximum there.

    A caustic's intensity grows like 1 / sqrt(distance past its edge): the bin holding the edge carries at least a
    quarter of the peak bin's share unless the edge lies within a few hundredths of a degree of its outer
    boundary, so this bin's centre is within half a bin (0.25°) of the edge, plus the band's dispersion."""
    mask = (AZIMUTHS >= lo) & (AZIMUTHS <= hi)
    values = row[mask]
    return float(AZIMUTHS[mask][np.argmax(values >= 0.25 * values.max())])


def test_closed_forms_reference_values():
    assert parhelion_azimuth_deg(1.31, 0.0) == pytest.approx(21.84, abs=0.01)  # the 22° halo at the horizon
    assert parhelion_azimuth_deg(1.31, 61.0) is None  # no parhelia above ~60.75°
    assert circumzenithal_elevation_deg(1.31, 32.0) is not None and circumzenithal_elevation_deg(1.31, 32.5) is None
    # the Parry passage is symmetric (minimum deviation) only for a sun near the horizon; at 20° it lies well
    # outside the 22° circle
    assert parry_arc_elevation_deg(1.311, 20.0) - 20.0 > 25.0


def test_sky_bins_cover_the_sphere_once():
    np.testing.assert_allclose(SOLID.sum(), 4.0 * math.pi, rtol=1e-12)
    assert SOLID.min() > 0.0
    rng = np.random.default_rng(1)
    look = rng.normal(size=(1000, 3))
    look /= np.linalg.norm(look, axis=1, keepdims=True)
    rows, cols = GRID.bins_of(look)
    elevation = np.degrees(np.arcsin(look[:, 1]))
    azimuth = np.degrees(np.arctan2(np.abs(look[:, 2]), look[:, 0]))
    assert np.all(np.abs(ELEVATIONS[rows] - elevation) <= 0.5 + 1e-9)
    assert np.all(np.abs(AZIMUTHS[cols] - azimuth) <= 0.25 + 1e-9)


def test_tables_are_normalised_finite_and_non_negative(device):
    for table in (_plates(device), _table("parry", 0.0, (20.0,), device), _table("plate", 2.0, (20.0,), device)):
        assert np.all(np.isfinite(table.phase)) and table.phase.min() >= 0.0
        integral = (table.phase.astype(np.float64) * SOLID[None, :, :, None]).sum(axis=(1, 2))
        np.testing.assert_allclose(integral, 1.0, atol=1e-3)
        assert np.all(table.trapped_fraction < 2e-3)


@pytest.mark.parametrize("sun", [0.0, 20.0, 40.0])
def test_parhelion_sits_at_bravais_azimuth_with_red_inside(sun, device):
    table = _plates(device)
    s = list(table.sun_elevations_deg).index(sun)
    edges = []
    for c, n in enumerate(INDEX_AT_CENTRES):
        expected = parhelion_azimuth_deg(n, sun)
        row = table.phase[s, row_of(sun), :, c]
        edge = _inner_edge(row, expected - 8.0, expected + 8.0)
        window = (AZIMUTHS >= expected - 8.0) & (AZIMUTHS <= expected + 8.0)
        peak = float(AZIMUTHS[window][np.argmax(row[window])])
        assert abs(edge - expected) <= 0.3, f"channel {c}: inner edge {edge:.2f}°, Bravais {expected:.2f}°"
        assert expected - 0.3 <= peak <= expected + 1.0, f"channel {c}: peak {peak:.2f}°, Bravais {expected:.2f}°"
        # the sundog stands well above the parhelic circle (reflections off the vertical faces) in the same row
        assert row[window].max() > 8.0 * np.median(row[(AZIMUTHS > 70.0) & (AZIMUTHS < 170.0)])
        edges.append(edge)
    assert edges[0] < edges[2], f"red inner edge {edges[0]}° not inside blue's {edges[2]}°"


def test_perfect_plates_keep_the_sun_elevation_in_the_parhelion(device):
    table = _plates(device)
    for s, sun in enumerate(table.sun_elevations_deg[:3]):
        expected = parhelion_azimuth_deg(INDEX_AT_CENTRES[1], sun)
        band = (AZIMUTHS > expected - 1.0) & (AZIMUTHS < expected + 6.0)
        near = np.abs(ELEVATIONS - sun) < 15.0
        energy = (_geometric(table, s, 1) * SOLID)[np.ix_(near, band)]
        assert energy[row_of(sun) - np.argmax(near)].sum() > 0.98 * energy.sum()


def test_circumzenithal_arc_only_below_32_degrees(device):
    table = _table("plate", 0.0, (20.0, 40.0), device)
    sides = []
    for s in range(2):
        energy = _geometric(table, s, 1) * SOLID
        sunward = energy[:, AZIMUTHS < 90.0]
        away = energy[:, AZIMUTHS > 90.0]
        sides.append((sunward, away))
    arc = circumzenithal_elevation_deg(INDEX_AT_CENTRES[1], 20.0)
    band = slice(row_of(arc) - 1, row_of(arc) + 2)
    sunward, away = sides[0]
    assert sunward[band].sum() > 0.02, f"circumzenithal arc at {arc:.1f}° carries {sunward[band].sum():.2e}"
    assert sunward[band].sum() > 100.0 * away[band].sum()
    # e = 40°: the zenith cap (elevation > 60°) sunward holds no more than the same cap away from the sun
    cap = ELEVATIONS > 60.0
    sunward, away = sides[1]
    photons = 0.5 * PHOTONS  # about half the photons hit; Poisson noise on the difference of the two caps
    noise = math.sqrt((sunward[cap].sum() + away[cap].sum()) / photons) + 1.0 / photons
    assert abs(sunward[cap].sum() - away[cap].sum()) < 5.0 * noise
    assert sunward[cap].sum() < 1e-3


def test_zenith_sun_plates_are_a_slab_without_sundogs(device):
    table = _plates(device)
    s = list(table.sun_elevations_deg).index(90.0)
    for c, n in enumerate(INDEX_AT_CENTRES):
        energy = _geometric(table, s, c) * SOLID
        ring = (ELEVATIONS > 60.0) & (ELEVATIONS < 75.0)  # 22° from the zenith sun
        assert energy[ring].sum() < 1e-6
        reflectance = ((n - 1.0) / (n + 1.0)) ** 2
        slab = 2.0 * reflectance / (1.0 + reflectance)
        reflected = energy[0].sum()  # the nadir bin
        assert reflected == pytest.approx(slab, abs=1.5e-3), f"channel {c}: reflected {reflected:.4f}, slab {slab:.4f}"
    # the horizon sun's table is finite and carries its sundog
    assert np.all(np.isfinite(table.phase[0])) and table.phase[0, row_of(0.0), :, 1].max() > 1.0


def test_upper_tangent_arc_and_parry_arc_above_the_sun(device):
    sun = 20.0
    for kind, expected in (("column", sun + math.degrees(2.0 * math.asin(INDEX_AT_CENTRES[1] / 2.0)) - 60.0),
                           ("parry", parry_arc_elevation_deg(INDEX_AT_CENTRES[1], sun))):
        table = _table(kind, 0.0, (sun,), device)
        above = table.phase[0, :, 0, 1]  # the sun's vertical, green
        window = (ELEVATIONS > sun + 10.0) & (ELEVATIONS < sun + 45.0)
        peak = float(ELEVATIONS[window][np.argmax(above[window])])
        assert abs(peak - expected) <= 0.5, f"{kind}: arc above the sun at {peak:.1f}°, expected {expected:.2f}°"
        assert above[row_of(peak)] > 20.0 * np.median(above[window])


def _expected_bins(phase: np.ndarray, sun_deg: float, grid: SkyBins, sub: int = 6) -> np.ndarray:
    """(E, A) energy in each bin of a phase function of the scattering angle, by sub-sampling each bin."""
    elev, azim = grid.edges()
    u = (np.arange(sub) + 0.5) / sub
    e_sub = elev[:-1, None] + np.outer(np.diff(elev), u)  # (E, sub)
    a_sub = azim[:-1, None] + np.outer(np.diff(azim), u)  # (A, sub)
    sun = math.radians(sun_deg)
    out = np.zeros((len(elev) - 1, len(azim) - 1))
    for i in range(sub):
        for j in range(sub):
            cos_t = (math.sin(sun) * np.sin(e_sub[:, i])[:, None]
                     + math.cos(sun) * np.cos(e_sub[:, i])[:, None] * np.cos(a_sub[:, j])[None, :])
            weight = np.cos(e_sub[:, i])[:, None]
            out += np.interp(np.arccos(np.clip(cos_t, -1.0, 1.0)), angle_grid(), phase) * weight
    weight_sum = np.cos(e_sub).sum(axis=1)[:, None] * sub
    return out / weight_sum * grid.solid_angles()


def test_random_orientation_reproduces_the_ice_phase(device):
    sun = 30.0
    photons = 2_000_000
    table = _table("random", 0.0, (sun,), device, photons)
    reference = ice_optics("column", seed=11, photons=photons, device=device)
    elevation = np.radians(ELEVATIONS)[:, None]
    azimuth = np.radians(AZIMUTHS)[None, :]
    cos_t = math.sin(math.radians(sun)) * np.sin(elevation) + math.cos(math.radians(sun)) * np.cos(elevation) * np.cos(
        azimuth)
    theta = np.degrees(np.arccos(np.clip(cos_t, -1.0, 1.0)))
    rings = np.arange(4.0, 181.0, 2.0)  # 2° rings of scattering angle (bin centres), past the diffraction peak
    column = HABITS["column"]
    hit_share = column.mean_projected_area / (column.diameter**2 * (1.0 + column.half_length_ratio**2))  # Cauchy
    for c in range(3):
        ours = table.phase[0, :, :, c] * SOLID
        theirs = _expected_bins(reference.phase[c], sun, GRID)
        a = np.array([ours[(theta >= lo) & (theta < lo + 2.0)].sum() for lo in rings[:-1]])
        b = np.array([theirs[(theta >= lo) & (theta < lo + 2.0)].sum() for lo in rings[:-1]])
        # a ring's energy a = (1/2) k / M for k of the M leaving photons: variance a / (2 M), M = hit share x N
        sigma = np.sqrt((a + b) / (2.0 * hit_share * photons)) + 1e-7
        z = (a - b) / sigma
        worst = int(np.argmax(np.abs(z)))
        assert abs(z[worst]) < 4.5, f"channel {c}: ring {rings[worst]:g}° z = {z[worst]:.1f}"
        assert np.mean(z**2) < 1.6  # chi^2 / dof of 87 rings, 99.9 % point ~1.5
        # the 22° halo ring stands out in both
        halo = int(np.argmin(np.abs(rings - 22.0)))
        assert a[halo] > 1.5 * a[halo - 2]


def test_diffraction_bins_match_the_cap_integrals():
    radius = HABITS["column"].equal_area_radius
    wavelengths = band_samples(1)[0]
    profile = diffraction_phase(radius, wavelengths)
    for sun in (0.0, 45.0, 90.0):
        values = diffraction_bins(radius, wavelengths, sun, GRID)
        np.testing.assert_allclose((values * SOLID).sum(), 1.0, rtol=1e-12)
        elevation = np.radians(ELEVATIONS)[:, None]
        azimuth = np.radians(AZIMUTHS)[None, :]
        cos_t = math.sin(math.radians(sun)) * np.sin(elevation) + math.cos(math.radians(sun)) * np.cos(
            elevation) * np.cos(azimuth)
        inside = np.degrees(np.arccos(np.clip(cos_t, -1.0, 1.0))) < 5.0
        cap = sphere_integral(profile, upto=math.radians(5.0))
        assert (values * SOLID)[inside].sum() == pytest.approx(cap, abs=2e-3)


def test_lookups_interpolate_mirror_and_follow_the_sun(device):
    table = _table("plate", 1.0, (20.0, 22.0), device, 300_000)
    middle, grid = oriented_slice(table, 21.0)
    assert middle.dtype == np.float32 and middle.shape == (grid.elevation_bins, grid.azimuth_bins, 3)
    np.testing.assert_allclose(middle, 0.5 * (table.phase[0] + table.phase[1]), rtol=1e-6, atol=1e-9)
    below, _ = oriented_slice(table, -20.0)
    np.testing.assert_array_equal(below, table.phase[0][::-1])
    with pytest.raises(SceneError, match="outside"):
        oriented_slice(table, 30.0)
    # a sun at 20° elevation and 130° world azimuth: the parhelion seen 24.7° to either side of it
    e, phi = math.radians(20.0), math.radians(130.0)
    sun_dir = np.array([math.cos(e) * math.cos(phi), math.sin(e), math.cos(e) * math.sin(phi)])
    frame = sun_frame(sun_dir)
    np.testing.assert_allclose(frame @ sun_dir, [math.cos(e), math.sin(e), 0.0], atol=1e-12)
    offset = parhelion_azimuth_deg(INDEX_AT_CENTRES[1], 20.0) + 0.6
    looks = []
    for delta in (offset, -offset, offset - 4.0):
        a = phi + math.radians(delta)
        looks.append([math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)])
    values = oriented_phase(table, 20.0, (frame @ np.array(looks).T).T)
    assert values.shape == (3, 3)
    np.testing.assert_allclose(values[0], values[1], rtol=1e-6)
    assert values[0, 1] > 20.0 * values[2, 1]
    marginal, conditional = slice_cdf(middle, grid)
    np.testing.assert_allclose(marginal[-1], 1.0)
    assert np.all(np.diff(marginal, axis=0) >= 0.0) and np.all(np.diff(conditional, axis=1) >= 0.0)


def test_table_cache_builds_once(tmp_path, monkeypatch, capsys):
    from warpsky.optics.tables import BUILD_LOG

    monkeypatch.setenv("WARPSKY_CACHE", str(tmp_path))
    orientation = IceOrientation("plate", 0.5)
    before = len(BUILD_LOG)
    first = oriented_ice_table(orientation, sun_elevations_deg=(10.0,), photons=20_000, device="cpu")
    assert "building oriented ice table" in capsys.readouterr().err and len(BUILD_LOG) == before + 1
    second = oriented_ice_table(orientation, sun_elevations_deg=(10.0,), photons=20_000, device="cpu")
    assert len(BUILD_LOG) == before + 1 and capsys.readouterr().err == ""
    np.testing.assert_array_equal(first.phase, second.phase)
    assert list((tmp_path / "optics").glob("ice-oriented-plate-plate-*.npz"))


def test_parse_orientation_validates_usd_attributes():
    assert parse_orientation("plate", "plate", 1.5, "/World/Cirrus") == IceOrientation("plate", 1.5, "plate")
    assert parse_orientation("column", "random", 0.0, "/W").habit == "column"
    cases = [
        (("needle", "random", 0.0), "warpsky:ice:habit"),
        (("plate", "tumbling", 0.0), "warpsky:ice:orientation"),
        (("plate", "plate", -1.0), "warpsky:ice:tilt"),
        (("plate", "plate", float("nan")), "warpsky:ice:tilt"),
        (("column", "plate", 1.0), "warpsky:ice:orientation"),
        (("plate", "parry", 1.0), "warpsky:ice:orientation"),
    ]
    for args, attribute in cases:
        with pytest.raises(SceneError, match=f"/World/Cirrus.{attribute}"):
            parse_orientation(*args, "/World/Cirrus")
    with pytest.raises(SceneError, match="tilt"):
        IceOrientation("plate", 120.0)


def test_trace_rejects_bad_inputs():
    with pytest.raises(SceneError, match="photons"):
        trace_oriented(IceOrientation(), 10.0, 0)
    with pytest.raises(SceneError, match="sun elevation"):
        trace_oriented(IceOrientation(), 95.0, 10)
    with pytest.raises(SceneError, match="divide 180"):
        SkyBins(elevation_step_deg=0.7)


def test_hits_weigh_crystals_by_the_area_they_show_the_sun(device):
    """Level plates show the sun their hexagon foreshortened by sin e plus their rim, whose width averaged over the
    spin is the hexagon's mean caliper diameter, perimeter / pi (Cauchy): A(e) = (3 sqrt 3 / 2) a^2 sin e +
    (6 a / pi) L cos e. Random orientation shows a fourth of the surface."""
    table = _plates(device)
    plate = HABITS["plate"]
    a, length = 0.5 * plate.diameter, plate.length
    for s, sun in enumerate(table.sun_elevations_deg):
        e = math.radians(sun)
        expected = 1.5 * math.sqrt(3.0) * a * a * math.sin(e) + 6.0 * a / math.pi * length * math.cos(e)
        assert table.projected_area[s] == pytest.approx(expected, rel=5e-3), f"sun {sun}°"
    random = _table("random", 0.0, (30.0,), device, 2_000_000)
    assert random.projected_area[0] == pytest.approx(HABITS["column"].mean_projected_area, rel=5e-3)


@pytest.mark.parametrize("sun", [0.0, 20.0, 40.0])
def test_parhelion_distance_from_the_sun_within_a_fifth_of_a_degree(sun, device):
    """On 0.1° azimuth bins: the parhelion's inner edge, as an angular distance d from the sun
    (sin(d / 2) = cos e sin(da / 2)), against Bravais' minimum deviation for the band's least-refracted sample
    wavelength (the edge belongs to the smallest index in the band) within 0.2°, per channel."""
    from warpsky.optics.ice import ice_refractive_index
    from warpsky.optics.oriented_ice import trace_oriented

    fine = SkyBins(elevation_step_deg=1.0, azimuth_step_deg=0.1)
    trace = trace_oriented(IceOrientation("plate", 0.0), sun, PHOTONS, grid=fine, seed=11, device=device)
    azimuths = fine.azimuth_centres_deg()
    row = int(round((sun + 90.0) / fine.elevation_step_deg))
    e = math.radians(sun)

    def distance(da_deg: float) -> float:
        return math.degrees(2.0 * math.asin(math.cos(e) * math.sin(math.radians(da_deg) / 2.0)))

    for c in range(3):
        n = float(np.min(ice_refractive_index(band_samples(c)[0])))
        expected = parhelion_azimuth_deg(n, sun)
        counts = trace.histogram[c, row]
        window = (azimuths >= expected - 5.0) & (azimuths <= expected + 5.0)
        values = counts[window]
        edge = float(azimuths[window][np.argmax(values >= 0.25 * values.max())])
        assert abs(distance(edge) - distance(expected)) <= 0.2, (c, distance(edge), distance(expected))

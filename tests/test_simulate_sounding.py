"""The cloud solver's environment: the Weisman & Klemp (1982) sounding, CM1's input_sounding format read and written,
and the hydrostatic base state."""

from __future__ import annotations

import numpy as np
import pytest

from warpsky.core.errors import UsageError
from warpsky.simulate.sounding import (
    GRAVITY,
    R_DRY,
    base_state,
    read_sounding,
    saturation_mixing_ratio,
    weisman_klemp,
    write_sounding,
)


def test_weisman_klemp_has_its_published_profile():
    """θ 300 K at the ground and 343 K at the 12 km tropopause, 14 g/kg capped boundary layer, relative humidity
    1 - 0.75 (z/12 km)^1.25 above it, 25 % above the tropopause, u = 15 tanh(z / 3 km)."""
    s = weisman_klemp()
    assert s.surface_theta == pytest.approx(300.0) and s.surface_vapour == pytest.approx(0.014)
    at = s.at(np.array([12000.0, 6000.0, 3000.0]))
    assert at["theta"][0] == pytest.approx(343.0, abs=1e-6)
    base = base_state(s, 80, 250.0)
    z = (np.arange(80) + 0.5) * 250.0
    humidity = base.vapour / saturation_mixing_ratio(base.temperature, base.pressure)
    free = (z > 2000.0) & (z < 11500.0)
    np.testing.assert_allclose(humidity[free], 1.0 - 0.75 * (z[free] / 12000.0) ** 1.25, atol=0.01)
    np.testing.assert_allclose(humidity[z > 12500.0], 0.25, atol=0.01)
    assert base.vapour[0] == pytest.approx(0.014, abs=1e-6)
    np.testing.assert_allclose(base.wind_u, 15.0 * np.tanh(z / 3000.0), atol=0.02)


def test_base_state_is_hydrostatic():
    """dp/dz = -ρ g between the levels to 0.1 %, and p at the surface is the sounding's."""
    s = weisman_klemp()
    base = base_state(s, 64, 250.0)
    gradient = np.diff(base.pressure) / 250.0
    mean_density = 0.5 * (base.density[1:] + base.density[:-1])
    np.testing.assert_allclose(gradient, -mean_density * GRAVITY, rtol=1e-3)
    assert base.density_face[0] * R_DRY * 300.0 * (1 + 0.014 / 0.622) / (1 + 0.014) == pytest.approx(1.0e5, rel=1e-3)


def test_input_sounding_round_trip(tmp_path):
    """What write_sounding writes, read_sounding reads back (to the file's printed precision)."""
    s = weisman_klemp()
    path = write_sounding(tmp_path / "input_sounding", s)
    first = path.read_text().splitlines()[0].split()
    assert [float(v) for v in first] == pytest.approx([1000.0, 300.0, 14.0])
    back = read_sounding(path)
    np.testing.assert_allclose(back.height, s.height)
    np.testing.assert_allclose(back.theta, s.theta, atol=1e-4)
    np.testing.assert_allclose(back.vapour, s.vapour, atol=1e-8)
    np.testing.assert_allclose(back.wind_u, s.wind_u, atol=1e-4)


@pytest.mark.parametrize("text, message", [
    ("1000 300 14\n100 300 14 0 0\n", "at least two levels"),
    ("1000 300\n100 300 14 0 0\n200 300 14 0 0\n", ":1: expected 3 numbers"),
    ("1000 300 14\n100 300 14 0\n200 300 14 0 0\n", ":2: expected 5 numbers"),
    ("1000 300 14\n200 300 14 0 0\n100 300 14 0 0\n", ":3: heights must increase"),
    ("100000 300 14\n100 300 14 0 0\n200 300 14 0 0\n", "must be in mb"),
    ("1000 300 14\n100 30.0 14 0 0\n200 300 14 0 0\n", "must be in K"),
    ("1000 300 x\n100 300 14 0 0\n200 300 14 0 0\n", ":1: expected numbers"),
])
def test_bad_soundings_name_the_line(tmp_path, text, message):
    path = tmp_path / "input_sounding"
    path.write_text(text)
    with pytest.raises(UsageError, match=message):
        read_sounding(path)

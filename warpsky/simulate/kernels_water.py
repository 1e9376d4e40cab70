"""The solver's moist kernels: Kessler (1969) warm rain and saturation adjustment with latent heating, and the rain's
fall at its terminal speed.

Rates follow Klemp & Wilhelmson (1978, J. Atmos. Sci. 35, 1070; "KW78"), as CM1 and the DCMIP test cases use them:

- autoconversion k1 (q_c - a), k1 = 0.001 1/s, a = 0.001 kg/kg, and accretion 2.2 q_c q_r^0.875 [1/s], taken
  implicitly in q_r (their eq. 2.13);
- rain evaporation (1 - q_v/q_vs) C (ρ q_r)^0.525 / (ρ (5.4e5 + 2.55e6 / (p q_vs))), C = 1.6 + 124.9 (ρ q_r)^0.2046,
  ρ in g/cm^3 and p in mb (eq. 2.14);
- terminal speed 36.34 (0.001 ρ q_r)^0.1364 (ρ_surface / ρ)^½ [m/s] (eq. 2.15, ρ in kg/m^3).

Saturation adjustment (KW78 eq. 3.10, iterated): vapour above saturation condenses, cloud below it evaporates,
each warming or cooling θ by L_v / (c_p π); the saturation vapour pressure is Bolton's (1980, eq. 10). The
Exner function is the environment's (the perturbation pressure's share is neglected, as in KW78's adjustment).
Left out: ice processes and the latent heat of freezing (the condensate above the freezing level is called ice
only when the frames are written, by temperature), and the rain's drag beyond its weight in the buoyancy.
"""

from __future__ import annotations

import warp as wp

from warpsky.simulate.fields import Column, Grid, Water

LATENT = 2.501e6  # [J/kg] latent heat of vapourisation
CP = 1005.7  # [J/(kg K)]
EPSILON = 0.6220  # R_d / R_v


@wp.func
def saturation_vapour(temperature: float, pressure: float) -> float:
    """Saturation mixing ratio over liquid [kg/kg] at ``temperature`` [K] and ``pressure`` [Pa] (Bolton 1980)."""
    celsius = temperature - 273.15
    es = 611.2 * wp.exp(17.67 * celsius / (celsius + 243.5))
    return EPSILON * es / wp.max(pressure - es, 1.0)


@wp.func
def saturation_slope(temperature: float, pressure: float) -> float:
    """d q_vs / dT [1/K] of :func:`saturation_vapour` (Clausius-Clapeyron in Bolton's form)."""
    celsius = temperature - 273.15
    return saturation_vapour(temperature, pressure) * 17.67 * 243.5 / ((celsius + 243.5) * (celsius + 243.5))


@wp.kernel
def microphysics(column: Column, water: Water, dt: float, x_offset: int):
    """One step of Kessler warm rain then saturation adjustment at every cell."""
    x, j, k = wp.tid()
    i = x + x_offset
    exner = column.exner[j]
    pressure = column.pressure[j]
    density = column.density[j]
    theta = water.theta[i, j, k]
    vapour = water.vapour[i, j, k]
    cloud = water.cloud[i, j, k]
    rain = water.rain[i, j, k]
    if rain < 0.0:  # a transport undershoot: borrowed from the vapour, so that the water total is kept
        vapour += rain
        rain = 0.0
    # autoconversion and accretion (KW78 eq. 2.13, implicit in the rain)
    produced = cloud - (cloud - dt * wp.max(0.001 * (cloud - 0.001), 0.0)) / (1.0 + dt * 2.2 * wp.pow(rain, 0.875))
    produced = wp.clamp(produced, 0.0, wp.max(cloud, 0.0))
    cloud -= produced
    rain += produced
    # rain evaporation into subsaturated air (KW78 eq. 2.14)
    temperature = theta * exner
    saturated = saturation_vapour(temperature, pressure)
    if rain > 0.0 and vapour < saturated:
        rho_rain = 0.001 * density * rain  # [g/cm^3]
        ventilation = 1.6 + 124.9 * wp.pow(rho_rain, 0.2046)
        rate = ventilation * wp.pow(rho_rain, 0.525) / (5.4e5 + 2.55e6 / (0.01 * pressure * saturated))
        rate *= (1.0 - vapour / saturated) / (0.001 * density)
        deficit = (saturated - vapour) / (1.0 + LATENT / CP * saturation_slope(temperature, pressure))
        evaporated = wp.min(wp.min(dt * rate, rain), deficit)
        rain -= evaporated
        vapour += evaporated
        theta -= LATENT / (CP * exner) * evaporated
    # saturation adjustment: Newton on q_v - δ = q_vs(T + L δ / c_p), δ >= -q_c
    condensed = float(0.0)  # a negative cloud (a transport undershoot) condenses back to zero from the vapour
    for _ in range(3):
        t = (theta + LATENT / (CP * exner) * condensed) * exner
        excess = vapour - condensed - saturation_vapour(t, pressure)
        condensed += excess / (1.0 + LATENT / CP * saturation_slope(t, pressure))
        condensed = wp.max(condensed, -cloud)
    water.theta[i, j, k] = theta + LATENT / (CP * exner) * condensed
    water.vapour[i, j, k] = vapour - condensed
    water.cloud[i, j, k] = cloud + condensed
    water.rain[i, j, k] = rain


@wp.func
def fall_speed(column: Column, rain: float, j: int) -> float:
    """Terminal speed of rain [m/s] with mixing ratio ``rain`` [kg/kg] on level ``j`` (KW78 eq. 2.15)."""
    if rain <= 0.0:
        return 0.0
    density = column.density[j]
    return 36.34 * wp.pow(0.001 * density * rain, 0.1364) * wp.sqrt(column.density_face[0] / density)


@wp.kernel
def sediment(grid: Grid, column: Column, water: Water, fallen: wp.array2d(dtype=float), dt: float, substeps: int,
             x_offset: int):
    """The rain's fall over ``dt`` [s] in each column (launched over (nx, nz)): upwind fluxes of ρ q_r V in
    ``substeps`` steps (each below a Courant number of 1), what leaves through the floor added to ``fallen``
    [kg/m^2]."""
    t, k = wp.tid()
    i = t + x_offset
    step = dt / float(substeps)
    for _ in range(substeps):
        # bottom-up: each level loses its own flux and gains the one from above, read before it changes
        out_here = column.density[0] * water.rain[i, 0, k] * fall_speed(column, water.rain[i, 0, k], 0)
        fallen[i, k] = fallen[i, k] + step * out_here
        for j in range(grid.ny):
            out_above = float(0.0)
            if j + 1 < grid.ny:
                above = water.rain[i, j + 1, k]
                out_above = column.density[j + 1] * above * fall_speed(column, above, j + 1)
            change = step * (out_above - out_here) / (column.density[j] * grid.dy)
            water.rain[i, j, k] = water.rain[i, j, k] + change
            out_here = out_above

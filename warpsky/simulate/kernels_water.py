"""The solver's moist kernels: Kessler (1969) rain with the slower rates of cloud ice, saturation adjustment with
latent heating, and the precipitation's fall at its terminal speed, rain's or snow's by temperature.

The solver carries one condensate (q_c) and one precipitation (q_r) category. Both are split into liquid and ice by
temperature alone (:func:`frozen_share`: all liquid above 0 C, all ice below -20 C, linear between, the partition
of the mixed-phase layer in e.g. Lord et al. 1984), the split the frames write as cloud/ice and rain/snow, and the
rates below blend the warm and the cold process by it. Warm rates follow Klemp & Wilhelmson (1978, J. Atmos.
Sci. 35, 1070; "KW78"), as CM1 and the DCMIP test cases use them:

- autoconversion k1 (q_c - a), k1 = 0.001 1/s, a = 0.001 kg/kg, and accretion 2.2 q_c q_r^0.875 [1/s], taken
  implicitly in q_r (their eq. 2.13); where the condensate is ice both are scaled by Lin, Farley & Orville (1983,
  J. Clim. Appl. Meteor. 22, 1065)'s exp(0.025 (T - 273.15)): their cloud-ice-to-snow autoconversion
  0.001 exp(0.025 (T - T0)) (q_i - 0.001) (eq. 21), and their collection efficiency of ice by snow on Kessler's
  accretion (a simplification of their snow-collects-ice rate);
- evaporation (1 - q_v/q_vs) C (ρ q_r)^0.525 / (ρ (5.4e5 + 2.55e6 / (p q_vs))), C = 1.6 + 124.9 (ρ q_r)^0.2046,
  ρ in g/cm^3 and p in mb (eq. 2.14), for snow's sublimation too;
- terminal speed: rain's 36.34 (0.001 ρ q_r)^0.1364 (ρ_surface / ρ)^½ [m/s] (eq. 2.15, ρ in kg/m^3) blended with
  snow's mass-weighted c Γ(4 + d)/6 λ^-d (ρ_surface / ρ)^½ of Lin et al. (1983) for Locatelli & Hobbs (1974)'s
  aggregates (:data:`SNOW_SPEED`; about 1 m/s), each cell falling at its own speed so the fluxes stay
  conservative.

Saturation adjustment (KW78 eq. 3.10, iterated): vapour above saturation (over liquid, Bolton 1980 eq. 10)
condenses, condensate below it evaporates, each warming or cooling θ by L / (c_p π). The Exner function is the
environment's (the perturbation pressure's share is neglected, as in KW78's adjustment).
The latent heat is vapourisation's plus fusion's on the frozen share, L = L_v + f(T) L_f (:func:`latent_heat`,
f at the cell's temperature before the step): condensate formed where it is cold releases the heat of
deposition, and evaporating (sublimating) there takes it back, as in the ice-phase parcel theory that the
equilibrium-level test computes. The freezing of liquid carried up across the freezing levels and the melting of
snow falling below them are not modelled: condensate formed warm and frozen aloft releases no fusion heat, and
snow formed aloft and evaporated as rain below keeps the fusion heat its deposition released.
Left out besides: the ice categories' own prognostic variables (cloud ice and snow are the cold share of q_c
and q_r, so cloud carried up is called ice and snow carried down is called rain the moment their temperature says
so, with no time scale and, as said, no heat), graupel and hail, riming beyond the accretion above, saturation
over ice, ice sedimentation other than snow's, and the precipitation's drag beyond its weight in the buoyancy.
"""

from __future__ import annotations

import warp as wp

from warpsky.simulate.fields import Column, Grid, Water

LATENT = 2.501e6  # [J/kg] latent heat of vapourisation
FUSION = 3.337e5  # [J/kg] latent heat of fusion at 0 C
CP = 1005.7  # [J/(kg K)]
EPSILON = 0.6220  # R_d / R_v
#: Temperatures [K] of the ice partition: all liquid above the first, all ice below the second.
ALL_LIQUID, ALL_ICE = 273.15, 253.15
#: Snow's mass-weighted terminal speed SNOW_SPEED (ρ q_s)^SNOW_EXPONENT [m/s] (ρ q_s in kg/m^3) before the
#: density correction: Lin et al. (1983)'s c Γ(4 + d) / 6 (π ρ_s n_0s)^(-d/4) with V(D) = c D^d, c = 11.72, d = 0.41
#: (Locatelli & Hobbs 1974's aggregates), ρ_s = 100 kg/m^3, n_0s = 3e6 m^-4 (about 1 m/s at 1 g/kg).
SNOW_SPEED, SNOW_EXPONENT = 2.4139, 0.1025


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


@wp.func
def frozen_share(temperature: float) -> float:
    """The share of condensate and precipitation that is ice at ``temperature`` [K]: 0 above :data:`ALL_LIQUID`,
    1 below :data:`ALL_ICE`, linear between (the frames' partition, :func:`.frames.ice_fraction`)."""
    return wp.clamp((ALL_LIQUID - temperature) / (ALL_LIQUID - ALL_ICE), 0.0, 1.0)


@wp.func
def cold_efficiency(temperature: float) -> float:
    """The factor on Kessler's autoconversion and accretion rates at ``temperature`` [K]: 1 where the condensate
    is liquid, Lin et al. (1983)'s exp(0.025 (T - 273.15)) (their cloud ice to snow and snow's collection of ice)
    where it is ice, blended by :func:`frozen_share`."""
    return wp.lerp(1.0, wp.exp(0.025 * (temperature - 273.15)), frozen_share(temperature))


@wp.func
def latent_heat(temperature: float) -> float:
    """Heat [J/kg] released by condensate formed at ``temperature`` [K]: vapourisation's, plus fusion's on the
    frozen share (deposition where it is all ice)."""
    return LATENT + FUSION * frozen_share(temperature)


@wp.func
def evaporation(vapour: float, rain: float, temperature: float, pressure: float, density: float,
                latent: float, dt: float) -> float:
    """Precipitation [kg/kg] evaporating over ``dt`` [s] into subsaturated air (KW78 eq. 2.14), at most what
    brings the air to saturation when it cools by ``latent`` [J/kg] per kg."""
    saturated = saturation_vapour(temperature, pressure)
    if rain <= 0.0 or vapour >= saturated:
        return 0.0
    rho_rain = 0.001 * density * rain  # [g/cm^3]
    ventilation = 1.6 + 124.9 * wp.pow(rho_rain, 0.2046)
    rate = ventilation * wp.pow(rho_rain, 0.525) / (5.4e5 + 2.55e6 / (0.01 * pressure * saturated))
    rate *= (1.0 - vapour / saturated) / (0.001 * density)
    deficit = (saturated - vapour) / (1.0 + latent / CP * saturation_slope(temperature, pressure))
    return wp.min(wp.min(dt * rate, rain), deficit)


@wp.kernel
def microphysics(column: Column, water: Water, dt: float, x_offset: int):
    """One step of Kessler rain (with the cold rates of :func:`cold_efficiency`) then saturation adjustment with
    :func:`latent_heat` at every cell."""
    x, j, k = wp.tid()
    i = x + x_offset
    exner = column.exner[j]
    pressure = column.pressure[j]
    theta = water.theta[i, j, k]
    vapour = water.vapour[i, j, k]
    cloud = water.cloud[i, j, k]
    rain = water.rain[i, j, k]
    if rain < 0.0:  # a transport undershoot: borrowed from the vapour, so that the water total is kept
        vapour += rain
        rain = 0.0
    temperature = theta * exner
    latent = latent_heat(temperature)
    # autoconversion and accretion (KW78 eq. 2.13, implicit in the rain; slower where cold, Lin et al. 1983)
    efficiency = cold_efficiency(temperature)
    produced = cloud - ((cloud - dt * wp.max(0.001 * efficiency * (cloud - 0.001), 0.0))
                        / (1.0 + dt * 2.2 * efficiency * wp.pow(rain, 0.875)))
    produced = wp.clamp(produced, 0.0, wp.max(cloud, 0.0))
    cloud -= produced
    rain += produced
    # rain evaporation (snow sublimation) into subsaturated air
    evaporated = evaporation(vapour, rain, temperature, pressure, column.density[j], latent, dt)
    rain -= evaporated
    vapour += evaporated
    theta -= latent / (CP * exner) * evaporated
    # saturation adjustment: Newton on q_v - δ = q_vs(T + L δ / c_p), δ >= -q_c
    condensed = float(0.0)  # a negative cloud (a transport undershoot) condenses back to zero from the vapour
    for _ in range(3):
        t = (theta + latent / (CP * exner) * condensed) * exner
        excess = vapour - condensed - saturation_vapour(t, pressure)
        condensed += excess / (1.0 + latent / CP * saturation_slope(t, pressure))
        condensed = wp.max(condensed, -cloud)
    water.theta[i, j, k] = theta + latent / (CP * exner) * condensed
    water.vapour[i, j, k] = vapour - condensed
    water.cloud[i, j, k] = cloud + condensed
    water.rain[i, j, k] = rain


@wp.func
def fall_speed(column: Column, rain: float, temperature: float, j: int) -> float:
    """Mass-weighted terminal speed [m/s] of precipitation with mixing ratio ``rain`` [kg/kg] at ``temperature``
    [K] on level ``j``: rain's (KW78 eq. 2.15) and snow's (Lin et al. 1983) blended by :func:`frozen_share`."""
    if rain <= 0.0:
        return 0.0
    density = column.density[j]
    thinning = wp.sqrt(column.density_face[0] / density)
    liquid = 36.34 * wp.pow(0.001 * density * rain, 0.1364)
    frozen = SNOW_SPEED * wp.pow(density * rain, SNOW_EXPONENT)
    return wp.lerp(liquid, frozen, frozen_share(temperature)) * thinning


@wp.func
def falling_flux(column: Column, water: Water, i: int, j: int, k: int) -> float:
    """Downward mass flux ρ q_r V [kg/(m^2 s)] of the precipitation in cell (i, j, k), V its :func:`fall_speed` at
    the cell's temperature."""
    rain = water.rain[i, j, k]
    return column.density[j] * rain * fall_speed(column, rain, water.theta[i, j, k] * column.exner[j], j)


@wp.kernel
def sediment(grid: Grid, column: Column, water: Water, fallen: wp.array2d(dtype=float), dt: float, substeps: int,
             x_offset: int):
    """The precipitation's fall over ``dt`` [s] in each column (launched over (nx, nz)): upwind fluxes of ρ q_r V
    in ``substeps`` steps (each below a Courant number of 1), what leaves through the floor added to ``fallen``
    [kg/m^2]. V is each cell's own (:func:`fall_speed` at its temperature), so the fluxes conserve the water at
    any blend of rain and snow."""
    t, k = wp.tid()
    i = t + x_offset
    step = dt / float(substeps)
    for _ in range(substeps):
        # bottom-up: each level loses its own flux and gains the one from above, read before it changes
        out_here = falling_flux(column, water, i, 0, k)
        fallen[i, k] = fallen[i, k] + step * out_here
        for j in range(grid.ny):
            out_above = float(0.0)
            if j + 1 < grid.ny:
                out_above = falling_flux(column, water, i, j + 1, k)
            change = step * (out_above - out_here) / (column.density[j] * grid.dy)
            water.rain[i, j, k] = water.rain[i, j, k] + change
            out_here = out_above

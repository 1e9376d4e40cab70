"""RGB channels as wavelength bands, and the wavelengths each channel averages.

Each channel is a 100 nm band of a flat (equal-energy) spectrum, sampled at the centres of five equal sub-bands with
equal weights. Optical properties of a channel are the weighted mean over its samples (phase functions weighted also
by each wavelength's scattering cross section, so that the mean is the phase function of the band's light).

======= ============== ==================================== =========
channel band [nm]      sample wavelengths [nm]              weights
======= ============== ==================================== =========
R       600 - 700      610, 630, 650, 670, 690              1/5 each
G       500 - 600      510, 530, 550, 570, 590              1/5 each
B       400 - 500      410, 430, 450, 470, 490              1/5 each
======= ============== ==================================== =========

``samples_per_band`` can be raised (the sub-band centres follow) for smoother colours at a higher build cost.
"""

from __future__ import annotations

import numpy as np

CHANNELS = ("R", "G", "B")
#: Band edges [m] per channel, in CHANNELS order.
BANDS = ((600e-9, 700e-9), (500e-9, 600e-9), (400e-9, 500e-9))
#: Representative (centre) wavelength [m] per channel.
CENTRES = tuple(0.5 * (lo + hi) for lo, hi in BANDS)


def band_samples(channel: int, samples_per_band: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths [m], weights summing to 1) that average channel ``channel`` (0 = R, 1 = G, 2 = B)."""
    lo, hi = BANDS[channel]
    edges = np.linspace(lo, hi, samples_per_band + 1)
    return 0.5 * (edges[:-1] + edges[1:]), np.full(samples_per_band, 1.0 / samples_per_band)

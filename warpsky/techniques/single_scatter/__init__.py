"""Single-scattering ray march: the foundation technique and the low-albedo comparison mode."""

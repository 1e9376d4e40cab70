"""Analytic fog (Biri et al. 2002): closed-form transmittance and single-scattered sun and sky light."""

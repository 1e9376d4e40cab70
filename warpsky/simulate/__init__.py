"""``warpsky simulate``: a small cloud-dynamics solver in Warp kernels that grows a storm for warpsky to render.

An anelastic, semi-Lagrangian solver on a MAC grid (after Harris et al. 2003, "Simulation of cloud dynamics on
graphics hardware", whose output Riley et al. 2004 rendered) with Kessler (1969) rain, slow snow and the heat of
deposition aloft (Lin et al. 1983's cold rates), started from a sounding
in CM1's ``input_sounding`` format (Weisman & Klemp 1982 by default) and a warm bubble. It writes per-frame
NanoVDB fields (cloud, ice, rain, snow, velocity) and a USD stage with their time samples.
"""

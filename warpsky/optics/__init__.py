"""Optics: phase functions and (later) per-species cross sections and tables."""

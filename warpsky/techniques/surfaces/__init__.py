"""Opaque Lambertian surfaces: triangle meshes (terrain) through a BVH, and the ground plane."""

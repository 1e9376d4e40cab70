"""Opaque surfaces on the device: triangle meshes through Warp's BVH."""

"""Rendering techniques: each a host class plus its kernels, returning a :class:`~warpsky.layer.Layer`."""

"""Rendering techniques: each a host class plus its kernels, returning a :class:`~warpsky.techniques.base.Layer`."""

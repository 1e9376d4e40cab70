"""Rendering techniques: each a host class plus its kernels, returning an :class:`~warpsky.core.image.ImageLayer`."""

"""The sun's transmittance through stratiform layers, for kernels that light points below them (the fog pass).

It is :func:`~warpsky.media.stratiform.thickness.layer_sun_transmittance` on the device: a point below a layer's base
takes exp(-kappa t / sin e), t the thickness where its ray towards the sun pierces the base plane (bilinear on the
:func:`~warpsky.media.stratiform.thickness.signed_thickness` map, clamped at 0, 0 outside the map), e the sun's
elevation; a point at or above the base, or a sun at or below the horizon, is not dimmed. Every layer's map is padded
into one (layers, nx, nz) array with its own shape, placement and extinction beside it. The light the layers scatter
down is not included (the technique's paths carry it, or the pass's ambient term stands for it).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpsky.media.stratiform.thickness import at_time, signed_thickness


@wp.struct
class LayerShadows:
    """The layers' maps and placement, camera-relative (float64 positions)."""

    count: int
    maps: wp.array3d(dtype=wp.float32)  # (layers, nx_max, nz_max) signed thickness [m], padded with 0
    shapes: wp.array(dtype=wp.vec2i)  # each map's (nx, nz)
    frames: wp.array(dtype=wp.vec4d)  # (x0, z0, size x, size z) [m], camera-relative
    bases: wp.array(dtype=wp.float64)  # base altitude [m], camera-relative
    extinctions: wp.array(dtype=wp.float64)  # kappa [1/m]


def layer_shadows(layers, camera_position, device: str) -> LayerShadows:
    """:class:`LayerShadows` of ``layers`` (at their times) relative to ``camera_position`` (count 0 for none)."""
    kept = [resolved for resolved in (at_time(layer, device) for layer in layers)
            if float(resolved.thickness.max()) > 0.0]
    out = LayerShadows()
    out.count = len(kept)
    eye = np.asarray(camera_position, dtype=np.float64)
    nx = max([layer.thickness.shape[0] for layer in kept], default=2)
    nz = max([layer.thickness.shape[1] for layer in kept], default=2)
    maps = np.zeros((max(1, len(kept)), nx, nz), np.float32)
    shapes, frames, bases, extinctions = [(2, 2)], [(0.0, 0.0, 1.0, 1.0)], [0.0], [0.0]
    if kept:
        shapes, frames, bases, extinctions = [], [], [], []
    for index, layer in enumerate(kept):
        signed = signed_thickness(layer.thickness)
        maps[index, :signed.shape[0], :signed.shape[1]] = signed
        shapes.append(signed.shape)
        frames.append((layer.origin[0] - eye[0], layer.origin[1] - eye[2], layer.size[0], layer.size[1]))
        bases.append(layer.base_altitude - eye[1])
        extinctions.append(layer.extinction)
    out.maps = wp.array(maps, dtype=wp.float32, device=device)
    out.shapes = wp.array(np.asarray(shapes, np.int32), dtype=wp.vec2i, device=device)
    out.frames = wp.array(np.asarray(frames, np.float64), dtype=wp.vec4d, device=device)
    out.bases = wp.array(np.asarray(bases, np.float64), dtype=wp.float64, device=device)
    out.extinctions = wp.array(np.asarray(extinctions, np.float64), dtype=wp.float64, device=device)
    return out


@wp.func
def map_thickness(shadows: LayerShadows, layer: int, x: wp.float64, z: wp.float64) -> wp.float64:
    """ImageLayer ``layer``'s thickness [m] at camera-relative (x, z): bilinear between texel centres, clamped at 0,
    the edge texels' values out to the border, 0 beyond it (as the stratiform kernels sample it)."""
    frame = shadows.frames[layer]
    if x < frame[0] or z < frame[1] or x > frame[0] + frame[2] or z > frame[1] + frame[3]:
        return wp.float64(0.0)
    nu = shadows.shapes[layer][0]
    nv = shadows.shapes[layer][1]
    half = wp.float64(0.5)
    u = wp.clamp((x - frame[0]) / frame[2] * wp.float64(nu) - half, wp.float64(0.0), wp.float64(nu - 1))
    v = wp.clamp((z - frame[1]) / frame[3] * wp.float64(nv) - half, wp.float64(0.0), wp.float64(nv - 1))
    i0 = wp.min(int(u), nu - 2)
    j0 = wp.min(int(v), nv - 2)
    fu = u - wp.float64(i0)
    fv = v - wp.float64(j0)
    one = wp.float64(1.0)
    m = shadows.maps
    value = ((wp.float64(m[layer, i0, j0]) * (one - fu) + wp.float64(m[layer, i0 + 1, j0]) * fu) * (one - fv)
             + (wp.float64(m[layer, i0, j0 + 1]) * (one - fu) + wp.float64(m[layer, i0 + 1, j0 + 1]) * fu) * fv)
    return wp.max(value, wp.float64(0.0))


@wp.func
def layers_sun_transmittance(shadows: LayerShadows, p: wp.vec3d, sun: wp.vec3d) -> wp.float64:
    """Transmittance of the sunlight (unit direction ``sun``, towards it) through every layer above the
    camera-relative point ``p``."""
    tau = wp.float64(0.0)
    if sun[1] <= wp.float64(0.0):
        return wp.float64(1.0)
    for layer in range(shadows.count):
        base = shadows.bases[layer]
        if p[1] < base:
            pierce = p + ((base - p[1]) / sun[1]) * sun
            tau += shadows.extinctions[layer] * map_thickness(shadows, layer, pierce[0], pierce[2]) / sun[1]
    return wp.exp(-tau)

"""Advected textures on the device (Neyret 2003): semi-Lagrangian steps of per-layer coordinate offsets and the
contrast-preserving blend of the layers' texture lookups, as ``@wp.func`` that other kernels can call.

Units inside the kernels are *texels of the advected texture* (texel centres on integers, periodic with the
texture's shape). A layer's texture coordinate at position ``x`` is ``c = x + d(x)``: the kernels store and
interpolate the displacement ``d`` (periodic, because the flow is), never the wrapped coordinate, so the periodic
wrap leaves no seam. Velocities are in texels per second, already in the frame that moves with the uniform wind;
the host folds the wind into one wrapped ``shift`` per frame.

Blend (Neyret's contrast-preserving blend, generalised to correlated layers): with weights ``w_i``, layer values
``v_i`` and the texture's mean ``m``, ``out = m + sum_i w_i (v_i - m) / sqrt(sum_ij w_i w_j R(c_i - c_j))`` where
``R`` is the texture's normalised autocorrelation. For independent layers (``R(c_i - c_j) = 0``) this is Neyret's
``sqrt(sum w_i^2)``; for layers that sample the same point it is the plain weighted mean, so a flow that moves
every layer alike (none, or uniform wind) shows the texture itself.
"""

from __future__ import annotations

from typing import Any

import warp as wp

MAX_LAYERS = wp.constant(8)
vec8 = wp.types.vector(length=8, dtype=float)


@wp.struct
class LayerState:
    """A 2D advected layer at one time, for :func:`advected_value_2d` (arrays are indexed [row y, column x])."""

    texture: wp.array2d(dtype=float)  # the periodic source texture
    correlation: wp.array2d(dtype=float)  # its normalised autocorrelation R(lag), R[0, 0] = 1
    displacement: wp.array3d(dtype=wp.vec2)  # [layer, y, x] coordinate offset d at the grid's nodes [texels]
    cells_per_texel: wp.vec2  # displacement-grid cells per texel along x, y
    weights: vec8  # blend weight per layer (zero at each layer's regeneration)
    layer_count: int
    shift: wp.vec2  # wind displacement wind * t, wrapped into the texture's period [texels]
    mean: float  # the texture's mean


@wp.struct
class DetailState:
    """A 3D advected detail field at one time, for :func:`advected_detail` (arrays are indexed [z, y, x])."""

    texture: wp.array3d(dtype=float)
    correlation: wp.array3d(dtype=float)
    displacement: wp.array4d(dtype=wp.vec3)  # [layer, z, y, x] coordinate offset d [texels]
    cells_per_texel: wp.vec3
    weights: vec8
    layer_count: int
    shift: wp.vec3  # [texels]
    origin: wp.vec3  # the box's minimum corner in the caller's frame [m]
    texels_per_m: wp.vec3  # texture texels per metre along x, y, z
    mean: float
    std: float  # the texture's standard deviation (> 0)


@wp.func
def periodic_cell(x: float, n: int):
    """The cell of a periodic axis of ``n`` nodes holding ``x``: (i0, i1, t) with nodes i0, i1 = i0 + 1 (mod n) and
    the fraction t. Wraps in floating point (no integer division); integer ``x`` in [0, n) gives t = 0 exactly."""
    w = x - float(n) * wp.floor(x / float(n))
    i0 = int(w)
    if i0 >= n:  # w rounded up to n: the value is then the same as at node 0, reached through t = 1
        i0 = n - 1
    t = w - float(i0)
    i1 = i0 + 1
    if i1 == n:
        i1 = 0
    return i0, i1, t


@wp.func
def lerp_exact(a: Any, b: Any, t: float):
    """``a + (b - a) t`` for a float or a vector: returns ``a`` bit for bit at ``t = 0``."""
    return a + (b - a) * t


@wp.func
def periodic_bilinear(a: wp.array2d(dtype=Any), x: float, y: float):
    """Bilinear value (float or vector, as ``a`` holds) of the periodic grid ``a`` ([y, x]) at (x, y) in cell units
    (nodes on integers)."""
    ny = a.shape[0]
    nx = a.shape[1]
    i0, i1, tx = periodic_cell(x, nx)
    j0, j1, ty = periodic_cell(y, ny)
    return lerp_exact(lerp_exact(a[j0, i0], a[j0, i1], tx), lerp_exact(a[j1, i0], a[j1, i1], tx), ty)


@wp.func
def periodic_trilinear(a: wp.array3d(dtype=Any), x: float, y: float, z: float):
    """Trilinear value (float or vector, as ``a`` holds) of the periodic grid ``a`` ([z, y, x]) at (x, y, z) in cell
    units (nodes on integers)."""
    nz = a.shape[0]
    ny = a.shape[1]
    nx = a.shape[2]
    i0, i1, tx = periodic_cell(x, nx)
    j0, j1, ty = periodic_cell(y, ny)
    k0, k1, tz = periodic_cell(z, nz)
    c00 = lerp_exact(a[k0, j0, i0], a[k0, j0, i1], tx)
    c01 = lerp_exact(a[k0, j1, i0], a[k0, j1, i1], tx)
    c10 = lerp_exact(a[k1, j0, i0], a[k1, j0, i1], tx)
    c11 = lerp_exact(a[k1, j1, i0], a[k1, j1, i1], tx)
    return lerp_exact(lerp_exact(c00, c01, ty), lerp_exact(c10, c11, ty), tz)


@wp.func
def blend_layers(values: vec8, weights: vec8, pair_correlation: float, count: int, mean: float) -> float:
    """``mean + sum w_i (v_i - mean) / sqrt(D2)`` given ``pair_correlation = sum_{i<j} w_i w_j R_ij``."""
    numerator = float(0.0)
    d2 = float(0.0)
    total = float(0.0)
    for i in range(count):
        numerator += weights[i] * (values[i] - mean)
        d2 += weights[i] * weights[i]
        total += weights[i]
    d2 += 2.0 * pair_correlation
    # R is positive definite, so d2 >= 0; the floor only guards float rounding of nearly dependent layers
    d2 = wp.max(d2, 1.0e-6 * total * total)
    return mean + numerator / wp.sqrt(d2)


@wp.func
def advected_value_2d(state: LayerState, x: float, y: float) -> float:
    """The blended advected texture at (x, y) [texels of the texture, any real value: the layer is periodic]."""
    px = x - state.shift[0]
    py = y - state.shift[1]
    cx = vec8(0.0)
    cy = vec8(0.0)
    values = vec8(0.0)
    same = int(1)
    for k in range(state.layer_count):
        d = periodic_bilinear(state.displacement[k], px * state.cells_per_texel[0], py * state.cells_per_texel[1])
        cx[k] = px + d[0]
        cy[k] = py + d[1]
        values[k] = periodic_bilinear(state.texture, cx[k], cy[k])
        if cx[k] != cx[0] or cy[k] != cy[0]:
            same = 0
    if same != 0:
        return values[0]  # every layer samples the same point: the blend is that value, exactly
    pairs = float(0.0)
    for i in range(state.layer_count):
        for j in range(i + 1, state.layer_count):
            if state.weights[i] > 0.0 and state.weights[j] > 0.0:
                r = periodic_bilinear(state.correlation, cx[i] - cx[j], cy[i] - cy[j])
                pairs += state.weights[i] * state.weights[j] * r
    return blend_layers(values, state.weights, pairs, state.layer_count, state.mean)


@wp.func
def advected_detail(state: DetailState, p: wp.vec3) -> float:
    """The blended advected detail value at point ``p`` (the caller's frame, metres); it has the source texture's
    mean and standard deviation. Periodic: points outside the box see the texture tiled."""
    q = wp.cw_mul(p - state.origin, state.texels_per_m) - state.shift
    cx = vec8(0.0)
    cy = vec8(0.0)
    cz = vec8(0.0)
    values = vec8(0.0)
    same = int(1)
    for k in range(state.layer_count):
        d = periodic_trilinear(state.displacement[k], q[0] * state.cells_per_texel[0],
                               q[1] * state.cells_per_texel[1], q[2] * state.cells_per_texel[2])
        cx[k] = q[0] + d[0]
        cy[k] = q[1] + d[1]
        cz[k] = q[2] + d[2]
        values[k] = periodic_trilinear(state.texture, cx[k], cy[k], cz[k])
        if cx[k] != cx[0] or cy[k] != cy[0] or cz[k] != cz[0]:
            same = 0
    if same != 0:
        return values[0]
    pairs = float(0.0)
    for i in range(state.layer_count):
        for j in range(i + 1, state.layer_count):
            if state.weights[i] > 0.0 and state.weights[j] > 0.0:
                r = periodic_trilinear(state.correlation, cx[i] - cx[j], cy[i] - cy[j], cz[i] - cz[j])
                pairs += state.weights[i] * state.weights[j] * r
    return blend_layers(values, state.weights, pairs, state.layer_count, state.mean)


@wp.func
def modulated_density(state: DetailState, coarse: float, p: wp.vec3, amplitude: float) -> float:
    """``coarse * max(0, 1 + amplitude * z)`` with ``z`` the advected detail at ``p`` in standard deviations.

    ``amplitude`` 0 returns ``coarse``; 0.3 makes a one-sigma wisp 30 % denser. Use inside a density sampler; the
    coarse grid itself is never rewritten.
    """
    z = (advected_detail(state, p) - state.mean) / state.std
    return coarse * wp.max(0.0, 1.0 + amplitude * z)


@wp.kernel
def reset_layers_2d(reset: wp.array(dtype=int), d: wp.array3d(dtype=wp.vec2)):
    k, j, i = wp.tid()
    if reset[k] != 0:
        d[k, j, i] = wp.vec2(0.0)


@wp.kernel
def advect_step_2d(
    velocity: wp.array2d(dtype=wp.vec2),  # [y, x] velocity in the wind's frame [texels/s]
    velocity_cells_per_cell: wp.vec2,  # velocity-grid cells per displacement-grid cell
    texels_per_cell: wp.vec2,  # texture texels per displacement-grid cell
    dt_table: wp.array2d(dtype=float),  # [row, layer] step length [s]; 0 copies the layer unchanged
    row: int,
    src: wp.array3d(dtype=wp.vec2),
    dst: wp.array3d(dtype=wp.vec2),
):
    """One semi-Lagrangian step of every layer's displacement: ``d'(x) = d(p) + (p - x)`` with ``p`` the point
    the flow carries to ``x`` in ``dt`` (RK2 back-trace). Interpolation is a convex combination, so any CFL is
    stable."""
    k, j, i = wp.tid()
    dt = dt_table[row, k]
    if dt == 0.0:
        dst[k, j, i] = src[k, j, i]
        return
    x = float(i)
    y = float(j)
    vx = velocity_cells_per_cell[0]
    vy = velocity_cells_per_cell[1]
    u1 = periodic_bilinear(velocity, x * vx, y * vy)  # texels/s
    mx = x - 0.5 * dt * u1[0] / texels_per_cell[0]
    my = y - 0.5 * dt * u1[1] / texels_per_cell[1]
    u2 = periodic_bilinear(velocity, mx * vx, my * vy)
    back = -dt * u2  # texels
    px = x + back[0] / texels_per_cell[0]
    py = y + back[1] / texels_per_cell[1]
    dst[k, j, i] = periodic_bilinear(src[k], px, py) + back


@wp.kernel
def advected_layer_kernel(state: LayerState, out: wp.array2d(dtype=float), row_offset: int):
    """The blended layer on the texture's own grid (one thread per texel)."""
    r, i = wp.tid()
    j = r + row_offset
    out[j, i] = advected_value_2d(state, float(i), float(j))


@wp.kernel
def reset_layers_3d(reset: wp.array(dtype=int), d: wp.array4d(dtype=wp.vec3)):
    k, l, j, i = wp.tid()
    if reset[k] != 0:
        d[k, l, j, i] = wp.vec3(0.0)


@wp.kernel
def advect_step_3d(
    velocity: wp.array3d(dtype=wp.vec3),  # [z, y, x] velocity in the wind's frame [texels/s]
    velocity_cells_per_cell: wp.vec3,
    texels_per_cell: wp.vec3,
    dt_table: wp.array2d(dtype=float),
    row: int,
    src: wp.array4d(dtype=wp.vec3),
    dst: wp.array4d(dtype=wp.vec3),
):
    """3D version of :func:`advect_step_2d`."""
    k, l, j, i = wp.tid()
    dt = dt_table[row, k]
    if dt == 0.0:
        dst[k, l, j, i] = src[k, l, j, i]
        return
    x = wp.vec3(float(i), float(j), float(l))
    u1 = periodic_trilinear(velocity, x[0] * velocity_cells_per_cell[0], x[1] * velocity_cells_per_cell[1],
                            x[2] * velocity_cells_per_cell[2])
    m = x - 0.5 * dt * wp.cw_div(u1, texels_per_cell)
    u2 = periodic_trilinear(velocity, m[0] * velocity_cells_per_cell[0], m[1] * velocity_cells_per_cell[1],
                            m[2] * velocity_cells_per_cell[2])
    back = -dt * u2
    p = x + wp.cw_div(back, texels_per_cell)
    dst[k, l, j, i] = periodic_trilinear(src[k], p[0], p[1], p[2]) + back


@wp.kernel
def detail_grid_kernel(state: DetailState, start: wp.vec3, spacing: wp.vec3, out: wp.array3d(dtype=float),
                       row_offset: int):
    """``out[z, y, x] = advected_detail(state, start + (x, y, z) * spacing)``; rows are z * ny + y."""
    r, i = wp.tid()
    row = r + row_offset
    ny = out.shape[1]
    l = row // ny
    j = row - l * ny
    p = start + wp.cw_mul(wp.vec3(float(i), float(j), float(l)), spacing)
    out[l, j, i] = advected_detail(state, p)

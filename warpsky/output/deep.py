"""Deep EXR: a frame's layers as OpenEXR deep samples, for compositors that merge volumes with other renders.

Each layer the frame composites becomes at most one sample per pixel where it shows something (radiance or
attenuation): the depth-merged passes (the technique's media, stratiform decks, fog, height-field decks, meshes)
each on its own, in the per-pixel order of their depths, between the air in front and the sky behind. A layer
with a depth is a point sample (``Z`` = ``ZBack``) there; the air in front is a volume sample from the camera
to the first sample behind it, the sky a point at the far clip.

Deep samples carry one alpha per sample while a layer attenuates each colour channel by its own transmittance
T_k, so the samples are built for OpenEXR's flattening ("Interpreting OpenEXR Deep Pixels": front to back,
colour C = sum_k C_k prod_{j<k} (1 - A_j), alpha likewise) to give back the flat frame exactly:

    A_k = 1 - lum(P_k T_k) / lum(P_k),     C_k = L_k P_k / lum(P_k),

with L_k the layer's radiance, P_k the per-channel product of the transmittances in front of it and lum the
luminance weights of the frame's alpha. The alphas telescope, prod_{j<k} (1 - A_j) = lum(P_k), so the flattened
colour is sum_k L_k P_k, the beauty, and the flattened alpha is the beauty's alpha. What is approximate is only a
merge with other deep images: a sample inserted between two of warpsky's is attenuated by the luminance of the
transmittance in front, not per channel. Depths are made non-decreasing along each pixel's samples (a layer's
representative depth can sit in front of the one composited before it; the sample order is the compositing
order). A volume is one sample per layer: a render placed inside a cloud is composited in front of or behind all
of it. With extra suns the merged layer is written as one sample.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from warpsky.files import OutputError, atomic_write
from warpsky.scene.model import LUMINANCE_WEIGHTS

#: Below this luminance of the transmittance in front, a layer is hidden and gets no sample.
HIDDEN_BELOW = 1e-12


@dataclass
class DeepPixels:
    """Deep samples of an image: ``counts`` (H, W) samples per pixel; each channel a flat float32 array of all
    samples, pixel after pixel in scanline order and front to back within a pixel."""

    counts: np.ndarray
    channels: dict

    def per_pixel(self, name: str) -> np.ndarray:
        """Channel ``name`` as OpenEXR's Python bindings take a deep channel: an (H, W) object array of 1-D
        float32 arrays."""
        height, width = self.counts.shape
        parts = np.split(self.channels[name], np.cumsum(self.counts.reshape(-1))[:-1])
        out = np.empty(height * width, dtype=object)
        for i, part in enumerate(parts):
            out[i] = part
        return out.reshape(height, width)


def _stacks(layers, region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(radiance (N, H, W, 3), transmittance (N, H, W, 3), depth (N, H, W)) float64 of the layers as composited
    front to back, a merged layer expanded into its parts in the per-pixel order of their depths (as the merge
    composited them), a part's ``front`` light (already attenuated to the eye) as a clear sample ahead of the group,
    cropped to ``region`` (x, y, width, height; None: all)."""
    x, y, width, height = region if region is not None else (0, 0, layers[0].depth.shape[1], layers[0].depth.shape[0])
    rows = (slice(y, y + height), slice(x, x + width))
    radiance, transmittance, depth = [], [], []
    for layer in layers:
        group = layer.parts or [layer]
        d = np.stack([np.asarray(part.depth, np.float64)[rows] for part in group])
        for front in (part.front for part in group if part.front is not None):  # light already seen through the
            radiance.append(np.asarray(front.radiance, np.float64)[rows])       # group: a clear sample at its
            transmittance.append(np.ones_like(radiance[-1]))                    # nearest depth, ahead of it
            depth.append(d.min(axis=0))
        order = np.argsort(d, axis=0, kind="stable")
        r = np.stack([np.asarray(part.radiance, np.float64)[rows] for part in group])
        t = np.stack([np.asarray(part.transmittance, np.float64)[rows] for part in group])
        radiance += list(np.take_along_axis(r, order[..., None], axis=0))
        transmittance += list(np.take_along_axis(t, order[..., None], axis=0))
        depth += list(np.take_along_axis(d, order, axis=0))
    return np.stack(radiance), np.stack(transmittance), np.stack(depth)


def _sample_depths(depth: np.ndarray, present: np.ndarray, far: float) -> tuple[np.ndarray, np.ndarray]:
    """(Z, ZBack) (N, H, W) of the samples: a layer with a depth in front of ``far`` is a point there (never in
    front of the sample before it); an unbounded one (the air in front, the sky) spans from the sample before it
    (or the camera) to the one after it, or is a point at ``far`` when nothing bounded lies behind it."""
    bounded = present & (depth < far)
    z = np.zeros_like(depth)
    last = np.zeros(depth.shape[1:])
    for k in range(depth.shape[0]):
        z[k] = np.where(bounded[k], np.maximum(depth[k], last), last)
        last = np.where(bounded[k], z[k], last)
    back = z.copy()
    following = np.full(depth.shape[1:], np.inf)
    for k in reversed(range(depth.shape[0])):
        unbounded = present[k] & ~bounded[k]
        back[k] = np.where(unbounded, following, back[k])
        following = np.where(bounded[k], z[k], following)
    sky = ~np.isfinite(back)
    return np.where(sky, far, z), np.where(sky, far, back)


def deep_from_layers(layers, far: float, matrix: np.ndarray | None = None, region=None) -> DeepPixels:
    """The deep samples of ``layers`` (:class:`~warpsky.layer.Layer`, composited front to back) in ``region``
    (x, y, width, height of their pixels; None: all), with colours taken to the output colour space by ``matrix``
    (3x3, applied to column vectors; None: unchanged)."""
    weights = LUMINANCE_WEIGHTS.astype(np.float64)
    radiance, transmittance, depth = _stacks(layers, region)
    front = np.cumprod(np.concatenate([np.ones_like(transmittance[:1]), transmittance[:-1]]), axis=0)  # P_k
    seen = front @ weights
    present = ((radiance.max(axis=-1) > 0.0) | (transmittance.min(axis=-1) < 1.0)) & (seen > HIDDEN_BELOW)
    safe = np.where(present, seen, 1.0)
    alpha = np.clip(1.0 - ((front * transmittance) @ weights) / safe, 0.0, 1.0)
    colour = radiance * front / safe[..., None]
    if matrix is not None:
        colour = colour @ np.asarray(matrix, dtype=np.float64).T
    z, z_back = _sample_depths(depth, present, far)
    pick = np.moveaxis(present, 0, -1)  # (H, W, N): pixel after pixel, front to back within each

    def flat(values):
        return np.moveaxis(values, 0, -1)[pick].astype(np.float32)

    channels = {c: flat(colour[..., i]) for i, c in enumerate("RGB")}
    channels.update(A=flat(alpha), Z=flat(z), ZBack=flat(z_back))
    return DeepPixels(pick.sum(axis=-1).astype(np.int64), channels)


def _visibility(deep: DeepPixels) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, prod (1 - A) of its pixel's samples in front of it, and that product including itself."""
    counts = deep.counts.reshape(-1)
    start = np.cumsum(counts) - counts
    before, after = np.empty(int(counts.sum())), np.empty(int(counts.sum()))
    through = np.ones(counts.size)
    for k in range(int(counts.max(initial=0))):
        has = counts > k
        index = start[has] + k
        before[index] = through[has]
        through[has] *= 1.0 - deep.channels["A"][index].astype(np.float64)
        after[index] = through[has]
    return before, after


def average_deep(deeps: list[DeepPixels]) -> DeepPixels:
    """One deep image that flattens to the mean of the flattened ``deeps`` (a motion-blurred frame's sub-frames).

    Every sub-frame's samples are kept, merged per pixel in depth order. Along one sub-frame k a sample sees
    v_k = prod (1 - A) of the samples in front of it; the mean image's visibility in front of the merged sample m
    is V_m = 1 - sum over the merged samples l before it of (v_before_l - v_after_l) / N. The sample gets
    A_m = 1 - V_(m+1) / V_m and colour C_m = C v_before / (N V_m), so the flattened colour is
    sum_m C v_before / N and the flattened alpha 1 - mean_k v_k, exactly the mean of the sub-frames."""
    n = len(deeps)
    counts = np.sum([d.counts for d in deeps], axis=0)
    pixel, z, order, before, after = [], [], [], [], []
    for k, deep in enumerate(deeps):
        v_before, v_after = _visibility(deep)
        pixel.append(np.repeat(np.arange(deep.counts.size), deep.counts.reshape(-1)))
        z.append(deep.channels["Z"]), order.append(np.full(v_before.size, k))
        before.append(v_before), after.append(v_after)
    pixel, z, order = np.concatenate(pixel), np.concatenate(z), np.concatenate(order)
    sort = np.lexsort((order, z, pixel))
    v_before, v_after = np.concatenate(before)[sort], np.concatenate(after)[sort]
    drop = (v_before - v_after) / n
    owner = pixel[sort]
    total = np.cumsum(drop)
    first = np.searchsorted(owner, owner)  # each sample's pixel's first merged sample
    seen_before = 1.0 - (total - drop - np.where(first > 0, total[np.maximum(first - 1, 0)], 0.0))
    seen_after = seen_before - drop
    visible = seen_before > HIDDEN_BELOW
    safe = np.where(visible, seen_before, 1.0)
    channels = {name: np.concatenate([d.channels[name] for d in deeps])[sort] for name in ("Z", "ZBack")}
    for name in "RGB":
        colour = np.concatenate([d.channels[name] for d in deeps]).astype(np.float64)[sort]
        channels[name] = np.where(visible, colour * v_before / (n * safe), 0.0).astype(np.float32)
    channels["A"] = np.where(visible, np.clip(1.0 - seen_after / safe, 0.0, 1.0), 0.0).astype(np.float32)
    return DeepPixels(counts.astype(np.int64), channels)


def flatten(deep: DeepPixels) -> np.ndarray:
    """(H, W, 4) RGBA of OpenEXR's flattening of point samples sorted front to back: each sample's colour seen
    through 1 - alpha of those in front of it; alpha 1 - prod (1 - A_k)."""
    height, width = deep.counts.shape
    counts = deep.counts.reshape(-1)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = np.zeros((height * width, 4))
    through = np.ones(height * width)
    for k in range(int(counts.max(initial=0))):
        has = counts > k
        index = start[has] + k
        colour = np.stack([deep.channels[c][index] for c in "RGB"], axis=-1).astype(np.float64)
        out[has, :3] += through[has, None] * colour
        through[has] *= 1.0 - deep.channels["A"][index].astype(np.float64)
    out[:, 3] = 1.0 - through
    return out.reshape(height, width, 4)


def write_deep_exr(path: str | os.PathLike, deep: DeepPixels, *, header: dict | None = None) -> os.PathLike:
    """Write ``deep`` as a deep scanline EXR (channels R, G, B, A, Z, ZBack, 32-bit float) atomically, with the
    attributes in ``header`` (``warpsky/...`` metadata and OpenEXR's standard attributes, as the flat frame has)."""
    import OpenEXR

    for name, values in deep.channels.items():
        if not np.all(np.isfinite(values)):
            raise OutputError(f"deep channel {name}: {int(np.sum(~np.isfinite(values)))} NaN/Inf samples; "
                              "refusing to write them")
    attributes = {"compression": OpenEXR.ZIPS_COMPRESSION, "type": OpenEXR.deepscanline, **(header or {})}
    channels = {name: deep.per_pixel(name) for name in ("R", "G", "B", "A", "Z", "ZBack")}
    return atomic_write(path, lambda tmp: OpenEXR.File(attributes, channels).write(str(tmp)))


def deep_up_to_date(path: str | os.PathLike, settings_hash: str) -> bool:
    """Whether ``path`` is a readable deep EXR whose header carries ``settings_hash`` (a batch's resume test)."""
    import OpenEXR

    from warpsky.output.exr import METADATA_PREFIX

    if not os.path.isfile(path):
        return False
    try:
        with OpenEXR.File(os.fspath(path), header_only=True) as exr:  # the header lives while the file is open
            header = exr.header()
            return (str(header.get("type", "")).endswith("deepscanline")
                    and header.get(METADATA_PREFIX + "settingsHash") == settings_hash)
    except Exception:  # noqa: BLE001 - a truncated or foreign file is simply not up to date
        return False


def deep_path(out_path: str | os.PathLike) -> str:
    """The deep file written beside a flat frame: ``name.0001.exr`` -> ``name.0001.deep.exr``."""
    text = os.fspath(out_path)
    return text[:-4] + ".deep.exr" if text.endswith(".exr") else text + ".deep.exr"

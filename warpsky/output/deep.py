"""Deep EXR: a frame's layers as OpenEXR deep samples, for compositors that merge volumes with other renders.

Each layer the frame composites becomes samples of its own where it shows something (radiance or attenuation): the
depth-merged passes (the technique's media, stratiform decks, fog, height-field decks, meshes) each on its own, in the
per-pixel order of their depths, between the air in front and the sky behind. A volume layer that drew a depth
profile (the technique's voxel media and analytic fog, when a frame asks for deep output) is K volume samples
(``Z < ZBack``, ``--deep-samples``, default 8) between its media's entry and exit along each pixel's ray, each
holding a bounded share of its opacity, plus a point on the ground it drew behind them
(:mod:`warpsky.output.deep_bins`): a render merged into the volume is seen through the part in front of it and hides
the part behind. Every other layer with a
depth (stratiform and height-field decks, meshes, a volume pixel its media do not reach) is a point sample
(``Z`` = ``ZBack``) there; the air in front is a volume sample from the camera to the first sample behind it, the
sky a point at the far clip.

Deep samples carry one alpha per sample while a layer attenuates each colour channel by its own transmittance
T_k, so the samples are built for OpenEXR's flattening ("Interpreting OpenEXR Deep Pixels": front to back,
colour C = sum_k C_k prod_{j<k} (1 - A_j), alpha likewise) to give back the flat frame exactly:

    A_k = 1 - lum(P_k T_k) / lum(P_k),     C_k = L_k P_k / lum(P_k),

with L_k the layer's radiance, P_k the per-channel product of the transmittances in front of it and lum the
luminance weights of the frame's alpha. The alphas telescope, prod_{j<k} (1 - A_j) = lum(P_k), so the flattened
colour is sum_k L_k P_k, the beauty, and the flattened alpha is the beauty's alpha. What is approximate is only a
merge with other deep images: a sample inserted between two of warpsky's is attenuated by the luminance of the
transmittance in front, not per channel. Depths are made non-decreasing and samples non-overlapping along each
pixel (a layer's representative depth can sit in front of the one composited before it, a volume can reach into
the next layer: the sample order is the compositing order, and a sample starts no nearer than the one before it
ends). With extra suns the merged layer is written as one sample.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import OutputError
from warpsky.core.files import atomic_write
from warpsky.core.numerics import LUMINANCE_WEIGHTS
from warpsky.output.deep_bins import profile_samples

#: A deep image's channels, in the order they are written.
CHANNELS = ("R", "G", "B", "A", "Z", "ZBack")
#: Below this luminance of the transmittance in front, a layer is hidden and gets no sample.
HIDDEN_BELOW = 1e-12
#: Pixels built at once: the frame's deep samples are made in bands of rows of about this many pixels, so that the
#: per-sample stacks (float64, every layer's K + 2 samples) stay at tens of MB whatever the image size.
BAND_PIXELS = 2**16


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


def _samples(layer, rows) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(radiance, transmittance, Z, ZBack) of one layer's samples in ``rows``, with a leading sample axis: its
    profile's bins (:func:`~warpsky.output.deep_bins.profile_samples`), or one point at its depth."""
    if layer.profile is not None:
        return profile_samples(layer, rows)
    depth = np.asarray(layer.depth, np.float64)[rows][None]
    return (np.asarray(layer.radiance, np.float64)[rows][None], np.asarray(layer.transmittance, np.float64)[rows][None],
            depth, depth)


def _padded(samples, count: int):
    """``samples`` (:func:`_samples`) grown to ``count`` samples by clear ones that carry nothing."""
    missing = count - len(samples[0])
    if missing == 0:
        return samples
    radiance, through, z, back = samples
    last = np.repeat(z[-1:], missing, axis=0)
    return (np.concatenate([radiance, np.zeros((missing, *radiance.shape[1:]))]),
            np.concatenate([through, np.ones((missing, *through.shape[1:]))]),
            np.concatenate([z, last]), np.concatenate([back, last]))


def _stacks(layers, region) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(radiance (N, H, W, 3), transmittance (N, H, W, 3), Z (N, H, W), ZBack (N, H, W)) float64 of the samples of
    the layers as composited front to back, a merged layer expanded into its parts in the per-pixel order of their
    depths (as the merge composited them), each part into its samples (:func:`_samples`), a part's ``front`` light
    (already attenuated to the eye) as a clear sample ahead of the group, cropped to ``region`` (x, y, width,
    height)."""
    x, y, width, height = region
    rows = (slice(y, y + height), slice(x, x + width))
    radiance, transmittance, depth, back = [], [], [], []
    for layer in layers:
        group = layer.parts or [layer]
        d = np.stack([np.asarray(part.depth, np.float64)[rows] for part in group])
        for front in (part.front for part in group if part.front is not None):  # light already seen through the
            radiance.append(np.asarray(front.radiance, np.float64)[rows])       # group: a clear sample at its
            transmittance.append(np.ones_like(radiance[-1]))                    # nearest depth, ahead of it
            depth.append(d.min(axis=0))
            back.append(depth[-1])
        samples = [_samples(part, rows) for part in group]
        count = max(len(s[0]) for s in samples)
        samples = [_padded(s, count) for s in samples]
        order = np.argsort(d, axis=0, kind="stable")[:, None]  # (parts, 1, H, W): each part's samples stay together
        for i, out in enumerate((radiance, transmittance, depth, back)):
            stacked = np.stack([s[i] for s in samples])  # (parts, samples, H, W[, 3])
            pick = order[..., None] if stacked.ndim == 5 else order
            out += list(np.take_along_axis(stacked, pick, axis=0).reshape(-1, *stacked.shape[2:]))
    return np.stack(radiance), np.stack(transmittance), np.stack(depth), np.stack(back)


def _sample_depths(depth: np.ndarray, back: np.ndarray, present: np.ndarray,
                   far: float) -> tuple[np.ndarray, np.ndarray]:
    """(Z, ZBack) (N, H, W) of the samples: one with a depth in front of ``far`` spans [depth, back] (a point where
    they are equal), moved back so that it starts no nearer than the sample before it ends; an unbounded one (the
    air in front, the sky) spans from the sample before it (or the camera) to the one after it, or is a point at
    ``far`` when nothing bounded lies behind it."""
    bounded = present & (depth < far)
    z = np.zeros_like(depth)
    z_back = np.zeros_like(depth)
    last = np.zeros(depth.shape[1:])
    for k in range(depth.shape[0]):
        z[k] = np.where(bounded[k], np.maximum(depth[k], last), last)
        z_back[k] = np.where(bounded[k], np.maximum(back[k], z[k]), z[k])
        last = np.where(bounded[k], z_back[k], last)
    following = np.full(depth.shape[1:], np.inf)
    for k in reversed(range(depth.shape[0])):
        unbounded = present[k] & ~bounded[k]
        z_back[k] = np.where(unbounded, following, z_back[k])
        following = np.where(bounded[k], z[k], following)
    sky = ~np.isfinite(z_back)
    return np.where(sky, far, z), np.where(sky, far, z_back)


def deep_from_layers(layers, far: float, matrix: np.ndarray | None = None, region=None) -> DeepPixels:
    """The deep samples of ``layers`` (:class:`~warpsky.core.image.ImageLayer`, composited front to back) in ``region``
    (x, y, width, height of their pixels; None: all), with colours taken to the output colour space by ``matrix``
    (3x3, applied to column vectors; None: unchanged); built in bands of :data:`BAND_PIXELS`."""
    x, y, width, height = region if region is not None else (0, 0, layers[0].depth.shape[1], layers[0].depth.shape[0])
    rows = max(1, BAND_PIXELS // max(width, 1))
    bands = [_deep_band(layers, far, matrix, (x, top, width, min(rows, y + height - top)))
             for top in range(y, y + height, rows)]
    if not bands:
        return DeepPixels(np.zeros((0, width), np.int64), {c: np.zeros(0, np.float32) for c in CHANNELS})
    return DeepPixels(np.concatenate([band.counts for band in bands]),
                      {c: np.concatenate([band.channels[c] for band in bands]) for c in CHANNELS})


def _deep_band(layers, far: float, matrix, region) -> DeepPixels:
    """:func:`deep_from_layers` of the pixels ``region`` (x, y, width, height)."""
    weights = LUMINANCE_WEIGHTS.astype(np.float64)
    radiance, transmittance, depth, back = _stacks(layers, region)
    front = np.cumprod(np.concatenate([np.ones_like(transmittance[:1]), transmittance[:-1]]), axis=0)  # P_k
    seen = front @ weights
    present = ((radiance.max(axis=-1) > 0.0) | (transmittance.min(axis=-1) < 1.0)) & (seen > HIDDEN_BELOW)
    safe = np.where(present, seen, 1.0)
    alpha = np.clip(1.0 - ((front * transmittance) @ weights) / safe, 0.0, 1.0)
    colour = radiance * front / safe[..., None]
    if matrix is not None:
        colour = colour @ np.asarray(matrix, dtype=np.float64).T
    z, z_back = _sample_depths(depth, back, present, far)
    pick = np.moveaxis(present, 0, -1)  # (H, W, N): pixel after pixel, front to back within each

    def flat(values):
        return np.moveaxis(values, 0, -1)[pick].astype(np.float32)

    channels = {c: flat(colour[..., i]) for i, c in enumerate("RGB")}
    channels.update(A=flat(alpha), Z=flat(z), ZBack=flat(z_back))
    return DeepPixels(pick.sum(axis=-1).astype(np.int64), channels)


def visibility_in_front(deep: DeepPixels, depth) -> np.ndarray:
    """(H, W) float64 fraction of the light from a point at camera-space ``depth`` [m] (a number or (H, W)) that
    reaches the eye through the samples in front of it, as a deep merge sees it: prod (1 - A) of the samples with
    ``ZBack <= depth``, times (1 - A)^f of a volume sample that ``depth`` cuts, f the fraction of its
    [Z, ZBack] in front ("Interpreting OpenEXR Deep Pixels")."""
    counts = deep.counts.reshape(-1)
    depth = np.broadcast_to(np.asarray(depth, np.float64), deep.counts.shape).reshape(-1)
    owner = np.repeat(np.arange(counts.size), counts)
    z = deep.channels["Z"].astype(np.float64)
    z_back = deep.channels["ZBack"].astype(np.float64)
    at = depth[owner]
    span = z_back - z
    fraction = np.where(z_back <= at, 1.0, np.where(span > 0.0, np.clip((at - z) / np.where(span > 0.0, span, 1.0),
                                                                         0.0, 1.0), 0.0))
    clear = 1.0 - deep.channels["A"].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_clear = np.where(fraction > 0.0, fraction * np.log(clear), 0.0)
    return np.exp(np.bincount(owner, weights=log_clear, minlength=counts.size)).reshape(deep.counts.shape)


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

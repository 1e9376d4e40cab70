"""Deep output's volume samples: a layer cut along each pixel's camera ray into bins of its opacity.

A layer whose pass drew a :class:`DepthProfile` (the technique's voxel media, analytic fog) becomes, where its media
show, K volume samples (``Z < ZBack``) between the media's entry and exit along the ray, and one point sample for
what the layer attenuates beyond them where the ground ends the ray. The profile holds the media's optical depth
tau_k at the bins' K + 1 edges, placed so that every bin holds a bounded share of the opacity and of the length
(:mod:`warpsky.passes.depth_profile` marches it and gives the measured errors). A compositor splits a volume
sample's alpha exponentially in depth ("Interpreting OpenEXR Deep Pixels": a fraction f of the sample lets
(1 - A)^f through), which is exact for uniform extinction inside a bin.

From the layer's own transmittance T and radiance L (per channel):

* the profile is clamped to the layer's optical depth, tau'_k = min(tau_k, -ln T): a technique that stopped its
  march at its cut-off, or whose discretisation differs from the profile's march, keeps its own T;
* bin k lets exp(-(tau'_(k+1) - tau'_k)) through; what the layer attenuates beyond the profile, T exp(tau'_K), is
  one point sample at the profile's ``end`` where the ray ends on the ground plane the technique drew, else part of
  the last bin (a march's discretisation; for the path tracer also the air, fog, decks and meshes it traces into
  the same layer, which the profile does not see);
* L is split over the samples in proportion to each one's share of the layer's opacity as seen from the layer's
  front, exp(-tau'_k) (1 - exp(-(tau'_(k+1) - tau'_k))), per channel: a uniform source function per unit opacity.

The samples' transmittances multiply to T and their radiances, each seen through the samples in front, add up to L,
per channel, by construction: flattening gives back the frame exactly. Exact (up to the profile's march and the
uniform extinction inside a bin) are the alphas, so a render merged into the volume is held out by the part of the
volume in front of it; approximate is where in depth the colour comes from (the layer's light is spread as its
opacity, not as the sunlight inside the volume falls off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpsky.core.errors import UsageError

#: Volume samples per volume layer and pixel unless asked otherwise (``--deep-samples``): the visibility of a point
#: inside a density ramp rising 20-fold along the ray is then within 1e-2 of the closed form (4e-3 to 9e-3 measured),
#: inside a homogeneous medium within float32 rounding.
DEEP_SAMPLES = 8
#: At most this many volume samples per volume layer (each costs 16 bytes per pixel while the frame is built).
MAX_DEEP_SAMPLES = 64
#: Below this luminance opacity of its media along a pixel's ray, a layer stays one sample there.
SHOWN_OPACITY = 1.0e-6


def check_deep_samples(count, what: str = "--deep-samples") -> int:
    """``count`` as a whole number of volume samples in 1..:data:`MAX_DEEP_SAMPLES`; else a UsageError naming
    ``what``."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 1 <= count <= MAX_DEEP_SAMPLES:
        raise UsageError(f"{what} must be a whole number of samples per volume in 1..{MAX_DEEP_SAMPLES}, got "
                         f"{count!r}")
    return int(count)


@dataclass
class DepthProfile:
    """A layer's extinction along each pixel's camera ray, cut into bins.

    Attributes:
        edges: (H, W, K + 1) float32 camera-space depths [m] of the bins' edges along the view axis,
            non-decreasing: the media's entry, K - 1 inner edges, the end of the march (the media's exit, or where
            they hide all but 1e-6 of what lies behind); zeros where the ray meets no media.
        optical_depth: (H, W, K + 1, 3) float32 RGB optical depth from the first edge to each edge.
        end: (H, W) float32 depth [m] of the point sample for what the layer attenuates beyond the bins: the
            ground plane that ends the ray, else the last edge.
    """

    edges: np.ndarray
    optical_depth: np.ndarray
    end: np.ndarray

    @property
    def count(self) -> int:
        """Bins per pixel (K)."""
        return int(self.edges.shape[-1]) - 1

    def __repr__(self) -> str:
        height, width = self.end.shape
        return f"DepthProfile({self.count} bins, {width} x {height} pixels)"


def profile_samples(layer, rows) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(radiance (S, h, w, 3), transmittance (S, h, w, 3), Z (S, h, w), ZBack (S, h, w)) float64 of ``layer``'s
    samples in the pixels ``rows`` (a (rows, columns) slice pair), front to back, S = K + 2: the K bins of its
    ``profile`` and the point beyond them where its media show, else the layer as one point at its depth (the
    others then let everything through and carry nothing). Radiance is each sample's own, as a layer's: what it
    sends towards the eye from its front."""
    from warpsky.core.numerics import LUMINANCE_WEIGHTS  # a kernel module: loads Warp, which --help does without

    weights = LUMINANCE_WEIGHTS.astype(np.float64)
    radiance = np.asarray(layer.radiance, np.float64)[rows]
    through = np.clip(np.asarray(layer.transmittance, np.float64)[rows], 0.0, 1.0)
    depth = np.asarray(layer.depth, np.float64)[rows]
    profile = layer.profile
    edges = np.asarray(profile.edges, np.float64)[rows]
    tau = np.asarray(profile.optical_depth, np.float64)[rows]
    tau = np.maximum.accumulate(np.maximum(tau - tau[..., :1, :], 0.0), axis=-2)
    with np.errstate(divide="ignore"):
        own = -np.log(through)  # the layer's optical depth; inf where it is opaque
    tau = np.minimum(tau, own[..., None, :])
    end = np.maximum(np.asarray(profile.end, np.float64)[rows], edges[..., -1])
    rest = np.maximum(own - tau[..., -1, :], 0.0)
    fold = (end <= edges[..., -1])[..., None]  # nothing ends the ray behind the media: the rest is the last bin's
    depths = np.concatenate([np.diff(tau, axis=-2), np.where(fold, 0.0, rest)[..., None, :]], axis=-2)
    depths[..., -2, :] += np.where(fold, rest, 0.0)
    opacity = -np.expm1(-depths)  # (h, w, K + 1, 3): the bins, then what lies beyond them
    share = np.exp(-tau) * opacity  # of the layer's opacity, seen from its front
    total = share.sum(axis=-2, keepdims=True)
    luminous = share @ weights
    fraction = np.divide(luminous, luminous.sum(axis=-1, keepdims=True), out=np.zeros_like(luminous),
                         where=luminous.sum(axis=-1, keepdims=True) > 0.0)
    # a channel the layer does not dim (total 0) has its light split by the luminance shares (its tau' is 0)
    spread = np.where(total > 0.0, np.divide(opacity, total, out=np.zeros_like(opacity), where=total > 0.0),
                      fraction[..., None])
    shown = (-np.expm1(-tau[..., -1, :]) @ weights) > SHOWN_OPACITY
    binned = shown[None, ..., None]
    own_radiance = np.where(binned, np.moveaxis(radiance[..., None, :] * spread, -2, 0), 0.0)
    own_through = np.where(binned, np.moveaxis(np.exp(-depths), -2, 0), 1.0)
    z = np.moveaxis(edges, -1, 0)
    front = np.concatenate([z[:-1], end[None], depth[None]])
    back = np.concatenate([z[1:], end[None], depth[None]])
    one = ~shown[None, ..., None]
    radiance = np.concatenate([own_radiance, np.where(one, radiance[None], 0.0)])
    through = np.concatenate([own_through, np.where(one, through[None], 1.0)])
    return radiance, through, front, back

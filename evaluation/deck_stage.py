"""A small height-field cloud deck stage (Max 1986) for ``warpsky bench error-vs-time`` and the tests: a thin
broken deck with haze below, over a ground plane, seen from below.

The deck: mean plane H = 1500 m, equator rounding c = 100 m, bottom depth D = 80 m, density 0.01 1/m (albedo 1,
g = 0.85), pattern f = c0 + three long-crested waves (wavelengths 700, 900 and 1300 m, amplitudes 18, 14 and 8 m);
f_max = 41.4 m gives tops up to 100 m above H and bases down to 46 m below it (a band of about 146 m, vertical
optical depth up to about 1.5), and c0 = 1.4 m leaves about half the sky clear. Haze from the ground (y = 0) to the
lowest base, extinction 5e-4 1/m (albedo 0.9, g = 0.7). Ground plane albedo 0.3. Sun 50 deg above the horizon.
The camera stands 300 m up, looking 20 deg above the horizon (focal length 24 mm on a 36 x 24 mm aperture).

Measured (evaluation/scripts/bench_deck_error_vs_time.py, 96 x 64, CPU): the reference (2048 spp, 89 s; its grid 1474 x
32 x 1474 voxels of 12.5 x 4.6 m over a square of half-size 9.2 km) has a relative noise of 0.034 % of the mean and 4.7
% per pixel. The deck pass's rows: exact rel RMSE 0.654, bias -0.605 (0.9 s); max 0.649, -0.602 (0.08 s);
sexp 0.692, -0.624 (0.08 s), the same for step lengths 12.5, 6.25 and 3.125 m: the pass shows 40 % of the light.
That is multiple scattering (the haze's over long paths, the ground's bounce), not error: the exact mode against the
path tracer limited to single scattering (max_bounces = 1, 512 spp) is -0.46 % +- 0.11 %.
"""

from __future__ import annotations

from pathlib import Path

STAGE = """#usda 1.0
(
    defaultPrim = "World"
    upAxis = "Y"
    metersPerUnit = 1
)
def Xform "World"
{{
    def Camera "Camera"
    {{
        float focalLength = 24
        float horizontalAperture = 36
        float verticalAperture = 24
        float2 clippingRange = (1, 100000)
        double3 xformOp:translate = (0, {camera_height}, 0)
        float xformOp:rotateX = {camera_pitch}
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateX"]
    }}
    def DistantLight "Sun"
    {{
        float inputs:intensity = 1
        float3 xformOp:rotateXYZ = (-{sun_elevation}, {sun_azimuth}, 0)
        uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
    }}
{ground}    def Xform "Deck"
    {{
        uniform token warpsky:kind = "heightFieldClouds"
        float warpsky:hf:meanAltitude = 1500
        float[] warpsky:hf:polynomial = [{c0}]
        float2[] warpsky:hf:waveVectors = [(0.0089760, 0.0), (0.0034907, 0.0060460), (-0.0024166, 0.0041858)]
        float[] warpsky:hf:amplitudes = [18, 14, 8]
        float[] warpsky:hf:phases = [0.3, 1.7, 4.0]
        float warpsky:hf:equatorRounding = 100
        float warpsky:hf:bottomDepth = 80
        float warpsky:hf:density = {density}
        float warpsky:hf:g = 0.85
{haze}    }}
}}
"""

GROUND = """    def Plane "Ground"
    {
        uniform token axis = "Y"
        color3f warpsky:albedo = (0.3, 0.3, 0.3)
    }
"""

HAZE = """        color3f warpsky:haze:density = ({d}, {d}, {d})
        color3f warpsky:haze:albedo = (0.9, 0.9, 0.9)
        float warpsky:haze:g = 0.7
        float warpsky:haze:floor = 0
"""


def write_deck_stage(path, *, density: float = 0.01, haze: float | None = 5.0e-4, ground: bool = True,
                     sun_elevation: float = 50.0, sun_azimuth: float = 150.0, camera_height: float = 300.0,
                     camera_pitch: float = 20.0, c0: float = 1.4) -> Path:
    """Write the deck stage (module docstring) to ``path``: ``density`` [1/m] of the deck, ``haze`` extinction
    [1/m] (None: no haze), a ground plane or none, the sun's elevation and azimuth [deg], the camera's height [m]
    and pitch above the horizon [deg], the pattern's constant ``c0`` [m] (cover)."""
    path = Path(path)
    path.write_text(STAGE.format(
        camera_height=f"{camera_height:g}", camera_pitch=f"{camera_pitch:g}", sun_elevation=f"{sun_elevation:g}",
        sun_azimuth=f"{sun_azimuth:g}", ground=GROUND if ground else "", c0=f"{c0:g}", density=f"{density:g}",
        haze=HAZE.format(d=f"{haze:g}") if haze is not None else ""))
    return path


def deck_scene(path, **options):
    """The :class:`~warpsky.model.scene.Scene` of :func:`write_deck_stage` (written to ``path`` first)."""
    from warpsky.usd.stage import StageReader

    return StageReader(write_deck_stage(path, **options)).scene_at(None)


def main(argv=None) -> int:
    """``python -m evaluation.deck_stage OUT.usda``: write the stage."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    print(write_deck_stage(args[0] if args else "deck.usda"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

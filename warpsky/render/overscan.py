"""The pixels a frame renders and the part of them it writes: overscan for a data window reaching beyond the image,
and the data window's crop out of the rendered pixels.

A RenderProduct's ``dataWindowNDC`` may reach beyond the image (overscan: negative bounds, or beyond 1): the frame
then renders those pixels too, through the camera's film back grown and shifted so the image's own pixels stay
where they were (:func:`overscanned`). Written is the data window's part of what was rendered
(:func:`window_crop`), for the product that asked for the render and for any other product sharing it.
"""

from __future__ import annotations

from dataclasses import replace

from warpsky.core.errors import SceneError


def overscanned(plan, scene, bounds: tuple[int, int, int, int]):
    """(plan, scene) rendering the pixel ``bounds`` (x0, y0, x1, y1) of the image, which may reach beyond it
    (overscan): the camera's film back grown and shifted so the image's pixels stay where they were."""
    width, height = plan.width, plan.height
    x0, y0, x1, y1 = bounds
    if bounds == (0, 0, width - 1, height - 1):
        return plan, scene
    wide, tall = x1 - x0 + 1, y1 - y0 + 1
    camera = scene.camera.conformed(width, height)
    h_ap, v_ap = camera.horizontal_aperture, camera.vertical_aperture
    camera = replace(camera, horizontal_aperture=h_ap * wide / width, vertical_aperture=v_ap * tall / height,
                     horizontal_aperture_offset=camera.horizontal_aperture_offset
                     + h_ap * ((x0 + 0.5 * wide) / width - 0.5),
                     vertical_aperture_offset=camera.vertical_aperture_offset
                     + v_ap * (0.5 - (y0 + 0.5 * tall) / height))
    return replace(plan, width=wide, height=tall), replace(scene, camera=camera)


def window_crop(window, origin: tuple[int, int], shape: tuple[int, int], data_window) -> tuple | None:
    """The data ``window`` (pixel bounds x0, y0, x1, y1 in the image; None: all of it) as bounds in the rendered
    frame whose first pixel is the image's pixel ``origin`` and whose (height, width) is ``shape``; None for all
    of it. A SceneError when the window reaches beyond what was rendered (a product given another product's
    render, ``data_window`` its dataWindowNDC)."""
    if window is None:
        return None
    x, y = origin
    crop = (window[0] - x, window[1] - y, window[2] - x, window[3] - y)
    height, width = shape
    if min(crop[:2]) < 0 or crop[2] >= width or crop[3] >= height:
        raise SceneError(f"dataWindowNDC {tuple(data_window)} reaches beyond the frame rendered for the product it "
                         "shares a render with")
    return crop

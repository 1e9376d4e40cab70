"""Open Image Denoise on the memory of a Warp device: the frame's images stay where the paths were traced.

``pyoidn.denoise`` takes NumPy arrays (its CPU device) or PyTorch tensors. A Warp array is neither, but OIDN's
buffer API takes any pointer its device can read: :class:`DeviceDenoiser` keeps one OIDN device (CUDA for a
``cuda`` Warp device, CPU otherwise) and one ``RT`` filter, binds the colour, albedo and output arrays as shared
buffers (``pyoidn.Buffer.shared(device, array.ptr, nbytes)``) and runs the filter with the settings the host path
uses (HDR colour, a noise-free albedo guide, high quality). The PyPI wheel of pyoidn ships OIDN's CUDA device
(sm_75 to sm_120), so no PyTorch is needed. On the CPU it gives ``pyoidn.denoise``'s image bit for bit (tested);
OIDN's CUDA and CPU devices run different kernels, so their images differ by rounding.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from warpsky.core.device import is_cpu


class DeviceDenoiser:
    """One OIDN device and ``RT`` filter for the Warp device ``device`` (``cpu`` or ``cuda:0``)."""

    def __init__(self, device: str):
        import pyoidn

        self.pyoidn = pyoidn
        self.device = str(device)
        kind = pyoidn.OIDN_DEVICE_TYPE_CPU if is_cpu(device) else pyoidn.OIDN_DEVICE_TYPE_CUDA
        self.oidn = pyoidn.Device(kind)
        self.oidn.commit()
        self._check("creating the device")
        self.filter = pyoidn.Filter(self.oidn, pyoidn.OIDN_FILTER_TYPE_RT)
        self._check("creating the filter")

    def _check(self, doing: str) -> None:
        error = self.oidn.get_error()
        if error:
            raise RuntimeError(f"Open Image Denoise on {self.device}: {doing} failed: {error}")

    def run(self, color: wp.array, albedo: wp.array, output: wp.array) -> None:
        """Denoise ``color`` (H, W) of vec3 into ``output`` guided by ``albedo``, all on this denoiser's device."""
        pyoidn = self.pyoidn
        height, width = color.shape
        buffers = [pyoidn.Buffer.shared(self.oidn, a.ptr, height * width * 12) for a in (color, albedo, output)]
        try:
            for name, buffer in zip((pyoidn.OIDN_IMAGE_COLOR, pyoidn.OIDN_IMAGE_ALBEDO, pyoidn.OIDN_IMAGE_OUTPUT),
                                    buffers, strict=True):
                self.filter.set_image(name, buffer, pyoidn.OIDN_FORMAT_FLOAT3, width, height)
            self.filter.set_bool("hdr", True)
            self.filter.set_bool("cleanAux", True)
            self.filter.set_quality(pyoidn.OIDN_QUALITY_HIGH)
            self.filter.commit()
            self._check("committing the filter")
            wp.synchronize_device(self.device)  # the images were written on Warp's stream
            self.filter.execute()
            self._check("denoising")
        finally:
            for buffer in buffers:
                buffer.release()


@functools.cache
def device_denoiser(device: str) -> DeviceDenoiser | None:
    """The denoiser kept for ``device``, or None where the host path serves: a CUDA device other than ``cuda:0``
    (pyoidn opens the first one) or a machine whose OIDN has no CUDA device."""
    import pyoidn

    if not is_cpu(device) and (str(device) not in ("cuda", "cuda:0") or not pyoidn.Device.is_cuda_available(0)):
        return None
    return DeviceDenoiser(device)


def denoise_on_device(color: np.ndarray, albedo: np.ndarray, device: str) -> np.ndarray | None:
    """(H, W, 3) float32 ``color`` denoised on ``device`` guided by ``albedo``, or None where that device has no
    denoiser (see :func:`device_denoiser`)."""
    denoiser = device_denoiser(str(device))
    if denoiser is None:
        return None
    arrays = [wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=wp.vec3, device=device) for a in
              (color, albedo)]
    output = wp.zeros(color.shape[:2], dtype=wp.vec3, device=device)
    denoiser.run(arrays[0], arrays[1], output)
    return output.numpy().reshape(color.shape)

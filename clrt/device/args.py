"""Scene values passed to kernels by value (not in buffers)."""

from __future__ import annotations

import numpy as np
from pyopencl import cltypes

from clrt.scene.scene import Camera

#: The types of CAMERA_PARAMS (camera.cl), as clrt.device.program.typed_kernel takes them.
CAMERA_ARG_TYPES = [cltypes.float4] * 4 + [np.float32] * 2 + [np.uint32] * 2


def vec4(v) -> np.ndarray:
    """Three numbers as an OpenCL float4 argument (w = 0)."""
    return np.array([*v, 0.0], np.float32)


def camera_args(camera: Camera, origin=None) -> tuple:
    """The camera as the kernels' CAMERA_PARAMS (camera.cl); its eye moved by
    ``-origin`` (the device's frame, clrt.scene.arrays.device_origin) in float64
    when given."""
    forward, right, up = camera.basis()
    scale_x, scale_y = camera.scales()
    eye = np.asarray(camera.eye, np.float64) - (0.0 if origin is None else np.asarray(origin, np.float64))
    return (vec4(eye), vec4(forward), vec4(right), vec4(up), np.float32(scale_x),
            np.float32(scale_y), np.uint32(camera.width), np.uint32(camera.height))

"""Scene values passed to kernels by value: the records of the structs in
clrt/layouts.py that the host fills (the camera, the scene's values)."""

from __future__ import annotations

import functools

import numpy as np

from clrt.layouts import CAMERA, SCENE_INFO
from clrt.scene.scene import Camera


def vec4(v) -> np.ndarray:
    """Three numbers as an OpenCL float4 (w = 0)."""
    return np.array([*v, 0.0], np.float32)


def camera_value(camera: Camera, origin=None) -> np.ndarray:
    """The camera as the kernels' Camera struct (layouts.h); its eye moved by
    ``-origin`` (the device's frame, clrt.scene.arrays.device_origin) in float64
    when given.  (A copy of the record made once for a camera and origin: the
    basis and the record took 40-60 us of every frame's host time.)"""
    return _camera_record(camera, None if origin is None else tuple(float(x) for x in origin)).copy()


@functools.lru_cache(maxsize=16)
def _camera_record(camera: Camera, origin: tuple | None) -> np.ndarray:
    forward, right, up = camera.basis()
    scale_x, scale_y = camera.scales()
    eye = np.asarray(camera.eye, np.float64) - (0.0 if origin is None else np.asarray(origin, np.float64))
    record = np.zeros((), CAMERA)
    record["eye"], record["forward"], record["right"], record["up"] = vec4(eye), vec4(forward), vec4(right), vec4(up)
    record["scale_x"], record["scale_y"] = np.float32(scale_x), np.float32(scale_y)
    record["width"], record["height"] = camera.width, camera.height
    return record


def scene_value(num_tris: int, packets_at: int = 0, num_instances: int = 0, **shading) -> np.ndarray:
    """A SceneInfo struct (layouts.h): the triangle count, where the wide BVH's
    packets start, the instances of a two-level scene, and any of the
    renderer's ``shading`` fields (ambient_light, background as 3 numbers;
    num_lights; the tables' offsets)."""
    record = np.zeros((), SCENE_INFO)
    record["num_tris"], record["packets_at"], record["num_instances"] = num_tris, packets_at, num_instances
    for name, v in shading.items():
        record[name] = vec4(v) if name in ("ambient_light", "background") else v
    return record

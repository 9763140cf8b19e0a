"""clrt: Whitted ray tracing of triangle meshes in OpenCL kernels.

    >>> import clrt
    >>> image = clrt.render("bunny.off", width=320, height=240)   # (240, 320, 3) uint8

The pipeline, one module each: ``clrt.scene`` (meshes, materials, lights,
camera) -> acceleration build -> ``clrt.device`` (OpenCL context, buffer
layouts, programs) -> ``clrt/kernels/*.cl`` -> ``clrt.render`` (the frame).
"""

from clrt.errors import (ClrtError, DeviceError, DeviceMemoryError, InputError, KernelBuildError,
                         MeshLoadError, OutputError, TooLargeError)
from clrt.intersector import RayMeshIntersector
from clrt.render import Frame, Renderer, render
from clrt.scene.default import default_scene
from clrt.scene.load import load_mesh  # also registers our 3DS reader with trimesh.load
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject, scene_from_mesh
from clrt.trace import Accel, AllHits, CameraImages, Hits, all_hits, camera_images, count_hits, occluded, trace

__all__ = [
    "Accel", "AllHits", "Camera", "CameraImages", "ClrtError", "DeviceError", "DeviceMemoryError",
    "Frame", "Hits", "InputError", "KernelBuildError", "Light", "Material", "Mesh", "MeshLoadError",
    "OutputError", "RayMeshIntersector", "Renderer", "Scene", "SceneObject", "TooLargeError",
    "all_hits", "camera_images", "count_hits", "default_scene", "load_mesh", "occluded", "render",
    "scene_from_mesh", "trace",
]
__version__ = "0.1.0"

"""clrt: Whitted ray tracing of triangle meshes in OpenCL kernels.

    >>> import clrt
    >>> image = clrt.render("bunny.off", width=320, height=240)   # (240, 320, 3) uint8

The pipeline, one module each: ``clrt.scene`` (meshes, materials, lights,
camera) -> acceleration build -> ``clrt.device`` (OpenCL context, buffer
layouts, programs) -> ``clrt/kernels/*.cl`` -> ``clrt.render`` (the frame).
"""

import clrt.scene.load  # noqa: F401 -- registers our 3DS reader with trimesh.load as well
from clrt.errors import (ClrtError, DeviceError, DeviceMemoryError, InputError, KernelBuildError,
                         MeshLoadError, OutputError, TooLargeError)
from clrt.render import Frame, Renderer, render
from clrt.scene.default import default_scene
from clrt.intersector import RayMeshIntersector
from clrt.trace import Accel, AllHits, CameraImages, Hits, all_hits, camera_images, count_hits, occluded, trace
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject, scene_from_mesh


def load_mesh(path) -> Mesh:
    """Read a mesh file (OBJ, PLY, OFF, STL, GLB/GLTF, 3DS) into a :class:`Mesh`."""
    from clrt.scene.load import load_mesh as _load
    return _load(path)


__all__ = [
    "Accel", "Camera", "ClrtError", "DeviceError", "DeviceMemoryError", "OutputError", "TooLargeError", "Frame", "InputError", "KernelBuildError", "Light",
    "Material", "Mesh", "MeshLoadError", "Renderer", "Scene", "SceneObject", "default_scene",
    "Hits", "load_mesh", "occluded", "render", "scene_from_mesh", "trace",
    "AllHits", "CameraImages", "RayMeshIntersector", "all_hits", "camera_images", "count_hits",
]
__version__ = "0.1.0"

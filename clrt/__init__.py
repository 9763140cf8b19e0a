"""clrt: Whitted ray tracing of triangle meshes in OpenCL kernels.

    >>> import clrt
    >>> image = clrt.render("bunny.off", width=320, height=240)   # (240, 320, 3) uint8

The pipeline, one module each: ``clrt.scene`` (meshes, materials, lights,
camera) -> acceleration build -> ``clrt.device`` (OpenCL context, buffer
layouts, programs) -> ``clrt/kernels/*.cl`` -> ``clrt.render`` (the frame).
"""

import os as _os
import sys as _sys


def _started_as_command() -> bool:
    """Is this process the clrt command (the console script, or python -m clrt)?"""
    argv = list(getattr(_sys, "orig_argv", ()))
    by_module = "-m" in argv[:-1] and argv[argv.index("-m") + 1] == "clrt"
    return by_module or _os.path.basename(_sys.argv[0] if _sys.argv else "") == "clrt"


if _started_as_command():
    # Ctrl-C during the imports below (about half a second) ends like a later one:
    # one line and exit 130, not a traceback.  clrt.cli.main turns Ctrl-C back into
    # KeyboardInterrupt first thing, and handles it there.
    import signal as _signal

    def _interrupted_while_starting(signum, frame):
        _os.write(2, b"clrt: interrupted\n")
        _os._exit(130)

    try:
        _signal.signal(_signal.SIGINT, _interrupted_while_starting)
    except ValueError:   # not the main thread: leave signals alone
        pass

from clrt.errors import (ClrtError, DeviceError, DeviceMemoryError, InputError, KernelBuildError,
                         MeshLoadError, OutputError, TooLargeError)
from clrt.intersector import RayMeshIntersector
from clrt.render import Frame, Renderer, render
from clrt.scene.default import default_scene
from clrt.scene.load import load_mesh  # also registers our 3DS reader with trimesh.load
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject, scene_from_mesh
from clrt.scene.scene_file import load_scene
from clrt.trace import Accel, AllHits, CameraImages, Hits, all_hits, camera_images, count_hits, occluded, trace

__all__ = [
    "Accel", "AllHits", "Camera", "CameraImages", "ClrtError", "DeviceError", "DeviceMemoryError",
    "Frame", "Hits", "InputError", "KernelBuildError", "Light", "Material", "Mesh", "MeshLoadError",
    "OutputError", "RayMeshIntersector", "Renderer", "Scene", "SceneObject", "TooLargeError",
    "all_hits", "camera_images", "count_hits", "default_scene", "load_mesh", "load_scene", "occluded", "render",
    "scene_from_mesh", "trace",
]
__version__ = "0.1.0"

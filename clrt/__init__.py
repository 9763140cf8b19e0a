"""clrt: Whitted ray tracing of triangle meshes in OpenCL kernels.

    >>> import clrt
    >>> image = clrt.render("assets/meshes/knot.obj", width=320, height=240)   # (240, 320, 3) uint8

Where to start:

- images: ``clrt.render`` (one call), ``clrt.Renderer`` (upload once, render
  many frames; ``Frame`` results), scenes from ``clrt.scene_from_mesh``,
  ``clrt.load_scene`` (TOML files), ``clrt.default_scene``; ``clrt.Camera``,
  ``clrt.Material``, ``clrt.Light``;
- ray queries: ``clrt.trace``, ``clrt.occluded``, ``clrt.camera_images`` (one
  call each), ``clrt.Accel`` (build once, query often), ``clrt.RayMeshIntersector``
  and ``clrt.ProximityQuery`` (trimesh's ``mesh.ray`` and ``mesh.nearest``);
  results ``clrt.Hits``, ``clrt.AllHits``, ``clrt.CameraImages`` (``help()``
  on each lists its arrays);
- point queries: ``clrt.closest_points`` (``clrt.ClosestPoints``), ``clrt.distance``,
  ``clrt.signed_distance``, ``clrt.winding_number``, ``clrt.contains``, ``clrt.sdf_grid``;
- meshes: ``clrt.load_mesh``, ``clrt.Mesh``; meshes placed many times:
  ``clrt.Instances`` (or a list of ``(mesh, transform)`` pairs, docs/instances.md);
- devices: ``device=None`` (the first GPU, else the CPU), ``"gpu"``, ``"cpu"``
  or ``"P:D"`` (platform and device indices, as ``clrt info`` lists them).

Every error clrt raises on purpose is a ``clrt.ClrtError`` (bad input:
``clrt.InputError``); a frame that shows nothing but the background warns
with ``clrt.NothingVisibleWarning``.

The pipeline, one package each: ``clrt.scene`` (meshes, materials, lights,
camera, scene files) -> ``clrt.accel`` (BVH builders and volumes) ->
``clrt.device`` (OpenCL context, programs, uploads) -> ``clrt/kernels/*.cl`` ->
``clrt.renderer`` (frames) and ``clrt.query`` (batch ray queries); see
docs/architecture.md.

These names are imported on first use, so ``import clrt`` stays cheap: no
OpenCL, trimesh or benchmark code is loaded until something needs it.
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

from importlib import import_module

from clrt.errors import (ClrtError, ClrtWarning, DeviceError, DeviceMemoryError, InputError, KernelBuildError,
                         MeshLoadError, MeshLoadWarning, NothingVisibleWarning, OutputError,
                         TooLargeError)

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY = {
    "Accel": "clrt.query", "AllHits": "clrt.query", "CameraImages": "clrt.query", "Hits": "clrt.query",
    "all_hits": "clrt.query", "any_hit": "clrt.query", "camera_images": "clrt.query",
    "count_hits": "clrt.query", "occluded": "clrt.query", "trace": "clrt.query",
    "ClosestPoints": "clrt.query", "closest_points": "clrt.query", "distance": "clrt.query",
    "signed_distance": "clrt.query", "winding_number": "clrt.query", "contains": "clrt.query",
    "sdf_grid": "clrt.query",
    "RayMeshIntersector": "clrt.query.intersector",
    "ProximityQuery": "clrt.query.proximity",
    "Frame": "clrt.renderer", "Renderer": "clrt.renderer", "TileLimits": "clrt.renderer", "render": "clrt.renderer",
    "default_scene": "clrt.scene.default",
    "load_mesh": "clrt.scene.load",
    "Environment": "clrt.scene.environment",
    "Mesh": "clrt.scene.mesh",
    "Instances": "clrt.scene.instances",
    "Camera": "clrt.scene.scene", "Light": "clrt.scene.scene", "Material": "clrt.scene.scene",
    "Scene": "clrt.scene.scene", "SceneObject": "clrt.scene.scene", "scene_from_mesh": "clrt.scene.scene",
    "load_scene": "clrt.scene.scene_file",
}

__all__ = sorted(["ClrtError", "ClrtWarning", "DeviceError", "DeviceMemoryError", "InputError", "KernelBuildError",
                  "MeshLoadError", "MeshLoadWarning", "NothingVisibleWarning", "OutputError", "TooLargeError",
                  *_LAZY])


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'clrt' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value      # the next lookup is a plain attribute
    return value


def __dir__():
    return __all__

"""The host side of a frame, stage by stage as in the paper:

1. initialisation      -- flatten the scene into typed arrays (``flatten_scene``)
2. acceleration build  -- a BVH (box, sphere or ellipsoid volumes; ``accel="none"``
                          tests every ray against every triangle)
3. copy to device      -- context, program build, buffer upload (once per Renderer)
4. ray generation      -- ``generate_rays`` kernel, one ray per pixel
5. pixel colour        -- ``shade_pixels`` kernel: nearest hit, Phong, shadow rays
6. read back           -- ``encode_srgb8`` (or the linear image) copied to the host

Stages 1-3 happen when a :class:`Renderer` is made; 4-6 on every ``render`` call,
so frames after the first reuse the uploaded scene and the built program.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyopencl as cl

from clrt.device import layouts
from clrt.device.context import create_context, device_label
from clrt.device.geometry import DeviceGeometry, order_triangles
from clrt.device.program import build_program
from clrt.errors import InputError
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Scene, scene_from_mesh


@dataclass
class SceneArrays:
    """The scene as the kernels see it (dtypes from :mod:`clrt.device.layouts`)."""

    tri_verts: np.ndarray        # (F,) TRIANGLE_VERTS
    tri_info: np.ndarray         # (F,) TRIANGLE_INFO
    vertex_normals: np.ndarray   # (V, 4) float32
    materials: np.ndarray        # (M,) MATERIAL
    lights: np.ndarray           # (L,) LIGHT
    bounds: np.ndarray           # (2, 3) float64


def flatten_scene(scene: Scene) -> SceneArrays:
    """One triangle list for all objects, each triangle tagged with its material."""
    meshes = [o.mesh for o in scene.objects]
    mesh = Mesh.concatenate(meshes)
    material_of_tri = np.repeat(np.arange(len(meshes), dtype=np.int32), [len(m.faces) for m in meshes])

    tri_verts = np.zeros(len(mesh.faces), layouts.TRIANGLE_VERTS)
    corners = mesh.vertices[mesh.faces]                       # (F, 3, 3)
    for k, name in enumerate(("v0", "v1", "v2")):
        tri_verts[name][:, :3] = corners[:, k]
    tri_info = np.zeros(len(mesh.faces), layouts.TRIANGLE_INFO)
    tri_info["vertex"] = mesh.faces
    tri_info["material"] = material_of_tri

    normals = np.zeros((len(mesh.vertices), 4), np.float32)
    start = 0
    for m in meshes:   # per object, so that normals never blend across objects
        normals[start:start + len(m.vertices), :3] = m.vertex_normals()
        start += len(m.vertices)

    materials = np.zeros(len(scene.objects), layouts.MATERIAL)
    for i, o in enumerate(scene.objects):
        mat = o.material
        materials[i]["color"][:3] = mat.color
        for name in ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior"):
            materials[i][name] = getattr(mat, name)
        materials[i]["flags"] = layouts.MATERIAL_SMOOTH if mat.smooth else 0

    lights = np.zeros(max(len(scene.lights), 1), layouts.LIGHT)   # OpenCL buffers cannot be empty
    for i, light in enumerate(scene.lights):
        lights[i]["position"][:3] = light.position
        lights[i]["color"][:3] = light.color
    return SceneArrays(tri_verts, tri_info, normals, materials, lights, scene.bounds)


def ray_epsilon(bounds: np.ndarray, camera: Camera) -> float:
    """How far shadow rays start off the surface: well above float32 rounding of hit
    points (relative to the coordinates' magnitude) yet small against the scene."""
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    magnitude = max(float(np.abs(bounds).max()), float(np.abs(camera.eye).max()))
    return 1e-4 * diag + 1e-6 * magnitude


@dataclass
class Frame:
    """One rendered image and how long each stage took (milliseconds)."""

    image: np.ndarray            # (H, W, 3) uint8 sRGB, or float32 linear RGB
    prim: np.ndarray | None      # (H, W) int32 triangle seen by each pixel, -1 for background
    t: np.ndarray | None         # (H, W) float32 distance along the camera ray, inf for background
    timings: dict = field(default_factory=dict)
    device: str = ""
    triangles: int = 0


class Renderer:
    """A scene uploaded to one OpenCL device, ready to render frames.

    ``accel``: "box" (default), "sphere", "ellipse" (BVH volume shape) or "none"
    (brute force); ``builder``: "sah" (default) or "paper"; ``leaf_size``: the
    most triangles in a BVH leaf.  Every choice renders the same image.
    """

    def __init__(self, scene: Scene, device: str | None = None, accel: str = "box",
                 builder: str = "sah", leaf_size: int = 4):
        self.timings: dict[str, float] = {}
        with _stage(self.timings, "initialisation"):
            self.scene = scene
            self.arrays = flatten_scene(scene)
        with _stage(self.timings, "acceleration build"):
            self.order = order_triangles(self.arrays.tri_verts, accel, builder, leaf_size)
            tri_info = self.arrays.tri_info[self.order.prim_ids]   # shading data in slot order
        with _stage(self.timings, "copy to device"):
            self.context, self.queue = create_context(device)
            self.device = device_label(self.queue.device)
            program = build_program(self.context, "render.cl", self.order.defines)
            # Kernel objects are made once: each attribute lookup on a Program makes a new one.
            self.kernels = {name: cl.Kernel(program, name)
                            for name in ("generate_rays", "shade_pixels", "encode_srgb8")}
            mf = cl.mem_flags
            a = self.arrays

            def upload(array):
                return cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=array)

            self.geometry = DeviceGeometry(self.context, self.order)
            self.buffers = {name: upload(getattr(a, name)) for name in
                            ("vertex_normals", "materials", "lights")}
            self.buffers["tri_info"] = upload(tri_info)
        self._frame_buffers: dict[str, cl.Buffer] = {}
        self._frame_pixels = -1

    def _buffers_for(self, pixels: int) -> dict:
        """Per-frame buffers, reallocated only when the resolution changes."""
        if pixels != self._frame_pixels:
            mf = cl.mem_flags
            self._frame_buffers = {
                "rays": cl.Buffer(self.context, mf.READ_WRITE, pixels * layouts.RAY.itemsize),
                "hits": cl.Buffer(self.context, mf.READ_WRITE, pixels * layouts.HIT.itemsize),
                "linear": cl.Buffer(self.context, mf.READ_WRITE, pixels * 16),
                "srgb8": cl.Buffer(self.context, mf.WRITE_ONLY, pixels * 4),
            }
            self._frame_pixels = pixels
        return self._frame_buffers

    def _launch(self, name: str, queue, global_size, local_size, *args) -> cl.Event:
        kernel = self.kernels[name]
        kernel.set_args(*args)
        return cl.enqueue_nd_range_kernel(queue, kernel, global_size, local_size)

    def render(self, camera: Camera | None = None, linear: bool = False, hits: bool = False,
               samples: int | None = None, max_depth: int | None = None, seed: int = 0) -> Frame:
        """Render one frame.

        ``samples``: anti-aliasing with samples x samples stratified, jittered rays
        per pixel (the jitter is a hash of pixel, sample and ``seed``, so renders
        are reproducible; 1 = one ray through each pixel centre).  ``max_depth``:
        reflection/refraction bounces.  Both default to the scene's.
        ``hits=True`` also reads back the camera rays' hits (``Frame.prim`` and
        ``Frame.t``, of the first sample; otherwise None).
        """
        camera = camera or self.scene.camera or Camera.framing(self.arrays.bounds)
        samples = self.scene.samples if samples is None else samples
        max_depth = self.scene.max_depth if max_depth is None else max_depth
        _check_int("samples", samples, 1, 16)
        _check_int("max_depth", max_depth, 0, MAX_BOUNCES)
        w, h = camera.width, camera.height
        pixels = w * h
        timings = dict(self.timings)
        buf = self._buffers_for(pixels)
        a = self.arrays
        q = self.queue
        vec4 = _vec4
        shading_args = (*self.geometry.args, self.buffers["tri_info"], self.buffers["vertex_normals"],
                        self.buffers["materials"], self.buffers["lights"], np.uint32(len(self.scene.lights)),
                        vec4(self.scene.ambient_light), vec4(self.scene.background),
                        np.float32(ray_epsilon(a.bounds, camera)))
        n = samples * samples
        events = []
        for sample in range(n):
            gen = self._launch("generate_rays", q, (w, h), None, buf["rays"], *camera_args(camera),
                               np.uint32(sample), np.uint32(samples), np.uint32(seed))
            shade = self._launch("shade_pixels", q, (pixels,), None, buf["rays"], buf["linear"], buf["hits"],
                                 np.uint32(pixels), np.uint32(max_depth), np.float32(1.0 / n),
                                 np.uint32(sample == 0), *shading_args)
            events.append((gen, shade))
        cl.wait_for_events([e for pair in events for e in pair])
        timings["ray generation"] = sum(_event_ms(g) for g, _ in events)
        timings["pixel colour"] = sum(_event_ms(s) for _, s in events)

        with _stage(timings, "read back"):
            if linear:
                out = np.empty((h, w, 4), np.float32)
                cl.enqueue_copy(q, out, buf["linear"])
                image = out[:, :, :3].copy()
            else:
                enc = self._launch("encode_srgb8", q, (pixels,), None, buf["linear"], buf["srgb8"],
                                   np.uint32(pixels))
                out = np.empty((h, w, 4), np.uint8)
                cl.enqueue_copy(q, out, buf["srgb8"], wait_for=[enc])
                image = out[:, :, :3].copy()
            prim = t = None
            if hits:
                records = np.empty((h, w), layouts.HIT)
                cl.enqueue_copy(q, records, buf["hits"])
                prim, t = records["prim"].copy(), records["t"].copy()
        return Frame(image, prim, t, timings, self.device, len(a.tri_verts))


MAX_BOUNCES = 16   # the stack bound in whitted.cl


def _vec4(v) -> np.ndarray:
    return np.array([*v, 0.0], np.float32)


def camera_args(camera: Camera) -> tuple:
    """The camera as the kernels' CAMERA_PARAMS (camera.cl)."""
    forward, right, up = camera.basis()
    scale_x, scale_y = camera.scales()
    return (_vec4(camera.eye), _vec4(forward), _vec4(right), _vec4(up), np.float32(scale_x),
            np.float32(scale_y), np.uint32(camera.width), np.uint32(camera.height))


def _check_int(name: str, value, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise InputError(f"{name} must be an integer in {lo}..{hi}, got {value!r}")


class _stage:
    """Context manager adding the wall time of a block to ``timings[name]`` in ms."""

    def __init__(self, timings: dict, name: str):
        self.timings, self.name = timings, name

    def __enter__(self):
        self.start = time.perf_counter()

    def __exit__(self, *exc):
        self.timings[self.name] = self.timings.get(self.name, 0.0) + 1e3 * (time.perf_counter() - self.start)


def _event_ms(event: cl.Event) -> float:
    return 1e-6 * (event.profile.end - event.profile.start)


def as_scene(source) -> Scene:
    """A Scene from a Scene, a Mesh, a file path, a trimesh object or (vertices, faces)."""
    if isinstance(source, Scene):
        return source
    if isinstance(source, Mesh):
        return scene_from_mesh(source)
    if isinstance(source, (str, Path)):
        from clrt.scene.load import load_mesh
        return scene_from_mesh(load_mesh(source))
    if hasattr(source, "vertices") and hasattr(source, "faces"):
        return scene_from_mesh(Mesh.from_arrays(source.vertices, source.faces))
    if isinstance(source, tuple) and len(source) == 2:
        return scene_from_mesh(Mesh.from_arrays(*source))
    raise InputError(f"cannot render a {type(source).__name__}: give a Scene, a Mesh, a path "
                     "or (vertices, faces)")


def render(source, camera: Camera | None = None, *, width: int | None = None,
           height: int | None = None, device: str | None = None, linear: bool = False,
           accel: str = "box", builder: str = "sah", leaf_size: int = 4) -> np.ndarray:
    """Render ``source`` and return an (H, W, 3) image: uint8 sRGB, or float32 linear RGB
    with ``linear=True``.  Without a camera the scene's own (or a framing of its
    bounds) is used; ``width``/``height`` override the camera's resolution."""
    scene = as_scene(source)
    if camera is None:
        camera = scene.camera or Camera.framing(scene.bounds)
    if width is not None or height is not None:
        camera = Camera(camera.eye, camera.target, camera.up, camera.fov,
                        width or camera.width, height or camera.height)
    return Renderer(scene, device, accel, builder, leaf_size).render(camera, linear=linear).image

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

import sys
import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from clrt import checks, config
from clrt.device import layouts
from clrt.device.context import create_context, device_label
from clrt.device.context import format_bytes as _size
from clrt.device.geometry import DeviceGeometry, order_triangles
from clrt.device.program import build_program
from clrt.errors import DeviceMemoryError, TooLargeError
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
    tiles: int = 1               # tiles the frame was rendered in (each: one launch per sample)


class Renderer:
    """A scene uploaded to one OpenCL device, ready to render frames.

    ``accel``: "box" (default), "sphere", "ellipse" (BVH volume shape) or "none"
    (brute force); ``builder``: "sah" (default) or "paper"; ``leaf_size``: the
    most triangles in a BVH leaf.  Every choice renders the same image.

    A frame is rendered in tiles -- bands of whole rows, or pieces of a row when
    memory is very short -- each with its own launches, which run the pixels in
    work-groups of ``block`` (16 x 8) pixels.  A tile is sized so that one launch
    takes about ``launch_ms`` (display watchdogs kill longer kernels; Ctrl-C
    takes effect between launches) and its buffers fit the device.  When the device runs out
    of memory the tiles shrink and the tile is retried; the image is the same
    for every tiling.
    """

    launch_ms = 200.0                 # target kernel time of one launch (watchdogs allow 2-5 s)
    first_launch_pixels = 1 << 21     # the first tile, before any launch was timed (1920x1080 fits)
    max_tile_pixels: int | None = None  # cap on the pixels of a tile (None: from device memory)
    min_tile_pixels = 256             # a failed allocation below this is reported, not retried
    block: tuple[int, int] | None = (16, 8)  # pixels of a work-group (None: the driver's choice)

    def __init__(self, scene: Scene, device: str | None = None, accel: str = "box",
                 builder: str = "sah", leaf_size: int = 4):
        scene = as_scene(scene)   # or a mesh, a mesh or scene file: what clrt.render takes
        device = checks.device(device)
        accel, builder, leaf_size = checks.accel_options(accel, builder, leaf_size)
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
            mf = cl.mem_flags
            a = self.arrays
            o = self.order
            scene_arrays = {"triangles": o.tri_verts, "BVH nodes": o.nodes, "triangle ids": o.prim_ids,
                            "shading data": tri_info, "vertex normals": a.vertex_normals,
                            "materials": a.materials, "lights": a.lights}
            self.device_bytes = sum(x.nbytes for x in scene_arrays.values())
            _check_fits(self.queue.device, self.device, scene_arrays)
            try:
                # Buffers larger than one allocation are uploaded in parts (split.cl).
                self.geometry = DeviceGeometry(self.context, self.order,
                                               {"tri_info": tri_info, "vertex_normals": a.vertex_normals})
                self.buffers = {name: cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                                hostbuf=getattr(a, name)) for name in ("materials", "lights")}
            except (cl.Error, MemoryError) as exc:
                if not _out_of_memory(exc):
                    raise
                raise self._memory_error(exc, 0) from None
            program = build_program(self.context, "render.cl", {**self.order.defines, **self.geometry.defines})
            # Kernel objects are made once: each attribute lookup on a Program makes a new one.
            self.kernels = {name: cl.Kernel(program, name)
                            for name in ("generate_rays", "shade_pixels", "encode_srgb8")}
        self._frame_buffers: dict[str, cl.Buffer] = {}
        self._frame_pixels = -1
        self._image_pool: list[np.ndarray] = []   # see _image_array
        self._max_group = None                    # work-items a launch's group may have, see _launch_shape

    def _buffers_for(self, pixels: int) -> dict:
        """Per-tile buffers for up to ``pixels`` pixels, reallocated only when that changes."""
        if pixels != self._frame_pixels:
            self._release_frame_buffers()
            mf = cl.mem_flags
            self._frame_buffers = {
                "rays": cl.Buffer(self.context, mf.READ_WRITE, pixels * layouts.RAY.itemsize),
                "hits": cl.Buffer(self.context, mf.READ_WRITE, pixels * layouts.HIT.itemsize),
                "linear": cl.Buffer(self.context, mf.READ_WRITE, pixels * 16),
                "srgb8": cl.Buffer(self.context, mf.WRITE_ONLY, pixels * 3),
                # Page-locked host memory: the device writes the 8-bit image there
                # by DMA, several times faster than into ordinary (pageable) memory.
                "staging": cl.Buffer(self.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, pixels * 3),
            }
            self._staging, _ = cl.enqueue_map_buffer(
                self.queue, self._frame_buffers["staging"], cl.map_flags.READ | cl.map_flags.WRITE,
                0, (pixels, 3), np.uint8)
            self._frame_pixels = pixels
        return self._frame_buffers

    def _release_frame_buffers(self) -> None:
        staging = getattr(self, "_staging", None)
        if staging is not None:
            staging.base.release(self.queue)
            self._staging = None
        for b in self._frame_buffers.values():
            b.release()
        self._frame_buffers, self._frame_pixels = {}, -1

    def tile_capacity(self, pixels: int) -> int:
        """The most pixels of one tile: the whole image if the device memory allows,
        at most half of what the scene leaves free and one buffer's size limit."""
        dev = self.queue.device
        free = max(dev.global_mem_size - self.device_bytes, 0) // 2
        cap = min(pixels, MAX_TILE_PIXELS, dev.max_mem_alloc_size // layouts.RAY.itemsize,
                  free // FRAME_BYTES_PER_PIXEL)
        cap = max(cap, min(pixels, self.min_tile_pixels))   # if even that fails, the error says so
        if self.max_tile_pixels is not None:
            cap = min(cap, self.max_tile_pixels)
        return max(int(cap), 1)

    def _memory_error(self, exc, tile: int) -> DeviceMemoryError:
        dev = self.queue.device
        frame = f" and {_size(tile * FRAME_BYTES_PER_PIXEL)} for a tile of {tile:,} pixels" if tile else ""
        return DeviceMemoryError(
            f"out of device memory on {self.device} ({_error_name(exc)}): the scene needs "
            f"{_size(self.device_bytes)}{frame}; the device has {_size(dev.global_mem_size)} "
            f"({_size(dev.max_mem_alloc_size)} at most per buffer), shared with other programs")

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
        if camera is not None and not isinstance(camera, Camera):
            raise checks.fail("camera", "a clrt.Camera or None", camera)
        camera = camera or self.scene.camera or Camera.framing(self.arrays.bounds)
        samples = checks.samples(self.scene.samples if samples is None else samples)
        max_depth = checks.max_depth(self.scene.max_depth if max_depth is None else max_depth)
        seed = checks.integer("seed", seed, 0, 2**32 - 1)
        w, h = camera.width, camera.height
        pixels = w * h
        host_bytes = pixels * ((12 if linear else 3) + (8 if hits else 0))
        if host_bytes > HOST_CHECK_BYTES:   # reading /proc/meminfo costs more than a small frame
            check_host_memory(host_bytes, f"a {w}x{h} image")
        timings = dict(self.timings)
        timings.update({"ray generation": 0.0, "pixel colour": 0.0, "read back": 0.0})
        if linear:
            image, pinned = np.empty((h, w, 3), np.float32), False
        else:
            image, pinned = self._image_array(pixels)
            image = image.reshape(h, w, 3)
        prim = np.empty((h, w), np.int32) if hits else None
        t = np.empty((h, w), np.float32) if hits else None
        shading_args = (*self.geometry.args, *self.geometry.buffers["tri_info"],
                        *self.geometry.buffers["vertex_normals"], self.buffers["materials"],
                        self.buffers["lights"], np.uint32(len(self.scene.lights)),
                        _vec4(self.scene.ambient_light), _vec4(self.scene.background),
                        np.float32(ray_epsilon(self.arrays.bounds, camera)))
        job = _Job(camera, samples, max_depth, seed, linear, shading_args, image, pinned, prim, t, timings)
        capacity = self.tile_capacity(pixels)
        budget = min(capacity, max(self.first_launch_pixels, 1))   # pixels of the next tile
        x = y = launches = 0
        ms_per_pixel = 0.0   # the most expensive tile so far: rows differ in cost (sky vs. mesh)
        try:
            while y < h:
                tw, th = _tile_shape(x, y, w, h, budget, (self.block or (1, 1))[1])
                try:
                    slowest_ms = self._render_tile(job, x, y, tw, th, capacity)
                except (cl.Error, MemoryError) as exc:
                    if not _out_of_memory(exc):
                        raise
                    # Lazy allocation means buffers may fail at their first use: retry smaller.
                    self._release_frame_buffers()
                    if capacity <= self.min_tile_pixels:
                        raise self._memory_error(exc, capacity) from None
                    capacity = budget = max(capacity // 4, self.min_tile_pixels)
                    continue
                x += tw
                if x == w:
                    x, y = 0, y + th
                launches += 1
                # Size the next tile for launch_ms at the highest cost per pixel seen,
                # growing at most twofold: the next rows may cost more than these.
                count = tw * th
                ms_per_pixel = max(ms_per_pixel, slowest_ms / count)
                fitting = self.launch_ms / ms_per_pixel if ms_per_pixel > 0 else capacity
                budget = int(min(max(fitting, 1), 2 * max(count, budget), capacity))
        except KeyboardInterrupt:
            self.queue.finish()   # no kernel may still write into buffers we drop
            raise
        return Frame(image, prim, t, timings, self.device, len(self.arrays.tri_verts), tiles=launches)

    def _image_array(self, pixels: int) -> tuple[np.ndarray, bool]:
        """(pixels * 3,) uint8 for a frame's image, and whether it is page-locked.
        Page-locked where possible: the device writes the image there directly
        by DMA, several times faster than into ordinary (pageable) memory, and
        no host copy follows.  The arrays are pooled: one is reused once nothing outside the
        pool refers to it any more (every view of it holds a reference, which
        ``sys.getrefcount`` sees), so an image handed out is never overwritten.
        With all pooled arrays still in use, ordinary memory is used (through
        the staging buffer)."""
        pool = self._image_pool
        for k in range(len(pool)):
            if sys.getrefcount(pool[k]) <= 2 and len(pool[k]) >= 3 * pixels:   # the pool's and the argument's
                return pool[k][:3 * pixels], True
        unused = [k for k in range(len(pool)) if sys.getrefcount(pool[k]) <= 2]
        for k in reversed(unused):   # too small for this frame: make room
            del pool[k]
        if len(pool) >= IMAGE_POOL_SIZE:
            return np.empty(3 * pixels, np.uint8), False
        try:
            buffer = cl.Buffer(self.context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, 3 * pixels)
            array, _ = cl.enqueue_map_buffer(self.queue, buffer, cl.map_flags.READ | cl.map_flags.WRITE,
                                             0, (3 * pixels,), np.uint8)
        except (cl.Error, MemoryError):   # page-locked memory is scarce: fall back to ordinary
            return np.empty(3 * pixels, np.uint8), False
        pool.append(array)
        return array, True

    def _render_tile(self, job: "_Job", x: int, y: int, w: int, h: int, capacity: int) -> float:
        """Render the w x h pixels at (x, y) into the job's host arrays; return the
        kernel time of the slowest launch (ms).  Each sample's launches are waited
        for -- the last together with the read back, so a frame of one tile and one
        sample waits only once -- so that Ctrl-C (raised by Python between calls)
        stops within one launch."""
        buf = self._buffers_for(capacity)
        q = self.queue
        count = w * h
        tile = (np.uint32(x), np.uint32(y), np.uint32(w), np.uint32(h))
        size, local = self._launch_shape(w, h)
        n = job.samples * job.samples
        launches = []
        for sample in range(n):
            gen = self._launch("generate_rays", q, size, local, buf["rays"], *camera_args(job.camera),
                               np.uint32(sample), np.uint32(job.samples), np.uint32(job.seed), *tile)
            shade = self._launch("shade_pixels", q, size, local, buf["rays"], buf["linear"], buf["hits"],
                                 np.uint32(w), np.uint32(h), np.uint32(job.max_depth), np.float32(1.0 / n),
                                 np.uint32(sample == 0), *job.shading_args)
            launches.append((gen, shade))
            if sample < n - 1:
                _wait_for(shade)

        image = job.image[y:y + h, x:x + w]
        # Straight into the image where the tile is one run of page-locked memory
        # (full-width tiles of a pooled image); else through the staging buffer.
        direct = job.pinned and w == job.image.shape[1]
        if job.linear:
            out = np.empty((count, 4), np.float32)
            copies = [cl.enqueue_copy(q, out, buf["linear"], is_blocking=False)]
        else:
            copies = [self._launch("encode_srgb8", q, (count,), None, buf["linear"], buf["srgb8"],
                                   np.uint32(count))]
            out = image.reshape(count * 3) if direct else self._staging[:count]
            copies.append(cl.enqueue_copy(q, out, buf["srgb8"], is_blocking=False))
        if job.prim is not None:
            records = np.empty(count, layouts.HIT)
            copies.append(cl.enqueue_copy(q, records, buf["hits"], is_blocking=False))
        _wait_for(copies[-1])
        host_start = time.perf_counter()
        if job.linear:
            image[...] = out[:, :3].reshape(h, w, 3)
        elif not direct:
            image[...] = out.reshape(h, w, 3)
        if job.prim is not None:
            job.prim[y:y + h, x:x + w] = records["prim"].reshape(h, w)
            job.t[y:y + h, x:x + w] = records["t"].reshape(h, w)
        # Read back: the encode kernel, the copies and any host copy after them.
        job.timings["read back"] += sum(_event_ms(e) for e in copies) + 1e3 * (time.perf_counter() - host_start)
        slowest = 0.0
        for gen, shade in launches:
            job.timings["ray generation"] += _event_ms(gen)
            job.timings["pixel colour"] += _event_ms(shade)
            slowest = max(slowest, _event_ms(gen) + _event_ms(shade))
        return slowest

    def _launch_shape(self, w: int, h: int) -> tuple:
        """Global and local size of a tile's launches: work-groups of ``block``
        pixels (rays of neighbouring pixels run together), the driver's choice
        where the kernels cannot run that many work-items at once."""
        if self._max_group is None:
            self._max_group = min(
                k.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, self.queue.device)
                for name, k in self.kernels.items() if name != "encode_srgb8")
        bw, bh = self.block or (0, 0)
        if not 0 < bw * bh <= self._max_group:
            return (w, h), None
        return (-(-w // bw) * bw, -(-h // bh) * bh), (bw, bh)


MAX_BOUNCES = 16   # the stack bound in whitted.cl

# Device bytes per pixel of a tile: its ray, hit record, linear and sRGB colour.
FRAME_BYTES_PER_PIXEL = layouts.RAY.itemsize + layouts.HIT.itemsize + 16 + 3
MAX_TILE_PIXELS = 1 << 23   # 8M pixels (a 4K frame), 544 MiB of tile buffers
IMAGE_POOL_SIZE = 3         # page-locked images per renderer (see Renderer._image_array)
HOST_CHECK_BYTES = 1 << 28  # frames needing more host memory than this check that it is there


def _tile_shape(x: int, y: int, width: int, height: int, budget: int, block_rows: int) -> tuple[int, int]:
    """Width and height of the tile at (x, y) of at most ``budget`` pixels: whole
    rows where the budget allows (a multiple of ``block_rows`` of them, to fill
    the launches' blocks), else a piece of one row.  Tiles go row-major through
    the image."""
    if x == 0 and budget >= width:
        rows = min(budget // width, height - y)
        if block_rows < rows < height - y:
            rows -= rows % block_rows
        return width, rows
    return min(budget, width - x), 1

# OpenCL status codes that mean "not enough memory" (on the device or the host).
_OUT_OF_MEMORY_CODES = {cl.status_code.MEM_OBJECT_ALLOCATION_FAILURE, cl.status_code.OUT_OF_RESOURCES,
                        cl.status_code.OUT_OF_HOST_MEMORY, cl.status_code.INVALID_BUFFER_SIZE}


@dataclass
class _Job:
    """What one render call needs in every tile."""

    camera: Camera
    samples: int
    max_depth: int
    seed: int
    linear: bool
    shading_args: tuple
    image: np.ndarray            # (H, W, 3), filled tile by tile
    pinned: bool                 # image is page-locked memory of the image pool
    prim: np.ndarray | None      # (H, W)
    t: np.ndarray | None         # (H, W)
    timings: dict


def _wait_for(event: cl.Event) -> None:
    """Wait for one launch.  Python raises KeyboardInterrupt once this returns, so
    Ctrl-C stops a render between launches (tests replace this to simulate it)."""
    event.wait()


def _out_of_memory(exc: BaseException) -> bool:
    if isinstance(exc, MemoryError):
        return True
    try:
        return isinstance(exc, cl.Error) and exc.code in _OUT_OF_MEMORY_CODES
    except Exception:   # noqa: BLE001 -- an Error made without a status code
        return False


def _error_name(exc: BaseException) -> str:
    try:
        return cl.status_code.to_string(exc.code)
    except Exception:   # noqa: BLE001
        return type(exc).__name__


def _check_fits(device, label: str, arrays: dict) -> None:
    """DeviceMemoryError, before any upload, if the scene cannot fit on ``device``.
    (A buffer larger than one allocation is split, see DeviceGeometry.)"""
    total = sum(a.nbytes for a in arrays.values())
    if total + MIN_FRAME_BYTES > device.global_mem_size:
        raise DeviceMemoryError(
            f"the scene needs {_size(total)} on the device, but {label} has {_size(device.global_mem_size)}")


MIN_FRAME_BYTES = 256 * FRAME_BYTES_PER_PIXEL


def available_host_memory() -> int | None:
    """Bytes of host memory available to a new allocation (Linux: MemAvailable), or None."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_host_memory(nbytes: int, what: str) -> None:
    """TooLargeError naming the size needed when ``nbytes`` exceed the available host memory."""
    available = available_host_memory()
    if available is not None and nbytes > available:
        raise TooLargeError(f"{what} needs {_size(nbytes)} of host memory, only {_size(available)} "
                            "is available: render a smaller image")


def _vec4(v) -> np.ndarray:
    return np.array([*v, 0.0], np.float32)


def camera_args(camera: Camera) -> tuple:
    """The camera as the kernels' CAMERA_PARAMS (camera.cl)."""
    forward, right, up = camera.basis()
    scale_x, scale_y = camera.scales()
    return (_vec4(camera.eye), _vec4(forward), _vec4(right), _vec4(up), np.float32(scale_x),
            np.float32(scale_y), np.uint32(camera.width), np.uint32(camera.height))


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
    """A Scene from a Scene, a TOML scene file (``.toml``), or anything
    :func:`~clrt.scene.scene.scene_from_mesh` takes (a Mesh, a mesh file path --
    a glTF camera node becomes the scene's camera --, a trimesh object,
    (vertices, faces)) with the default framing and light; InputError otherwise."""
    if isinstance(source, Scene):
        return source
    import os
    if isinstance(source, (str, os.PathLike)) and os.fspath(source).lower().endswith(".toml"):
        from clrt.scene.scene_file import load_scene
        return load_scene(source)
    return scene_from_mesh(source)


def render(source, camera: Camera | None = None, *, width: int | None = None,
           height: int | None = None, device: str | None = None, linear: bool = False,
           accel: str = "box", builder: str = "sah", leaf_size: int = 4) -> np.ndarray:
    """Render ``source`` and return an (H, W, 3) image: uint8 sRGB, or float32 linear RGB
    with ``linear=True``.  ``source``: a Scene, a TOML scene file, a mesh file or
    anything else :func:`as_scene` takes.  Without a camera the scene's own (or
    a framing of its bounds) is used; ``width``/``height`` override the camera's
    resolution.  Values are checked as the CLI checks them (clrt.checks)."""
    if camera is not None and not isinstance(camera, Camera):
        raise checks.fail("camera", "a clrt.Camera or None", camera)
    if width is not None:
        checks.integer("width", width, 1, config.MAX_IMAGE_SIDE)
    if height is not None:
        checks.integer("height", height, 1, config.MAX_IMAGE_SIDE)
    device = checks.device(device)
    checks.accel_options(accel, builder, leaf_size)
    scene = as_scene(source)
    # A mesh (not a Scene, not a scene file) gets the default light from the final camera, as in the CLI.
    mesh_light = not isinstance(source, Scene) and not str(source).lower().endswith(".toml")
    if camera is None and (scene.camera is None or scene.camera_framed):
        base = scene.camera or Camera.framing(scene.bounds)
        camera = Camera.framing(scene.bounds, base.width if width is None else width,
                                base.height if height is None else height, base.fov, up=base.up)
    camera = camera or scene.camera
    if width is not None or height is not None:
        camera = Camera(camera.eye, camera.target, camera.up, camera.fov,
                        camera.width if width is None else width, camera.height if height is None else height)
    if mesh_light:
        from clrt.scene.scene import default_light
        scene.lights = [default_light(scene.bounds, camera)]
    return Renderer(scene, device, accel, builder, leaf_size).render(camera, linear=linear).image

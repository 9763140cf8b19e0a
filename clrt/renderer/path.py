"""The path tracer's host side (``integrator="path"``): its program, its light
tables, and a frame rendered in passes of samples.

A frame's sums (radiance, albedo, shading normal: path.cl) live on the device
for the whole image, so a render goes in passes: each pass adds its samples
to every pixel, launch by launch over bands of rows sized to take about
``TileLimits.launch_ms`` each.  The passes have fixed sizes -- 1, 1, 2, 4,
... samples, at most PASS_SAMPLES -- so the order in which the sums are added
up, and with the counter-based random numbers the image, depends on the seed
and the sample count alone, not on the device's speed or the tiling.

The host keeps QUEUED_LAUNCHES launches queued behind the one it waits for,
so the device never waits for the host between launches; Ctrl-C is seen
between waits and ends the render early with the samples of every launch
queued by then (``Frame.interrupted``; each pixel averages its own samples,
so a band of rows that got one launch more is still right).  At the end a
kernel divides the sums into means on the device, and the means alone come
back, into page-locked memory (the renderer's image pool): the sums buffer
stays on the device for the next frame of the same size.
"""

from __future__ import annotations

from collections import deque
from typing import Callable

import numpy as np
import pyopencl as cl

from clrt.config import PATH_RR_DEPTH, PATH_STRATEGIES
from clrt.device.args import camera_value, vec4
from clrt.device.context import device_kind
from clrt.device.geometry import replace_buffer
from clrt.device.program import build_program, launch_size
from clrt.device.signature import typed_kernels
from clrt.layouts import PATH_LAUNCH, PATH_RECORD_HEAD, RAY
from clrt.renderer.kernels import FRAME_HEADER, PATH_ARRAYS, PATH_KERNELS, pack_tables
from clrt.scene.emitters import emitting_triangles, light_tables
from clrt.scene.texture import srgb_encode8

#: The most samples of a pass: later passes add this many each.
PASS_SAMPLES = 64
#: Bytes a pixel of the path tracer's frame buffer: its three float4 sums.
PATH_BYTES_PER_PIXEL = 16 * len(PATH_ARRAYS)
#: Bytes a pixel of the means read back: three packed float RGB (path_resolve).
MEAN_BYTES_PER_PIXEL = 12 * len(PATH_ARRAYS)
#: Launches left queued behind the one the host waits for (Ctrl-C lets them finish).
QUEUED_LAUNCHES = 1
#: Work-items per work-group of path_resolve: the driver's choice on a GPU,
#: fixed on a CPU device (PoCL compiles a variant per size: launch_size).
RESOLVE_GROUP: dict = {"gpu": None, "cpu": 64}
#: Registers a work-item of the megakernel may use on NVIDIA devices.  Left
#: to itself the compiler takes 110 (the lent H200's driver, 2026-12-02),
#: room for 16 warps an SM; capped, more warps fit and hide the latency of
#: the BVH walks' memory reads, which outweighs the spills: kernel time at
#: depth 8 fell by 20 % (Cornell box) and 17 % (bunny00) at 40, against 12
#: and 13 % at 64 (docs/benchmark-log.md).
NVIDIA_MAX_REGISTERS = 40


def register_cap(device: cl.Device) -> tuple[str, ...]:
    """The path program's compiler options that cap its registers, where the
    device's compiler takes them (NVIDIA's cl_nv_compiler_options)."""
    if "cl_nv_compiler_options" in device.extensions.split():
        return (f"-cl-nv-maxrregcount={NVIDIA_MAX_REGISTERS}",)
    return ()


#: Build a diffuse-only path program for scenes whose every material is
#: Lambertian (bsdf_defines); False: every scene gets the general BSDF (tests
#: compare the two).
DIFFUSE_ONLY_PROGRAMS = True


def bsdf_defines(materials: np.ndarray, used: np.ndarray | None = None) -> dict:
    """The BSDF's build-time defines for a scene's MATERIAL rows (``used``:
    the rows its triangles name; default all): BSDF_DIFFUSE_ONLY where no
    material used has a metal, specular or transmission lobe (bsdf.cl: the
    same answers from a smaller kernel; on the H200 the general BSDF's
    registers cost a diffuse scene a third of its speed)."""
    m = materials if used is None else materials[np.unique(used)]
    lambertian = not ((m["metallic"] > 0).any() or (m["specular_weight"] > 0).any() or (m["transmission"] > 0).any())
    return {"BSDF_DIFFUSE_ONLY": None} if DIFFUSE_ONLY_PROGRAMS and lambertian else {}


def pass_sizes(spp: int) -> list[int]:
    """The samples of each pass of a render of ``spp`` samples per pixel:
    1, 1, 2, 4, ... up to PASS_SAMPLES a pass, the last one what is left."""
    sizes, size, done = [], 1, 0
    while done < spp:
        n = min(size, spp - done)
        sizes.append(n)
        done += n
        size = min(max(done, 1), PASS_SAMPLES)
    return sizes


def tone_map(linear: np.ndarray, exposure: float) -> np.ndarray:
    """8-bit sRGB of a linear image: scaled by 2**exposure, clamped to 0..1,
    then the sRGB curve (IEC 61966-2-1) -- the documented tone map of clrt's
    PNG output (docs/path-tracing.md)."""
    scaled = linear if exposure == 0 else linear * np.float32(2.0 ** exposure)
    return srgb_encode8(scaled)


#: The EXR channels of the path tracer's guides for denoisers: the mean albedo
#: and shading normal (world space) of the camera rays' first hits, as
#: Mitsuba's AOV integrator and Intel Open Image Denoise's tools name them.
PATH_CHANNELS = {"albedo": ("albedo.R", "albedo.G", "albedo.B"), "normal": ("normal.X", "normal.Y", "normal.Z")}


def path_channels(frame) -> dict:
    """A frame's albedo and normal images as EXR channels (PATH_CHANNELS);
    none for a Whitted frame, which has neither."""
    if frame.albedo is None or frame.normal is None:
        return {}
    return {name: getattr(frame, layer)[..., k] for layer, names in PATH_CHANNELS.items()
            for k, name in enumerate(names)}


def file_image(frame, depth: str, exposure: float) -> np.ndarray:
    """The image a file of ``depth`` (clrt.output's "8-bit", "16-bit",
    "float") gets from a frame rendered linear for 16-bit and float, 8-bit
    otherwise: 8-bit as the renderer tone-mapped it, 16-bit scaled by
    2**exposure (its writer clamps and encodes, so both follow the
    documented tone map), float linear as rendered -- what ``clrt render``
    and ``clrt batch render`` write alike."""
    if depth == "16-bit" and exposure != 0:
        return frame.image * np.float32(2.0 ** exposure)
    return frame.image


class PathTracer:
    """The path tracer of one Renderer: its program, its light tables and its
    frame buffers on that renderer's device (built on the first path-traced
    frame; the buffers kept for frames of the same size)."""

    def __init__(self, renderer):
        self.renderer = renderer
        detail = {"SURFACE_DETAIL": None} if renderer.arrays.detail is not None else None
        defines = {**renderer.device_scene.defines(detail), **bsdf_defines(renderer.arrays.materials,
                                                                             renderer.arrays.triangle_materials)}
        program = build_program(renderer.context, "path.cl", defines, register_cap(renderer.queue.device))
        self._defines = defines
        self.kernels = typed_kernels(program, PATH_KERNELS, defines)
        self.kernel = self.kernels["path_trace"]
        self.max_group = self.kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE,
                                                          renderer.queue.device)
        self.resolve_group = RESOLVE_GROUP[device_kind(renderer.queue.device)]
        self.tables = None
        self._tables_of = None   # what the tables were built from
        self._frame = self._means = None   # the sums and the means of a frame of _pixels pixels
        self._pixels = 0

    def forget_tables(self) -> None:
        """Build the light tables again for the next frame (the renderer's
        instances moved, and their emitters with them)."""
        self._tables_of = None

    def _light_tables(self, scene):
        """The `tables` buffer with the light tables of the renderer's scene as
        it is now (lights, background, environment), and PathLaunch's values."""
        r = self.renderer
        key = (tuple(scene.lights), tuple(scene.background), id(scene.environment), id(r.arrays))
        if key == self._tables_of:
            return self._launch_values
        a = r.arrays
        corners, material_of, slots, instances = emitting_triangles(a, r.acceleration.slot_order())
        tables = light_tables(corners, material_of, a.materials, scene.lights, scene.background, scene.environment,
                              a.bounds, slots=slots, instances=instances)
        detail = (a.detail.textures, a.detail.srgb_table) if a.detail is not None else (None, None)
        packed, offsets = pack_tables(a.materials, a.lights, *detail, entries=tables.entries, env=tables.texels,
                                      marginal=tables.marginal, conditional=tables.conditional)
        with r.device_scene.out_of_memory():
            if self.tables is None:
                self.tables = cl.Buffer(r.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                        hostbuf=packed)
            else:
                self.tables = replace_buffer(r.queue, self.tables, packed)
        self._tables_of = key
        self._scene_offsets = {k: offsets[k] for k in ("materials_at", "lights_at", "textures_at", "srgb_at")}
        self._launch_values = dict(entries_at=offsets["entries_at"], num_entries=tables.num_entries,
                                   inv_power=tables.inv_power, env_at=offsets["env_at"],
                                   env_width=tables.env_size[0], env_height=tables.env_size[1],
                                   marginal_at=offsets["marginal_at"], conditional_at=offsets["conditional_at"],
                                   background_probability=tables.background_probability)
        return self._launch_values

    def _buffers(self, pixels: int) -> tuple[cl.Buffer, cl.Buffer]:
        """The frame buffer (FRAME_HEADER bytes, then the sums of PATH_ARRAYS)
        and the means' buffer for ``pixels`` pixels, made anew when the size changes."""
        r = self.renderer
        if pixels != self._pixels:
            self.release()
            nbytes = FRAME_HEADER + PATH_BYTES_PER_PIXEL * pixels
            if PATH_BYTES_PER_PIXEL * pixels > r.queue.device.max_mem_alloc_size - FRAME_HEADER:
                raise r.device_scene.memory_error(MemoryError("the image's sums exceed one allocation"),
                                                  f" and {nbytes:,} bytes for the path tracer's image sums")
            with r.device_scene.out_of_memory():
                self._frame = cl.Buffer(r.context, cl.mem_flags.READ_WRITE, nbytes)
                self._means = cl.Buffer(r.context, cl.mem_flags.READ_WRITE, MEAN_BYTES_PER_PIXEL * pixels)
            self._pixels = pixels
        return self._frame, self._means

    def release(self) -> None:
        """Let go of the frame buffers (the next frame makes them again)."""
        for b in (self._frame, self._means):
            if b is not None:
                b.release()
        self._frame = self._means = None
        self._pixels = 0

    def _read_means(self, frame, launch, arrays: int, means: cl.Buffer, host: np.ndarray) -> cl.Event:
        """Queue path_resolve of the first ``arrays`` sums and their copy into
        ``host`` (float32, 3 x arrays x pixels); returns the copy's event."""
        pixels = launch["cam"]["width"] * launch["cam"]["height"]
        resolve = self.kernels["path_resolve"]
        resolve.set_args(frame, launch, np.uint32(arrays), means)
        cl.enqueue_nd_range_kernel(self.renderer.queue, resolve, *launch_size(int(pixels), self.resolve_group))
        return cl.enqueue_copy(self.renderer.queue, host, means, is_blocking=False)

    def _path_launch(self, camera, seed: int, max_depth: int, strategy: str) -> tuple:
        """path_trace's PathLaunch (the image's array offsets set, the
        rectangle and samples left to the caller) and its other arguments."""
        r = self.renderer
        scene = r.scene
        values = self._light_tables(scene)
        pixels = camera.width * camera.height
        launch = np.zeros((), PATH_LAUNCH)
        launch["cam"] = camera_value(camera, r.arrays.origin)
        launch["background"] = vec4(scene.background)
        env = scene.environment
        angle = np.radians(env.rotation) if env is not None else 0.0
        launch["environment"] = (np.cos(angle), np.sin(angle), env.strength if env is not None else 1.0,
                                 values["background_probability"])
        for k, name in enumerate(PATH_ARRAYS):
            launch[f"{name}_at"] = FRAME_HEADER + k * 16 * pixels
        launch["seed"], launch["max_depth"], launch["rr_depth"] = seed, max_depth, PATH_RR_DEPTH
        launch["strategy"] = PATH_STRATEGIES[strategy]
        for name in ("entries_at", "num_entries", "inv_power", "env_at", "env_width", "env_height", "marginal_at",
                     "conditional_at"):
            launch[name] = values[name]
        b = r.geometry.buffers
        scene_value = r.geometry.scene_value(ambient_light=scene.ambient_light, background=scene.background,
                                             num_lights=len(r.arrays.lights), **self._scene_offsets)
        detail = (*b["tri_detail"], *b["texels"]) if r.arrays.detail is not None else ()
        args = (*r.geometry.buffer_args, scene_value, *b["tri_info"], *b["vertex_normals"], self.tables, *detail)
        return launch, args

    def render(self, camera, *, spp: int, max_depth: int, seed: int, strategy: str, progress: Callable,
               wait: Callable, limits, preview: Callable | None = None) -> dict:
        """Render ``spp`` samples a pixel; return the linear image, the albedo
        and normal images (H, W, 3 float32), the samples done, whether Ctrl-C
        ended it early, whether a camera ray hit anything, the tiles
        (launches), the kernel milliseconds and the read-back's.
        ``preview(image, samples)``, if given, gets the linear image after
        each pass but the last.  ``wait(event)`` waits for a launch (or a
        preview's copy), in the order they were queued."""
        r = self.renderer
        w, h = camera.width, camera.height
        pixels = w * h
        frame, means = self._buffers(pixels)
        cl.enqueue_fill_buffer(r.queue, frame, np.zeros(1, np.uint32), 0, FRAME_HEADER)
        launch, args = self._path_launch(camera, seed, max_depth, strategy)
        # The means come back into page-locked memory where the pool has some.
        block = r.image_pool.take(MEAN_BYTES_PER_PIXEL * pixels)
        host = (block.view(np.float32) if block is not None else np.empty(3 * len(PATH_ARRAYS) * pixels, np.float32))
        seen = np.zeros(1, np.uint32)

        pending = deque()   # (event, what to do once it is done), in queue order
        stats = {"kernel_ms": 0.0, "ms_per_sample": 0.0}   # ms_per_sample: the most a pixel sample has cost

        def settle(keep: int) -> None:
            """Wait for the oldest queued events until ``keep`` are left."""
            while len(pending) > keep:
                event, then = pending.popleft()
                wait(event)
                then(event)

        def launched(n: int, rows: int) -> Callable:
            def then(event):
                ms = 1e-6 * (event.profile.end - event.profile.start)
                stats["kernel_ms"] += ms
                stats["ms_per_sample"] = max(stats["ms_per_sample"], ms / (n * w * rows))
                progress(w * rows * n)
            return then

        def previewed(image: np.ndarray, samples: int) -> Callable:
            return lambda event: preview(image.reshape(h, w, 3), samples)

        queued = 0      # samples of every pixel once the queued launches are done
        launches, copy, interrupted = 0, None, False
        try:
            for n in pass_sizes(spp):
                launch["sample_first"], launch["sample_count"], launch["samples_before"] = queued, n, queued
                y = 0
                while y < h:
                    if stats["ms_per_sample"] > 0:
                        rows = int(limits.launch_ms / (stats["ms_per_sample"] * n * w))
                    else:
                        rows = limits.first_launch_pixels // (w * n)
                    rows = max(1, min(rows, h - y))
                    launch["x"], launch["y"], launch["w"], launch["h"] = 0, y, w, rows
                    size, local = self._launch_shape(w, rows, limits)
                    self.kernel.set_args(frame, launch, *args)
                    pending.append((cl.enqueue_nd_range_kernel(r.queue, self.kernel, size, local),
                                    launched(n, rows)))
                    launches += 1
                    y += rows
                    queued += n if y >= h else 0
                    settle(QUEUED_LAUNCHES)
                if preview is not None and queued < spp:   # the image so far (the last one is the frame)
                    image = np.empty(3 * pixels, np.float32)
                    pending.append((self._read_means(frame, launch, 1, means, image), previewed(image, queued)))
            copy = self._read_means(frame, launch, len(PATH_ARRAYS), means, host)
            settle(0)
        except KeyboardInterrupt:
            r.queue.finish()   # every queued launch has added its samples
            if queued == 0:
                raise
            interrupted = True
        if copy is None:
            copy = self._read_means(frame, launch, len(PATH_ARRAYS), means, host)
        cl.enqueue_copy(r.queue, seen, frame, src_offset=0, is_blocking=False).wait()
        read_ms = 1e-6 * (copy.profile.end - copy.profile.start)
        images = host.reshape(len(PATH_ARRAYS), h, w, 3)
        return dict(image=images[0], albedo=images[1], normal=images[2], spp=queued, interrupted=interrupted,
                    seen=bool(seen[0]), tiles=launches, kernel_ms=stats["kernel_ms"], read_ms=read_ms)

    #: The kinds of rays record_rays returns, in PathRecordHead's order (path.cl's RECORD_<KIND>).
    RECORD_KINDS = ("bounce", "shadow")

    def record_rays(self, camera, *, spp: int, max_depth: int, seed: int, capacity: int,
                    strategy: str = "mis") -> dict:
        """The rays path_trace traces after the camera's for ``spp`` samples of
        every pixel of ``camera``'s image (path.cl's -DPATH_RECORD_RAYS, a
        program of its own; for benchmarks): {"bounce": (origins,
        directions), "shadow": (origins, directions, tmax), "traced":
        {"bounce": n, "shadow": n}}, in the scene's coordinates (origins
        float64, the rest float32), at most ``capacity`` of each kind (the
        first recorded, in the order the work-items ran; "traced" counts them
        all).  One launch over the image."""
        r = self.renderer
        kinds = {f"RECORD_{name.upper()}": f"{k}u" for k, name in enumerate(self.RECORD_KINDS)}
        program = build_program(r.context, "path.cl", {**self._defines, "PATH_RECORD_RAYS": None, **kinds},
                                register_cap(r.queue.device))
        kernel = typed_kernels(program, PATH_KERNELS, self._defines)["path_trace"]
        max_group = kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, r.queue.device)
        w, h = camera.width, camera.height
        record_at = FRAME_HEADER + PATH_BYTES_PER_PIXEL * w * h
        nbytes = record_at + PATH_RECORD_HEAD.itemsize + len(self.RECORD_KINDS) * capacity * RAY.itemsize
        if nbytes > r.queue.device.max_mem_alloc_size:
            raise r.device_scene.memory_error(MemoryError("the record exceeds one allocation"),
                                              f" and {nbytes:,} bytes for the path tracer's recorded rays")
        with r.device_scene.out_of_memory():
            frame = cl.Buffer(r.context, cl.mem_flags.READ_WRITE, nbytes)
        head = np.empty((), PATH_RECORD_HEAD)
        rays = np.empty(len(self.RECORD_KINDS) * capacity, RAY)
        try:
            cl.enqueue_fill_buffer(r.queue, frame, np.zeros(1, np.uint32), 0, FRAME_HEADER)
            cl.enqueue_fill_buffer(r.queue, frame, np.zeros(1, np.uint32), record_at, PATH_RECORD_HEAD.itemsize)
            launch, args = self._path_launch(camera, seed, max_depth, strategy)
            launch["x"], launch["y"], launch["w"], launch["h"] = 0, 0, w, h
            launch["sample_first"], launch["sample_count"], launch["samples_before"] = 0, spp, 0
            launch["record_at"], launch["record_capacity"] = record_at, capacity
            kernel.set_args(frame, launch, *args)
            cl.enqueue_nd_range_kernel(r.queue, kernel, *self._launch_shape(w, h, r.limits, max_group))
            cl.enqueue_copy(r.queue, head, frame, src_offset=record_at)
            cl.enqueue_copy(r.queue, rays, frame, src_offset=record_at + PATH_RECORD_HEAD.itemsize, is_blocking=True)
        finally:
            frame.release()
        out = {"traced": {}}
        for kind, name in enumerate(self.RECORD_KINDS):
            traced = int(head["traced"][kind])
            kept = rays[kind * capacity:kind * capacity + min(traced, capacity)]
            # float64: far from the origin a float32 point may fall behind the
            # surface a ray leaves (the device frame's spawn offset is smaller
            # than float32's step there)
            origins = kept["origin"][:, :3].astype(np.float64) + r.arrays.origin
            rows = (origins, np.ascontiguousarray(kept["dir"][:, :3]))
            out[name] = rows if name == "bounce" else (*rows, np.ascontiguousarray(kept["dir"][:, 3]))
            out["traced"][name] = traced
        return out

    def _launch_shape(self, w: int, h: int, limits, max_group: int | None = None) -> tuple:
        """path_trace's global and local sizes over w x h pixels: the limits'
        block where the kernel's work-groups may be that large (``max_group``:
        its most work-items, by default the rendering kernel's)."""
        bw, bh = limits.block or (0, 0)
        if not 0 < bw * bh <= (max_group or self.max_group):
            return (w, h), None
        return (-(-w // bw) * bw, -(-h // bh) * bh), (bw, bh)

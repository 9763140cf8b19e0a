"""The host side of a frame, stage by stage as in the paper:

1. initialisation      -- flatten the scene into typed arrays (clrt.scene.arrays)
2. acceleration build  -- a BVH (box, sphere or ellipsoid volumes; ``accel="none"``
                          tests every ray against every triangle) (clrt.accel)
3. copy to device      -- context, program build, buffer upload (once per Renderer)
4. ray generation      -- ``generate_rays`` kernel, one ray per pixel
5. pixel colour        -- ``shade_pixels`` kernel: nearest hit, Phong, shadow rays;
                          the last sample's also encodes the pixel as 8-bit sRGB
6. read back           -- the sRGB image (or the linear one) copied to the host

Stages 1-3 happen when a :class:`Renderer` is made; 4-6 on every ``render`` call,
so frames after the first reuse the uploaded scene and the built program.
Tiling and the memory fallback: tiles.py; page-locked images: clrt/device/pinned.py.
"""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
import threading
import time
import warnings
import weakref
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl as cl

from clrt import checks
from clrt import options as opts
from clrt.config import (DEFAULT_ACCEL, DEFAULT_BUILDER, DEFAULT_LEAF_SIZE, DEFAULT_MAX_DEPTH,
                         DEFAULT_PATH_MAX_DEPTH, DEFAULT_SPP, INTEGRATORS, PATH_STRATEGIES)
from clrt.device import scene as device_scene
from clrt.device.args import camera_value
from clrt.device.context import create_context
from clrt.device.context import format_bytes as _size
from clrt.accel.bvh import Acceleration
from clrt.device.acceleration import build_acceleration
from clrt.device.crease import UploadedMesh, shade_on_device, upload_mesh
from clrt.device.geometry import replace_buffer
from clrt.device.instances import instanced_scene, move_instances, refit_meshes
from clrt.device.pinned import PinnedPool
from clrt.device.scene import DeviceScene, stage
from clrt.device.sharing import check_process, forked_after_start, one_at_a_time
from clrt.errors import DeviceMemoryError, InputError, NothingVisibleWarning
from clrt.layouts import HIT, TILE
from clrt.renderer.kernels import FRAME_ARRAYS, FRAME_HEADER, RENDER_KERNELS, frame_offsets, pack_tables
from clrt.renderer.path import PathTracer, tone_map
from clrt.renderer.tiles import TileLimits, run_tiles
from clrt.renderer.visible import nothing_visible
from clrt.scene.arrays import flatten_scene, light_records, moved_meshes, uses_pbr_textures
from clrt.scene.instances import is_instance_list
from clrt.scene.mesh import Mesh
from clrt.scene.placed import moved_scene
from clrt.scene.scene import Camera, Scene, far_triangle
from clrt.scene.render_setup import render_frame
from clrt.scene.sources import as_scene
from clrt.scene.texture import srgb_encode8


@dataclass
class Frame:
    """One rendered image and how long each of its stages took (milliseconds):
    ``timings`` holds this frame's work alone ("ray generation", "pixel
    colour", "read back"; the path tracer's "path tracing", "kernels", "read
    back") -- the set-up done once per Renderer is in ``Renderer.timings``."""

    image: np.ndarray            # (H, W, 3) uint8 sRGB, or float32 linear RGB
    prim: np.ndarray | None      # (H, W) int32 triangle seen by each pixel, -1 for background
    t: np.ndarray | None         # (H, W) float32 distance along the camera ray, inf for background
    timings: dict = field(default_factory=dict)
    device: str = ""
    triangles: int = 0
    tiles: int = 1               # tiles the frame was rendered in (each: one launch per sample)
    visible: bool = True         # a camera ray (of the first sample) hit a triangle; False: only background
    albedo: np.ndarray | None = None   # path tracer: (H, W, 3) float32 mean albedo of the first hits (0: none)
    normal: np.ndarray | None = None   # path tracer: (H, W, 3) float32 mean shading normal of the first hits
    spp: int = 0                 # path tracer: samples per pixel done (fewer than asked if interrupted)
    interrupted: bool = False    # path tracer: Ctrl-C ended the render after `spp` samples

    def __repr__(self) -> str:
        h, w = self.image.shape[:2]
        kind = "uint8 sRGB" if self.image.dtype == np.uint8 else "float32 linear RGB"
        total = sum(self.timings.values())
        return (f"<clrt.Frame {w}x{h} {kind}{', with prim and t' if self.prim is not None else ''}, "
                f"{self.triangles:,} triangles on {self.device}, {total:.1f} ms>")

    def to_pil(self):
        """The image as a PIL image (a linear image is clamped and sRGB-encoded first)."""
        from PIL import Image
        return Image.fromarray(self.image if self.image.dtype == np.uint8 else srgb_encode8(self.image))

    def _repr_png_(self) -> bytes:
        """PNG bytes: Jupyter shows a Frame as its picture."""
        import io
        buffer = io.BytesIO()
        self.to_pil().save(buffer, format="PNG")
        return buffer.getvalue()


def _rebuilt_renderer(scene: Scene, options: dict, limits: TileLimits) -> "Renderer":
    """An unpickled (or copied) Renderer: made again from its scene and options
    (Renderer.__reduce__) -- in a child forked after OpenCL started, a shell
    whose renders raise the DeviceError (as clrt.query.accel._rebuilt_accel)."""
    if forked_after_start():
        shell = Renderer.__new__(Renderer)
        shell._lock, shell.scene, shell._options, shell.limits = threading.RLock(), scene, options, limits
        return shell
    return Renderer(scene, limits=limits, **options)


def _own_copy(scene: Scene) -> Scene:
    """A Renderer's own copy of ``scene``: what it uploaded stays what it shows.
    Changing the caller's Scene later (its lights, background, materials) does
    not reach the renderer -- set_lights, refit or a new Renderer do."""
    return dataclasses.replace(scene, objects=list(scene.objects), lights=list(scene.lights))


def _bare_mesh(source) -> Mesh | None:
    """``source``'s Mesh where it is a bare mesh -- a Mesh or ``(vertices,
    faces)`` (checked here, as the scene would check it), without authored
    normals or corner colours, not a crease split -- whose scene is its default
    framing, light and material; else None."""
    if isinstance(source, Mesh):
        mesh = source
    elif isinstance(source, (tuple, list)) and len(source) == 2 and not is_instance_list(source):
        mesh = Mesh.from_arrays(*source)
    else:
        return None
    return mesh if mesh.normals is None and mesh.colors is None and mesh.crease_split_of is None else None


@dataclass
class _TreeFirst:
    """A bare mesh, its vertices and faces on the device and the tree built
    from them, before its scene was made (Renderer._tree_first)."""

    mesh: Mesh
    uploaded: UploadedMesh
    acceleration: Acceleration

    def release(self) -> None:
        """Let go of the uploaded mesh (the tree's buffers go with the last reference)."""
        self.uploaded.release()


class Renderer:
    """A scene uploaded to one OpenCL device, ready to render frames.

    The renderer keeps its own copy of the scene as it was when made (or last
    refitted): later changes to the caller's Scene object are not shown --
    use :meth:`set_lights`, :meth:`refit` or a new Renderer.  A copy or an
    unpickled Renderer is a new one, made from this one's scene and options
    (a worker process started by "spawn" can be sent one).

    ``scene``: a Scene, or anything :func:`~clrt.scene.sources.as_scene` takes
    (a mesh, a mesh or scene file).  The options go by keyword, in the same
    order as :class:`~clrt.query.accel.Accel`'s (the choices of the structure
    first, then the device): ``accel``: "box" (default), "sphere", "ellipse"
    (BVH volume shape) or "none" (brute force); ``builder``: "auto" (default:
    "device" where the device computes in float64, else "sah"), "sah",
    "paper" (on the host) or "device" (PLOC on the device,
    clrt.device.build); ``leaf_size``: the most triangles in a BVH leaf.
    Every choice renders the same image.  ``device``: None (the first GPU,
    else the CPU), "gpu", "cpu" or "P:D" (as ``clrt info`` lists them).
    ``limits``: how frames are cut into launches (:class:`TileLimits`);
    ``max_buffer_bytes``: split scene buffers above this size (as scenes larger
    than the device's largest allocation are; tests and benchmarks use it).

    Only the scene goes by position: the options once did, in an order of
    their own (device, accel, builder, leaf_size, where Accel had accel,
    builder, leaf_size, device), so ``Renderer(scene, "gpu")`` now raises
    InputError showing the call with keywords rather than meaning something else.

    ``timings``: the set-up's stages, in ms, reported once here rather than
    in every frame's: "initialisation", "acceleration build", "copy to
    device" (the context, the upload and the programs), and "program build"
    once the path tracer's program is built (its first frame).  Where a GPU
    builds the tree from a one-object scene's mesh, it also makes the crease
    split, the vertex normals and the per-slot shading data, in
    "acceleration build" (clrt.device.crease): the host makes none of them.

    Threads may share a Renderer: its renders, refits and light changes take
    turns (clrt.device.sharing), so a frame shows the scene as it was when
    the frame began.
    """

    @checks.keyword_options("device", "accel", "builder", "leaf_size")
    def __init__(self, scene: Scene, *, accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER,
                 leaf_size: int = DEFAULT_LEAF_SIZE, device: str | None = None,
                 limits: TileLimits | None = None, max_buffer_bytes: int | None = None):
        device = opts.check("device", device)   # the table's rules (clrt/options.py), as clrt render's
        check_process()   # before a long host build that could not be used
        accel, builder, leaf_size = (opts.check(name, value) for name, value in
                                     (("accel", accel), ("builder", builder), ("leaf_size", leaf_size)))
        self.limits = limits or TileLimits()
        self._options = dict(accel=accel, builder=builder, leaf_size=leaf_size, device=device,
                             max_buffer_bytes=max_buffer_bytes)   # for a rebuild (refit)
        self.timings: dict[str, float] = {}
        self._lock = threading.RLock()
        self._followers = weakref.WeakSet()   # Accel.from_renderer's queries, kept on this scene
        with contextlib.ExitStack() as ahead:
            # A bare mesh that a GPU builds and shades: its tree first, so that
            # the scene's framing and lights read the box the build found.
            first = self._tree_first(scene, accel, builder, leaf_size, device, ahead) \
                if max_buffer_bytes is None else None
            with stage(self.timings, "initialisation"):
                self.scene = _own_copy(as_scene(scene if first is None else first.mesh))
                # The path tracer's textures (emission, metallic-roughness, normal
                # maps) for scenes made for it; Whitted reads base colours only.
                self._pbr_textures = self.scene.integrator == "path"
                # Where a GPU builds the tree from the mesh, it makes a plain
                # mesh's shading arrays too: no crease split on the host (clrt.device.crease)
                # -- but for a machine's first build, on the host (clrt.device.first_build).
                objects = self.scene.objects
                if first is not None:
                    builder = first.acceleration.builder
                elif (max_buffer_bytes is None and len(objects) == 1 and not self.scene.instanced
                      and device_scene.shades_on_device(accel, builder, device)):   # (else built from corners)
                    builder = device_scene.first_builder(objects[0].mesh, accel, builder, leaf_size, device)
                shades = max_buffer_bytes is None and device_scene.shades_on_device(accel, builder, device)
                self.arrays = flatten_scene(self.scene, pbr_textures=self._pbr_textures, device_shading=shades)
            a = self.arrays
            if first is not None and (a.shading is None or a.shading.mesh is not first.mesh):
                first.release()   # (a bare mesh's scene is shaded on the device: not met)
                first = None
            detail = {"SURFACE_DETAIL": None} if a.detail is not None else None

            def shading_arrays(acceleration) -> dict:
                """Per-slot and per-vertex arrays (split with the geometry when large)."""
                slots = acceleration.slot_order()   # shading data in slot order
                split = {"tri_info": a.tri_info[slots], "vertex_normals": a.vertex_normals}
                if a.detail is not None:   # textures or colours: the -DSURFACE_DETAIL program (texture.cl)
                    split.update(tri_detail=a.detail.tri_detail[slots], texels=a.detail.texels)
                return split

            tables = self._tables()
            upload = dict(accel=accel, builder=builder, leaf_size=leaf_size, device=device, extra=shading_arrays,
                          whole_bytes=tables.nbytes, reserve=MIN_FRAME_BYTES, max_buffer_bytes=max_buffer_bytes,
                          timings=self.timings)
            self.instances = a.instances   # placed meshes: a two-level scene (docs/instances.md), else None
            # The program compiles while the tree builds, where its defines are foreseen (build_ahead).
            if first is None:
                ahead.enter_context(device_scene.build_ahead("render.cl", accel, device, detail,
                                                             instanced=a.instances is not None,
                                                             split=max_buffer_bytes is not None))
            if a.instances is not None:
                self.device_scene = instanced_scene(a.instances, material_base=a.material_base, **upload)
            elif a.shading is not None:
                self.device_scene = self._shaded_on_device(upload, first)
            else:
                self.device_scene = DeviceScene(a.corners, bounds=a.bounds, origin=a.origin, **upload)
            on_device = self.device_scene
            self.acceleration, self.geometry = on_device.acceleration, on_device.geometry
            self.context, self.queue, self.device = on_device.context, on_device.queue, on_device.device
            self.rays_per_item = on_device.rays_per_item
            with stage(self.timings, "copy to device"), on_device.out_of_memory():
                self.tables = cl.Buffer(self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                        hostbuf=tables)
                self.kernels = on_device.kernels("render.cl", RENDER_KERNELS, detail)
        self._frame_buffers: dict[str, cl.Buffer] = {}
        self._frame_pixels = -1
        self._staging = None
        self.image_pool = PinnedPool(self.context, self.queue, IMAGE_POOL_SIZE)
        self._path = None   # the path tracer's program and tables, made on its first frame
        self._frame_records = None   # see _frame_args
        self._max_group = min(   # work-items a launch's group may have, see _launch_shape
            k.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, self.queue.device)
            for k in self.kernels.values())

    def _tree_first(self, source, accel: str, builder: str, leaf_size: int, device: str | None,
                    ahead: contextlib.ExitStack) -> "_TreeFirst | None":
        """Where ``source`` is a bare mesh (:func:`_bare_mesh`) whose tree the
        device builds from its vertices and faces and whose shading it makes:
        the mesh uploaded and its tree built before its scene is made (with
        render.cl building beside it: build_ahead, entered on ``ahead``), its
        bounds those the build found -- the host's Mesh.bounds, which the
        scene's framing and light would ask for first, is not computed (3-6
        ms at 1M triangles on the H200's hosts; docs/benchmarks.md).  Else None."""
        with stage(self.timings, "initialisation"):
            mesh = _bare_mesh(source)
            if mesh is None or not device_scene.shades_on_device(accel, builder, device):
                return None
            builder = device_scene.first_builder(mesh, accel, builder, leaf_size, device)
            if not device_scene.shades_on_device(accel, builder, device):
                return None
        ahead.enter_context(device_scene.build_ahead("render.cl", accel, device))
        context, queue = create_context(device)
        with stage(self.timings, "acceleration build"):
            uploaded = upload_mesh(context, queue, mesh)
            try:
                acceleration = build_acceleration(mesh, accel, builder, leaf_size, device, uploaded=uploaded)
            except BaseException:
                uploaded.release()
                raise
        lo, hi, _ = acceleration.frame
        mesh.__dict__.setdefault("_bounds", np.array([lo, hi]))   # the numbers Mesh.bounds would find
        return _TreeFirst(mesh, uploaded, acceleration)

    def _shaded_on_device(self, upload: dict, first: "_TreeFirst | None") -> DeviceScene:
        """The DeviceScene of a one-object scene whose shading arrays the device
        makes (SceneArrays.shading): the mesh's vertices and faces uploaded
        once, the tree built and the corners gathered from them (or ``first``'s,
        built before the scene: _tree_first), then the
        crease split, the vertex normals and the per-slot TriangleInfo made
        there (clrt.device.crease) -- bit for bit the host's arrays."""
        source = self.arrays.shading
        context, queue = create_context(upload["device"])
        if first is not None:
            uploaded = first.uploaded
        else:
            with stage(self.timings, "acceleration build"):
                uploaded = upload_mesh(context, queue, source.mesh)

        def shading_arrays(acceleration) -> dict:
            try:
                made = shade_on_device(context, queue, uploaded, source.crease, acceleration.device_buffers.prim_ids,
                                       source.mesh.face_material, source.material_base)
            finally:
                uploaded.release()
            return made.extra()

        return DeviceScene(source.mesh, bounds=None, origin=None, uploaded=uploaded,
                           acceleration=None if first is None else first.acceleration,
                           **{**upload, "extra": shading_arrays})

    @property
    def device_bytes(self) -> int:
        """Bytes of the scene on the device (geometry, shading arrays and tables)."""
        return self.device_scene.device_bytes

    def _tables(self) -> np.ndarray:
        """The scene's small tables as the `tables` buffer holds them (pack_tables),
        their offsets kept for the SceneInfo of every frame."""
        a = self.arrays
        detail = (a.detail.textures, a.detail.srgb_table) if a.detail is not None else ()
        packed, self._table_offsets = pack_tables(a.materials, a.lights, *detail)
        return packed

    # ----------------------------------------------------------------------- a frame

    @one_at_a_time
    @checks.keyword_options("linear", "hits", "samples", "max_depth", "seed", "progress", "integrator", "spp",
                            "exposure", "strategy", "preview")
    def render(self, camera: Camera | None = None, *, linear: bool = False, hits: bool = False,
               samples: int | None = None, max_depth: int | None = None, seed: int | None = None,
               progress: Callable[[int], None] | None = None, integrator: str | None = None,
               spp: int | None = None, exposure: float | None = None, strategy: str = "mis",
               preview: Callable[["Frame"], None] | None = None) -> Frame:
        """Render one frame.

        ``integrator``: "whitted" (the paper's model) or "path" (the path
        tracer, docs/path-tracing.md; its emission, metallic-roughness and
        normal textures are uploaded for a Renderer made from a scene whose
        integrator is "path"); the scene's by default, as are
        ``samples``, ``spp``, ``max_depth``, ``seed`` and ``exposure``.
        Whitted: ``samples``: anti-aliasing with samples x samples stratified,
        jittered rays per pixel (the jitter is a hash of pixel, sample and
        ``seed``, so renders are reproducible; 1 = one ray through each pixel
        centre); ``max_depth``: reflection/refraction bounces (0..16).  Path:
        ``spp`` samples per pixel, ``max_depth`` counted as Mitsuba counts it (1
        emitters seen directly, 2 direct light, -1 unbounded), ``seed`` keys
        the random numbers (a seed gives the same image on one device);
        ``strategy`` "mis" (default), "light" or "bsdf" samples lights and
        BSDFs together or one alone (clrt.config.PATH_STRATEGIES: a debugging
        aid); the frame also has the mean ``albedo`` and ``normal`` of the
        first hits, and Ctrl-C after the first pass of samples returns the
        passes done (``Frame.interrupted``); ``preview(frame)`` is called
        with the image so far after each pass but the last (a notebook's
        display handle can show it: docs/notebooks.md).  ``exposure``: the uint8 image is
        the linear one x 2**exposure, clamped, sRGB-encoded (a linear image is
        returned as it is).  ``hits=True`` (Whitted only) also reads back the
        camera rays' hits (``Frame.prim`` and ``Frame.t``, of the first sample;
        otherwise None).  ``progress(n)`` is called each time n more pixel
        samples are done (width x height x samples**2, or x spp, in all; a tile
        retried after running out of memory counts again).
        """
        integrator = checks.choice("integrator", self.scene.integrator if integrator is None else integrator,
                                   INTEGRATORS)
        exposure = opts.check("exposure", self.scene.exposure if exposure is None else exposure)
        seed = opts.check("seed", self.scene.seed if seed is None else seed)
        if integrator == "path":
            return self._render_path(camera, linear, hits, max_depth, seed, spp, exposure, strategy, progress,
                                     preview)
        if exposure != 0 and not linear:   # tone-mapped on the host from the linear image
            frame = self.render(camera, linear=True, hits=hits, samples=samples, max_depth=max_depth, seed=seed,
                                progress=progress, integrator=integrator)
            frame.image = tone_map(frame.image, exposure)
            return frame
        job = self._job(camera, linear, hits, samples, max_depth, seed)
        # Rays from too far for the float32 triangle test: one error, not missed hits.
        self.geometry.reach.check_render(job.camera.eye, lambda: far_triangle(self.scene))
        job.camera_args, job.scene_args = self._frame_args(job.camera)
        job.progress = progress or (lambda n: None)
        capacity = self.tile_capacity(job.camera.width * job.camera.height)
        try:
            tiles = run_tiles(job.camera.width, job.camera.height, capacity, self.limits,
                              lambda x, y, w, h, cap: self._render_tile(job, x, y, w, h, cap),
                              self._release_frame_buffers, self._memory_error)
        except KeyboardInterrupt:
            self.queue.finish()   # no kernel may still write into buffers we drop
            raise
        if not job.seen:   # one warning, saying why where it can (clrt render prints it as one line)
            warnings.warn(nothing_visible(self.arrays.corners, self.arrays.bounds, job.camera),
                          NothingVisibleWarning, stacklevel=4)   # past one_at_a_time and keyword_options
        return Frame(job.image, job.prim, job.t, job.timings, self.device, self.arrays.num_triangles, tiles=tiles,
                     visible=job.seen)

    def _render_path(self, camera, linear, hits, max_depth, seed, spp, exposure, strategy, progress,
                     preview) -> Frame:
        """A frame of the path tracer (clrt/renderer/path.py)."""
        if hits:
            raise InputError("hits=True reads back the Whitted integrator's camera hits; for the path tracer, "
                             "query them with clrt.camera_images")
        if not self._pbr_textures and uses_pbr_textures(self.scene):
            raise InputError("the scene's emission, metallic-roughness or normal textures were not uploaded: "
                             "this Renderer was made for the Whitted integrator; set the Scene's "
                             "integrator = \"path\" before making the Renderer to path-trace them")
        camera = self._camera(camera)
        spp = opts.check("spp", spp if spp is not None else self.scene.spp or DEFAULT_SPP)
        depth = max_depth if max_depth is not None else self.scene.max_depth
        depth = checks.max_depth(DEFAULT_PATH_MAX_DEPTH if depth is None else depth, "max_depth", "path")
        strategy = checks.choice("strategy", strategy, tuple(PATH_STRATEGIES))
        self.geometry.reach.check_render(camera.eye, lambda: far_triangle(self.scene))
        w, h = camera.width, camera.height
        host_bytes = w * h * 4 * 12 * 2
        if host_bytes > HOST_CHECK_BYTES:
            check_host_memory(host_bytes, f"a {w}x{h} image")
        if self._path is None:
            with stage(self.timings, "program build"):
                self._path = PathTracer(self)
        timings = {}
        shown = None
        if preview is not None:
            def shown(image, done):
                preview(Frame(image if linear else tone_map(image, exposure), None, None, {}, self.device,
                              self.arrays.num_triangles, spp=done))
        with stage(timings, "path tracing"):
            out = self._path.render(camera, spp=spp, max_depth=depth, seed=seed, strategy=strategy,
                                    progress=progress or (lambda n: None), wait=lambda e: wait_for(e),
                                    limits=self.limits, preview=shown)
        timings["kernels"], timings["read back"] = out["kernel_ms"], out["read_ms"]
        image = out["image"] if linear else tone_map(out["image"], exposure)
        if not out["seen"]:
            warnings.warn(nothing_visible(self.arrays.corners, self.arrays.bounds, camera),
                          NothingVisibleWarning, stacklevel=4)
        return Frame(image, None, None, timings, self.device, self.arrays.num_triangles, tiles=out["tiles"],
                     visible=out["seen"], albedo=out["albedo"], normal=out["normal"], spp=out["spp"],
                     interrupted=out["interrupted"])

    def _camera(self, camera) -> Camera:
        if camera is not None and not isinstance(camera, Camera):
            raise checks.fail("camera", "a clrt.Camera or None", camera)
        return camera or self.scene.camera or Camera.framing(self.arrays.bounds)

    def _job(self, camera, linear, hits, samples, max_depth, seed) -> "_Job":
        """The arguments of one render call checked and defaulted, and its outputs."""
        camera = self._camera(camera)
        samples = opts.check("samples", self.scene.samples if samples is None else samples)
        depth = self.scene.max_depth if max_depth is None else max_depth
        max_depth = checks.max_depth(DEFAULT_MAX_DEPTH if depth is None else depth, "max_depth", "whitted")
        seed = checks.integer("seed", seed, 0, 2**32 - 1)
        w, h = camera.width, camera.height
        host_bytes = w * h * ((12 if linear else 3) + (8 if hits else 0))
        if host_bytes > HOST_CHECK_BYTES:   # reading /proc/meminfo costs more than a small frame
            check_host_memory(host_bytes, f"a {w}x{h} image")
        timings = {"ray generation": 0.0, "pixel colour": 0.0, "read back": 0.0}
        if linear:
            image, pinned = np.empty((h, w, 3), np.float32), False
        else:
            image = self.image_pool.take(3 * w * h)
            pinned = image is not None
            image = (image if pinned else np.empty(3 * w * h, np.uint8)).reshape(h, w, 3)
        prim = np.empty((h, w), np.int32) if hits else None
        t = np.empty((h, w), np.float32) if hits else None
        return _Job(camera, samples, max_depth, seed, linear, image, pinned, prim, t, timings)

    def _frame_args(self, camera: Camera) -> tuple[np.ndarray, tuple]:
        """The arguments that hold for a whole frame: the Camera (generate_rays),
        and the scene's with the values that change between frames only by
        this renderer's own methods (refit, set_lights, move_instances):
        shade_pixels' GEOMETRY_PARAMS and SHADING_PARAMS.  The two records are
        made again only where what they are made of changed (compared by
        identity, the camera by value; those methods also drop them): making
        them took 35-40 us of a 1080p frame's 0.2 ms of host time on the
        H200's host."""
        g, scene, arrays = self.geometry, self.scene, self.arrays
        key = (camera, g, g.num_tris, g.packets_at, g.num_instances, scene, scene.ambient_light, scene.background,
               arrays, arrays.lights, self._table_offsets)
        cached = self._frame_records
        if (cached is None or (cached[0][0] is not camera and cached[0][0] != camera)
                or any(a is not b for a, b in zip(cached[0][1:], key[1:]))):
            values = g.scene_value(ambient_light=scene.ambient_light, background=scene.background,
                                   num_lights=len(arrays.lights), **self._table_offsets)
            cached = self._frame_records = (key, camera_value(camera, arrays.origin), values)
        b = g.buffers   # read per frame: a refit may have replaced some
        detail = (*b["tri_detail"], *b["texels"]) if arrays.detail is not None else ()
        return cached[1], (*g.buffer_args, cached[2], *b["tri_info"], *b["vertex_normals"], self.tables, *detail)

    @one_at_a_time
    def refit(self, scene, *, rebuild: bool = False) -> None:
        """Show ``scene``: the same objects with the same triangles as this renderer's
        scene, their vertices moved (animation, deformation).  The BVH is refitted
        on the device (the tree kept, every volume fitted anew: the image stays
        exact) and the triangles, vertex normals, materials and lights uploaded
        again; the camera and settings are ``scene``'s too -- the renderer shows
        ``scene`` as given, so a ``scene_from_mesh(moved)`` without a material
        shows the default material: pass the material again to keep it.
        ``rebuild=True`` builds a new BVH instead (a tree refitted through large
        motions traces slower).  A scene of placed meshes: the same objects
        placing the same meshes (objects sharing a Mesh object still share
        one), their vertices moved -- their placements too, if given so --:
        each moved mesh's BVH is refitted, and the instance table and the top
        level are built again over the new boxes (docs/instances.md)."""
        scene = as_scene(scene)
        arrays = flatten_scene(scene, pbr_textures=self._pbr_textures)
        # The same triangles of the same objects; their vertex normals may be
        # split differently (the crease angle looks at the moved faces).
        same = (arrays.num_triangles == self.arrays.num_triangles
                and np.array_equal(arrays.triangle_materials, self.arrays.triangle_materials)
                and len(arrays.materials) == len(self.arrays.materials))
        moved = moved_meshes(self.arrays, arrays)   # a scene of placed meshes: those whose vertices moved
        if not same or (moved is None) != (self.instances is None):
            raise InputError("refit needs the scene's objects with the same triangles (only their vertices "
                             "may move) and, for placed meshes, the same placements of the same meshes: "
                             "make a new Renderer")
        if rebuild or self.geometry.shifts is not None:
            fresh = Renderer(scene, **self._options, limits=self.limits)
            followers, lock = self._followers, self._lock   # the queries and threads on this one
            self.__dict__.update(fresh.__dict__)
            self._followers, self._lock = followers, lock
        else:
            if moved is None:
                self.geometry.refit(self.queue, arrays.corners, arrays.bounds, arrays.origin)
            elif refit_meshes(self.device_scene, arrays.instances, moved):   # programs of another stack size
                detail = {"SURFACE_DETAIL": None} if arrays.detail is not None else None
                self.kernels, self._path = self.device_scene.kernels("render.cl", RENDER_KERNELS, detail), None
            self.instances = arrays.instances
            self.geometry.replace(self.queue, "tri_info", arrays.tri_info[self.acceleration.slot_order()])
            self.geometry.replace(self.queue, "vertex_normals", arrays.vertex_normals)
            self.scene, self.arrays = _own_copy(scene), arrays
            self.set_lights(scene.lights)   # uploads the tables, the new materials with the lights
        for queries in list(self._followers):
            queries.follow(self, queries.chunk_rays)

    @one_at_a_time
    def move_instances(self, transforms) -> None:
        """Place a scene of placed meshes anew: ``transforms`` (I, 4, 4),
        object -> world, one for each placement in the order of
        ``self.instances`` (docs/instances.md).  Only the instance table and
        the top level are built again (on the device where it built the
        meshes, else on the host); the meshes' BVHs, shading arrays and
        materials stay.  The frames after show the
        moved scene as a new Renderer of it would, bit for bit (its lights
        stay where they are)."""
        if self.instances is None:
            raise InputError("move_instances needs a scene of placed meshes (docs/instances.md); one whose "
                             "vertices move is refitted (Renderer.refit)")
        instances, changed = move_instances(self.device_scene, self.instances, transforms)
        origin = self.geometry.origin
        self.scene, self.instances = moved_scene(self.scene, instances.transforms), instances
        self.arrays = dataclasses.replace(self.arrays, instances=instances, bounds=instances.bounds, origin=origin,
                                          lights=light_records(self.scene.lights, origin))
        self.tables = replace_buffer(self.queue, self.tables, self._tables())
        self._frame_records = None   # (the key would also see it; this lets the old scene go now)
        if changed:   # a top level of another depth: programs of another stack size
            detail = {"SURFACE_DETAIL": None} if self.arrays.detail is not None else None
            self.kernels, self._path = self.device_scene.kernels("render.cl", RENDER_KERNELS, detail), None
        elif self._path is not None:
            self._path.forget_tables()   # its lights' triangles moved
        for queries in list(self._followers):
            queries.follow(self, queries.chunk_rays)

    # As an Accel: a copy, a deep copy or an unpickled Renderer is a new one, made
    # from this one's scene (its lights and refits included) and options -- on the
    # device named by them -- without the queries that follow this one.
    def __reduce__(self):
        return _rebuilt_renderer, (self.scene, dict(self._options), self.limits)

    def __repr__(self) -> str:
        if "scene" not in self.__dict__:    # its __init__ failed
            return "<clrt.Renderer, not made>"
        if "arrays" not in self.__dict__:   # _rebuilt_renderer's shell
            return f"<clrt.Renderer of {self.scene.num_triangles:,} triangles, unpickled where OpenCL cannot run>"
        placed = f" in {len(self.instances):,} placements" if self.instances is not None else ""
        return (f"<clrt.Renderer of {self.arrays.num_triangles:,} triangles{placed}, {len(self.arrays.lights)} "
                f"light(s), {self.acceleration.accel} ({self.acceleration.builder}) on {self.device}>")

    def add_follower(self, queries) -> None:
        """Keep ``queries`` (Accel.from_renderer's) on this renderer's scene through refits."""
        self._followers.add(queries)

    @one_at_a_time
    def set_lights(self, lights) -> None:
        """Replace the lights this renderer shows (its copy of the scene's; the
        caller's Scene is left as it is); the geometry stays uploaded (a
        turntable of ``clrt batch render`` moves the default light with the camera)."""
        self.scene.lights = list(lights)
        self.arrays.lights = light_records(self.scene.lights, self.arrays.origin)
        self.tables = replace_buffer(self.queue, self.tables, self._tables())
        self._frame_records = None   # (the key would also see it; this lets the old records go now)

    # ----------------------------------------------------------------------- memory

    def tile_capacity(self, pixels: int) -> int:
        """The most pixels of one tile: the whole image if the device memory allows,
        at most half of what the scene leaves free and one buffer's size limit."""
        dev = self.queue.device
        free = max(dev.global_mem_size - self.device_bytes, 0) // 2
        cap = min(pixels, MAX_TILE_PIXELS, (dev.max_mem_alloc_size - FRAME_HEADER) // FRAME_BYTES_PER_PIXEL,
                  free // FRAME_BYTES_PER_PIXEL)
        cap = max(cap, min(pixels, self.limits.min_tile_pixels))   # if even that fails, the error says so
        if self.limits.max_tile_pixels is not None:
            cap = min(cap, self.limits.max_tile_pixels)
        return max(int(cap), 1)

    def _buffers_for(self, pixels: int) -> dict:
        """Per-tile buffers for up to ``pixels`` pixels, reallocated only when that changes."""
        if pixels != self._frame_pixels:
            self._release_frame_buffers()
            mf = cl.mem_flags
            self._frame_buffers = {
                # The rays, hits, linear and sRGB colours of a tile (render.cl, frame_offsets).
                "frame": cl.Buffer(self.context, mf.READ_WRITE, frame_offsets(pixels)["end"]),
                # Page-locked host memory for tiles that cannot be read back in place.
                "staging": cl.Buffer(self.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, pixels * 3),
            }
            self._staging, _ = cl.enqueue_map_buffer(
                self.queue, self._frame_buffers["staging"], cl.map_flags.READ | cl.map_flags.WRITE,
                0, (pixels, 3), np.uint8)
            self._frame_pixels = pixels
            self._frame_at = frame_offsets(pixels)
        return self._frame_buffers

    def _release_frame_buffers(self) -> None:
        if self._staging is not None:
            self._staging.base.release(self.queue)
            self._staging = None
        for b in self._frame_buffers.values():
            b.release()
        self._frame_buffers, self._frame_pixels = {}, -1

    def _memory_error(self, exc, tile: int) -> DeviceMemoryError:
        frame = f" and {_size(tile * FRAME_BYTES_PER_PIXEL)} for a tile of {tile:,} pixels" if tile else ""
        return self.device_scene.memory_error(exc, frame)

    # ----------------------------------------------------------------------- launches

    def _launch(self, name: str, global_size, local_size, *args) -> cl.Event:
        kernel = self.kernels[name]
        kernel.set_args(*args)
        return cl.enqueue_nd_range_kernel(self.queue, kernel, global_size, local_size)

    def _render_tile(self, job: "_Job", x: int, y: int, w: int, h: int, capacity: int) -> float:
        """Render the w x h pixels at (x, y) into the job's host arrays; return the
        kernel time of the slowest launch (ms).  Each sample's launches are waited
        for -- the last together with the read back, so a frame of one tile and one
        sample waits only once -- so that Ctrl-C (raised by Python between calls)
        stops within one launch."""
        buf = self._buffers_for(capacity)
        frame, at = buf["frame"], self._frame_at
        count = w * h
        size, local = self._launch_shape(w, h)
        n = job.samples * job.samples
        srgb_at = 0 if job.linear else at["srgb"]   # the last sample's pixel colour writes the sRGB image too
        # (made whole: setting a structured scalar's fields one by one cost several us a frame)
        tile = np.array((x, y, w, h, at["rays"], at["hits"], at["image"], 0, job.samples, job.seed, job.max_depth,
                         1.0 / n, 1, srgb_at if n == 1 else 0), TILE)
        launches = []
        for sample in range(n):   # (a launch takes its arguments' values when they are set)
            if sample:
                tile["sample"], tile["first_sample"] = sample, 0
                tile["srgb_at"] = srgb_at if sample == n - 1 else 0
            gen = self._launch("generate_rays", size, local, frame, job.camera_args, tile)
            shade = self._launch("shade_pixels", *self._launch_shape(w, h, self.rays_per_item), frame, tile,
                                 *job.scene_args)
            launches.append((gen, shade))
            if sample < n - 1:
                wait_for(shade)
                job.progress(count)

        image = job.image[y:y + h, x:x + w]
        # Straight into the image where the tile is one run of page-locked memory
        # (full-width tiles of a pooled image); else through the staging buffer.
        direct = job.pinned and w == job.image.shape[1]
        q = self.queue
        if job.linear:
            out = np.empty((count, 4), np.float32)
            copies = [cl.enqueue_copy(q, out, frame, src_offset=at["image"], is_blocking=False)]
        else:
            out = image.reshape(count * 3) if direct else self._staging[:count]
            copies = [cl.enqueue_copy(q, out, frame, src_offset=srgb_at, is_blocking=False)]
        if job.prim is not None:
            records = np.empty(count, HIT)
            copies.append(cl.enqueue_copy(q, records, frame, src_offset=at["hits"], is_blocking=False))
        seen = np.zeros(1, np.uint32)   # did a camera ray hit anything (render.cl's TILE_SEEN)
        # The last copy blocks: NVIDIA's driver returns from a blocking read 0.06-0.15 ms sooner after the
        # copy ends than from a wait on its event (a 1080p frame's time above its stages on the H200: 0.16-0.25
        # -> 0.09-0.10 ms, docs/benchmark-log.md, session 24).  wait_for, the point where Ctrl-C stops a
        # render, then finds it done.
        copies.append(cl.enqueue_copy(q, seen, frame, src_offset=at["seen"], is_blocking=True))
        wait_for(copies[-1])
        job.seen = job.seen or bool(seen[0])
        job.progress(count)
        host_start = time.perf_counter()
        if job.linear:
            image[...] = out[:, :3].reshape(h, w, 3)
        elif not direct:
            image[...] = out.reshape(h, w, 3)
        if job.prim is not None:
            job.prim[y:y + h, x:x + w] = records["prim"].reshape(h, w)
            job.t[y:y + h, x:x + w] = records["t"].reshape(h, w)
        # Read back: the copies and any host copy after them.
        job.timings["read back"] += sum(_event_ms(e) for e in copies) + 1e3 * (time.perf_counter() - host_start)
        slowest = 0.0
        for gen, shade in launches:
            gen_ms, shade_ms = _event_ms(gen), _event_ms(shade)
            job.timings["ray generation"] += gen_ms
            job.timings["pixel colour"] += shade_ms
            slowest = max(slowest, gen_ms + shade_ms)
        return slowest

    def _launch_shape(self, w: int, h: int, row_pixels: int = 1) -> tuple:
        """Global and local size of a tile's launches: work-groups of ``limits.block``
        pixels (rays of neighbouring pixels run together), the driver's choice
        where the kernels cannot run that many work-items at once.  With
        ``row_pixels``, each work-item takes that many pixels of a row."""
        w = -(-w // row_pixels)
        bw, bh = self.limits.block or (0, 0)
        bw = max(1, bw // row_pixels)
        if not 0 < bw * bh <= self._max_group:
            return (w, h), None
        return (-(-w // bw) * bw, -(-h // bh) * bh), (bw, bh)


# Device bytes per pixel of a tile: its ray, hit record, linear and sRGB
# colours, all in the one frame buffer (FRAME_ARRAYS).
FRAME_BYTES_PER_PIXEL = sum(FRAME_ARRAYS.values())
MIN_FRAME_BYTES = 256 * FRAME_BYTES_PER_PIXEL
MAX_TILE_PIXELS = 1 << 23   # 8M pixels (a 4K frame), 536 MiB of tile buffers
IMAGE_POOL_SIZE = 3         # page-locked images per renderer (clrt/device/pinned.py)
HOST_CHECK_BYTES = 1 << 28  # frames needing more host memory than this check that it is there


@dataclass
class _Job:
    """What one render call needs in every tile."""

    camera: Camera
    samples: int
    max_depth: int
    seed: int
    linear: bool
    image: np.ndarray            # (H, W, 3), filled tile by tile
    pinned: bool                 # image is page-locked memory of the image pool
    prim: np.ndarray | None      # (H, W)
    t: np.ndarray | None         # (H, W)
    timings: dict
    camera_args: np.ndarray | None = None   # generate_rays' Camera, and shade_pixels' scene arguments:
    scene_args: tuple = ()                   # set once per frame (Renderer._frame_args)
    seen: bool = False           # a camera ray of a tile so far hit a triangle
    progress: Callable[[int], None] | None = None   # see Renderer.render


def wait_for(event: cl.Event) -> None:
    """Wait for one launch.  Python raises KeyboardInterrupt once this returns, so
    Ctrl-C stops a render between launches (tests replace this to simulate it)."""
    event.wait()


def check_host_memory(nbytes: int, what: str) -> None:
    """TooLargeError naming the size needed when ``nbytes`` exceed the available host memory."""
    checks.host_memory(nbytes, what, "render a smaller image")


def _event_ms(event: cl.Event) -> float:
    # (get_profiling_info directly: event.profile's attribute lookup costs 10x more)
    return 1e-6 * (event.get_profiling_info(_END) - event.get_profiling_info(_START))


_START, _END = cl.profiling_info.START, cl.profiling_info.END


def render(source=None, camera: Camera | None = None, *, linear: bool = False, **options) -> np.ndarray:
    """Render ``source`` and return an (H, W, 3) image: uint8 sRGB, or float32 linear
    RGB with ``linear=True`` -- the image ``clrt render`` writes for the same options.

    ``source``: a Scene, a TOML scene file, a mesh file or anything else
    :func:`~clrt.scene.sources.as_scene` takes; None: the built-in scene.
    ``camera``: a :class:`~clrt.scene.scene.Camera` to start from instead of
    the scene's own (or a framing of its bounds); the camera options below
    replace its fields.  A mesh, or a scene file without lights, is lit as
    ``clrt render`` lights it: by the default light placed for the camera
    used -- where ``Renderer(scene_from_mesh(mesh))`` (or a Scene given here)
    keeps the light placed for its own camera (a Scene keeps its own lights
    unless ``lights`` is given).

    ``options``: the options of ``clrt render``, by their Python names, from one
    table (clrt/options.py), checked by the same rules -- a bad value raises
    InputError with the command line's message under this name ("width must be
    ..." for "--width must be ..."); None or left out: the default.  Not taken,
    as they make no sense for an image in memory: ``output`` (-o; write the
    image with clrt.output.write_image), ``force`` (-f: no file is written),
    ``bit_depth`` (it returns uint8, or float32 with ``linear=True``), ``aov``
    (per-pixel images: clrt.camera_images) and ``quiet`` (-q: it prints
    nothing).  A frame that shows only the background warns
    (:class:`~clrt.errors.NothingVisibleWarning`).

{options}
    """
    if camera is not None and not isinstance(camera, Camera):
        raise checks.fail("camera", "a clrt.Camera or None", camera)
    checks.boolean("linear", linear)
    values = opts.check_api(options, "render")
    scene, camera = render_frame(source, camera, **opts.by_stage(values, opts.SCENE, opts.CAMERA, opts.LIGHTS))
    renderer = Renderer(scene, **opts.by_stage(values, opts.RENDERER))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", NothingVisibleWarning)
        image = renderer.render(camera, linear=linear).image
    for w in caught:   # shown as the caller's (Renderer.render's own points at this function)
        warnings.warn(w.message, w.category, stacklevel=2)
    return image


render.__doc__ = render.__doc__.format(options=opts.api_doc())
render.__signature__ = inspect.Signature(
    [inspect.Parameter("source", inspect.Parameter.POSITIONAL_OR_KEYWORD, default=None),
     inspect.Parameter("camera", inspect.Parameter.POSITIONAL_OR_KEYWORD, default=None, annotation="Camera | None"),
     inspect.Parameter("linear", inspect.Parameter.KEYWORD_ONLY, default=False, annotation="bool")]
    + [inspect.Parameter(o.name, inspect.Parameter.KEYWORD_ONLY, default=o.default) for o in opts.API_OPTIONS.values()],
    return_annotation="np.ndarray")

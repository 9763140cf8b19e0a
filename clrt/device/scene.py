"""A scene on one device: the set-up that Renderer and Accel share.

    >>> scene = DeviceScene(corners, accel="box", builder="auto", leaf_size=4, device=None,
    ...                     bounds=mesh.bounds, origin=None)
    >>> kernels = scene.kernels("trace.cl", QUERY_KERNELS)

In order: the acceleration structure is built (clrt.device.acceleration, on
the host or on the device), the context made, the triangles, the tree and
any shading arrays uploaded (DeviceGeometry, after checking that they fit),
and each program is built with the defines the scene calls for (its
traversal, split buffers, ray packets) and its kernels made from their
signature table (clrt.device.signature).
"""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Callable

import numpy as np
import pyopencl as cl

from clrt.config import HOST_DEFAULT_BUILDER
from clrt.device import first_build
from clrt.device.acceleration import build_acceleration
from clrt.device.context import create_context, device_kind, device_label, error_name, format_bytes, is_out_of_memory
from clrt.device.geometry import WIDE_BVH_KINDS, DeviceGeometry, check_fits, packet_rays, traversal_defines
from clrt.device.program import build_program
from clrt.device.signature import typed_kernels
from clrt.device.warmup import start_driver_thread
from clrt.errors import DeviceMemoryError
from clrt.scene.arrays import device_origin, triangle_corners
from clrt.scene.mesh import Mesh


def gathers_on_device(accel: str, builder: str, device: str | None) -> bool:
    """Does a DeviceScene of a Mesh (an Accel's, a Renderer's that the device
    shades) with these options upload its vertices and faces, to be gathered
    into corners by the device's build?  Where the device builds the tree: on
    the H200's host the gather and box (mesh_corners) took twice the device
    build's time; on PoCL (two cores) an ``Accel((V, F))`` took 2.5-8 % less
    wall time than with the host's gather (docs/benchmark-log.md, session 31)."""
    if accel == "none" or builder not in ("device", "auto"):
        return False
    return "cl_khr_fp64" in create_context(device)[1].device.extensions


def shades_on_device(accel: str, builder: str, device: str | None) -> bool:
    """Does a Renderer of one plain mesh with these options have the device
    make its crease split, vertex normals and per-slot data (clrt.device.crease)
    from the vertices and faces its build gathers?  On GPUs.  A CPU device
    splits on the host: a scene keeps the host's split for its next Renderer,
    and PoCL would compile the split's kernels in a first call."""
    return gathers_on_device(accel, builder, device) and device_kind(create_context(device)[1].device) == "gpu"


def first_builder(mesh, accel: str, builder: str, leaf_size: int, device: str | None) -> str:
    """``builder``, or the host's for an "auto" build of ``mesh`` (a Mesh, or
    None) that runs on the host while the device builder compiles
    (clrt.device.first_build) -- decided once, before anything is uploaded,
    so that the host then gathers the corners (and splits the creases)."""
    if builder == "auto" and isinstance(mesh, Mesh) and first_build.builds_on_host_first(mesh, accel, device,
                                                                                         leaf_size):
        return HOST_DEFAULT_BUILDER
    return builder


def foreseen_defines(accel: str, device: str | None, instanced: bool = False, split: bool = False) -> dict | None:
    """The defines a DeviceScene of ``accel`` on ``device`` will call for
    (DeviceScene.defines), known before its tree is built -- where they do not
    depend on the tree: not a CPU device's wide walk (its stack follows the
    tree's depth), not a two-level scene's, not a scene the caller ``split``
    into parts; else None.  (A scene too large for one buffer per array,
    split on its own, is not foreseen: a program built ahead for it is then
    not the one it asks for.)"""
    kind = device_kind(create_context(device)[1].device)
    if instanced or split or (accel == "box" and kind in WIDE_BVH_KINDS):
        return None
    return traversal_defines(accel)      # (one ray a work-item: packets go with the wide walk)


@contextlib.contextmanager
def build_ahead(entry: str, accel: str, device: str | None, extra: dict | None = None, instanced: bool = False,
                split: bool = False):
    """A block during which the program whose entry file is ``entry``, for a
    scene of ``accel`` on ``device`` (with the defines ``extra``), builds in a
    thread where its defines are foreseen (foreseen_defines); the block's end
    waits for it.  The scene's own build of it, within the block, waits for
    that one (clrt.device.program.build_program) instead of compiling it: a
    first call's compile runs beside its tree's build (a GPU's compiler, 0.5 s
    for render.cl on the H200, beside the host's first build;
    docs/benchmarks.md, "Time to the first image").  A failure there is left
    to the scene's own build to report.  (Waited for at the end, so that no
    build of clrt's is left running in the caller's code: a failed call's, or
    one of defines that turned out otherwise.)"""
    defines = foreseen_defines(accel, device, instanced, split)
    thread = None
    if defines is not None:
        context = create_context(device)[0]

        def build() -> None:
            try:
                build_program(context, entry, {**defines, **(extra or {})})
            except Exception:      # (the scene's own build of it raises it, named)
                pass

        thread = start_driver_thread(threading.Thread(target=build, name=f"clrt-build-{entry}"))
    try:
        yield
    finally:
        if thread is not None:
            thread.join()


def mesh_corners(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A mesh's corners in the device frame, their box in the caller's frame
    and the frame's origin, made on the host."""
    origin = device_origin(mesh.bounds)
    return triangle_corners(mesh, origin), mesh.bounds, origin


class stage:
    """Context manager adding the wall time of a block to ``timings[name]`` in ms
    (nothing when ``timings`` is None)."""

    def __init__(self, timings: dict | None, name: str):
        self.timings, self.name = timings, name

    def __enter__(self):
        self.start = time.perf_counter()

    def __exit__(self, *exc):
        if self.timings is not None:
            self.timings[self.name] = self.timings.get(self.name, 0.0) + 1e3 * (time.perf_counter() - self.start)


class DeviceScene:
    """Triangles, their acceleration structure and any shading arrays, uploaded
    to one device.

    ``corners``: (F, 3, 3) float32 in the device's frame (moved by
    ``-origin``; clrt.scene.arrays.device_origin), input order; ``bounds``:
    their (2, 3) box in the caller's frame.  Or a Mesh (``bounds`` and
    ``origin`` None): where the device builds its tree, its vertices and
    faces are uploaded and the device gathers the corners and chooses the
    frame (clrt.device.build); elsewhere the host does (mesh_corners).  ``accel``, ``builder``,
    ``leaf_size``, ``device``: checked options, as Renderer and Accel take
    them.  ``extra``: per-slot or per-vertex arrays the kernels index beside
    the geometry (split with it when large), by parameter name, or a function
    of the Acceleration giving them (per-slot arrays follow its ``prim_ids``);
    ``whole_bytes``: what else the caller uploads (counted when checking the
    fit); ``reserve``: device bytes to leave for per-launch buffers.
    ``timings``: where the stages' wall times go ("acceleration build",
    "copy to device"), if given.  ``acceleration``: one built already (a
    two-level scene's, clrt.device.instances: ``corners`` are then its
    meshes' corners, mesh after mesh; or a Mesh's, built from its vertices
    and faces on the device: the Renderer's _tree_first).  ``uploaded``: a Mesh's vertices and
    faces on the device already (clrt.device.crease.UploadedMesh: the
    Renderer's, which the device shades too), for the build that gathers them.

    Attributes: ``acceleration``, ``context``, ``queue``, ``device`` (its
    label), ``kind`` ("gpu" or "cpu"), ``geometry`` (DeviceGeometry),
    ``device_bytes`` (the scene's bytes on the device, ``whole_bytes``
    included) and ``rays_per_item`` (rays a work-item of the tracing kernels
    takes: a packet on CPU devices that walk them, else 1).
    """

    def __init__(self, corners: np.ndarray, *, accel: str, builder: str, leaf_size: int, device: str | None,
                 bounds, origin, extra: dict | Callable | None = None, whole_bytes: int = 0, reserve: int = 0,
                 max_buffer_bytes: int | None = None, max_buffer_label: str = "max_buffer_bytes",
                 timings: dict | None = None, acceleration=None, uploaded=None):
        with stage(timings, "acceleration build"):
            if acceleration is None and uploaded is None and max_buffer_bytes is None:   # (else decided)
                builder = first_builder(corners, accel, builder, leaf_size, device)
            gathered = (getattr(acceleration, "frame", None) is not None if acceleration is not None   # from a Mesh
                        else max_buffer_bytes is None and gathers_on_device(accel, builder, device))
            if isinstance(corners, Mesh) and not gathered:
                corners, bounds, origin = mesh_corners(corners)
            self.acceleration = (acceleration if acceleration is not None
                                 else build_acceleration(corners, accel, builder, leaf_size, device,
                                                         uploaded=uploaded if isinstance(corners, Mesh) else None))
            if callable(extra):
                extra = extra(self.acceleration)
        with stage(timings, "copy to device"):
            self.context, self.queue = create_context(device)
            self.device = device_label(self.queue.device)
            self.kind = device_kind(self.queue.device)
            # A first figure, before the wide BVH of CPU devices: DeviceGeometry
            # builds that, then gives the whole one (fits) before its first upload.
            self.device_bytes = (self.acceleration.device_bytes() + whole_bytes
                                 + sum(x.nbytes for x in (extra or {}).values()))

            def fits(geometry_bytes: int) -> None:
                self.device_bytes = geometry_bytes + whole_bytes
                check_fits(self.queue.device, self.device, self.device_bytes, reserve)

            with self.out_of_memory():
                self.geometry = DeviceGeometry(self.context, corners, self.acceleration, extra, max_buffer_bytes,
                                               fits=fits, max_buffer_label=max_buffer_label, bounds=bounds,
                                               origin=origin, queue=self.queue)
            self.rays_per_item = packet_rays(self.context, self.geometry)

    @contextlib.contextmanager
    def out_of_memory(self):
        """A block that uploads: the driver's out-of-memory error becomes a
        DeviceMemoryError that says what the scene needs (memory_error)."""
        try:
            yield
        except (cl.Error, MemoryError) as exc:
            if not is_out_of_memory(exc):
                raise
            raise self.memory_error(exc) from None

    def memory_error(self, exc, more: str = "") -> DeviceMemoryError:
        """The DeviceMemoryError for the driver's ``exc``: what the scene needs
        (and ``more``, as " and ... for ..."), and what the device has."""
        dev = self.queue.device
        return DeviceMemoryError(
            f"out of device memory on {self.device} ({error_name(exc)}): the scene needs "
            f"{format_bytes(self.device_bytes)}{more}; the device has {format_bytes(dev.global_mem_size)} "
            f"({format_bytes(dev.max_mem_alloc_size)} at most per buffer), shared with other programs")

    def defines(self, extra: dict | None = None) -> dict:
        """The program defines this scene calls for (its traversal, split
        buffers, ray packets), with ``extra``."""
        defines = dict(self.geometry.defines)
        if self.rays_per_item > 1:
            defines["RAY_PACKETS"] = self.rays_per_item
        return {**defines, **(extra or {})}

    def kernels(self, entry: str, table: dict, extra_defines: dict | None = None,
                groups: tuple | None = None) -> dict[str, cl.Kernel]:
        """The kernels of ``table`` (clrt.device.signature) in the program whose
        entry file is ``entry``, built for this scene.  ``groups``: the
        table's kernels in groups (tuples of names), each built as a
        program of its own when one of its kernels is first asked for (and
        kept on disk as such: clrt.device.program).  A compiler takes a
        program's kernels whole: of a first Accel, trace.cl's 17 took 1.0 s
        on PoCL (the ray queries' alone 0.5) and about 3 s on the H200 (1.5)
        (docs/benchmarks.md)."""
        defines = self.defines(extra_defines)
        if groups is None:
            return typed_kernels(build_program(self.context, entry, defines), table, defines)
        group_of = {name: tuple(group) for group in groups for name in group}
        return typed_kernels(lambda name: build_program(self.context, entry, defines, kernels=group_of[name]),
                             table, defines)

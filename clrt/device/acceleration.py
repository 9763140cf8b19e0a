"""The one build front end: an acceleration structure over a scene's
triangles, built on the host (clrt.accel: "sah", "paper") or on the device
(clrt.device.build: "device"), whichever the options choose.

    >>> acceleration = build_acceleration(corners, "box", "auto", 4, device=None)

Renderer and Accel (through clrt.device.scene.DeviceScene) and ``clrt info``
build through here, so every caller makes the same choice for "auto".
"""

from __future__ import annotations

import functools
import time

import numpy as np
import pyopencl as cl

from clrt.accel import Acceleration
from clrt.accel import build as build_on_host
from clrt.accel.rows import exact_rows
from clrt.config import HOST_BUILDERS, HOST_DEFAULT_BUILDER
from clrt.device import first_build
from clrt.device.build import build_on_device
from clrt.device.context import create_context, format_bytes, is_out_of_memory
from clrt.errors import DeviceMemoryError
from clrt.scene.mesh import Mesh

# Device scratch of a build, per triangle: the corners (36 bytes), sort keys and
# ids (16), build nodes (96), clusters twice (64), heights and per-place ints
# (8), path sums and ancestors (80); tests/test_device_build.py
# checks it against the workspace's buffers.
SCRATCH_BYTES_PER_TRIANGLE = 300
# The SAH partition's buffers, 0.7 MB whatever the mesh, and the hierarchy's
# segment ranks: not per triangle, so left out of the estimate above (and of its test).
FIXED_SCRATCH = ("parts", "part_bins", "segment_ranks")


def build_acceleration(corners: np.ndarray, accel: str, builder: str, leaf_size: int,
                       device: str | None = None, statistics: bool = False, uploaded=None) -> Acceleration:
    """The acceleration structure over ``corners`` (F, 3, 3): clrt.accel.build for
    the host builders, for ``builder="device"`` a build on ``device`` (clrt's
    device choice, as the renderer and queries use it), and for "auto" the
    device builder where the device has float64, else the host SAH builder
    (clrt.config.DEFAULT_BUILDER says why).

    A device build keeps its buffers on the device for the first
    DeviceGeometry on that context (clrt.accel.Acceleration.take_device_buffers);
    its host copies of the rows and ids are read back when first asked for
    (refit, statistics, per-slot data: DeviceAcceleration).  ``statistics``:
    the caller will ask for ``stats()`` (``clrt info``): a device build then
    writes the exact boxes too, read back rather than made on the host.
    ``uploaded``: a Mesh's vertices and faces on the device already
    (clrt.device.crease.UploadedMesh), for a device build.
    """
    if builder == "auto" and accel != "none":
        builder = "device" if "cl_khr_fp64" in create_context(device)[1].device.extensions else HOST_DEFAULT_BUILDER
        # A machine's first builds: on the host while the builder compiles (first_build).
        # (A Mesh's is decided before its upload: clrt.device.scene.first_builder.)
        if (builder == "device" and not statistics and not isinstance(corners, Mesh)
                and first_build.builds_on_host_first(corners, accel, device, leaf_size)):
            builder = HOST_DEFAULT_BUILDER
    if builder not in ("device", "auto") or accel == "none":
        return build_on_host(corners, accel, builder if builder in HOST_BUILDERS else HOST_DEFAULT_BUILDER,
                             leaf_size)
    start = time.perf_counter()
    context, queue = create_context(device)
    try:
        bvh = build_on_device(context, queue, corners, volume=accel, leaf_size=leaf_size, keep_boxes=statistics,
                              uploaded=uploaded)
        if first_build.applies(context):
            first_build.record(context, accel, corners)
    except (cl.Error, MemoryError) as exc:
        if not is_out_of_memory(exc):
            raise
        count = corners.num_triangles if isinstance(corners, Mesh) else len(corners)
        raise DeviceMemoryError(
            f"out of device memory building the BVH of {count:,} triangles on "
            f"{queue.device.name.strip()}: it needs about {format_bytes(SCRATCH_BYTES_PER_TRIANGLE * count)} "
            "of scratch memory; use --builder sah (built on the host)") from None
    return DeviceAcceleration(bvh, accel, build_ms=1e3 * (time.perf_counter() - start))


class DeviceAcceleration(Acceleration):
    """An Acceleration built on the device (clrt.device.build.DeviceBvh ``bvh``):
    its buffers stay there, for the first DeviceGeometry on their context to
    take over, and its host copies are read back only when first asked for --
    ``rows`` (a refit, the wide BVH of CPU devices, point queries' far
    fields), ``prim_ids`` (a Renderer's per-slot shading data) and
    ``exact_rows`` (``stats()``: made on the host from the rows and the
    slot-ordered triangles, clrt.accel.rows.exact_rows).  A build that read
    them all back at once (the rows and their exact boxes, 128 bytes a
    triangle) spent longer on that than on the build from a million
    triangles on (docs/benchmarks.md).

    Letting go of ``device_buffers`` without taking them (a two-level scene
    joins its meshes' rows on the host) reads the host copies and frees the
    device buffers.  A refit calls :meth:`settle` first, which keeps the
    slot-ordered triangles as built for the statistics.
    """

    _LAZY = ("rows", "prim_ids", "exact_rows")

    def __init__(self, bvh, accel: str, build_ms: float):
        super().__init__(accel, "device", None, None, depth=int(bvh.depth), build_ms=build_ms,
                         leaf_size=int(bvh.leaf_size), device_buffers=bvh)
        for name in self._LAZY:     # read on first use (functools.cached_property below)
            del self.__dict__[name]
        self._bvh = bvh
        self._slotted = None        # the triangles as built, slot order, once settled
        self._counts = (int(bvh.num_rows), int(bvh.num_triangles))

    @property
    def frame(self) -> np.ndarray | None:
        """Built from a Mesh: its box and device origin (DeviceBvh.frame)."""
        return self._bvh.frame

    @functools.cached_property
    def rows(self) -> np.ndarray:
        return self._source().read_rows()

    @functools.cached_property
    def prim_ids(self) -> np.ndarray:
        return self._source().read_prim_ids()

    @functools.cached_property
    def exact_rows(self) -> np.ndarray:
        bvh = self._bvh
        if self._slotted is None and bvh is not None and bvh.exact_rows is not None:   # kept by the build
            exact = bvh.read_exact_rows()
            bvh.exact_rows.release()
            bvh.exact_rows = None
            return exact
        slotted, self._slotted = self._slotted if self._slotted is not None else self._read_slotted(), None
        return exact_rows(self.rows, slotted)

    def _read_slotted(self) -> np.ndarray:
        """(F, 3, 3) float32 view of the slot-ordered triangles read back."""
        return self._source().read_triangles().view(np.float32).reshape(-1, 3, 4)[:, :, :3]

    def _source(self):
        if self._bvh is None or self._bvh.rows is None:
            raise RuntimeError("the device buffers of this BVH were released before its host copies were read")
        return self._bvh

    @property
    def num_rows(self) -> int:
        return self._counts[0]

    @property
    def num_slots(self) -> int:
        return self._counts[1]

    @property
    def device_buffers(self):
        return self.__dict__.get("_offered")

    @device_buffers.setter
    def device_buffers(self, bvh) -> None:
        if bvh is None and self.__dict__.get("_offered") is not None:   # let go, not taken
            self.keep_on_host()
        self.__dict__["_offered"] = bvh

    def take_device_buffers(self, context):
        built = self.device_buffers
        if built is None or built.rows is None or built.queue.context.int_ptr != context.int_ptr:
            return None
        self.__dict__["_offered"] = None    # handed out once: the geometry owns them now
        return built

    def keep_on_host(self) -> None:
        """Read the host copies now (the rows, the ids, and what the statistics
        need) and free the device buffers, unless a geometry took them over."""
        if self._bvh is None:
            return
        self.settle()
        self.rows, self.prim_ids   # noqa: B018 -- read now
        if self.__dict__.get("_offered") is not None:
            self._bvh.release()
            self.__dict__["_offered"] = None
        self._bvh = None

    def settle(self) -> None:
        """Keep what the statistics need on the host (before a refit moves the
        triangles on the device): the exact rows a build kept, else the
        slot-ordered triangles as built."""
        if self._slotted is not None or "exact_rows" in self.__dict__ or self._bvh is None:
            return
        if self._bvh.exact_rows is not None:
            self.exact_rows   # noqa: B018 -- read now
        else:
            self._slotted = self._read_slotted()

    def __getstate__(self):
        self.settle()        # what is on the device does not travel: its host copies do
        self.rows, self.prim_ids   # noqa: B018 -- read now
        state = super().__getstate__()
        state.pop("_offered", None)
        state["_bvh"] = None
        return state

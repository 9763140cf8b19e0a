"""The one build front end: an acceleration structure over a scene's
triangles, built on the host (clrt.accel: "sah", "paper") or on the device
(clrt.device.build: "device"), whichever the options choose.

    >>> acceleration = build_acceleration(corners, "box", "auto", 4, device=None)

Renderer and Accel (through clrt.device.scene.DeviceScene) and ``clrt info``
build through here, so every caller makes the same choice for "auto".
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from clrt.accel import Acceleration
from clrt.accel import build as build_on_host
from clrt.config import HOST_BUILDERS, HOST_DEFAULT_BUILDER
from clrt.device.build import build_on_device
from clrt.device.context import create_context, format_bytes, is_out_of_memory
from clrt.errors import DeviceMemoryError

# Device scratch of a build, per triangle: the corners (36 bytes), sort keys and
# ids (16), build nodes (96), clusters twice (64), heights and per-place ints
# (8, 12 on CPUs), path sums and ancestors (80); tests/test_device_build.py
# checks it against the workspace's buffers.
SCRATCH_BYTES_PER_TRIANGLE = 300
# The SAH partition's buffers, 0.7 MB whatever the mesh: not per triangle, so
# left out of the estimate above (and of its test).
FIXED_SCRATCH = ("parts", "part_bins")


def build_acceleration(corners: np.ndarray, accel: str, builder: str, leaf_size: int,
                       device: str | None = None) -> Acceleration:
    """The acceleration structure over ``corners`` (F, 3, 3): clrt.accel.build for
    the host builders, for ``builder="device"`` a build on ``device`` (clrt's
    device choice, as the renderer and queries use it), and for "auto" the
    device builder where the device has float64, else the host SAH builder
    (clrt.config.DEFAULT_BUILDER says why).

    A device build keeps its buffers on the device for the first
    DeviceGeometry on that context (clrt.accel.Acceleration.take_device_buffers);
    the rows and ids are also read back (refit, statistics, per-slot data).
    """
    if builder == "auto" and accel != "none":
        builder = "device" if "cl_khr_fp64" in create_context(device)[1].device.extensions else HOST_DEFAULT_BUILDER
    if builder not in ("device", "auto") or accel == "none":
        return build_on_host(corners, accel, builder if builder in HOST_BUILDERS else HOST_DEFAULT_BUILDER,
                             leaf_size)
    start = time.perf_counter()
    context, queue = create_context(device)
    try:
        bvh = build_on_device(context, queue, corners, volume=accel, leaf_size=leaf_size, keep_boxes=True)
    except (cl.Error, MemoryError) as exc:
        if not is_out_of_memory(exc):
            raise
        raise DeviceMemoryError(
            f"out of device memory building the BVH of {len(corners):,} triangles on "
            f"{queue.device.name.strip()}: it needs about {format_bytes(SCRATCH_BYTES_PER_TRIANGLE * len(corners))} "
            "of scratch memory; use --builder sah (built on the host)") from None
    rows, prim_ids = bvh.read_back()
    exact_rows = bvh.read_exact_rows()      # the statistics are computed when asked for
    bvh.exact_rows.release()
    bvh.exact_rows = None
    return Acceleration(accel, "device", rows, prim_ids, depth=int(bvh.depth),
                        build_ms=1e3 * (time.perf_counter() - start), leaf_size=int(leaf_size),
                        exact_rows=exact_rows, device_buffers=bvh)

"""Triangles and their acceleration structure, uploaded to one OpenCL device.

This is the part of a scene that ray queries need (``Geometry`` in
geometry.cl: ``closest_hit`` and ``any_hit`` in the kernels); the renderer and
the batch ray queries share it.  The acceleration structure itself is built
by ``clrt.accel``; here it is only uploaded.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from clrt.accel import Acceleration
from clrt.config import MAX_PARTS, VOLUME_DEFINES, stack_size
from clrt.device.context import format_bytes
from clrt.errors import DeviceMemoryError
from clrt.scene.arrays import triangle_verts


def accel_defines(acceleration: Acceleration) -> dict:
    """Program build options that select the traversal of ``acceleration``."""
    if not acceleration.is_bvh:
        return {}
    return {"ACCEL_BVH": None, VOLUME_DEFINES[acceleration.accel]: None,
            "BVH_STACK_SIZE": stack_size(acceleration.depth)}


def check_fits(device, label: str, nbytes: int, reserve: int = 0) -> None:
    """DeviceMemoryError, before any upload, if ``nbytes`` of scene (plus ``reserve``
    for per-launch buffers) cannot fit on ``device``.  (A buffer larger than one
    allocation is split, see DeviceGeometry.)"""
    if nbytes + reserve > device.global_mem_size:
        raise DeviceMemoryError(f"the scene needs {format_bytes(nbytes)} on the device, but {label} "
                                f"has {format_bytes(device.global_mem_size)}")


class DeviceGeometry:
    """Uploaded slot-ordered triangles, BVH rows and slot -> triangle ids, and
    any further per-slot or per-vertex ``extra`` arrays the kernels index (the
    renderer's shading data), by their kernel parameter names.

    ``corners``: (F, 3, 3) float32 in input order; ``acceleration``: its
    :class:`clrt.accel.Acceleration`.  A buffer larger than the device's largest
    allocation -- or than ``max_buffer_bytes``, which tests and benchmarks lower
    to split small scenes -- is uploaded in parts (see split.cl): then every
    buffer here is, and ``defines`` says so to the program build.
    """

    def __init__(self, context: cl.Context, corners: np.ndarray, acceleration: Acceleration,
                 extra: dict | None = None, max_buffer_bytes: int | None = None):
        self.acceleration = acceleration
        prim_ids = acceleration.prim_ids
        arrays = {"tris": triangle_verts(corners[prim_ids]), "nodes": acceleration.rows,
                  "prim_ids": prim_ids, **(extra or {})}
        arrays = {name: np.ascontiguousarray(a) for name, a in arrays.items()}
        limit = min(d.max_mem_alloc_size for d in context.devices)
        if max_buffer_bytes is not None:
            limit = min(limit, int(max_buffer_bytes))
        self.shifts = part_shifts(arrays, limit)
        self.defines = dict(accel_defines(acceleration))
        if self.shifts is not None:
            self.defines["SPLIT_BUFFERS"] = None
            self.defines.update({f"{name}_PART_SHIFT": shift for name, shift in self.shifts.items()})
        mf = cl.mem_flags

        def upload(array):
            return cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=array)

        self.buffers: dict[str, tuple] = {}
        for name, array in arrays.items():
            if self.shifts is None:
                self.buffers[name] = (upload(array),)
                continue
            step = 1 << self.shifts[name]
            parts = [upload(array[k:k + step]) for k in range(0, max(len(array), 1), step)]
            self.buffers[name] = tuple(parts + parts[-1:] * (MAX_PARTS - len(parts)))
        self.num_tris = np.uint32(len(prim_ids))
        self.nbytes = sum(a.nbytes for a in arrays.values())

    @property
    def arg_types(self) -> list:
        """The types of GEOMETRY_PARAMS (clrt.device.program.typed_kernel)."""
        parts = [None] * len(self.buffers["tris"])
        return [*parts, np.uint32, *parts, *parts]

    def extra_arg_types(self, name: str) -> list:
        """The types of an extra buffer's parameters: one buffer, or its parts."""
        return [None] * len(self.buffers[name])

    @property
    def args(self) -> tuple:
        """Kernel arguments matching GEOMETRY_PARAMS in geometry.cl."""
        b = self.buffers
        return (*b["tris"], self.num_tris, *b["nodes"], *b["prim_ids"])

    def parts(self) -> int:
        """Buffers of the largest split array (1: nothing split)."""
        return max(len(set(b)) for b in self.buffers.values())


def part_shifts(arrays: dict, limit: int) -> dict | None:
    """None when every array fits in one buffer of ``limit`` bytes, else per array
    log2 of the elements per part: the most whole elements, a power of two
    (the kernels find the part with a shift), that fit in ``limit``.
    DeviceMemoryError when an array needs more than MAX_PARTS parts."""
    if all(a.nbytes <= limit for a in arrays.values()):
        return None
    shifts = {}
    for name, a in arrays.items():
        row = max(a[:1].nbytes, 1) if len(a) else a.itemsize
        per_part = limit // row
        if per_part < 1:
            raise DeviceMemoryError(f"one element of the {name} buffer ({row} B) exceeds the "
                                    f"largest allocation of {format_bytes(limit)}")
        shift = min(int(per_part).bit_length() - 1, 30)
        if -(-len(a) // (1 << shift)) > MAX_PARTS:
            raise DeviceMemoryError(
                f"the {name} buffer needs {format_bytes(a.nbytes)}, more than {MAX_PARTS} buffers of at "
                f"most {format_bytes(limit)} (the device's largest allocation) can hold")
        shifts[name] = shift
    return shifts

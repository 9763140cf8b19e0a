"""Triangles and their acceleration structure, uploaded to one OpenCL device.

This is the part of a scene that ray queries need (``Geometry`` in
geometry.cl: ``closest_hit`` and ``any_hit`` in the kernels, GEOMETRY in
clrt/device/signature.py); the renderer and the batch ray queries share it.  The acceleration structure itself is built
by ``clrt.accel``; here it is only uploaded.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import pyopencl as cl

from clrt.accel import Acceleration
from clrt.accel.rows import tree_levels
from clrt.accel.wide import WIDE, WideBvh, collapse
from clrt.config import MAX_PARTS, VOLUME_DEFINES, stack_size
from clrt.device import pinned
from clrt.device.args import scene_value
from clrt.device.context import device_kind, format_bytes
from clrt.device.reach import MEASURE_DIAGONAL, Reach
from clrt.device.signature import buffer, typed_kernels, value
from clrt.device.wide_build import DeviceWideBvh, collapse_on_device
from clrt.errors import DeviceMemoryError, InputError
from clrt.layouts import BVH_PAIR_NODE, INSTANCE, TRIANGLE_VERTS
from clrt.scene.arrays import triangle_corners, triangle_verts
from clrt.scene.mesh import Mesh


# Device kinds (clrt.device.context.device_kind) that walk the wide BVH of
# clrt/accel/wide.py (accel_wide.cl) where it applies -- box volumes, buffers
# not split -- instead of the binary rows.  On PoCL it took a third to a half
# off every ray set's kernel time (docs/benchmark-log.md); a GPU runs a
# work-item's walk in one lane, where it would only read more bytes a node,
# and builds none of it.  Tests empty it to compare the two walks on one
# device.
WIDE_BVH_KINDS = ("cpu",)

# Device kinds whose query kernels (query_closest, query_any in trace.cl) give
# each work-item PACKET_RAYS consecutive rays where the wide BVH is walked
# (-DRAY_PACKETS=PACKET_RAYS): rays that travel together walk it as one ray
# packet (accel_packet.cl), which took about half off camera rays' kernel
# time on PoCL; the others take the single-ray walk (docs/benchmark-log.md).
# Tests empty it to compare the two on one device.
RAY_PACKET_KINDS = ("cpu",)
PACKET_RAYS = 8      # the float8 lanes of rays.cl and accel_packet.cl (rays.cl checks it)


# A binary walk's stack holds a tree of up to this depth whatever the tree
# (a deeper one's: stack_size's steps above it), so that a program's defines
# are known before its tree is built: a Renderer on a GPU compiles its
# program while the tree builds (traversal_defines; clrt.renderer.frame).  On
# the H200 a stack of 64 entries against 32 made no difference to bunny00's or
# the built-in scene's 1080p frames (docs/benchmark-log.md, session 28).  The
# wide walk of CPU devices keeps stack_size's own (WIDE - 1 entries a level).
STACK_DEPTH = 64


def traversal_defines(accel: str, depth: int = 1, wide: bool = False, instanced: bool = False) -> dict:
    """Program build options that select the traversal of an acceleration
    ``accel`` ("none": no tree) of ``depth`` levels (``wide``: its wide BVH,
    the walk of accel_wide.cl; ``instanced``: a two-level scene's)."""
    # A two-level scene (clrt.accel.instances): its walk (docs/instances.md).
    defines = {"ACCEL_INSTANCES": None} if instanced else {}
    if accel == "none":
        return defines
    if not wide:
        depth = max(depth, STACK_DEPTH)
    defines.update({"ACCEL_BVH": None, VOLUME_DEFINES[accel]: None, "BVH_STACK_SIZE": stack_size(depth)})
    if wide:
        # Each node on the path pushes at most WIDE - 1 children and takes one;
        # the wide tree is no deeper than the binary one, whose rounded depth
        # keeps trees of similar depth on one program.
        defines.update(BVH_WIDE=None, WIDE_STACK_SIZE=(WIDE - 1) * defines["BVH_STACK_SIZE"] + 1)
    return defines


def accel_defines(acceleration: Acceleration, wide: WideBvh | None = None) -> dict:
    """Program build options that select the traversal of ``acceleration``
    (with ``wide``, its wide BVH: the walk of accel_wide.cl)."""
    return traversal_defines(acceleration.accel, acceleration.depth, wide is not None,
                             acceleration.instances is not None)


def walks_wide(context: cl.Context, acceleration: Acceleration, split: bool) -> bool:
    """Do queries on ``context`` walk the wide BVH of ``acceleration``?  (Not yet
    a two-level scene's: it walks the binary rows.)"""
    return (acceleration.accel == "box" and not split and acceleration.instances is None
            and all(device_kind(d) in WIDE_BVH_KINDS for d in context.devices))


def packet_rays(context: cl.Context, geometry: "DeviceGeometry") -> int:
    """Rays a work-item of the query kernels query_closest / query_any answers
    on ``context`` for ``geometry``: PACKET_RAYS where packets are walked, else 1."""
    packets = geometry.wide is not None and all(device_kind(d) in RAY_PACKET_KINDS for d in context.devices)
    return PACKET_RAYS if packets else 1


def _stand_in(dtype, count: int, row=()) -> np.ndarray:
    """(count, *row) of ``dtype`` in no memory: the size of an array kept on the device."""
    return np.broadcast_to(np.zeros((1, *row), dtype), (count, *row))


@dataclass(frozen=True)
class DeviceArray:
    """An ``extra`` array that the device made itself (clrt.device.crease):
    its buffer, holding ``count`` rows of ``row`` elements of ``dtype``
    (TRIANGLE_INFO, ``()``; float32, ``(4,)``)."""

    buffer: cl.Buffer
    dtype: np.dtype
    count: int
    row: tuple = ()

    @property
    def nbytes(self) -> int:
        return self.count * int(np.prod(self.row, dtype=np.int64)) * np.dtype(self.dtype).itemsize

    def stand_in(self) -> np.ndarray:
        return _stand_in(self.dtype, self.count, self.row)

    def read(self, queue: cl.CommandQueue) -> np.ndarray:
        """A host copy (a scene split into parts uploads its arrays from the host)."""
        out = np.empty((self.count, *self.row), self.dtype)
        cl.enqueue_copy(queue, out, self.buffer, is_blocking=True)
        return out


def _host_arrays(corners: np.ndarray, acceleration: Acceleration) -> dict:
    """The triangles in slot order, the rows and the ids of ``acceleration``, for upload."""
    return {"tris": triangle_verts(corners[acceleration.slot_order()]),
            "nodes": np.ascontiguousarray(acceleration.rows), "prim_ids": np.ascontiguousarray(acceleration.prim_ids)}


def check_fits(device, label: str, nbytes: int, reserve: int = 0) -> None:
    """DeviceMemoryError, before any upload, if ``nbytes`` of scene (plus ``reserve``
    for per-launch buffers) cannot fit on ``device``.  (A buffer larger than one
    allocation is split, see DeviceGeometry.)"""
    if nbytes + reserve > device.global_mem_size:
        raise DeviceMemoryError(f"the scene needs {format_bytes(nbytes)} on the device, but {label} "
                                f"has {format_bytes(device.global_mem_size)}")


def replace_buffer(queue: cl.CommandQueue, old: cl.Buffer, array: np.ndarray) -> cl.Buffer:
    """A read-only buffer holding ``array`` in place of ``old``: ``old`` itself,
    overwritten, when the size is unchanged; else a new buffer, ``old`` released."""
    array = np.ascontiguousarray(array)
    if old.size == max(array.nbytes, 1):
        cl.enqueue_copy(queue, old, array)
        return old
    queue.finish()   # no launch may still read the old buffer
    new = cl.Buffer(queue.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)
    old.release()
    return new


class DeviceGeometry:
    """Uploaded slot-ordered triangles, BVH rows and slot -> triangle ids, and
    any further per-slot or per-vertex ``extra`` arrays the kernels index (the
    renderer's shading data), by their kernel parameter names.

    ``corners``: (F, 3, 3) float32 in input order; ``acceleration``: its
    :class:`clrt.accel.Acceleration`.  An ``extra`` array may be a
    :class:`DeviceArray`, made on the device already: its buffer is taken as
    it is.  A buffer larger than the device's largest
    allocation -- or than ``max_buffer_bytes``, which tests and benchmarks lower
    to split small scenes -- is uploaded in parts (see split.cl): then every
    buffer here is, and ``defines`` says so to the program build.

    ``max_buffer_label``: how errors name the source of ``max_buffer_bytes``
    (an option of the caller's, say).

    ``fits``: called with ``nbytes`` -- every buffer here, the wide BVH of CPU
    devices included (built here, so known only here) -- before the first
    upload; :func:`check_fits` raises there when the scene cannot fit.

    ``origin``: (3,) float64, where the device's frame lies in the caller's
    (clrt.scene.arrays.device_origin; None: the same frame): ``corners`` and the
    tree are in the device's frame, moved by ``-origin``; the queries and the
    renderer move their rays' origins into it (``origin`` here).

    ``queue``: a queue of ``context``, for the large arrays' staged uploads
    (clrt.device.pinned.upload); without it every buffer is made from its array.

    ``bounds``: (2, 3) min and max corner of the triangles in the caller's
    frame, when the caller has them (else computed; a two-level scene gives
    its instances' world box, its corners being in the meshes' frames); ``reach``
    (:class:`clrt.device.reach.Reach`, in the caller's frame) tells the queries
    and the renderer how far from the triangles their rays may start.
    """

    def __init__(self, context: cl.Context, corners: np.ndarray, acceleration: Acceleration,
                 extra: dict | None = None, max_buffer_bytes: int | None = None,
                 fits: Callable[[int], None] | None = None, max_buffer_label: str = "max_buffer_bytes",
                 bounds=None, origin=None, queue: cl.CommandQueue | None = None):
        self.acceleration = acceleration
        mesh = corners if isinstance(corners, Mesh) else None    # gathered by the device's build (DeviceScene)
        if mesh is not None:
            lo, hi, origin = acceleration.frame
            bounds = np.array([lo, hi])
            mesh.__dict__.setdefault("_bounds", bounds)      # the same numbers Mesh.bounds would find
            measure = float(np.linalg.norm(hi - lo)) > MEASURE_DIAGONAL
            corners = triangle_corners(mesh, origin) if measure else None     # (Reach's largest triangle)

        def host_corners() -> np.ndarray:
            """The corners in the device frame, made on the host where a device build gathered them."""
            return corners if corners is not None else triangle_corners(mesh, origin)

        self._place(corners, bounds, origin)
        # A tree built on this context's device is on it already, with its
        # triangles in slot order: taken over (once), not uploaded again, and
        # its arrays here are stand-ins of the right size (a device build's
        # host copies are not even read back: clrt.device.acceleration).
        built = acceleration.take_device_buffers(context)
        if built is not None:
            arrays = {"tris": _stand_in(TRIANGLE_VERTS, acceleration.num_slots),
                      "nodes": _stand_in(BVH_PAIR_NODE, acceleration.num_rows),
                      "prim_ids": _stand_in(np.int32, acceleration.num_slots)}
        else:
            arrays = _host_arrays(host_corners(), acceleration)
        made = {name: array for name, array in (extra or {}).items() if isinstance(array, DeviceArray)}
        for name, array in {**(extra or {}), **({} if acceleration.instances is None
                                               else {"instances": acceleration.instances})}.items():
            arrays[name] = array.stand_in() if name in made else np.ascontiguousarray(array)
        limit = min(d.max_mem_alloc_size for d in context.devices)
        source = "the device's largest allocation"
        if max_buffer_bytes is not None and int(max_buffer_bytes) < limit:
            limit, source = int(max_buffer_bytes), f"set by {max_buffer_label}"
        self.shifts = part_shifts(arrays, limit, source)
        if built is not None and self.shifts is not None:    # split into parts: uploaded from the host
            acceleration.keep_on_host()
            built.release()
            built = None
            arrays.update(_host_arrays(host_corners(), acceleration))
        if made and self.shifts is not None:
            reader = queue or cl.CommandQueue(context)
            arrays.update({name: array.read(reader) for name, array in made.items()})
            made = {}
        # The bytes the buffers hold (parts of a split array add up to it).
        self.nbytes = int(sum(a.nbytes for a in arrays.values()))
        # The wide BVH only where it is walked: other devices pay nothing.  Its
        # nodes and packets lie in one buffer (geometry.cl says why), the
        # packets from byte packets_at on (a multiple of a node's 256 B).  A
        # tree built on this device is collapsed there (clrt.device.wide_build:
        # the same nodes and packets, checked by ``fits`` before its buffer is
        # made), else on the host and uploaded.
        self.wide = None
        if walks_wide(context, acceleration, self.shifts is not None):
            if built is not None:
                def fits_wide(wide_bytes: int) -> None:
                    if fits is not None:
                        fits(self.nbytes + wide_bytes)
                self.wide = collapse_on_device(context, queue or built.queue, built.rows, acceleration.num_rows,
                                               built.tri_verts, built.kernels, fits=fits_wide)
            else:
                self.wide = collapse(acceleration.rows,
                                     host_corners()[acceleration.slot_order()].astype(np.float32, copy=False))
                arrays["wide"] = np.concatenate([self.wide.nodes.view(np.uint8).ravel(),
                                                 self.wide.packets.view(np.uint8).ravel()])
            self.nbytes += self.wide.nbytes
        self.packets_at = 0 if self.wide is None else self.wide.packets_at
        self.defines = dict(accel_defines(acceleration, self.wide))
        if fits is not None and not isinstance(self.wide, DeviceWideBvh):   # (else checked by the collapse)
            fits(self.nbytes)
        if self.shifts is not None:
            self.defines["SPLIT_BUFFERS"] = None
            self.defines.update({f"{name}_PART_SHIFT": shift for name, shift in self.shifts.items()})
        mf = cl.mem_flags

        copies = []

        def upload(array, flags=mf.READ_ONLY):
            # Large arrays through clrt.device.pinned's staging (the driver's own
            # copy of pageable memory ran at about 8 GB/s on the H200's host).
            if queue is None or array.nbytes < pinned.STAGED_MIN_BYTES:
                return cl.Buffer(context, flags | mf.COPY_HOST_PTR, hostbuf=array)
            buffer = cl.Buffer(context, flags, array.nbytes)
            copies.append(pinned.upload(context, queue, buffer, array))
            return buffer

        self.buffers: dict[str, tuple] = {}
        if built is not None:
            self.buffers.update(tris=(built.tri_verts,), nodes=(built.rows,), prim_ids=(built.prim_ids,))
            if self.wide is not None:
                self.buffers["wide"] = (self.wide.buffer,)
        self.buffers.update({name: (array.buffer,) for name, array in made.items()})
        for name, array in arrays.items():
            if name in self.buffers:
                continue
            if self.shifts is None:
                # The rows are refitted in place (refit.cl writes them).
                self.buffers[name] = (upload(array, mf.READ_WRITE if name == "nodes" else mf.READ_ONLY),)
                continue
            step = 1 << self.shifts[name]
            parts = [upload(array[k:k + step]) for k in range(0, max(len(array), 1), step)]
            self.buffers[name] = tuple(parts + parts[-1:] * (MAX_PARTS - len(parts)))
        for copy in copies:   # the host arrays may go once this returns
            copy.wait()
        self.num_tris = np.uint32(acceleration.num_slots)
        self.num_instances = 0 if acceleration.instances is None else len(acceleration.instances)
        self._refit: dict = {}   # the refit plans (None: the whole tree; k: mesh k's rows), made on first use

    def _place(self, corners: np.ndarray, bounds, origin) -> None:
        """The frame (``origin``) and ``reach`` of triangles ``corners`` (device frame)."""
        self.origin = np.zeros(3) if origin is None else np.array(origin, np.float64)
        if bounds is None:
            flat = corners.reshape(-1, 3)
            bounds = np.array([[flat[:, k].min() for k in range(3)], [flat[:, k].max() for k in range(3)]],
                              np.float64) + self.origin
        # A two-level scene's corners lie in its meshes' frames: its reach is
        # bounded from its world box alone.
        self.reach = Reach(corners if self.acceleration.instances is None else None, bounds)

    @property
    def buffer_args(self) -> tuple:
        """The buffers of GEOMETRY_PARAMS (geometry.cl), in order: each one, or its parts."""
        b = self.buffers
        return (*b["tris"], *b["nodes"], *b["prim_ids"], *(b["wide"] if self.wide is not None else ()),
                *b.get("instances", ()))

    def scene_value(self, **shading) -> np.ndarray:
        """The SceneInfo value of GEOMETRY_PARAMS: this geometry's triangle count
        and packets, with the renderer's ``shading`` fields (clrt.device.args.scene_value)."""
        return scene_value(int(self.num_tris), self.packets_at, num_instances=self.num_instances, **shading)

    def refit(self, queue: cl.CommandQueue, corners: np.ndarray, bounds=None, origin=None) -> None:
        """Move the triangles to ``corners`` (F, 3, 3) float32, input order, the same
        triangles as before, in the device's frame of ``origin`` (which may differ
        from the last one: the volumes are all fitted anew; None: the caller's
        frame) -- ``bounds``: their min and max corner in the caller's frame,
        or None -- and refit the BVH to them on the device: the tree
        and the slots stay, every volume is fitted anew to its subtree's exact
        box as a build fits it (refit.cl).  The host copy of the rows follows;
        the statistics keep describing the tree as it was built."""
        acceleration = self.acceleration
        if self.shifts is not None:
            raise InputError("refit of a scene whose buffers are split into parts is not supported: "
                             "build it anew")
        if acceleration.instances is not None:
            raise InputError("refit of a scene of instances is not supported yet: build it anew")
        if len(corners) != acceleration.num_slots:
            raise InputError(f"refit needs the same {acceleration.num_slots:,} triangles, got {len(corners):,}")
        acceleration.settle()   # the statistics describe the tree as built
        self._place(corners, bounds, origin)
        cl.enqueue_copy(queue, self.buffers["tris"][0], triangle_verts(corners[acceleration.prim_ids]))
        if not acceleration.is_bvh:
            return
        if None not in self._refit:
            self._refit[None] = _RefitPlan(queue.context, acceleration)
        self._refit[None].run(queue, self.buffers["nodes"][0], self.buffers["tris"][0])
        cl.enqueue_copy(queue, acceleration.rows, self.buffers["nodes"][0])
        if self.wide is not None:   # the same wide tree, the refitted boxes and moved corners
            self.wide.refit(acceleration.rows, corners[acceleration.prim_ids].astype(np.float32, copy=False))
            (wide,) = self.buffers["wide"]
            cl.enqueue_copy(queue, wide, self.wide.nodes)
            cl.enqueue_copy(queue, wide, self.wide.packets, dst_offset=self.packets_at)

    def refit_mesh(self, queue: cl.CommandQueue, mesh: int, corners: np.ndarray) -> None:
        """Move a two-level scene's mesh ``mesh`` (an index among its distinct
        meshes) to ``corners`` ((F, 3, 3) float32, its faces' order, in its own
        device frame -- which may differ from the last one) and refit its rows
        on the device as :meth:`refit` refits a tree: its slots uploaded anew,
        its rows' volumes fitted anew, the host copy of its rows following.
        The instances that place it and the top level over their boxes are
        the caller's to place anew (clrt.device.instances.refit_meshes)."""
        two = self.acceleration
        if self.shifts is not None:
            raise InputError("refit of a scene whose buffers are split into parts is not supported: "
                             "build it anew")
        bottom = two.bottoms[mesh]
        if len(corners) != len(bottom.prim_ids):
            raise InputError(f"refit needs the same {len(bottom.prim_ids):,} triangles, got {len(corners):,}")
        placing = two.instances[int(np.flatnonzero(two.instances["mesh"] == mesh)[0])]
        first, root = int(placing["first"]), int(placing["root"])
        cl.enqueue_copy(queue, self.buffers["tris"][0], triangle_verts(corners[bottom.prim_ids]),
                        dst_offset=first * TRIANGLE_VERTS.itemsize)
        if not two.is_bvh:
            return
        if mesh not in self._refit:
            self._refit[mesh] = _RefitPlan(queue.context, two, root, len(bottom.rows))
        self._refit[mesh].run(queue, self.buffers["nodes"][0], self.buffers["tris"][0])
        rows = two.rows[root:root + len(bottom.rows)]
        cl.enqueue_copy(queue, rows, self.buffers["nodes"][0], src_offset=root * rows.itemsize)
        for name in bottom.rows.dtype.names:   # its own copy: the volumes, its references its own
            bottom.rows[name][:, :3] = rows[name][:, :3]

    def move_instances(self, queue: cl.CommandQueue, rows: int, bounds, origin) -> bool:
        """Upload a two-level scene's moved instances (clrt.accel.instances.move
        changed the acceleration's instance table and its first ``rows``
        rows), in the frame of ``origin``, their world box ``bounds``.
        Returns whether the program defines changed (the top level's depth
        can change the stack's size): then the caller's kernels must be made
        anew."""
        acceleration = self.acceleration
        self._place(None, bounds, origin)
        self._write(queue, "nodes", acceleration.rows[:rows])
        self._write(queue, "instances", acceleration.instances)
        defines = accel_defines(acceleration, self.wide)
        changed = any(self.defines.get(k, "none") != v for k, v in defines.items())
        self.defines.update(defines)
        return changed

    def place_instances(self, queue: cl.CommandQueue, top, after: cl.Event, bounds, origin) -> tuple[bool, cl.Event]:
        """Take a two-level scene's instances as the device placed them anew
        (clrt.device.top_level.DeviceTopLevel ``top``: its table and top-level
        rows, written when ``after`` is done), copied on the device over the
        old ones on ``queue`` -- after every launch queued there before -- in
        the frame of ``origin``, their world box ``bounds``.  Returns whether
        the program defines changed, as move_instances does, and the last
        copy's event."""
        self._place(None, bounds, origin)
        self._copy(queue, "nodes", top.rows, top.num_rows, BVH_PAIR_NODE.itemsize, after)
        copied = self._copy(queue, "instances", top.table, top.count, INSTANCE.itemsize, after)
        defines = accel_defines(self.acceleration, self.wide)
        changed = any(self.defines.get(k, "none") != v for k, v in defines.items())
        self.defines.update(defines)
        return changed, copied

    def _copy(self, queue: cl.CommandQueue, name: str, source: cl.Buffer, count: int, itemsize: int,
              after: cl.Event) -> cl.Event:
        """Copy the first ``count`` elements of device buffer ``source`` over
        those of buffer ``name`` (its parts, where split), after ``after``."""
        buffers = self.buffers[name]
        step = count if self.shifts is None else 1 << self.shifts[name]
        for k in range(0, count, step):
            event = cl.enqueue_copy(queue, buffers[k // step], source, byte_count=min(step, count - k) * itemsize,
                                    src_offset=k * itemsize, wait_for=[after])
        return event

    def _write(self, queue: cl.CommandQueue, name: str, array: np.ndarray) -> None:
        """Overwrite the first ``len(array)`` elements of buffer ``name`` (its
        parts, where split) with ``array``."""
        array = np.ascontiguousarray(array)
        buffers = self.buffers[name]
        if self.shifts is None:
            cl.enqueue_copy(queue, buffers[0], array)
            return
        step = 1 << self.shifts[name]
        for k in range(0, len(array), step):
            cl.enqueue_copy(queue, buffers[k // step], array[k:k + step])

    def replace(self, queue: cl.CommandQueue, name: str, array: np.ndarray) -> None:
        """Upload ``array`` as the extra buffer ``name`` anew (a scene not split into
        parts): in place when its size is unchanged, else in a new buffer."""
        (old,) = self.buffers[name]
        self.buffers[name] = (replace_buffer(queue, old, array),)

    def parts(self) -> int:
        """Buffers of the largest split array (1: nothing split)."""
        return max(len(set(b)) for b in self.buffers.values())


def part_shifts(arrays: dict, limit: int, limit_source: str = "the device's largest allocation") -> dict | None:
    """None when every array fits in one buffer of ``limit`` bytes, else per array
    log2 of the elements per part: the most whole elements, a power of two
    (the kernels find the part with a shift), that fit in ``limit``.
    DeviceMemoryError when an array needs more than MAX_PARTS parts;
    ``limit_source`` says in it where ``limit`` came from."""
    if all(a.nbytes <= limit for a in arrays.values()):
        return None
    shifts = {}
    for name, a in arrays.items():
        row = max(a[:1].nbytes, 1) if len(a) else a.itemsize
        per_part = limit // row
        if per_part < 1:
            raise DeviceMemoryError(f"one element of the {name} buffer ({row} B) exceeds the "
                                    f"largest buffer of {format_bytes(limit)} ({limit_source})")
        shift = min(int(per_part).bit_length() - 1, 30)
        if -(-len(a) // (1 << shift)) > MAX_PARTS:
            held = MAX_PARTS << shift
            raise DeviceMemoryError(
                f"the {name} buffer needs {format_bytes(a.nbytes)} ({len(a):,} elements of {row} B), more "
                f"than {MAX_PARTS} parts can hold: each part holds a power-of-two number of elements (the "
                f"kernels find the part with a shift), at most {1 << shift:,} ({format_bytes(row << shift)}) "
                f"in a buffer of at most {format_bytes(limit)} ({limit_source}), so {MAX_PARTS} parts hold "
                f"{held:,} elements ({format_bytes(row * held)})")
        shifts[name] = shift
    return shifts


# The refit program (refit.cl): its kernels' parameters (clrt.device.signature).
REFIT_KERNELS = {
    "refit_leaves": (buffer("rows"), value("first_row", np.uint32), value("num_rows", np.uint32), buffer("tris"),
                     buffer("box_lo"), buffer("box_hi")),
    "refit_level": (buffer("rows"), buffer("level_rows"), value("count", np.uint32), buffer("box_lo"),
                    buffer("box_hi")),
    "refit_fit": (buffer("rows"), value("first_row", np.uint32), value("num_rows", np.uint32), buffer("box_lo"),
                  buffer("box_hi")),
}


class _RefitPlan:
    """What a refit of one tree needs, made once: the program, the rows of every
    tree level (the order of refit_level's launches), the boxes' scratch.  The
    tree: ``num_rows`` rows from ``root`` among the acceleration's rows (a
    two-level scene's mesh), all of them by default."""

    def __init__(self, context: cl.Context, acceleration: Acceleration, root: int = 0, num_rows: int | None = None):
        from clrt.device.build import build_defines   # the fit's constants, as the device builder's
        from clrt.device.program import build_program
        defines = build_defines(acceleration.accel)
        self.kernels = typed_kernels(build_program(context, "refit.cl", defines), REFIT_KERNELS, defines)
        self.levels = [cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=level)
                       for level in tree_levels(acceleration.rows, root)]
        self.level_sizes = [b.size // 4 for b in self.levels]
        self.first_row = root
        self.num_rows = len(acceleration.rows) if num_rows is None else num_rows
        mf = cl.mem_flags   # (indexed by the global row: a box for each of the acceleration's rows)
        self.box_lo = cl.Buffer(context, mf.READ_WRITE, 2 * 16 * len(acceleration.rows))
        self.box_hi = cl.Buffer(context, mf.READ_WRITE, 2 * 16 * len(acceleration.rows))

    def run(self, queue: cl.CommandQueue, rows: cl.Buffer, tris: cl.Buffer) -> None:
        """Refit ``rows`` (the uploaded BVH, in place) to ``tris`` (the uploaded,
        moved triangles)."""
        k, first, n = self.kernels, self.first_row, self.num_rows
        k["refit_leaves"].set_args(rows, first, n, tris, self.box_lo, self.box_hi)
        cl.enqueue_nd_range_kernel(queue, k["refit_leaves"], (n,), None)
        for level, size in zip(reversed(self.levels), reversed(self.level_sizes)):
            k["refit_level"].set_args(rows, level, size, self.box_lo, self.box_hi)
            cl.enqueue_nd_range_kernel(queue, k["refit_level"], (size,), None)
        k["refit_fit"].set_args(rows, first, n, self.box_lo, self.box_hi)
        cl.enqueue_nd_range_kernel(queue, k["refit_fit"], (n,), None)

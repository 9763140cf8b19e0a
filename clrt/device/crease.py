"""The crease split and the smooth vertex normals, made by the device from a
mesh's uploaded vertices and faces (kernels/crease.cl): where a GPU builds a
Renderer's tree from the mesh (clrt.device.scene.shades_on_device), the host
neither splits, nor sums normals, nor gathers per-slot data (issue 38: on the
H200's host those took 172 ms of a 1M-triangle Renderer, against 8 ms of
device build; the split alone 815 / 12,134 ms at 1M / 10M triangles, the
device's 1.3 / 9.9 ms, python -m benchmarks.host_stages, 2026-12-03).

    >>> uploaded = upload_mesh(context, queue, mesh)      # vertices and faces, once
    >>> acceleration = build_acceleration(mesh, "box", "device", 4, uploaded=uploaded)
    >>> shading = shade_on_device(context, queue, uploaded, crease=45.0,
    ...                           prim_ids=acceleration.device_buffers.prim_ids)
    >>> shading.extra()     # tri_info and vertex_normals, DeviceArrays for DeviceGeometry

The answers are Mesh.split_at_creases' and Mesh.vertex_normals' bit for bit
(tests/test_device_crease.py): the same groups of corners -- merged positions
by a hash table keeping each position's smallest vertex (only the classes
matter), an edge's half-edges paired by index (the host's stable sort), the
union-find's groups labelled by their smallest corners whatever the order of
the joins -- numbered in corner order, and the same float64 sums in the same
order.  The launches, in order:

1. ``area_normals``; with a crease angle ``weld_insert``, ``weld_read``,
   ``edge_ends``, ``edge_insert``, ``edge_joins``, then rounds of ``hook_joins`` and
   ``compress_labels`` until a round joins nothing (the host reads a flag
   after every ROUNDS_PER_READ: a mesh takes a few), and the roots numbered
   (a prefix sum, its total read) into the split faces (``split_vertices``);
2. ``count_corners``, a prefix sum, ``place_corners``: each vertex's corners
   in one list; ``vertex_normals`` puts each list in the host's order and
   sums it;
3. with the BVH's ``prim_ids``, ``triangle_info``: the TriangleInfo of every slot.

Scratch buffers live in the context's Workspace (clrt.device.build_kernels),
and calls take turns with the builds on its lock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from clrt.device import pinned
from clrt.device.build import BUILD_GROUP
from clrt.device.build_kernels import build_queue, one_build_per_context, workspace
from clrt.device.context import format_bytes, is_out_of_memory
from clrt.device.geometry import DeviceArray
from clrt.device.program import build_program
from clrt.device.signature import buffer as B
from clrt.device.signature import value
from clrt.errors import DeviceError, DeviceMemoryError
from clrt.layouts import TRIANGLE_INFO
from clrt.scene.mesh import Mesh, crease_cos_limit


def U(name: str):
    return value(name, np.uint32)


# Every kernel's parameters, as crease.cl declares them (tests/test_kernel_args.py checks them).
CREASE_KERNELS = {
    "weld_insert": (B("vertex_bits"), U("num_vertices"), B("table"), U("mask"), B("slot_of")),
    "weld_read": (B("table"), B("slot_of"), U("num_vertices"), B("weld")),
    "area_normals": (B("vertices"), B("faces"), U("num_faces"), B("area")),
    "edge_ends": (B("faces"), B("weld"), U("num_corners"), B("ends")),
    "edge_insert": (B("ends"), U("num_corners"), B("table"), U("mask"), B("slot_of"), B("next")),
    "edge_joins": (B("ends"), B("area"), U("num_corners"), B("table"), B("slot_of"), B("next"),
                   value("cos_limit", np.float64), B("joins"), B("label")),
    "hook_joins": (B("joins"), U("num_joins"), B("label"), B("changed")),
    "compress_labels": (B("label"), U("num_corners"), B("is_root")),
    "scan_tiles": (B("data"), U("n"), B("tile_sums")),
    "scan_tile_sums": (B("tile_sums"), U("tiles")),
    "scan_apply": (B("data"), U("n"), B("tile_sums")),
    "split_vertices": (B("label"), B("index"), B("faces"), U("num_corners"), B("corner_vertex"), B("source")),
    "count_corners": (B("corner_vertex"), U("num_corners"), B("counts")),
    "place_corners": (B("corner_vertex"), U("num_corners"), B("ends"), B("corner_list")),
    "vertex_normals": (B("corner_list"), B("ends"), U("num_vertices"), U("num_faces"), B("area"), B("normals")),
    "triangle_info": (B("corner_vertex"), B("prim_ids"), U("num_faces"), B("face_material"),
                      value("per_face", np.int32), value("material_base", np.int32), B("tri_info")),
}

# Union-find rounds queued before the host reads whether the last joined
# anything (a wait for the device each time): the meshes of the tests and
# benchmarks take 2-3 rounds, the last joining nothing.
ROUNDS_PER_READ = 2
SCAN_ITEMS = 8                       # entries a work-item of a prefix sum takes (build_scan.cl's SCAN_ITEMS)
SCAN_TILE = BUILD_GROUP * SCAN_ITEMS
# Device scratch per triangle of a split, at most about (a closed mesh: V =
# F / 2): the area normals (24 B), the weld's table, slots and ids (12), the
# edges' ends, table, slots and lists (24 + 48 + 12 + 12: the table has 2-4
# slots per half-edge), the joins (48), labels, roots and the split faces
# (36), the corner lists and their ends (16).  The Workspace keeps them
# for the next call, as it keeps a build's.
SCRATCH_BYTES_PER_TRIANGLE = 240


def crease_defines() -> dict:
    return {"BUILD_GROUP": BUILD_GROUP}


def crease_kernels(split: bool, per_slot: bool) -> tuple[str, ...]:
    """The kernels a call launches -- with a crease angle (``split``), with
    the BVH's slots (``per_slot``) -- which its program keeps
    (clrt.device.program.keep_kernels: a kernel costs its first build)."""
    scan = ("scan_tiles", "scan_tile_sums", "scan_apply")
    splitting = ("weld_insert", "weld_read", "edge_ends", "edge_insert", "edge_joins", "hook_joins",
                 "compress_labels", "split_vertices") if split else ()
    return ("area_normals", *splitting, *scan, "count_corners", "place_corners", "vertex_normals",
            *(("triangle_info",) if per_slot else ()))


@dataclass
class UploadedMesh:
    """A mesh's vertices ((V, 3) float32) and faces ((F, 3) int32) in device
    buffers, the copies complete (any queue of the context may read them)."""

    vertices: cl.Buffer
    faces: cl.Buffer
    num_vertices: int
    num_faces: int

    def release(self) -> None:
        self.vertices.release()
        self.faces.release()


def upload_mesh(context: cl.Context, queue: cl.CommandQueue, mesh: Mesh) -> UploadedMesh:
    """``mesh``'s vertices and faces copied to the device (clrt.device.pinned's
    staged copies for large ones), complete when this returns."""
    if 3 * len(mesh.faces) >= 2**31:
        raise DeviceError(f"the device's crease split numbers corners in int32: {len(mesh.faces):,} "
                          "triangles are too many")
    mf = cl.mem_flags
    vertices = cl.Buffer(context, mf.READ_ONLY, max(mesh.vertices.nbytes, 4))
    faces = cl.Buffer(context, mf.READ_ONLY, mesh.faces.nbytes)
    for copy in pinned.upload_together(context, queue, [(vertices, mesh.vertices), (faces, mesh.faces)]):
        copy.wait()
    return UploadedMesh(vertices, faces, len(mesh.vertices), len(mesh.faces))


@dataclass
class DeviceShading:
    """What :func:`shade_on_device` made: ``vertex_normals`` ((V', 4) float32,
    w 0: the Renderer's layout) of the ``num_vertices`` vertices of the split
    (or of the mesh's own, without a crease angle); ``tri_info``, with the
    BVH's slots, (F,) TRIANGLE_INFO in slot order; ``rounds``: the union-find's.
    With ``read_split``, host copies of the split: ``faces`` (F, 3) int32
    and ``sources`` (V',) int32, the input vertex at each new vertex (its
    position: the split's vertices are ``mesh.vertices[sources]``)."""

    vertex_normals: cl.Buffer
    num_vertices: int
    num_faces: int
    tri_info: cl.Buffer | None = None
    rounds: int = 0
    faces: np.ndarray | None = None
    sources: np.ndarray | None = None

    def extra(self) -> dict:
        """The Renderer's shading arrays (DeviceGeometry's ``extra``), as DeviceArrays."""
        return {"tri_info": DeviceArray(self.tri_info, TRIANGLE_INFO, self.num_faces),
                "vertex_normals": DeviceArray(self.vertex_normals, np.dtype(np.float32), self.num_vertices, (4,))}

    def read_normals(self, queue: cl.CommandQueue) -> np.ndarray:
        return DeviceArray(self.vertex_normals, np.dtype(np.float32), self.num_vertices, (4,)).read(queue)

    def read_tri_info(self, queue: cl.CommandQueue) -> np.ndarray:
        return DeviceArray(self.tri_info, TRIANGLE_INFO, self.num_faces).read(queue)


def _table_size(entries: int) -> int:
    """Slots of a hash table for ``entries`` keys: the least power of two at
    least twice as many (linear probing stays short at half load)."""
    return 1 << max((2 * entries - 1).bit_length(), 2)


def _groups(n: int) -> int:
    return max(-(-int(n) // BUILD_GROUP), 1)


@one_build_per_context
def shade_on_device(context: cl.Context, queue: cl.CommandQueue, mesh: UploadedMesh, crease: float | None,
                    prim_ids: cl.Buffer | None = None, face_material: np.ndarray | None = None,
                    material_base: int = 0, read_split: bool = False) -> DeviceShading:
    """The vertex normals of ``mesh`` split at creases of ``crease`` degrees
    (Mesh.split_at_creases, then Mesh.vertex_normals; None: of the mesh's own
    vertices), and with ``prim_ids`` (the BVH's slot -> triangle, a device
    buffer) the TriangleInfo of every slot: the split's vertex numbers and
    the material row -- ``material_base``, or ``material_base + 1 +
    face_material`` where the mesh has ``face_material`` ((F,) int32).
    Complete when this returns.  Raises DeviceMemoryError when the scratch
    buffers do not fit, DeviceError without float64."""
    device = queue.device
    if "cl_khr_fp64" not in device.extensions:
        raise DeviceError(f"the device's crease split sums normals in float64, which {device.name.strip()} lacks")
    try:
        return _shade(context, device, mesh, crease, prim_ids, face_material, material_base, read_split)
    except (cl.Error, MemoryError) as exc:
        if not is_out_of_memory(exc):
            raise
        raise DeviceMemoryError(
            f"out of device memory splitting {mesh.num_faces:,} triangles at creases on {device.name.strip()}: "
            f"it needs about {format_bytes(SCRATCH_BYTES_PER_TRIANGLE * mesh.num_faces)} of scratch memory") from None


def _shade(context, device, mesh, crease, prim_ids, face_material, material_base, read_split) -> DeviceShading:
    split = crease is not None
    defines = crease_defines()
    program = build_program(context, "crease.cl", defines, kernels=crease_kernels(split, prim_ids is not None))
    ws = workspace(context)
    k = ws.kernels_of(program, defines, CREASE_KERNELS)
    queue = build_queue(context, device)

    def launch(name: str, groups: int, *args) -> cl.Event:
        k[name].set_args(*args)
        return cl.enqueue_nd_range_kernel(queue, k[name], (groups * BUILD_GROUP,), (BUILD_GROUP,))

    def fill(buffer: cl.Buffer, word: int, nbytes: int) -> None:
        cl.enqueue_fill_buffer(queue, buffer, np.int32(word), 0, nbytes)

    def prefix_sum(data: cl.Buffer, n: int, total: bool = True) -> int | None:
        """data[0, n) exclusively summed in place; with ``total``, returns the
        sum (read, a wait for the device: the host sizes buffers by it)."""
        tiles = _groups(-(-n // SCAN_ITEMS))
        sums = ws.get("crease_tile_sums", 4 * (tiles + 1))
        launch("scan_tiles", tiles, data, np.uint32(n), sums)
        launch("scan_tile_sums", 1, sums, np.uint32(tiles))
        launch("scan_apply", tiles, data, np.uint32(n), sums)
        if not total:
            return None
        read = np.empty(1, np.uint32)
        cl.enqueue_copy(queue, read, sums, src_offset=4 * tiles, is_blocking=True)
        return int(read[0])

    F, V = mesh.num_faces, mesh.num_vertices
    corners = 3 * F
    area = ws.get("crease_area", 24 * F)
    launch("area_normals", _groups(F), mesh.vertices, mesh.faces, np.uint32(F), area)
    rounds, sources = 0, None
    if split:
        # The weld: each vertex's smallest twin at its position.
        size = _table_size(V)
        table, slot_of, weld = ws.get("crease_weld_table", 4 * size), ws.get("crease_weld_slots", 4 * V), \
            ws.get("crease_weld", 4 * V)
        fill(table, -1, 4 * size)
        launch("weld_insert", _groups(V), mesh.vertices, np.uint32(V), table, np.uint32(size - 1), slot_of)
        launch("weld_read", _groups(V), table, slot_of, np.uint32(V), weld)
        # The edges: each half-edge into its edge's list, then paired with the next by index.
        size = _table_size(corners)
        ends, table = ws.get("crease_edge_ends", 8 * corners), ws.get("crease_edge_table", 4 * size)
        slot_of, after = ws.get("crease_edge_slots", 4 * corners), ws.get("crease_edge_next", 4 * corners)
        launch("edge_ends", _groups(corners), mesh.faces, weld, np.uint32(corners), ends)
        fill(table, -1, 4 * size)
        launch("edge_insert", _groups(corners), ends, np.uint32(corners), table, np.uint32(size - 1), slot_of, after)
        joins, label = ws.get("crease_joins", 16 * corners), ws.get("crease_label", 4 * corners)
        launch("edge_joins", _groups(corners), ends, area, np.uint32(corners), table, slot_of, after,
               np.float64(crease_cos_limit(crease)), joins, label)
        # Union-find: rounds until one joins nothing, ROUNDS_PER_READ queued
        # before the host reads the last one's flag.
        is_root, changed = ws.get("crease_roots", 4 * corners), ws.get("crease_changed", 4)
        flag = np.ones(1, np.int32)
        while flag[0]:
            for _ in range(ROUNDS_PER_READ):
                fill(changed, 0, 4)
                launch("hook_joins", _groups(2 * corners), joins, np.uint32(2 * corners), label, changed)
                launch("compress_labels", _groups(corners), label, np.uint32(corners), is_root)
            cl.enqueue_copy(queue, flag, changed, is_blocking=True)
            rounds += ROUNDS_PER_READ
        # The roots, numbered in corner order, are the new vertices.
        count = prefix_sum(is_root, corners)
        corner_vertex = ws.get("crease_faces", 4 * corners)
        source = ws.get("crease_sources", 4 * count)
        launch("split_vertices", _groups(corners), label, is_root, mesh.faces, np.uint32(corners), corner_vertex,
               source)
        if read_split:
            sources = np.empty(count, np.int32)
            cl.enqueue_copy(queue, sources, source, is_blocking=False)
    else:
        corner_vertex, count = mesh.faces, V
    # Each vertex's corners in one list, then its normal.
    ends, corner_list = ws.get("crease_ends", 4 * count), ws.get("crease_corner_list", 4 * corners)
    fill(ends, 0, 4 * max(count, 1))
    launch("count_corners", _groups(corners), corner_vertex, np.uint32(corners), ends)
    prefix_sum(ends, count, total=False)      # (3F: every corner is listed)
    launch("place_corners", _groups(corners), corner_vertex, np.uint32(corners), ends, corner_list)
    normals = cl.Buffer(context, cl.mem_flags.READ_WRITE, 16 * max(count, 1))
    launch("vertex_normals", _groups(count), corner_list, ends, np.uint32(count), np.uint32(F), area, normals)
    tri_info = None
    if prim_ids is not None:
        per_face = face_material is not None
        materials = (cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                               hostbuf=np.ascontiguousarray(face_material, np.int32)) if per_face
                     else ws.get("crease_no_materials", 4))
        tri_info = cl.Buffer(context, cl.mem_flags.READ_WRITE, TRIANGLE_INFO.itemsize * F)
        launch("triangle_info", _groups(F), corner_vertex, prim_ids, np.uint32(F), materials, np.int32(per_face),
               np.int32(material_base), tri_info)
    faces = None
    if read_split:
        faces = np.empty((F, 3), np.int32)
        cl.enqueue_copy(queue, faces, corner_vertex, is_blocking=False)
    queue.finish()
    return DeviceShading(normals, count, F, tri_info, rounds, faces, sources)

"""The device builder's program (entry build_bvh.cl): its kernels' signatures,
and what the builds on one context share -- scratch buffers, the queue
untimed builds run on, and the lock by which they take turns."""

from __future__ import annotations

import functools
import threading

import numpy as np
import pyopencl as cl

from clrt.device.signature import buffer as B
from clrt.device.signature import typed_kernels, value


# The most clusters the SAH top takes (build_top.cl's tables in ploc_top's
# local memory; clrt.device.build.SAH_TOP_CLUSTERS says more).
SAH_TOP_MAX = 256


def U(name: str):
    return value(name, np.uint32)


def I(name: str):   # noqa: E743 -- the table reads as the kernels' own lists
    return value(name, np.int32)


# Every build kernel's parameters, as build_*.cl declare them: setting the
# arguments of a build's 40-odd launches then costs no Python time to speak
# of (clrt.device.program.typed_kernel); tests/test_kernel_args.py checks the table.
BUILD_KERNELS = {
    "init_build_state": (B("state"), U("num_tris")),
    "gather_corners": (B("vertices"), B("faces"), U("num_tris"), B("corners"), B("box")),
    "shift_corners": (B("corners"), U("num_tris"), B("box"), value("recentre_distance", np.float64), B("frame")),
    "centroid_bounds": (B("corners"), U("num_tris"), B("state")),
    "morton_codes": (B("corners"), U("num_tris"), B("state"), B("keys"), B("ids")),
    "radix_histogram": (B("keys"), U("n"), U("shift"), B("tile_counts")),
    "scan_counts": (B("counts"), U("n")),
    "radix_scatter": (B("keys"), B("ids"), U("n"), U("shift"), B("tile_offsets"), B("keys_out"), B("ids_out")),
    "radix_digit_counts": (B("keys"), U("n"), B("state"), B("status"), U("status_words")),
    "radix_scatter_lookback": (B("keys"), B("ids"), U("n"), U("pass"), B("state"), B("status"), B("keys_out"),
        B("ids_out")),
    "init_leaves": (B("corners"), B("sorted_ids"), B("sorted_keys"), I("segmented"), U("num_tris"), B("nodes"),
        B("clusters"), B("tile_status"), B("treelet_done")),
    "ploc_merge": (B("clusters"), B("next"), B("tile_status"), B("nodes"), B("heights"), I("num_tris"), B("state"),
        I("iteration"), U("leaf_size")),
    "ploc_compact": (B("merged"), B("clusters"), B("tile_kept"), B("nodes"), B("heights"), I("num_tris"), B("state"),
        I("iteration"), U("leaf_size")),
    "ploc_tail": (B("clusters"), B("spare"), B("nearest"), B("nodes"), B("heights"), I("num_tris"), B("state"),
        I("first_iteration"), U("leaf_size")),
    "ploc_tail_serial": (B("clusters"), B("spare"), B("nearest"), B("nodes"), B("heights"), I("num_tris"),
        B("state"), I("first_iteration"), U("leaf_size")),
    "ploc_top": (B("clusters"), B("spare"), B("nodes"), B("heights"), I("num_tris"), B("state"), U("leaf_size")),
    "ploc_merge_tiles": (B("clusters"), B("merged"), B("tile_kept"), B("state"), I("iteration")),
    "hierarchy_clear": (B("bounds"), U("num_tris")),
    "segment_ranks": (B("keys"), U("num_tris"), B("ranks")),
    "ploc_hierarchy": (B("clusters"), B("keys"), B("ranks"), B("bounds"), B("spare_numbers"), B("nodes"),
        B("heights"), I("num_tris"), B("top"), U("leaf_size")),
    "hierarchy_top": (B("ranks"), I("num_tris"), B("state")),
    "partition_clear": (B("bins"), B("sample_part"), U("samples")),
    "partition_init": (B("parts"), B("state"), I("samples"), I("limit")),
    "partition_bin": (B("corners"), U("samples"), U("stride"), B("sample_part"), B("parts"), B("bins"), B("state")),
    "partition_split": (B("parts"), B("bins"), B("state"), I("limit"), I("budget")),
    "partition_assign": (B("corners"), U("samples"), U("stride"), B("sample_part"), B("parts"), B("state")),
    "partition_order": (B("parts"), B("state")),
    "partition_morton_codes": (B("corners"), U("num_tris"), B("parts"), B("keys"), B("ids")),
    "treelet_levels": (B("nodes"), B("heights"), I("num_tris"), U("min_count"), B("state")),
    "treelet_order": (B("nodes"), B("heights"), I("num_tris"), U("min_count"), B("state"), B("order")),
    "treelet_restructure": (B("nodes"), B("heights"), B("order"), B("treelet_done"), B("state"), I("num_tris"),
        U("min_count"), U("leaf_size")),
    "reinsert_clear": (B("locks"), I("num_nodes")),
    "reinsert_search": (B("nodes"), B("moves"), B("locks"), B("arrivals"), I("num_tris")),
    "reinsert_claim": (B("nodes"), B("moves"), B("locks"), I("num_tris")),
    "reinsert_check": (B("nodes"), B("moves"), B("locks"), I("num_tris")),
    "reinsert_apply": (B("nodes"), B("moves"), B("locks"), I("num_tris")),
    "reinsert_refit": (B("nodes"), B("heights"), B("arrivals"), I("num_tris"), U("leaf_size")),
    "init_root_paths": (B("nodes"), U("num_nodes"), B("ancestor"), B("path")),
    "jump_root_paths": (B("ancestor"), B("path"), U("num_nodes"), B("ancestor_out"), B("path_out")),
    "emit_tree": (B("nodes"), U("num_nodes"), I("root"), B("corners"), B("sorted_ids"), B("ancestor"), B("path"),
        B("rows"), B("exact_rows"), B("tris"), B("prim_ids"), B("state")),
    # The wide BVH of CPU devices from the rows (build_wide.cl, clrt/device/wide_build.py).
    "wide_plan": (B("rows"), I("num_rows"), B("cost"), B("choice"), B("best"), B("subtree"), B("node_rows"),
        B("stack"), B("lanes"), B("leaves"), B("state")),
    "wide_write": (B("rows"), B("tris"), B("lanes"), B("leaves"), I("num_nodes"), I("num_leaves"), B("wide"),
        value("packets_at", np.uint64), B("sources")),
    # The top level of a scene of instances (build_instances.cl, clrt/device/top_level.py).
    "place_instances": (B("transforms"), B("mesh_of"), B("meshes"), U("num_instances"), B("group_results"),
        B("state")),
    "instance_frame": (B("group_results"), U("groups"), value("recentre_distance", np.float64), B("frame"),
        B("summary")),
    "instance_rows": (B("transforms"), B("mesh_of"), B("meshes"), B("frame"), U("num_instances"), B("table"),
        B("keys"), B("ids"), B("arrivals")),
    "lbvh_nodes": (B("keys"), U("num_instances"), B("children"), B("parents")),
    "lbvh_fit": (B("children"), B("parents"), B("sorted_ids"), B("table"), U("num_instances"), B("boxes"),
        B("arrivals"), B("rows"), B("exact_rows")),
}


def check_tuning(tail_threshold=None, treelet_leaves=None, treelet_min=None, tail_group=None,
                 largest_group: int = 4096, top_clusters=None, partition=None, reinsert_iterations=None,
                 hierarchy=None) -> None:
    """InputError for a benchmark's tuning value (build_on_device's arguments of
    these names) that the kernels cannot take, rather than a failed program
    build or a wrong tree; ``largest_group``: the device's work-group limit."""
    from clrt import checks
    if tail_threshold is not None:
        checks.integer("tail_threshold", tail_threshold, 1)
    if treelet_leaves is not None and checks.integer("treelet_leaves", treelet_leaves, 0, 8) in (1, 2):
        raise checks.fail("treelet_leaves", "0 (none) or an integer in 3..8", treelet_leaves)
    if treelet_min is not None:
        checks.integer("treelet_min", treelet_min, 0)
    if tail_group is not None:
        group = checks.integer("tail_group", tail_group, 1, largest_group)
        if group & (group - 1):
            raise checks.fail("tail_group", f"a power of two in 1..{largest_group}", tail_group)
    if top_clusters is not None:
        checks.integer("top_clusters", top_clusters, 1, SAH_TOP_MAX)
    if partition is not None:
        checks.integer("partition", partition, 0, 1)
    if hierarchy is not None:
        checks.integer("hierarchy", hierarchy, 0, 1)
    if reinsert_iterations is not None:
        from clrt.device.reinsert import check_iterations
        check_iterations(reinsert_iterations)


def launched_kernels(kind: str, segmented: bool = False, treelets: bool = False, tail: bool = False,
                     indexed: bool = False, wide: bool = False, reinsertion: bool = False,
                     hierarchical: bool = False) -> tuple[str, ...]:
    """The kernels a build on a ``kind`` ("cpu" or "gpu") device launches
    (clrt.device.build: a GPU sorts by a look-back radix sort and merges by
    ploc_merge; on a CPU the host sorts and PLOC iterates in two plain
    passes; ``hierarchical``: PLOC up the linear BVH in ploc_hierarchy
    instead, with the partition), with the SAH partition's, the reinsertion's, the treelets', the
    tail's (ploc_tail, on a CPU ploc_tail_serial), from a mesh's vertices and
    faces the corners' gather, and with ``wide`` (box volumes, CPU devices)
    the wide collapse's, which the geometry launches on the built tree
    (clrt.device.wide_build).  The program keeps only these
    (clrt.device.program.keep_kernels): every kernel of a program costs its
    first build, PoCL's front end and NVIDIA's compiler alike -- build_bvh.cl
    whole 3.8-4.3 s on the H200, its 15 kernels of a bunny00 build 1.6 s
    (docs/benchmarks.md, "Time to the first image")."""
    partition = tuple(name for name in BUILD_KERNELS if name.startswith("partition_"))
    if kind == "gpu":
        sort, ploc, tail_kernel = ("radix_digit_counts", "radix_scatter_lookback"), ("ploc_merge",), "ploc_tail"
    else:
        sort, ploc, tail_kernel = (), ("ploc_merge_tiles", "ploc_compact"), "ploc_tail_serial"
    if hierarchical:
        ploc, tail = ("hierarchy_clear", "segment_ranks", "ploc_hierarchy", "hierarchy_top"), False
    return ("init_build_state", *(("gather_corners", "shift_corners") if indexed else ()), "centroid_bounds",
            *(partition if segmented else ("morton_codes",)), *sort,
            "init_leaves", *ploc, *((tail_kernel,) if tail else ()), "ploc_top",
            *(("treelet_levels", "treelet_order", "treelet_restructure") if treelets else ()),
            *((name for name in BUILD_KERNELS if name.startswith("reinsert_")) if reinsertion else ()),
            "init_root_paths", "jump_root_paths", "emit_tree",
            *(("wide_plan", "wide_write") if wide and kind == "cpu" else ()))


def top_level_kernels(kind: str) -> tuple[str, ...]:
    """The kernels the top level of a scene of instances launches on a
    ``kind`` device (clrt.device.top_level: its sort is the device's, as a
    build's on that kind would be)."""
    sort = (("radix_digit_counts", "radix_scatter_lookback") if kind == "gpu"
            else ("radix_histogram", "scan_counts", "radix_scatter"))
    return ("place_instances", "instance_frame", "instance_rows", *sort, "lbvh_nodes", "lbvh_fit")


class Workspace:
    """What the builds on one context share: scratch buffers, kept between
    builds and grown when a build needs more (allocations are not free on a
    GPU); the queues untimed builds run on (build_queue); and the lock by
    which builds take turns (one_build_per_context)."""

    def __init__(self, context: cl.Context):
        self.context = context
        self.buffers: dict[str, cl.Buffer] = {}
        self.queues: dict[int, cl.CommandQueue] = {}     # by device
        self.lock = threading.Lock()
        self.kernels: dict[int, dict] = {}               # by program

    def get(self, name: str, nbytes: int) -> cl.Buffer:
        nbytes = max(int(nbytes), 4)
        buffer = self.buffers.get(name)
        if buffer is None or buffer.size < nbytes:
            if buffer is not None:
                buffer.release()
            buffer = cl.Buffer(self.context, cl.mem_flags.READ_WRITE, nbytes)
            self.buffers[name] = buffer
        return buffer

    def kernels_of(self, program: cl.Program, defines: dict, table: dict | None = None) -> dict:
        """The kernels of ``program`` (built with ``defines``) in signature
        ``table`` (default BUILD_KERNELS), made once."""
        key = program.int_ptr
        if key not in self.kernels:
            self.kernels[key] = typed_kernels(program, BUILD_KERNELS if table is None else table, defines)
        return self.kernels[key]


workspaces: dict[int, Workspace] = {}


def workspace(context: cl.Context) -> Workspace:
    """The context's Workspace (made by the first build on it)."""
    found = workspaces.get(context.int_ptr)
    return found if found is not None else workspaces.setdefault(context.int_ptr, Workspace(context))


def build_queue(context: cl.Context, device: cl.Device) -> cl.CommandQueue:
    """The queue untimed builds run on: one per context and device, without
    profiling.  On the H200 a launch costs the host 8.5 us to queue there and
    14 us on a profiling queue, and a small build waits on its host: bunny00
    2.35 -> 2.13 ms (docs/benchmark-log.md, session 6)."""
    queues = workspace(context).queues
    queue = queues.get(device.int_ptr)
    if queue is None:
        queue = queues[device.int_ptr] = cl.CommandQueue(context, device)
    return queue


def one_build_per_context(build):
    """Builds on one context take turns: they share its scratch buffers
    (Workspace) and its build queue, so two threads building at once (each
    with an Accel of its own, say) would overwrite each other's keys and
    nodes -- on PoCL the process crashed (tests/test_device_build.py).  A
    build holds no lock the caller could be waiting on, and takes
    milliseconds."""
    @functools.wraps(build)
    def one_at_a_time(context: cl.Context, *args, **kwargs):
        with workspace(context).lock:
            return build(context, *args, **kwargs)
    return one_at_a_time

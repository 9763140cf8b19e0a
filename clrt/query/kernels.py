"""The ray-query program (entry trace.cl): every kernel's parameters, declared
once (clrt.device.signature; tests/test_kernel_args.py checks them against
the compiler's view of trace.cl).

A query kernel takes its rays (the four input arrays, the bad-ray slots and
a QueryLaunch by value: rays.cl), one ``results`` buffer that its outputs lie
in at the launch's byte offsets (QueryLaunch.field_at), and the geometry.
"""

from __future__ import annotations

import numpy as np

from clrt.device.context import device_kind
from clrt.device.signature import GEOMETRY, buffer, value
from clrt.layouts import CAMERA, QUERY_LAUNCH

# Work-items per work-group of the query kernels; None lets the driver choose.
# Measured on the H200 (benchmarks.raysets --group, docs/benchmark-log.md): 128
# takes 5-7 % off incoherent sets (random, diffuse, AO) against the driver's
# choice, and 1-2 % off camera rays; 64 is as good on incoherent rays but
# slower on camera rays.  On a CPU device (PoCL) the driver's choice, 8, 64 and
# 512 measured within the noise of each other, but PoCL compiles and keeps a
# variant of the kernel for every work-group size it runs, and its own choice
# follows the batch size (1000 rays: 1000; 4099: 1; 2^20: 4096): a program
# sending batches of many sizes grew by tens of kB a new size, to hundreds of
# MB.  A fixed size keeps one variant.  The kernels skip the work-items past
# the last ray.
QUERY_GROUP: dict = {"gpu": 128, "cpu": 64}


def point_defines(device) -> dict:
    """The trace.cl program's point-query choices for ``device`` (point.cl,
    point_order.cl and winding.cl say what each does).  On GPUs, whose
    neighbouring work-items run in lockstep, the far fields of winding numbers
    are taken for a whole cell of points at once (POINT_CELL_REGIONS); on
    NVIDIA's, whose compiler takes PTX, the 32 points of a warp walk the BVH
    for their closest points together (POINT_WARP_WALK).  CPU devices walk
    the wide BVH instead (their point groups: clrt.query.points).  Measured
    on the H200: docs/benchmarks.md."""
    if device_kind(device) == "cpu":
        return {}
    defines = {"POINT_CELL_REGIONS": None}
    if "cl_nv_compiler_options" in device.extensions.split():
        defines["POINT_WARP_WALK"] = None
    return defines


#: RAY_INPUT_PARAMS (rays.cl).
RAY_INPUT = (buffer("origins"), buffer("dirs"), buffer("tmins"), buffer("tmaxs"), buffer("bad"),
             value("launch", QUERY_LAUNCH))

#: POINT_INPUT_PARAMS (rays.cl).
POINT_INPUT = (buffer("origins"), buffer("tmaxs"), buffer("bad"), value("launch", QUERY_LAUNCH), buffer("order"))

QUERY_KERNELS = {
    "query_closest": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    "query_any": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    "query_count": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    "query_all": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    # point queries (point.cl): points in `origins`, their largest distance in `tmaxs`, visited in the
    # order that point_order.cl's three kernels leave in `order`
    "query_closest_point": (*POINT_INPUT, buffer("results"), buffer("records"), *GEOMETRY),
    "closest_point_fields": (buffer("records"), value("launch", QUERY_LAUNCH), buffer("results")),
    "point_cells": (buffer("origins"), value("launch", QUERY_LAUNCH), buffer("order")),
    "point_offsets": (buffer("order"),),
    "point_scatter": (value("launch", QUERY_LAUNCH), buffer("order")),
    "point_cell_of": (buffer("origins"), value("launch", QUERY_LAUNCH), buffer("order")),
    "point_run_counts": (value("launch", QUERY_LAUNCH), buffer("order"), buffer("counts")),
    "point_run_offsets": (buffer("counts"), value("runs", np.uint32)),
    "point_run_scatter": (value("launch", QUERY_LAUNCH), buffer("order"), buffer("counts")),
    "point_cell_seeds": (buffer("seeds"), value("launch", QUERY_LAUNCH), *GEOMETRY),
    # inside and outside (winding.cl, point.cl): points as query_closest_point takes them, and
    # each kernel's rule's buffer -- the tree's WindingNodes or the PseudoNormals
    "query_winding_number": (*POINT_INPUT, buffer("results"), buffer("winding"), *GEOMETRY),
    "query_signed_distance_winding": (*POINT_INPUT, buffer("results"), buffer("winding"), *GEOMETRY),
    "query_signed_distance_parity": (*POINT_INPUT, buffer("results"), *GEOMETRY),
    "query_signed_distance_normal": (*POINT_INPUT, buffer("results"), buffer("normals"), *GEOMETRY),
    "winding_nodes": (buffer("winding"), buffer("level_rows"), value("count", np.uint32),
                      value("top_level", np.uint32), *GEOMETRY),
    # sdf_grid's samples, a chunk at a time (point_grid.cl)
    "grid_points": (buffer("points"), buffer("axes"), value("first", np.uint64), value("count", np.uint32),
                    value("size_y", np.uint32), value("size_z", np.uint32)),
    "camera_rays": (buffer("dirs"), value("cam", CAMERA), value("first", np.uint64), value("count", np.uint32)),
    # one-launch kernels of the primary-ray benchmark (Accel.launch_camera)
    "trace_camera": (buffer("hits"), value("cam", CAMERA), *GEOMETRY),
    "occlude_camera": (buffer("occluded"), value("cam", CAMERA), *GEOMETRY),
}

#: The query program's kernels by what a call asks: each group is a program
#: of its own, built when a call first needs one of its kernels
#: (clrt.device.scene.DeviceScene.kernels).
QUERY_PROGRAMS = (
    ("query_closest",), ("query_any",), ("query_count", "query_all"), ("camera_rays", "trace_camera", "occlude_camera"),
    ("query_closest_point", "closest_point_fields", "point_cells", "point_offsets", "point_scatter", "point_cell_of",
     "point_run_counts", "point_run_offsets", "point_run_scatter", "point_cell_seeds", "grid_points",
     "query_signed_distance_parity", "query_signed_distance_normal"),
    ("query_winding_number", "query_signed_distance_winding", "winding_nodes"),
)

"""The ray-query program (entry trace.cl): every kernel's parameters, declared
once (clrt.device.signature; tests/test_kernel_args.py checks them against
the compiler's view of trace.cl).

A query kernel takes its rays (the four input arrays, the bad-ray slots and
a QueryLaunch by value: rays.cl), one ``results`` buffer that its outputs lie
in at the launch's byte offsets (QueryLaunch.field_at), and the geometry.
"""

from __future__ import annotations

import numpy as np

from clrt.device.signature import GEOMETRY, buffer, value
from clrt.layouts import CAMERA, QUERY_LAUNCH

#: RAY_INPUT_PARAMS (rays.cl).
RAY_INPUT = (buffer("origins"), buffer("dirs"), buffer("tmins"), buffer("tmaxs"), buffer("bad"),
             value("launch", QUERY_LAUNCH))

#: POINT_INPUT_PARAMS (rays.cl): the point queries that take no largest distance.
POINT_INPUT = (buffer("points"), buffer("bad"), value("launch", QUERY_LAUNCH))

QUERY_KERNELS = {
    "query_closest": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    "query_any": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    "query_count": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    "query_all": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    # point queries (point.cl): points in `origins`, their largest distance in `tmaxs`
    "query_closest_point": (*RAY_INPUT, buffer("results"), *GEOMETRY),
    # inside and outside (winding.cl, point.cl): each takes its rule's buffer
    # beside the points -- the tree's WindingNodes or the PseudoNormals
    "query_winding_number": (*POINT_INPUT, buffer("results"), buffer("winding"), *GEOMETRY),
    "query_signed_distance_winding": (*POINT_INPUT, buffer("results"), buffer("winding"), *GEOMETRY),
    "query_signed_distance_parity": (*POINT_INPUT, buffer("results"), *GEOMETRY),
    "query_signed_distance_normal": (*POINT_INPUT, buffer("results"), buffer("normals"), *GEOMETRY),
    "winding_nodes": (buffer("winding"), buffer("level_rows"), value("count", np.uint32), *GEOMETRY),
    "camera_rays": (buffer("dirs"), value("cam", CAMERA), value("first", np.uint64), value("count", np.uint32)),
    # one-launch kernels of the primary-ray benchmark (Accel.launch_camera)
    "trace_camera": (buffer("hits"), value("cam", CAMERA), *GEOMETRY),
    "occlude_camera": (buffer("occluded"), value("cam", CAMERA), *GEOMETRY),
}

"""What ray queries return: closest hits, all hits, camera images, closest
points, signed distances and winding numbers.

Each result is a named tuple of arrays whose fields are described once, in the
tables below (shape, dtype, meaning, value on a miss).  The named tuples, their
docstrings (``help(clrt.Hits)``), the docstrings of the queries that return
them (``help(clrt.Accel.trace)``) and the buffers the kernels write are all
made from these tables, so none of them can list a field the others lack;
docs/ray-queries.md repeats the closest-hit table for readers (a test compares).
"""

from __future__ import annotations

import textwrap
from typing import NamedTuple

import numpy as np

from clrt.errors import InputError


class Field(NamedTuple):
    """One array of a query result."""

    dtype: type          # of the numpy array the caller gets (bool flags are uint8 0 / 1 on the device)
    item_shape: tuple    # the shape of one ray's (hit's, pixel's) value: () or (3,)
    meaning: str
    miss: str | None     # its value on a miss (None: results hold hits only)


# The closest hit's outputs (query_closest in trace.cl), in kernel order: the
# order of the kernel's output arguments and of Hits' fields.
CLOSEST_FIELDS = {
    "t": Field(np.float32, (), "distance to the hit along the normalised direction", "inf"),
    "instance": Field(np.int32, (), "instance hit: its index in the list of meshes or instances the Accel "
                      "was made from (0 for a single mesh)", "-1"),
    "prim": Field(np.int32, (), "triangle hit: its row in the faces of the instance's mesh (for "
                  "Accel.from_renderer: its index in the scene's triangles, objects in order)", "-1"),
    "u": Field(np.float32, (), "barycentric weight of the triangle's vertex 1", "0"),
    "v": Field(np.float32, (), "barycentric weight of the triangle's vertex 2 (vertex 0 has 1 - u - v)", "0"),
    "normal": Field(np.float32, (3,), "unit geometric normal (v1 - v0) x (v2 - v0) in the world (of the "
                    "placed triangle), as wound (not flipped towards the ray)", "(0, 0, 0)"),
    "front": Field(np.bool_, (), "the ray met the triangle against its normal (saw v0, v1, v2 "
                   "counter-clockwise)", "False"),
    "hit": Field(np.bool_, (), "the ray hit something: prim >= 0", "False"),
}

# Every hit of every ray (query_all in trace.cl), sorted by ray, then t, then
# instance, then triangle.
ALL_HITS_FIELDS = {
    "ray_id": Field(np.int64, (), "index of the ray", None),
    "instance": Field(np.int32, (), "instance hit: its index in the Accel's list (0 for a single mesh)", None),
    "prim": Field(np.int32, (), "triangle hit: its row in the faces of the instance's mesh", None),
    "t": Field(np.float32, (), "distance to the hit along the ray's normalised direction", None),
}

# The nearest point of the mesh to each query point (query_closest_point in
# trace.cl), in kernel order.  The distance is float32, within
# POINT_DISTANCE_BOUND of the exact one (docs/ray-queries.md, "Point queries").
POINT_FIELDS = {
    "point": Field(np.float32, (3,), "the mesh's point nearest to the query point, in the caller's frame (each "
                   "coordinate rounded to float32 there)", "NaN"),
    "distance": Field(np.float32, (), "distance from the query point to it (a miss: none within max_distance)",
                      "inf"),
    "prim": Field(np.int32, (), "its triangle: the row in the mesh's faces (the lowest of equally near ones; "
                  "of its instance's mesh in an Accel of instances)", "-1"),
    "u": Field(np.float32, (), "barycentric weight of the triangle's vertex 1 at the point", "0"),
    "v": Field(np.float32, (), "barycentric weight of the triangle's vertex 2 (vertex 0 has 1 - u - v)", "0"),
    "instance": Field(np.int32, (), "its instance: the index in the Accel's list (0 for a single mesh; the "
                      "lowest of equally near ones, then the lowest triangle)", "-1"),
}

# The inside queries' values, one array a query (Accel.signed_distance,
# Accel.winding_number, Accel.contains; query_signed_distance_* and
# query_winding_number in trace.cl): every point has one, so no miss value.
INSIDE_FIELDS = {
    "signed_distance": Field(np.float32, (), "the point's distance to the mesh (as ClosestPoints.distance), "
                             "negative inside by the sign rule: the winding number >= 1/2, ray parity, or the "
                             "pseudo-normal at the closest point", None),
    "winding_number": Field(np.float32, (), "the generalised winding number: the triangles' signed solid angles "
                            "over 4 pi (1 inside a closed mesh wound outwards, 0 outside, 1/2 on its faces), "
                            "within WINDING_NUMBER_ERROR of the exact sum", None),
    "inside": Field(np.bool_, (), "the winding number is >= 1/2 (Accel.contains)", None),
}

#: How far winding numbers lie from the exact sum of the triangles' solid
#: angles, as measured on the tests' meshes (tests/test_inside.py) and eight
#: scans (winding.cl's WINDING_BETA says how): measured, not proven.  Without
#: a BVH (accel="none") the sum is exact, in float64 where the device has it.
WINDING_NUMBER_ERROR = 1e-4

#: How far a reported distance may lie from the exact (float64) distance
#: between the mesh and the query point rounded to float32: this times the
#: largest coordinate of the point and of the mesh's vertices, both measured
#: from the device frame's origin (clrt.scene.arrays.device_origin).  The
#: point's move into that frame rounds once (float32), the distance once more;
#: the closest point itself is computed in float64 where the device has it.
POINT_DISTANCE_BOUND = 2.0 ** -21

# The images of Accel.camera_images, row 0 at the top.
CAMERA_FIELDS = {
    "depth": Field(np.float32, (), "distance along the optical axis (z in the camera frame)", "inf"),
    "t": Field(np.float32, (), "distance along the pixel's ray from the eye", "inf"),
    "normal": Field(np.float32, (3,), "world-space unit geometric normal (v1 - v0) x (v2 - v0)", "(0, 0, 0)"),
    "instance": Field(np.int32, (), "instance seen: its index in the Accel's list (0 for a single mesh)", "-1"),
    "prim": Field(np.int32, (), "triangle seen: its row in the faces of the instance's mesh", "-1"),
    "hit": Field(np.bool_, (), "the pixel's ray hit something: prim >= 0", "False"),
    "front": Field(np.bool_, (), "the front face was seen", "False"),
    "u": Field(np.float32, (), "barycentric weight of the triangle's vertex 1", "0"),
    "v": Field(np.float32, (), "barycentric weight of the triangle's vertex 2", "0"),
}


def asked_fields(fields, table: dict, kind: str) -> list:
    """The fields of ``table`` asked for (``fields``: a name, names, or None for
    all), in the table's (the kernel's) order; InputError naming a ``kind``
    field that is not there."""
    if fields is None:
        return list(table)
    if isinstance(fields, str):
        fields = (fields,)
    unknown = [f for f in fields if f not in table]
    if unknown:
        raise InputError(f"unknown {kind} field {unknown[0]!r}: choose from {', '.join(table)}")
    return [f for f in table if f in fields]


def _device_dtype(dtype) -> type:
    return np.uint8 if dtype is np.bool_ else dtype   # OpenCL buffers have no bool


# Dtype on the device and bytes a ray of every per-ray output (count: query_count's).
RESULT_DTYPES = {**{name: _device_dtype(f.dtype) for name, f in CLOSEST_FIELDS.items()}, "count": np.int32}
RESULT_BYTES = {name: np.dtype(dtype).itemsize * int(np.prod(CLOSEST_FIELDS[name].item_shape, dtype=int))
                if name in CLOSEST_FIELDS else np.dtype(dtype).itemsize for name, dtype in RESULT_DTYPES.items()}


def _kind(f: Field, rows: tuple) -> str:
    """'(N, 3) float32': the array's shape, ``rows`` leading, and its dtype."""
    dims = (*rows, *(str(n) for n in f.item_shape))
    return f"({', '.join(dims)}{',' if len(dims) == 1 else ''}) {np.dtype(f.dtype).name}"


def _meaning(f: Field) -> str:
    return f.meaning + (f"; {f.miss} on a miss" if f.miss is not None else "")


def describe_fields(table: dict, rows: tuple = ("N",)) -> str:
    """The fields of ``table`` as a numpy-style docstring section: name, shape
    (``rows`` leading, e.g. ("N",) or ("H", "W")), dtype, then the meaning and
    the value on a miss."""
    return "\n".join(f"{name} : {_kind(f, rows)}\n"
                     + textwrap.fill(_meaning(f), 76, initial_indent="    ", subsequent_indent="    ",
                                     break_on_hyphens=False)
                     for name, f in table.items())


def with_fields(table: dict, rows: tuple = ("N",), heading: str = "Fields", lead: str = ""):
    """Decorator: append ``table``'s fields (:func:`describe_fields`) under
    ``heading`` (and a ``lead`` line) to a function's or class's docstring, so
    that ``help()`` lists them from the table itself."""
    def append(obj):
        body = describe_fields(table, rows)
        section = f"{heading}\n{'-' * len(heading)}\n" + (f"{lead}\n" if lead else "") + body
        doc = obj.__doc__ or ""
        # Indent the section as the docstring's own lines are, so that
        # inspect.cleandoc (help) strips both alike.
        indent = min((len(line) - len(line.lstrip()) for line in doc.splitlines()[1:] if line.strip()),
                     default=0)
        section = "\n".join(" " * indent + line if line else line for line in section.splitlines())
        obj.__doc__ = f"{doc.rstrip()}\n\n{section}\n"
        return obj
    return append


def _result_class(name: str, table: dict, doc: str, rows: tuple):
    """A named tuple with one field per row of ``table``, in its order, documented from it."""
    cls = NamedTuple(name, [(field, np.ndarray) for field in table])
    cls.__doc__ = doc
    for field, f in table.items():   # help(cls) shows these beside each field
        getattr(cls, field).__doc__ = f"{_kind(f, rows)}: {_meaning(f)}"
    return with_fields(table, rows)(cls)


Hits = _result_class("Hits", CLOSEST_FIELDS, """Closest hits, one row per ray.

    Returned by Accel.trace and clrt.trace; Accel.trace_camera gives (H, W)
    arrays, one per pixel, instead of (N,).  Fields left out of the query's
    ``fields=`` are None.  Rays given as ``pyopencl.array.Array`` give device
    arrays, with ``front`` and ``hit`` as uint8 0 / 1 (OpenCL has no bool).
    """, ("N",))

AllHits = _result_class("AllHits", ALL_HITS_FIELDS, """Every hit of every ray, as flat arrays.

    Returned by Accel.all_hits and clrt.all_hits: K hits in all, sorted by
    ray, then distance, then instance, then triangle; a ray without hits has
    no entry.
    """, ("K",))

ClosestPoints = _result_class("ClosestPoints", POINT_FIELDS, """The nearest points of a mesh, one row per query point.

    Returned by Accel.closest_points and clrt.closest_points.  Fields left out
    of the query's ``fields=`` are None.  Points given as
    ``pyopencl.array.Array`` give device arrays.
    """, ("N",))

CameraImages = _result_class("CameraImages", CAMERA_FIELDS, """Per-pixel results of a camera's rays.

    Returned by Accel.camera_images and clrt.camera_images: (H, W) images,
    row 0 at the top.
    """, ("H", "W"))

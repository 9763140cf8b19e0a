"""Point queries on an Accel: the nearest point of the mesh to each query
point, and its distance (query_closest_point in trace.cl, point.cl).

Points go through the ray queries' input path (``PointBatch`` fills a ray
batch's origins and tmax), chunks and checks, so a point gives the same
answer alone or in a batch, in any chunk.  :class:`PointQueries` is a part
of :class:`~clrt.query.accel.Accel`: its methods use the Accel's chunks,
buffers and launches.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from clrt.config import POINT_CELLS, POINT_OFFSETS_GROUP
from clrt.device.program import launch_size
from clrt.device.sharing import one_at_a_time
from clrt.query.kernels import QUERY_GROUP
from clrt.query.rays import PointBatch
from clrt.query.results import POINT_FIELDS, ClosestPoints, asked_fields, with_fields


class PointQueries:
    """Accel's point queries (mixed into :class:`~clrt.query.accel.Accel`)."""

    def _point_outputs(self, n: int, fields, on_device: bool) -> dict:
        shapes = {name: (n, *POINT_FIELDS[name].item_shape) for name in fields}
        if on_device:
            import pyopencl.array as cla
            return {name: cla.empty(self.queue, shapes[name], POINT_FIELDS[name].dtype)   # no bool among them
                    for name in fields}
        return {name: np.empty(shapes[name], POINT_FIELDS[name].dtype) for name in fields}

    def _launch(self, name: str, args: tuple, items: int, group: int | None = None) -> None:
        """Kernel ``name`` (QUERY_KERNELS) with ``args`` over ``items`` work-items,
        its event kept for kernel_ms."""
        kernel = self.kernels[name]
        kernel.set_args(*args)
        self.launches.append(cl.enqueue_nd_range_kernel(
            self.queue, kernel, *launch_size(items, group or QUERY_GROUP[self._kind])))

    def _point_order(self, origins: cl.Buffer, launch: np.ndarray) -> cl.Buffer:
        """The `order` buffer of a launch of point queries (point_order.cl): its
        points sorted by cell of a grid over the scene, by three launches."""
        m = int(launch["num_rays"])
        order = self._buffer("order", 4 * (POINT_CELLS + 2 * m))
        cl.enqueue_fill_buffer(self.queue, order, np.uint32(0), 0, 4 * POINT_CELLS)
        self._launch("point_cells", (origins, launch, order), m)
        self._launch("point_offsets", (order,), POINT_OFFSETS_GROUP, POINT_OFFSETS_GROUP)
        self._launch("point_scatter", (launch, order), m)
        return order

    @one_at_a_time
    def _closest_points(self, batch: PointBatch, fields) -> ClosestPoints:
        fields = asked_fields(fields, POINT_FIELDS, "point")
        n = len(batch)
        out = self._point_outputs(n, fields, batch.on_device)
        slots = list(POINT_FIELDS)
        self._begin(batch)
        for start, stop in self._chunks(n):
            m = stop - start
            rays, launch = self._ray_args(batch, start, stop, 0)
            origins, _, _, tmaxs, bad = rays
            order = self._point_order(origins, launch)
            placed, nbytes = {}, 0
            for name in fields:   # every field is 4-byte aligned: float32 and int32 values
                placed[name] = nbytes
                launch["field_at"][slots.index(name)] = nbytes
                nbytes += m * 4 * int(np.prod(POINT_FIELDS[name].item_shape, dtype=int))
            results = self._buffer("results", nbytes)
            self._launch("query_closest_point", (origins, tmaxs, bad, launch, order, results,
                                                 *self.geometry.buffer_args, self._scene_value), m)
            for name, at in placed.items():
                self._copy_out(out[name], start, stop, results, at)
        self._check(batch)   # also waits for the copies
        return ClosestPoints(*(out.get(name) for name in ClosestPoints._fields))

    @with_fields(POINT_FIELDS, heading="Returns", lead="ClosestPoints, a named tuple of these arrays:")
    def closest_points(self, points, *, max_distance=np.inf, fields=None) -> ClosestPoints:
        """The mesh's nearest point to each query point, within ``max_distance``.

        ``points``: (3,) or (N, 3), any real dtype (or a float32
        ``pyopencl.array.Array``: the results are device arrays then);
        ``max_distance``: a number > 0 -- a point with no triangle within it
        (inclusive) is a miss.  ``fields``: the names of the fields below to
        compute and return (default: all); the others are None.  Ties of equal
        distance go to the lowest triangle index.  Distances are float32,
        within ``clrt.query.results.POINT_DISTANCE_BOUND`` times the largest
        coordinate (device frame) of the exact ones (docs/ray-queries.md).
        """
        return self._closest_points(PointBatch(points, max_distance), fields)

    def distance(self, points, *, max_distance=np.inf):
        """(N,) float32: each point's distance to the mesh (inf beyond
        ``max_distance``); see :meth:`closest_points`."""
        return self._closest_points(PointBatch(points, max_distance), ("distance",)).distance

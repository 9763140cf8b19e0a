"""Point queries on an Accel: the nearest point of the mesh to each query
point and its distance (query_closest_point in trace.cl, point.cl); signed
distances, winding numbers, inside tests and SDF grids (the kernels after
it in trace.cl; winding.cl; what they need beyond the scene: ``inside.py``).

Points go through the ray queries' input path (``PointBatch`` fills a ray
batch's origins and tmax), chunks and checks, so a point gives the same
answer alone or in a batch, in any chunk.  :class:`PointQueries` is a part
of :class:`~clrt.query.accel.Accel`: its methods use the Accel's chunks,
buffers and launches.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from clrt.accel.disks import packet_corners, wide_disks
from clrt.config import (NO_RESULT, POINT_CANDIDATES, POINT_CELLS, POINT_GROUPS, POINT_LANES, POINT_OFFSETS_GROUP,
                         POINT_RUN_CELLS, POINT_RUN_POINTS, POINT_RUNS_MAX, POINT_RUNS_PER_UNIT,
                         RAY_CHECKS)
from clrt.device.program import launch_size
from clrt.device.sharing import one_at_a_time
from clrt.query.inside import SIGN_KERNELS, GridPoints, grid_axes, pseudo_normals, sign_kernel, winding_nodes
from clrt.query.kernels import QUERY_GROUP
from clrt.query.rays import PointBatch
from clrt.query.results import INSIDE_FIELDS, POINT_FIELDS, ClosestPoints, asked_fields, with_fields


#: The kernels that answer closest points (trace.cl's CLOSEST_ITEM_POINTS a work-item).
CLOSEST_KERNELS = ("query_closest_point", *SIGN_KERNELS.values())


#: The kernels whose walks start from their cells' seeds (trace.cl's signed_distances says why not the winding rule's).
SEEDED_KERNELS = ("query_closest_point", SIGN_KERNELS["normal"], SIGN_KERNELS["parity"])


#: Points a batch takes the seeds for at least: one a cell of the grid (the seeds' launch walks a point a cell).
SEEDED_MIN_POINTS = POINT_CELLS


#: trace.cl's ClosestPointRecord: a point's answer, (point, distance) and (prim, u, v, instance)
CLOSEST_POINT_RECORD_BYTES = 32


def point_group_defines(scene) -> dict:
    """The defines of the query program (trace.cl) with which the closest-point
    kernels walk POINT_LANES points at a time (point_group.cl's
    walk_wide_point_group): where the device walks the wide BVH of a one-level
    scene and packets of eight rays (RAY_PACKETS) -- CPU devices; else none."""
    if scene.rays_per_item != 8 or scene.geometry.wide is None or "ACCEL_INSTANCES" in scene.geometry.defines:
        return {}
    return {"POINT_LANES": POINT_LANES, "POINT_GROUPS": POINT_GROUPS, "POINT_CANDIDATES": POINT_CANDIDATES}


def point_runs(points: int, compute_units: int) -> int:
    """The runs a CPU device's point order (point_order.cl's point_run_*)
    takes ``points`` in on a device of ``compute_units`` (clrt.config says why)."""
    return max(1, min(points // POINT_RUN_POINTS, POINT_RUNS_PER_UNIT * compute_units, POINT_RUNS_MAX))


class PointQueries:
    """Accel's point queries (mixed into :class:`~clrt.query.accel.Accel`)."""

    def _point_items(self, kernel: str, m: int) -> int:
        """Work-items of point kernel ``kernel`` for ``m`` points: trace.cl's
        ITEM_RAYS points a work-item, or for the closest-point kernels where
        they walk points in groups its CLOSEST_ITEM_POINTS (POINT_GROUPS
        groups of POINT_LANES)."""
        per_item = self.rays_per_item
        if kernel in CLOSEST_KERNELS and self.point_defines:
            per_item = self.point_defines["POINT_GROUPS"] * self.point_defines["POINT_LANES"]
        return -(-m // per_item)

    def _point_outputs(self, n: int, fields, on_device: bool) -> dict:
        shapes = {name: (n, *POINT_FIELDS[name].item_shape) for name in fields}
        if on_device:
            import pyopencl.array as cla
            return {name: cla.empty(self.queue, shapes[name], POINT_FIELDS[name].dtype)   # no bool among them
                    for name in fields}
        return self._host_outputs({name: (shapes[name], POINT_FIELDS[name].dtype) for name in fields})

    def _host_outputs(self, specs: dict) -> dict:
        """numpy arrays by name (``specs``: name -> (shape, dtype)) for the
        chunks' results to land in: views of one block of the result pool's
        page-locked memory when it has one, as the ray queries' (the device
        writes there by DMA, several times faster than into ordinary memory,
        and no page of it is touched for the first time during the copy);
        else ordinary arrays.  Laid out in the order given: callers put the
        4-byte values first, so that every view stays aligned."""
        sizes = {name: int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
                 for name, (shape, dtype) in specs.items()}
        total = sum(sizes.values())
        block = self.result_pool.take(total) if total else None
        if block is None:
            return {name: np.empty(shape, dtype) for name, (shape, dtype) in specs.items()}
        out, offset = {}, 0
        for name, (shape, dtype) in specs.items():
            out[name] = block[offset:offset + sizes[name]].view(dtype).reshape(shape)
            offset += sizes[name]
        return out

    def _point_geometry(self) -> tuple:
        """The geometry's arguments for the point queries' kernels (GEOMETRY_PARAMS):
        where the device walks the wide BVH, its copy that holds the children's
        disks (clrt/accel/disks.py) between its nodes and its packets, made on
        first use and again after a refit (a new ``geometry.reach``); else the
        geometry's own."""
        geometry = self.geometry
        wide = geometry.wide
        if wide is None:
            return (*geometry.buffer_args, self._scene_value)
        key = (geometry, geometry.reach)
        cached = self.__dict__.get("_disk_cache")
        if cached is not None and all(a is b for a, b in zip(cached[0], key)):
            return cached[1]
        slotted = packet_corners(wide.packets, len(self.acceleration.prim_ids))
        disks = wide_disks(self.acceleration.rows, wide.sources, slotted)
        combined = np.concatenate([wide.nodes.view(np.uint8).ravel(), disks.view(np.uint8).ravel(),
                                   wide.packets.view(np.uint8).ravel()])
        buffer = cl.Buffer(self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=combined)
        scene = self._scene_value.copy()
        scene["packets_at"] = wide.nodes.nbytes + disks.nbytes
        b = geometry.buffers
        args = (*b["tris"], *b["nodes"], *b["prim_ids"], buffer, scene)
        self._disk_cache = (key, args)
        return args

    def _launch(self, name: str, args: tuple, items: int, group: int | None = None) -> None:
        """Kernel ``name`` (QUERY_KERNELS) with ``args`` over ``items`` work-items,
        its event kept for kernel_ms; a query kernel submitted at once
        (clFlush), so that the device runs the chunk while the host enqueues
        its copies and makes the next chunk's points."""
        kernel = self.kernels[name]
        kernel.set_args(*args)
        self.launches.append(cl.enqueue_nd_range_kernel(
            self.queue, kernel, *launch_size(items, group or QUERY_GROUP[self._kind])))
        if name.startswith("query_"):
            self.queue.flush()

    def _point_order(self, origins: cl.Buffer, launch: np.ndarray, seeds: cl.Buffer | None = None) -> cl.Buffer:
        """The `order` buffer of a launch of point queries (point_order.cl): its
        points sorted by cell of a grid over the scene (_sorted_points), and
        the cells' seeds ``seeds`` (_cell_seeds: a closest-point kernel's,
        which walks them; None for the others) copied over its first
        POINT_CELLS values (POINT_CELL_SEEDS: the cell counts that the
        atomics' order has spent, or that the order in runs leaves unwritten)."""
        order = self._sorted_points(origins, launch)
        if seeds is not None:
            cl.enqueue_copy(self.queue, order, seeds, byte_count=4 * POINT_CELLS)
        return order

    def _sorted_points(self, origins: cl.Buffer, launch: np.ndarray) -> cl.Buffer:
        """_point_order's points by cell: on a GPU by point_order.cl's
        counting sort through atomic increments, on a CPU device (where PoCL
        runs atomics slowly) by its counting sort in runs of points -- from
        POINT_RUN_POINTS points on: below, zeroing and adding up a run's
        counters takes longer than the atomics (0.4 against 0.17 ms for one
        point, 0.65 against 0.53 for 30,000 on the development machine)."""
        m = int(launch["num_rays"])
        if self._kind == "cpu" and m >= POINT_RUN_POINTS:
            return self._run_point_order(origins, launch, point_runs(m, self.queue.device.max_compute_units))
        return self._atomic_point_order(origins, launch)

    def _atomic_point_order(self, origins: cl.Buffer, launch: np.ndarray) -> cl.Buffer:
        """_sorted_points by point_order.cl's point_cells, point_offsets and
        point_scatter (GPUs; small batches on CPU devices)."""
        m = int(launch["num_rays"])
        order = self._buffer("order", 4 * (POINT_CELLS + 2 * m))
        cl.enqueue_fill_buffer(self.queue, order, np.uint32(0), 0, 4 * POINT_CELLS)
        self._launch("point_cells", (origins, launch, order), m)
        self._launch("point_offsets", (order,), POINT_OFFSETS_GROUP, POINT_OFFSETS_GROUP)
        self._launch("point_scatter", (launch, order), m)
        return order

    def _run_point_order(self, origins: cl.Buffer, launch: np.ndarray, runs: int) -> cl.Buffer:
        """_sorted_points in ``runs`` runs of points by point_order.cl's
        point_cell_of and point_run_* (CPU devices; tests on any device)."""
        m = int(launch["num_rays"])
        order = self._buffer("order", 4 * (POINT_CELLS + 2 * m))
        counts = self._buffer("run_counts", 4 * POINT_RUN_CELLS * runs)
        self._launch("point_cell_of", (origins, launch, order), m)
        self._launch("point_run_counts", (launch, order, counts), runs, 1)
        self._launch("point_run_offsets", (counts, np.uint32(runs)), 1, 1)
        self._launch("point_run_scatter", (launch, order, counts), runs, 1)
        return order

    def _cell_seeds(self, points: int) -> cl.Buffer:
        """The seeds of a closest-point kernel's walks (point_order.cl's
        POINT_CELL_SEEDS) for a batch of ``points``: where points walk one a
        work-item, the slot of the triangle nearest to the centre of each cell
        of point_order.cl's grid (trace.cl's point_cell_seeds, over the
        scene's box as the batch's launch gives it: call after _begin), made
        on first use by a batch of at least SEEDED_MIN_POINTS (a smaller one
        would spend more on them than on its own walks) and again after a
        refit (a new ``geometry.reach``).  A table of -1 (none) until then,
        in a two-level scene, whose walk takes no seed, and without a BVH,
        which visits every triangle anyway.  (Point groups, on CPU devices,
        start from the group before: _closest_seeds asks for none.)"""
        key = (self.geometry, self.geometry.reach)
        cached = self.__dict__.get("_seeds_cache")
        if cached is not None and all(a is b for a, b in zip(cached[0], key)):
            return cached[1]
        if points < SEEDED_MIN_POINTS or not self.acceleration.is_bvh or self.instances is not None:
            return self._no_seeds()
        seeds = cl.Buffer(self.context, cl.mem_flags.READ_WRITE, 4 * POINT_CELLS)
        self._launch("point_cell_seeds", (seeds, self._batch_launch, *self._point_geometry()), POINT_CELLS)
        self._seeds_cache = (key, seeds)
        return seeds

    def _no_seeds(self) -> cl.Buffer:
        """A table of seeds that names none (-1 for every cell), made once."""
        table = self._buffers.get("no_seeds")
        if table is None:
            table = self._buffer("no_seeds", 4 * POINT_CELLS)
            cl.enqueue_fill_buffer(self.queue, table, np.int32(-1), 0, 4 * POINT_CELLS)
        return table

    def _closest_seeds(self, kernel: str, points: int) -> cl.Buffer | None:
        """The seeds that closest-point kernel ``kernel`` reads (every one of
        CLOSEST_KERNELS reads a table where points walk one a work-item; the
        winding rule's ignores it, so it takes -1s: trace.cl's
        signed_distances), or None for the other point kernels."""
        if kernel not in CLOSEST_KERNELS or self.point_defines:
            return None
        return self._cell_seeds(points) if kernel in SEEDED_KERNELS else self._no_seeds()

    @one_at_a_time
    def _closest_points(self, batch: PointBatch, fields) -> ClosestPoints:
        fields = asked_fields(fields, POINT_FIELDS, "point")
        n = len(batch)
        out = self._point_outputs(n, fields, batch.on_device)
        slots = list(POINT_FIELDS)
        self._begin(batch)
        seeds = self._closest_seeds("query_closest_point", n)
        for start, stop in self._chunks(n):
            m = stop - start
            rays, launch = self._ray_args(batch, start, stop, 0)
            origins, _, _, tmaxs, bad = rays
            order = self._point_order(origins, launch, seeds)
            placed, nbytes = {}, 0
            for name in fields:   # every field is 4-byte aligned: float32 and int32 values
                placed[name] = nbytes
                launch["field_at"][slots.index(name)] = nbytes
                nbytes += m * 4 * int(np.prod(POINT_FIELDS[name].item_shape, dtype=int))
            results = self._buffer("results", nbytes)
            # Where points walk in groups (CPU devices), several outputs go through one record a point
            # (trace.cl's write_closest_point says why).  Elsewhere the kernel reads no records: any
            # buffer will do for the argument (GPUs are given no null buffer).
            spread = bool(self.point_defines) and len(fields) > 1
            records = (self._buffer("records", CLOSEST_POINT_RECORD_BYTES * m) if spread
                       else None if self.point_defines else results)
            self._launch("query_closest_point", (origins, tmaxs, bad, launch, order, results, records,
                                                 *self._point_geometry()), self._point_items("query_closest_point", m))
            if spread:
                self._launch("closest_point_fields", (records, launch, results), m)
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

    # ------------------------------------------------------------------- inside and outside

    def _winding_nodes(self):
        """The far fields of the tree as it is now (clrt/query/inside.py), made
        on first use; a 1-byte stand-in without a BVH (the kernels then sum
        every triangle).  A refit -- of this Accel or of the Renderer it
        follows -- places the triangles anew (a new ``geometry.reach``), and
        they are made again."""
        key = (self.geometry, self.geometry.reach)
        cached = self.__dict__.get("_winding_cache")
        if cached is not None and all(a is b for a, b in zip(cached[0], key)):
            return cached[1]
        if self.acceleration.is_bvh:
            nodes = winding_nodes(self.queue, self.kernels["winding_nodes"], self.acceleration,
                                  (*self.geometry.buffer_args, self._scene_value), self.max_alloc, self.geometry.wide)
        else:
            nodes = self._buffer("no_winding_nodes", 1)
        self._winding_cache = (key, nodes)
        return nodes

    def _pseudo_normals(self):
        """The PseudoNormals of every slot (clrt/query/inside.py), made on first
        use and again for a moved mesh (a refit makes a new ``mesh``, or new
        ``instances``); in a two-level scene each distinct mesh's, in its own
        space (point.cl turns them into the world)."""
        key = (self.mesh, self.instances, self.acceleration)
        cached = self.__dict__.get("_normals_cache")
        if cached is not None and all(a is b for a, b in zip(cached[0], key)):
            return cached[1]
        if self.instances is None:
            by_slot = pseudo_normals(self.mesh.vertices, self.mesh.faces)[self.acceleration.prim_ids]
        else:   # each mesh's faces in order, mesh after mesh: the rows TwoLevel.order counts
            by_slot = np.concatenate([pseudo_normals(m.vertices, m.faces) for m in self.instances.meshes])[
                self.acceleration.slot_order()]
        normals = cl.Buffer(self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=by_slot)
        self._normals_cache = (key, normals)
        return normals

    @one_at_a_time
    def _inside(self, source, kernel: str, outputs: dict, out=None) -> dict:
        """Run inside-query ``kernel`` over the points of ``source`` (a PointBatch
        or GridPoints): ``outputs`` maps each value asked for (INSIDE_FIELDS) to
        its output slot in the kernel; ``out``: arrays to fill, by value (else
        made here: numpy, or device arrays for points given on the device)."""
        n = len(source)
        if out is None and source.on_device:
            import pyopencl.array as cla
            out = {name: cla.empty(self.queue, (n,), np.uint8 if INSIDE_FIELDS[name].dtype is np.bool_
                                   else INSIDE_FIELDS[name].dtype) for name in outputs}
        elif out is None:   # the float32 values first (outputs' order): every view stays aligned
            out = self._host_outputs({name: ((n,), INSIDE_FIELDS[name].dtype) for name in outputs})
        rule = ()
        if kernel in ("query_winding_number", "query_signed_distance_winding"):
            rule = (self._winding_nodes(),)
        elif kernel == "query_signed_distance_normal":
            rule = (self._pseudo_normals(),)
        self._begin(source)
        seeds = self._closest_seeds(kernel, n)
        for start, stop in self._chunks(n):
            m = stop - start
            if isinstance(source, GridPoints):
                origins, tmaxs, bad, launch = self._grid_args(source, start, stop)
            else:
                (origins, _, _, tmaxs, bad), launch = self._ray_args(source, start, stop, 0)
            order = self._point_order(origins, launch, seeds)
            placed, nbytes = {}, 0
            for name, slot in outputs.items():   # the float32 values first: each output stays aligned
                placed[name] = nbytes
                launch["field_at"][slot] = nbytes
                nbytes += m * np.dtype(INSIDE_FIELDS[name].dtype).itemsize
            results = self._buffer("results", nbytes)
            self._launch(kernel, (origins, tmaxs, bad, launch, order, results, *rule, *self._point_geometry()),
                         self._point_items(kernel, m))
            for name, at in placed.items():
                self._copy_out(out[name], start, stop, results, at)
        self._check(source)   # also waits for the copies
        return out

    def _grid_args(self, grid: GridPoints, start: int, stop: int) -> tuple:
        """POINT_INPUT_PARAMS' origins, tmaxs and bad buffers and the QueryLaunch
        for samples start..stop-1 of ``grid``, as _ray_args gives them for a
        host batch of points -- the samples made on the device (grid_points)."""
        m = stop - start
        origins = self._buffer("in_0", 12 * m)
        axes = self._upload("grid_axes", grid.axis_values)
        _, size_y, size_z = grid.shape
        self._launch("grid_points", (origins, axes, np.uint64(start), np.uint32(m), np.uint32(size_y),
                                     np.uint32(size_z)), m)
        launch = self._batch_launch.copy()
        launch["origin_stride"], launch["dir_stride"], launch["tmin_stride"], launch["tmax_stride"] = 3, 0, 0, 0
        launch["in_first"], launch["ray_first"], launch["num_rays"], launch["cull"] = 0, start, m, 0
        launch["field_at"] = NO_RESULT
        tmaxs = self._upload("in_3", np.full(1, np.inf, np.float32))
        return origins, tmaxs, self._buffer("bad", 4 * len(RAY_CHECKS)), launch

    def signed_distance(self, points, *, sign: str = "winding"):
        """(N,) float32: each point's distance to the mesh, negative inside.

        ``points`` as :meth:`closest_points` takes them (device arrays give a
        device array).  The distance is :meth:`distance`'s, bit for bit; the
        sign follows rule ``sign``:

        - "winding" (default): inside where the winding number is >= 1/2
          (:meth:`winding_number`) -- any mesh, open ones and soups included;
        - "parity": inside where rays from the point cross the surface an odd
          number of times, three fixed directions voting (a ray through an
          edge may count a crossing twice) -- closed meshes, any winding;
        - "normal": inside where the point lies behind the angle-weighted
          pseudo-normal of the face, edge or vertex holding its closest point
          (Baerentzen and Aanaes 2005) -- closed meshes wound consistently
          outwards; the fastest (no second walk).

        A point on the surface has distance 0 (either sign).
        """
        kernel = sign_kernel(sign)
        return self._inside(PointBatch(points), kernel, {"signed_distance": 0})["signed_distance"]

    def winding_number(self, points):
        """(N,) float32: the generalised winding number of the mesh at each point
        (Jacobson et al. 2013): the triangles' signed solid angles over 4 pi --
        1 inside a closed mesh wound outwards (-1 wound inwards), 0 outside,
        fractions for open meshes and soups, 1/2 on a face.  Through the BVH with
        the far-field series of Barill et al. 2018, within
        ``clrt.query.results.WINDING_NUMBER_ERROR`` (1e-4) of the exact sum
        (exact without a BVH); ``points`` as :meth:`closest_points` takes them."""
        return self._inside(PointBatch(points), "query_winding_number", {"winding_number": 0})["winding_number"]

    def contains(self, points):
        """(N,) bool: is each point inside the mesh -- its winding number >= 1/2
        (:meth:`winding_number`; the float32 value, so the two agree), for open
        meshes and soups as for closed ones.  Device arrays in give uint8 0 / 1."""
        out = self._inside(PointBatch(points), "query_winding_number", {"inside": 1})["inside"]
        return out.view(bool) if isinstance(out, np.ndarray) else out

    def sdf_grid(self, resolution, bounds=None, *, sign: str = "winding") -> np.ndarray:
        """(X, Y, Z) float32: :meth:`signed_distance` at the samples of a grid.

        ``resolution``: samples a side, an int (X = Y = Z) or three, each >= 2;
        ``bounds``: ((xmin, ymin, zmin), (xmax, ymax, zmax)), default the mesh's
        box grown on every side by 5 % of its longest side
        (``clrt.query.inside.GRID_MARGIN``).  Sample (i, j, k) lies at
        ``(xs[i], ys[j], zs[k])``, ``xs = np.linspace(xmin, xmax, X)`` (both
        ends included), likewise ys and zs, rounded to float32.  The samples are
        made on the device a chunk at a time (``chunk_rays`` points), so memory
        beyond the result stays bounded."""
        kernel = sign_kernel(sign)
        scene = self.mesh if self.instances is None else self.instances
        grid = GridPoints(*grid_axes(resolution, bounds, scene.bounds))
        volume = self._host_outputs({"volume": (grid.shape, np.float32)})["volume"]   # page-locked where it can be
        self._inside(grid, kernel, {"signed_distance": 0}, {"signed_distance": volume.reshape(-1)})
        return volume

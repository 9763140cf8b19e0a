"""clrt/query/host_order.py, CPU devices' point order made by the host, against
point_order.cl's kernels on the test device: the same cell for every point bit
for bit (points on and beside cell borders, outside the scene's box, not
finite, given as float64), the same cells in the same order, and the same
answers bit for bit through either order -- host arrays, device arrays in
chunks (the points read back from the device) and grids."""

import numpy as np
import pyopencl as cl

import clrt
from clrt.config import POINT_CELL_BITS, POINT_CELLS
from clrt.query import host_order
from clrt.query.points import PointQueries
from clrt.query.rays import PointBatch
from clrt.query.results import POINT_FIELDS
from clrt.scene import primitives


def _launch(accel, points):
    """The origins buffer and QueryLaunch of one launch of ``points``."""
    batch = PointBatch(points)
    accel._begin(batch)
    rays, launch = accel._ray_args(batch, 0, len(batch), 0)
    return rays[0], launch


def _order_buffer(accel, order, m: int) -> tuple:
    """(cells, visit) of a launch of m points: the cells point_cells wrote, the order the queries read."""
    raw = np.empty(POINT_CELLS + 2 * m, np.uint32)
    cl.enqueue_copy(accel.queue, raw, order)
    return raw[POINT_CELLS:POINT_CELLS + m], raw[POINT_CELLS + m:]


def _hard_points(accel, rng) -> np.ndarray:
    """float64 points where the float32 steps decide the cell: on every cell
    border of each axis and one float32 step either side, beyond the box, far
    away and not finite -- among points in and around the scene."""
    _, launch = _launch(accel, np.zeros((1, 3)))
    shift, lo, hi = (launch[f][:3].astype(np.float64) for f in ("shift", "scene_lo", "scene_hi"))
    borders = lo + np.linspace(0, 1, (1 << POINT_CELL_BITS) + 1)[:, None] * (hi - lo) + shift
    steps = borders.astype(np.float32)
    near = np.concatenate([steps, np.nextafter(steps, np.float32(-np.inf)), np.nextafter(steps, np.float32(np.inf))])
    mixed = near[rng.permutation(len(near))]
    mixed[:, 1:] = near[rng.integers(0, len(near), (len(near), 2)), [1, 2]]   # border coordinates on other axes too
    span = hi - lo
    inside = shift + lo + rng.uniform(-0.2, 1.2, (2000, 3)) * span
    odd = np.array([[1e30, -1e30, 0], [np.inf, 0, -np.inf], [np.nan, 0.1, 0.2], [0.3, np.nan, np.nan],
                    [3e38, -3e38, 1e-40]])
    return np.concatenate([near, mixed, inside, odd])


def test_the_host_gives_each_point_the_kernels_cell_and_place(device, monkeypatch):
    rng = np.random.default_rng(5)
    accel = clrt.Accel(primitives.torus(1.0, 0.35, 24, 12), device=device)   # no extent a power of 2
    points = _hard_points(accel, rng)
    origins, launch = _launch(accel, points)
    cells, _ = _order_buffer(accel, accel._device_point_order(origins, launch), len(points))
    host_cells = host_order.point_cells(points, launch)                       # from the float64 points
    number = ~np.isnan(points).any(axis=1)                 # NaN points (reported by the query): some cell
    assert (host_cells < POINT_CELLS).all() and not number.all()
    np.testing.assert_array_equal(host_cells[number], cells[number])
    np.testing.assert_array_equal(host_order.point_cells(points.astype(np.float32), launch), host_cells)
    monkeypatch.setattr(host_order, "CELL_BLOCK", 500)                        # in blocks, the last one short
    np.testing.assert_array_equal(host_order.point_cells(points, launch), host_cells)
    # the order of the points that are numbers (infinities too)
    points = points[number]
    origins, launch = _launch(accel, points)
    cells, visit = _order_buffer(accel, accel._device_point_order(origins, launch), len(points))
    host_cells = host_order.point_cells(points, launch)
    assert len(np.unique(cells)) > 1000                                       # many cells, border cells among them
    host_visit = host_order.cell_order(host_cells)
    np.testing.assert_array_equal(host_visit, np.argsort(cells, kind="stable"))
    np.testing.assert_array_equal(np.sort(visit), np.arange(len(points)))
    np.testing.assert_array_equal(cells[visit], host_cells[host_visit])       # cell by cell alike
    # the order the device under test's queries read: the host's on a CPU device
    _, used = _order_buffer(accel, accel._point_order(origins, launch, points.reshape(-1)), len(points))
    np.testing.assert_array_equal(cells[used], host_cells[host_visit])
    if accel._kind == "cpu":
        np.testing.assert_array_equal(used, host_visit)
    # a later chunk of points given on the device (read back by the host on a CPU device)
    import pyopencl.array as cla
    finite = points[np.isfinite(points).all(axis=1)].astype(np.float32)
    batch = PointBatch(cla.to_device(accel.queue, finite))
    accel._begin(batch)
    start = len(finite) // 3
    (origins, *_), launch = accel._ray_args(batch, start, len(finite), 0)
    _, used = _order_buffer(accel, accel._point_order(origins, launch, None), len(finite) - start)
    chunk_cells = host_order.point_cells(finite[start:], launch)
    assert (np.diff(chunk_cells[used].astype(np.int64)) >= 0).all()
    np.testing.assert_array_equal(np.sort(used), np.arange(len(finite) - start))


def _device_order(self, origins, launch, points):
    return self._device_point_order(origins, launch)


def test_either_order_gives_the_same_answers_bit_for_bit(device, monkeypatch):
    import pyopencl.array as cla
    mesh = primitives.torus(1.0, 0.35, 32, 16)
    rng = np.random.default_rng(9)
    points = rng.uniform(-1.6, 1.6, (3000, 3))
    accel = clrt.Accel(mesh, device=device)
    chunked = clrt.Accel(mesh, device=device, chunk_rays=700)

    def answers():
        on_device = cla.to_device(chunked.queue, points.astype(np.float32))
        return {"closest": accel.closest_points(points), "chunked": chunked.closest_points(on_device),
                "normal": accel.signed_distance(points, sign="normal"),
                "winding": chunked.signed_distance(on_device, sign="winding").get(),
                "grid": chunked.sdf_grid((14, 12, 10), sign="normal")}

    got = answers()
    monkeypatch.setattr(PointQueries, "_sorted_points", _device_order)
    want = answers()
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(got["closest"], field), getattr(want["closest"], field), err_msg=field)
        np.testing.assert_array_equal(getattr(got["chunked"], field).get(), getattr(want["closest"], field),
                                      err_msg=field)
    for name in ("normal", "winding", "grid"):
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert (got["normal"] < 0).any() and (got["normal"] > 0).any()

"""point_order.cl's two orders of a launch's points -- by atomic increments
(GPUs) and in runs of points (CPU devices) -- against a numpy reference: the
same cell for every point bit for bit (points on and beside cell borders,
outside the scene's box, not finite, given as float64), the points sorted
stably by cell (the runs' order exactly numpy's stable sort, in any number
of runs), and the same answers bit for bit through either order -- host
arrays, device arrays in chunks and grids."""

import numpy as np
import pyopencl as cl
import pytest

import clrt
from clrt.config import (POINT_CELL_BITS, POINT_CELLS, POINT_RUN_CELL_BITS, POINT_RUN_CELLS, POINT_RUN_POINTS,
                         POINT_RUNS_MAX, POINT_RUNS_PER_UNIT)
from clrt.query.points import PointQueries, point_runs
from clrt.query.rays import PointBatch
from clrt.query.results import POINT_FIELDS
from clrt.scene import primitives


def _numpy_cells(points: np.ndarray, launch, bits: int = POINT_CELL_BITS) -> np.ndarray:
    """point_order.cl's point_cell of each point (in a grid of 2^bits cells an axis), in the kernel's float32
    steps: converted as the upload converts it, moved by the launch's shift,
    its offset from the scene's corner divided by the extent, times the cells
    an axis, clamped to the grid and truncated; the axes' bits interleaved."""
    shift, lo, hi = (launch[field][:3].astype(np.float32) for field in ("shift", "scene_lo", "scene_hi"))
    extent = np.maximum(hi - lo, np.finfo(np.float32).tiny)
    with np.errstate(all="ignore"):
        q = (points.astype(np.float32) - shift - lo) / extent * np.float32(1 << bits)
        q = np.clip(q, 0, (1 << bits) - 1).astype(np.int64)
    return sum(((q[:, axis] >> b) & 1) << (3 * b + axis) for b in range(bits) for axis in range(3))
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


def _hard_points(accel, rng, bits: int) -> np.ndarray:
    """float64 points where the float32 steps decide the cell (of 2^bits an axis): on every cell
    border of each axis and one float32 step either side, beyond the box, far
    away and not finite -- among points in and around the scene."""
    _, launch = _launch(accel, np.zeros((1, 3)))
    shift, lo, hi = (launch[f][:3].astype(np.float64) for f in ("shift", "scene_lo", "scene_hi"))
    borders = lo + np.linspace(0, 1, (1 << bits) + 1)[:, None] * (hi - lo) + shift
    steps = borders.astype(np.float32)
    near = np.concatenate([steps, np.nextafter(steps, np.float32(-np.inf)), np.nextafter(steps, np.float32(np.inf))])
    mixed = near[rng.permutation(len(near))]
    mixed[:, 1:] = near[rng.integers(0, len(near), (len(near), 2)), [1, 2]]   # border coordinates on other axes too
    span = hi - lo
    inside = shift + lo + rng.uniform(-0.2, 1.2, (2000, 3)) * span
    odd = np.array([[1e30, -1e30, 0], [np.inf, 0, -np.inf], [np.nan, 0.1, 0.2], [0.3, np.nan, np.nan],
                    [3e38, -3e38, 1e-40]])
    return np.concatenate([near, mixed, inside, odd])


@pytest.mark.parametrize("order", ["atomic", "runs 1", "runs 3", "runs 7"])
def test_each_order_sorts_the_points_by_their_cells_stably(device, order):
    rng = np.random.default_rng(5)
    accel = clrt.Accel(primitives.torus(1.0, 0.35, 24, 12), device=device)   # no extent a power of 2

    def sort(origins, launch):
        if order == "atomic":
            return accel._atomic_point_order(origins, launch)
        return accel._run_point_order(origins, launch, int(order.split()[1]))

    bits, cell_count = (POINT_CELL_BITS, POINT_CELLS) if order == "atomic" else (POINT_RUN_CELL_BITS, POINT_RUN_CELLS)
    points = _hard_points(accel, rng, bits)
    origins, launch = _launch(accel, points)
    cells, visit = _order_buffer(accel, sort(origins, launch), len(points))
    want = _numpy_cells(points, launch, bits)                                  # from the float64 points
    number = ~np.isnan(points).any(axis=1)                 # NaN points (reported by the query): some cell
    assert (cells < cell_count).all() and not number.all()
    np.testing.assert_array_equal(cells[number], want[number])
    assert len(np.unique(cells)) > 1000                                       # many cells, border cells among them
    np.testing.assert_array_equal(np.sort(visit), np.arange(len(points)))     # every point once
    stable = np.argsort(cells, kind="stable")
    np.testing.assert_array_equal(cells[visit], cells[stable])                # cell by cell
    if order != "atomic":                                 # within a cell, the points' own order
        np.testing.assert_array_equal(visit, stable)
    # a later chunk of points given on the device: the launch starts past the first
    import pyopencl.array as cla
    finite = points[np.isfinite(points).all(axis=1)].astype(np.float32)
    batch = PointBatch(cla.to_device(accel.queue, finite))
    accel._begin(batch)
    start = len(finite) // 3
    (origins, *_), launch = accel._ray_args(batch, start, len(finite), 0)
    cells, visit = _order_buffer(accel, sort(origins, launch), len(finite) - start)
    np.testing.assert_array_equal(cells, _numpy_cells(finite[start:], launch, bits))
    np.testing.assert_array_equal(cells[visit], np.sort(cells))
    np.testing.assert_array_equal(np.sort(visit), np.arange(len(finite) - start))


def test_runs_past_the_points_and_nan_coordinates(device):
    """More runs than points (the extra runs empty), and a NaN coordinate in
    the first cell of its axis (its other coordinates' cells kept)."""
    accel = clrt.Accel(primitives.torus(1.0, 0.35, 24, 12), device=device)
    points = np.array([[0.3, -0.2, 0.1], [np.nan, 0.2, -0.3], [-1.0, np.nan, 0.25]])
    origins, launch = _launch(accel, points)
    for runs in (1, 3, 7, 8):
        cells, visit = _order_buffer(accel, accel._run_point_order(origins, launch, runs), len(points))
        np.testing.assert_array_equal(np.sort(visit), np.arange(len(points)))
        np.testing.assert_array_equal(cells[visit], np.sort(cells))
        want = _numpy_cells(np.nan_to_num(points, nan=-np.inf), launch, POINT_RUN_CELL_BITS)   # -inf: the first
        np.testing.assert_array_equal(cells, want)


def test_a_cpu_device_counts_in_runs_by_its_units_and_points():
    assert point_runs(0, 2) == point_runs(POINT_RUN_POINTS - 1, 64) == 1
    assert point_runs(100 * POINT_RUN_POINTS, 2) == POINT_RUNS_PER_UNIT * 2
    assert point_runs(3 * POINT_RUN_POINTS, 64) == 3
    assert point_runs(1 << 30, 1000) == POINT_RUNS_MAX


def _other_order(self, origins, launch):
    """The order the device under test does not take for this launch: runs
    where it takes the atomics' (GPUs; CPU devices below POINT_RUN_POINTS
    points), else the atomics'."""
    if self._kind == "cpu" and int(launch["num_rays"]) >= POINT_RUN_POINTS:
        return self._atomic_point_order(origins, launch)
    return self._run_point_order(origins, launch, 3)


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
    monkeypatch.setattr(PointQueries, "_sorted_points", _other_order)
    want = answers()
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(got["closest"], field), getattr(want["closest"], field), err_msg=field)
        np.testing.assert_array_equal(getattr(got["chunked"], field).get(), getattr(want["closest"], field),
                                      err_msg=field)
    for name in ("normal", "winding", "grid"):
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    assert (got["normal"] < 0).any() and (got["normal"] > 0).any()


def test_a_batch_past_the_runs_threshold_gives_the_same_answers_either_way(device, monkeypatch):
    """A launch of POINT_RUN_POINTS points or more: on a CPU device the order
    in runs by the finer grid (elsewhere the atomics'), against the other."""
    points = np.random.default_rng(4).uniform(-1.6, 1.6, (POINT_RUN_POINTS + 999, 3))
    accel = clrt.Accel(primitives.torus(1.0, 0.35, 24, 12), device=device)
    got = accel.closest_points(points)
    monkeypatch.setattr(PointQueries, "_sorted_points", _other_order)
    want = accel.closest_points(points)
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)

"""The GPU warp walk of closest points (point_warp.cl, NVIDIA's
-DPOINT_WARP_WALK), run on any device one point a work-item through the votes
of a warp of one (-DPOINT_WARP_EMULATE), against the plain walk and brute
force on the device, bit for bit: closest triangle, distance, point,
barycentrics and feature, with misses beyond max_distance among them, and
signed distances by normal."""

import numpy as np
import pytest

import clrt
from clrt.query.results import POINT_FIELDS
from clrt.scene import primitives

EMULATED = {"POINT_WARP_WALK": None, "POINT_WARP_EMULATE": None}


def _points(mesh, rng):
    """Points uniform in the box grown by 10 % (issue 36's benchmark points),
    on the surface, just off it, at vertices and far away."""
    lo, hi = mesh.bounds.astype(np.float64)
    corners = mesh.vertices[mesh.faces].astype(np.float64)
    f = rng.integers(len(corners), size=150)
    on = np.einsum("nk,nkj->nj", rng.dirichlet((1, 1, 1), size=150), corners[f])
    box = lo - 0.05 * (hi - lo) + rng.random((800, 3)) * 1.1 * (hi - lo)
    vertices = mesh.vertices[rng.integers(len(mesh.vertices), size=40)]
    far = 30 * rng.normal(size=(40, 3))
    return rng.permutation(np.concatenate([box, on, on + 1e-3 * rng.normal(size=on.shape), vertices, far]))\
        .astype(np.float32)


def _accel(mesh, volume, defines, device, monkeypatch, **options):
    """An Accel of ``mesh`` whose query program walks the binary rows one point
    a work-item (as a GPU's: no wide BVH, no packets) with point defines ``defines``."""
    import clrt.query.accel as query_accel
    import clrt.query.points as query_points
    from clrt.device import geometry

    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    monkeypatch.setattr(query_accel, "point_defines", lambda _: dict(defines))
    monkeypatch.setattr(query_points, "SEEDED_MIN_POINTS", 1)   # the seeds' walks for the few points here too
    return clrt.Accel(mesh, accel=volume, device=device, **options)


@pytest.mark.parametrize("volume", ["box", "sphere", "ellipse"])
def test_warp_walk_answers_as_the_plain_walk(volume, device, monkeypatch):
    """The warp walk, emulated, gives the plain walk's and brute force's
    closest points bit for bit -- with misses beyond max_distance among them
    -- and the same signed distances by normal; its program is built where
    point_warp.cl walks (WARP_WALKS: a one-level binary BVH)."""
    mesh = primitives.torus(1.0, 0.35, 40, 20)
    points = _points(mesh, np.random.default_rng(5))
    plain = _accel(mesh, volume, {}, device, monkeypatch)
    brute = clrt.Accel(mesh, accel="none", device=device)
    wants = {max_distance: plain.closest_points(points, max_distance=max_distance) for max_distance in (np.inf, 0.2)}
    assert 0 < (wants[0.2].prim < 0).sum() < len(points) / 2
    for max_distance, want in wants.items():
        other = brute.closest_points(points, max_distance=max_distance)
        for field in POINT_FIELDS:
            np.testing.assert_array_equal(getattr(want, field), getattr(other, field), err_msg=field)
    want_signed = plain.signed_distance(points, sign="normal")
    assert (want_signed < 0).any() and (want_signed > 0).any()

    walk = _accel(mesh, volume, EMULATED, device, monkeypatch)
    defines = walk.device_scene.defines(walk.trace_defines())
    assert EMULATED.keys() <= defines.keys() and "ACCEL_BVH" in defines
    assert not {"BVH_WIDE", "ACCEL_INSTANCES"} & defines.keys()
    for max_distance, want in wants.items():
        got = walk.closest_points(points, max_distance=max_distance)
        for field in POINT_FIELDS:
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
    np.testing.assert_array_equal(walk.signed_distance(points, sign="normal"), want_signed)


def test_the_cells_seeds_are_their_centres_nearest_triangles(device, monkeypatch):
    """The walks' seeds (point_order.cl's POINT_CELL_SEEDS, made by
    point_cell_seeds where points walk one a work-item): for every cell of the
    grid over the scene's box, a triangle as near to the cell's centre as
    brute force's nearest, to float32 rounding; copied into each launch's
    order over the cell counts."""
    import pyopencl as cl
    from clrt.config import POINT_CELL_BITS, POINT_CELLS
    from test_point_queries import reference

    mesh = primitives.torus(1.0, 0.35, 40, 20)
    walk = _accel(mesh, "box", EMULATED, device, monkeypatch)
    walk.distance(np.zeros((1, 3), np.float32))
    seeds, head = np.empty(POINT_CELLS, np.int32), np.empty(POINT_CELLS, np.int32)
    cl.enqueue_copy(walk.queue, seeds, walk._seeds_cache[1])
    cl.enqueue_copy(walk.queue, head, walk._buffers["order"])
    assert (seeds >= 0).all() and (seeds < len(mesh.faces)).all()
    np.testing.assert_array_equal(head, seeds)
    launch = walk._batch_launch
    lo, hi = (launch[field][:3].astype(np.float32) for field in ("scene_lo", "scene_hi"))
    cell = np.random.default_rng(2).choice(POINT_CELLS, 1000, replace=False)   # (a float64 reference of all: 10 GB)
    q = np.stack([sum(((cell >> (3 * b + axis)) & 1) << b for b in range(POINT_CELL_BITS)) for axis in range(3)], 1)
    centres = lo + (q.astype(np.float32) + np.float32(0.5)) / np.float32(1 << POINT_CELL_BITS) * (hi - lo)
    corners = (mesh.vertices[mesh.faces] - launch["shift"][:3]).astype(np.float32)   # the device's frame, near enough
    distances, _ = reference(centres, corners)
    nearest = distances.min(axis=1)
    by_seed = distances[np.arange(len(cell)), walk.acceleration.prim_ids[seeds[cell]]]
    np.testing.assert_allclose(by_seed, nearest, rtol=0, atol=1e-5 * float(np.abs(corners).max() + 1))
    # a GPU's path: the order made by point_order.cl's kernels, the seeds copied over its spent cell
    # counts, in chunks -- the answers brute force's
    from clrt.query.points import PointQueries
    monkeypatch.setattr(PointQueries, "_sorted_points", PointQueries._atomic_point_order)
    points = _points(mesh, np.random.default_rng(6))
    chunked = _accel(mesh, "box", EMULATED, device, monkeypatch, chunk_rays=300)
    got = chunked.closest_points(points)
    cl.enqueue_copy(chunked.queue, head, chunked._buffers["order"])
    cl.enqueue_copy(chunked.queue, seeds, chunked._seeds_cache[1])
    np.testing.assert_array_equal(head, seeds)
    want = clrt.Accel(mesh, accel="none", device=device).closest_points(points)
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)


def test_a_batch_of_fewer_points_than_cells_takes_no_seeds(device, monkeypatch):
    """Below SEEDED_MIN_POINTS (one a cell) the seeds' launch is not made: the
    launch's order holds no seed (-1s) and the answers are the same."""
    import pyopencl as cl
    import clrt.query.points as query_points
    from clrt.config import POINT_CELLS

    mesh = primitives.torus(1.0, 0.35, 40, 20)
    points = _points(mesh, np.random.default_rng(8))
    walk = _accel(mesh, "box", EMULATED, device, monkeypatch)
    monkeypatch.setattr(query_points, "SEEDED_MIN_POINTS", POINT_CELLS)
    assert len(points) < POINT_CELLS
    few = walk.closest_points(points)
    head = np.empty(POINT_CELLS, np.int32)
    cl.enqueue_copy(walk.queue, head, walk._buffers["order"])
    assert "_seeds_cache" not in walk.__dict__ and (head == -1).all()
    monkeypatch.setattr(query_points, "SEEDED_MIN_POINTS", 1)
    seeded = walk.closest_points(points)
    assert "_seeds_cache" in walk.__dict__
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(seeded, field), getattr(few, field), err_msg=field)

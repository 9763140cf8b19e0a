"""Point queries (Accel.closest_points, Accel.distance, clrt.closest_points,
clrt.distance) against a float64 brute force written here, on its own: the
distance within POINT_DISTANCE_BOUND, the triangle brute force's but at ties,
the point on it; every BVH volume, builder and brute force on the device
give the same answers bit for bit, in any chunk, near the origin and far
from it; bad input is one line."""

import numpy as np
import pytest

import clrt
from clrt.errors import InputError
from clrt.query.results import POINT_DISTANCE_BOUND, POINT_FIELDS
from clrt.scene import primitives
from clrt.scene.arrays import device_origin
from clrt.scene.mesh import Mesh


def _segment(p, a, b):
    """(N, F, 3) closest points on segments a..b ((F, 3) each) to points p (N, 3)."""
    ab = b - a
    t = np.einsum("nfk,fk->nf", p[:, None] - a[None], ab) / np.maximum(np.einsum("fk,fk->f", ab, ab), 1e-300)
    return a[None] + np.clip(t, 0, 1)[..., None] * ab[None]


def reference(points, corners):
    """(distance (N, F), closest point (N, F, 3)) of every point to every triangle,
    float64: the projection onto the plane where it falls inside, else the
    nearest of the three edges' closest points."""
    p = np.asarray(points, np.float64)
    a, b, c = (corners[:, k].astype(np.float64) for k in range(3))
    n = np.cross(b - a, c - a)
    n2 = np.einsum("fk,fk->f", n, n)
    unit = n / np.sqrt(np.maximum(n2, 1e-300))[:, None]
    height = np.einsum("nfk,fk->nf", p[:, None] - a[None], unit)
    q = p[:, None] - height[..., None] * unit[None]                      # on the plane
    inside = np.broadcast_to(n2 > 0, height.shape).copy()
    for x, y in ((a, b), (b, c), (c, a)):                                  # same side of every edge
        inside &= np.einsum("nfk,fk->nf", np.cross(y - x, q - x[None]), n) >= 0
    candidates = [_segment(p, a, b), _segment(p, b, c), _segment(p, c, a)]
    best = candidates[0]
    for cand in candidates[1:]:
        nearer = np.linalg.norm(cand - p[:, None], axis=2) < np.linalg.norm(best - p[:, None], axis=2)
        best = np.where(nearer[..., None], cand, best)
    best = np.where(inside[..., None], q, best)
    return np.linalg.norm(best - p[:, None], axis=2), best


def _thin_box() -> Mesh:
    """A plate 2 x 2 x 0.01: points inside it are near both large faces."""
    return primitives.box((2.0, 2.0, 0.01))


MESHES = {"torus": lambda: primitives.torus(1.0, 0.35, 24, 12), "thin": _thin_box,
          "icosphere": lambda: primitives.icosphere(2)}


def _points(mesh, seed=0):
    """Points near, on the surface (inside triangles, at vertices, on edges),
    far away and inside the mesh."""
    rng = np.random.default_rng(seed)
    corners = mesh.vertices[mesh.faces].astype(np.float64)
    lo, hi = mesh.bounds.astype(np.float64)
    size = np.linalg.norm(hi - lo)
    near = lo + (rng.random((60, 3)) * 1.4 - 0.2) * (hi - lo)
    f = rng.integers(len(corners), size=30)
    w = rng.dirichlet((1, 1, 1), size=30)
    surface = np.einsum("nk,nkj->nj", w, corners[f])
    vertices = mesh.vertices[rng.integers(len(mesh.vertices), size=10)].astype(np.float64)
    edges = corners[f[:10], 0] * 0.3 + corners[f[:10], 1] * 0.7
    far = (lo + hi) / 2 + 1e3 * size * rng.normal(size=(10, 3))
    inside = (lo + hi) / 2 + 0.2 * (rng.random((10, 3)) - 0.5) * (hi - lo)
    return np.concatenate([near, surface, vertices, edges, far, inside]).astype(np.float32)


def _bound(mesh, points):
    """(N,) POINT_DISTANCE_BOUND's bound of each point's distance."""
    o = device_origin(mesh.bounds)
    scale = np.maximum(np.abs(points.astype(np.float64) - o).max(axis=1),
                       np.abs(mesh.vertices.astype(np.float64) - o).max())
    return POINT_DISTANCE_BOUND * scale


def _check_against_reference(mesh, points, got):
    corners = mesh.vertices[mesh.faces]
    dist, closest = reference(points, corners)
    exact = dist.min(axis=1)
    bound = _bound(mesh, points)
    assert (np.abs(got.distance - exact) <= bound).all()
    rows = np.arange(len(points))
    # the triangle brute force picks, or one as near within the bound (a tie)
    assert (dist[rows, got.prim] <= exact + 2 * bound).all()
    # where the second nearest triangle is clearly farther, exactly brute force's
    # (most points are nearest to an edge or a vertex, shared by triangles at one distance)
    second = np.partition(dist, 1, axis=1)[:, 1] if dist.shape[1] > 1 else np.full(len(dist), np.inf)
    clear = second - exact > 4 * bound
    assert clear.sum() >= 10
    np.testing.assert_array_equal(got.prim[clear], dist[clear].argmin(axis=1))
    # the point lies on that triangle, at its weights, the distance away (its
    # coordinates rounded to float32 once more, in the caller's frame)
    point = got.point.astype(np.float64)
    slack = 4 * bound + 2 * np.spacing(np.abs(got.point).max(axis=1)).astype(np.float64)
    assert (np.abs(np.linalg.norm(point - points, axis=1) - got.distance) <= slack).all()
    c = corners[got.prim].astype(np.float64)
    at = c[:, 0] + got.u[:, None] * (c[:, 1] - c[:, 0]) + got.v[:, None] * (c[:, 2] - c[:, 0])
    assert (np.abs(at - point).max(axis=1) <= slack).all()
    assert (np.abs(closest[rows, got.prim] - point).max(axis=1) <= slack).all()
    assert (got.u >= 0).all() and (got.v >= 0).all() and (got.u + got.v <= 1 + 1e-6).all()


@pytest.mark.parametrize("name", sorted(MESHES))
def test_closest_points_match_float64_brute_force(name, device):
    mesh = MESHES[name]()
    points = _points(mesh)
    got = clrt.Accel(mesh, device=device).closest_points(points)
    assert got.point.shape == (len(points), 3) and got.point.dtype == np.float32
    for field in POINT_FIELDS:
        assert getattr(got, field).dtype == POINT_FIELDS[field].dtype
    _check_against_reference(mesh, points, got)
    # points on the surface are at distance ~0, vertices at 0 exactly
    assert (np.abs(got.distance[60:90]) <= _bound(mesh, points)[60:90]).all()
    assert (got.distance[90:100] == 0).all()


def test_every_volume_builder_and_brute_force_agree_bit_for_bit(device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    points = _points(mesh, seed=3)
    answers = {}
    for accel in ("none", "box", "sphere", "ellipse"):
        for builder in (("sah",) if accel == "none" else ("sah", "paper", "device")):
            answers[accel, builder] = clrt.Accel(mesh, accel=accel, builder=builder, leaf_size=2,
                                                 device=device).closest_points(points)
    first = answers["none", "sah"]
    for key, got in answers.items():
        for field in POINT_FIELDS:
            np.testing.assert_array_equal(getattr(got, field), getattr(first, field), err_msg=f"{key} {field}")


def test_chunks_single_points_and_distance_agree(device):
    mesh = primitives.icosphere(2)
    points = _points(mesh, seed=5)
    whole = clrt.Accel(mesh, device=device).closest_points(points)
    chunked = clrt.Accel(mesh, device=device, chunk_rays=7).closest_points(points)
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(whole, field), getattr(chunked, field))
    accel = clrt.Accel(mesh, device=device)
    one = accel.closest_points(points[17])
    assert one.distance.shape == (1,) and one.distance[0] == whole.distance[17]
    np.testing.assert_array_equal(accel.distance(points.astype(np.float64)), whole.distance)
    np.testing.assert_array_equal(clrt.distance(mesh, points, device=device), whole.distance)
    np.testing.assert_array_equal(clrt.closest_points(mesh, points, device=device).prim, whole.prim)
    only = accel.closest_points(points, fields=("prim",))
    assert only.point is None and only.distance is None
    np.testing.assert_array_equal(only.prim, whole.prim)
    empty = accel.closest_points(np.zeros((0, 3)))
    assert empty.point.shape == (0, 3) and empty.distance.shape == (0,)


def test_max_distance_makes_misses(device):
    mesh = primitives.icosphere(2)
    accel = clrt.Accel(mesh, device=device)
    points = np.array([[0, 0, 0], [0, 0, 1.5], [0, 0, 5], [0, 0, 1.0]], np.float32)
    all_of_them = accel.closest_points(points)
    got = accel.closest_points(points, max_distance=0.6)
    hit = all_of_them.distance <= 0.6
    assert list(hit) == [False, True, False, True]
    assert (got.prim[~hit] == -1).all() and np.isinf(got.distance[~hit]).all()
    assert np.isnan(got.point[~hit]).all() and (got.u[~hit] == 0).all() and (got.v[~hit] == 0).all()
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(got, field)[hit], getattr(all_of_them, field)[hit])
    # inclusive: a point exactly max_distance away is found
    at = accel.closest_points(points[1], max_distance=float(all_of_them.distance[1]))
    assert at.prim[0] == all_of_them.prim[0 + 1]


@pytest.mark.parametrize("offset", [1e4, 1e6])
def test_a_mesh_far_from_the_origin_answers_as_near_it(offset, device):
    """Moved on a grid where float32 moves are exact, mesh and points answer as
    at the origin (the device frame), the point reported in the caller's frame."""
    grid = 1.0 / 16
    base = primitives.torus(1.0, 0.35, 24, 12)
    vertices = np.round(base.vertices.astype(np.float64) * 4 / grid) * grid
    shift = offset * np.array([1.0, -0.5, 0.25])
    near = Mesh.from_arrays(vertices, base.faces)
    far = Mesh.from_arrays(vertices + shift, base.faces)
    assert device_origin(far.bounds).any()
    points = np.round(_points(near)[:100].astype(np.float64) / grid) * grid
    a = clrt.Accel(near, device=device).closest_points(points)
    b = clrt.Accel(far, device=device).closest_points(points + shift)
    np.testing.assert_array_equal(a.prim, b.prim)
    np.testing.assert_array_equal(a.distance, b.distance)
    np.testing.assert_array_equal(a.u, b.u)
    assert np.abs(b.point.astype(np.float64) - (a.point + shift)).max() <= np.spacing(np.float32(offset * 1.5))
    _check_against_reference(far, (points + shift).astype(np.float32), b)


@pytest.mark.parametrize("points, message", [
    ([[0, 0, np.nan]], "point 0 is [0.0, 0.0, nan]: points must be finite"),
    ([[1, 2, 3], [0, np.inf, 0]], "point 1 is [0.0, inf, 0.0]: points must be finite"),
    ([[1e39, 0, 0]], "point 0 is [1e+39, 0.0, 0.0]: 1e39 overflows float32"),
    (np.zeros((4, 2)), "points must have shape (3,) or (N, 3), got (4, 2)"),
    (np.zeros(3, "U1"), "points must be real numbers, got dtype <U1"),
    ("abc", "points must be real numbers"),
])
def test_bad_points_are_one_line(points, message, device):
    accel = clrt.Accel(primitives.icosphere(1), device=device)
    with pytest.raises(InputError) as err:
        accel.closest_points(points)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("value", [0, -1.0, np.nan, "far", None, True])
def test_bad_max_distance_is_one_line(value, device):
    accel = clrt.Accel(primitives.icosphere(1), device=device)
    with pytest.raises(InputError, match=r"^max_distance must be a number > 0 \(inf: no limit\), got "):
        accel.closest_points([0, 0, 0], max_distance=value)


def test_bad_fields_and_an_empty_mesh(device):
    accel = clrt.Accel(primitives.icosphere(1), device=device)
    with pytest.raises(InputError, match="unknown point field 't': choose from point, distance, prim, u, v"):
        accel.closest_points([0, 0, 0], fields=("t",))
    with pytest.raises(InputError) as err:
        clrt.closest_points((np.zeros((0, 3)), np.zeros((0, 3), int)), [0, 0, 0], device=device)
    assert "\n" not in str(err.value)


def test_device_arrays_and_split_buffers_answer_as_numpy(device):
    """Points given as a pyopencl array give device arrays of the same values;
    a scene whose buffers come in parts (split.cl) answers as a whole one."""
    import pyopencl.array as cla
    mesh = primitives.icosphere(2)
    points = _points(mesh, seed=7)
    accel = clrt.Accel(mesh, device=device)
    host = accel.closest_points(points)
    on_device = accel.closest_points(cla.to_device(accel.queue, points))
    split = clrt.Accel(mesh, device=device, max_buffer_bytes=8192)
    assert split.geometry.parts() > 1
    parts = split.closest_points(points)
    for field in POINT_FIELDS:
        assert isinstance(getattr(on_device, field), cla.Array)
        np.testing.assert_array_equal(getattr(on_device, field).get(), getattr(host, field))
        np.testing.assert_array_equal(getattr(parts, field), getattr(host, field))
    with pytest.raises(InputError, match="point 3 is not finite: points must be finite"):
        bad = points.copy()
        bad[3, 1] = np.nan
        accel.closest_points(cla.to_device(accel.queue, bad))


def test_every_test_mesh_every_volume_as_brute_force(test_mesh, device):
    """The shared test meshes (open, closed, faceted, a duplicate triangle):
    every volume gives brute force's answers, and those the float64 reference's."""
    points = _points(test_mesh, seed=11)
    answers = [clrt.Accel(test_mesh, accel=accel, device=device).closest_points(points)
               for accel in ("none", "box", "sphere", "ellipse")]
    for got in answers[1:]:
        for field in POINT_FIELDS:
            np.testing.assert_array_equal(getattr(got, field), getattr(answers[0], field), err_msg=field)
    _check_against_reference(test_mesh, points, answers[0])


def test_equal_distances_go_to_the_lower_triangle(device):
    """Triangle 4 duplicates triangle 0: a point over it gets 0, by every walk."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, -1, -1], [0, -1, 1], [0, 1, 1]], float)
    mesh = Mesh.from_arrays(v, np.array([[4, 5, 6], [0, 2, 3], [5, 4, 6], [1, 2, 0], [0, 1, 2]]), "ties")
    points = np.array([[0.5, -0.2, 0.3], [0.5, -0.2, -0.3]])
    for accel in ("none", "box", "sphere", "ellipse"):
        got = clrt.Accel(mesh, accel=accel, leaf_size=1, device=device).closest_points(points)
        assert list(got.prim) == [3, 3], accel


def test_a_refitted_accel_answers_as_brute_force_on_the_moved_mesh(device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    points = _points(mesh, seed=13)
    accel = clrt.Accel(mesh, device=device)
    accel.refit(mesh.vertices * 1.3)
    got = accel.closest_points(points)
    want = clrt.Accel((mesh.vertices * 1.3, mesh.faces), accel="none", device=device).closest_points(points)
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)


def test_points_are_visited_in_cell_order_each_once(device):
    """point_order.cl: the launch's order is a permutation of its points, cells
    in Morton order (points outside the box and NaN clamp to border cells), and
    answers do not depend on it: a shuffled batch gives the shuffled answers."""
    import pyopencl as cl
    from clrt.config import POINT_CELL_BITS, POINT_CELLS
    from clrt.query.rays import PointBatch

    mesh = primitives.icosphere(2)
    rng = np.random.default_rng(11)
    points = np.concatenate([rng.normal(0, 0.7, (3000, 3)), rng.uniform(-3, 3, (500, 3)),
                             np.repeat(rng.uniform(-1, 1, (3, 3)), 400, axis=0)]).astype(np.float32)
    accel = clrt.Accel(mesh, device=device)
    batch = PointBatch(points, np.inf)
    accel._begin(batch)
    rays, launch = accel._ray_args(batch, 0, len(points), 0)
    order = accel._atomic_point_order(rays[0], launch)   # (CPU devices' order: tests/test_point_order.py)
    raw = np.empty(POINT_CELLS + 2 * len(points), np.uint32)
    cl.enqueue_copy(accel.queue, raw, order)
    cells, visit = raw[POINT_CELLS:POINT_CELLS + len(points)], raw[POINT_CELLS + len(points):]
    np.testing.assert_array_equal(np.sort(visit), np.arange(len(points)))
    assert (np.diff(cells[visit].astype(np.int64)) >= 0).all()   # cell by cell, in Morton order
    lo, hi = launch["scene_lo"][:3], launch["scene_hi"][:3]
    scaled = (points - launch["shift"][:3].astype(np.float64) - lo) / (hi - lo) * (1 << POINT_CELL_BITS)
    q = np.clip(np.floor(scaled).astype(np.int64), 0, (1 << POINT_CELL_BITS) - 1)
    morton = sum(((q[:, axis] >> b) & 1) << (3 * b + axis) for axis in range(3) for b in range(POINT_CELL_BITS))
    clear = (np.abs(scaled - np.round(scaled)) > 1e-3).all(axis=1)   # not on a cell border, where rounding decides
    assert clear.mean() > 0.9
    np.testing.assert_array_equal(cells[clear], morton[clear])
    whole = accel.closest_points(points)
    shuffle = rng.permutation(len(points))
    shuffled = accel.closest_points(points[shuffle])
    for field in POINT_FIELDS:
        np.testing.assert_array_equal(getattr(shuffled, field), getattr(whole, field)[shuffle])


def test_the_wide_walk_skips_nothing_brute_force_picks(device, monkeypatch):
    """CPU devices' walks of the wide BVH (point.cl's walk_wide_points: disks
    beside boxes, float32 lower bounds before each double precision test; and
    walk_wide_point_group, eight points at a time, the default) against the
    binary walk and brute force, bit for bit, on a 16k-triangle torus: points
    in its box (most far from the surface, where a child's box and disk are
    both near the best distance), near it and on it, also one a work-item."""
    from clrt.device import geometry

    mesh = primitives.torus(1.0, 0.35, 128, 64)
    rng = np.random.default_rng(17)
    corners = mesh.vertices[mesh.faces].astype(np.float64)
    f = rng.integers(len(corners), size=200)
    on = np.einsum("nk,nkj->nj", rng.dirichlet((1, 1, 1), size=200), corners[f])
    lo, hi = mesh.bounds
    points = np.concatenate([lo + rng.random((1500, 3)) * (hi - lo), on, on + 1e-3 * rng.normal(size=on.shape)])
    points = points.astype(np.float32)
    wide = clrt.Accel(mesh, device=device)
    if wide.geometry.wide is None:
        pytest.skip("the device under test does not walk the wide BVH")
    got = wide.closest_points(points)
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())   # one point a work-item: no seeds
    single = clrt.Accel(mesh, device=device)
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    binary = clrt.Accel(mesh, device=device)
    brute = clrt.Accel(mesh, accel="none", device=device).closest_points(points)
    assert single.rays_per_item == 1 and binary.geometry.wide is None
    for other in (single.closest_points(points), binary.closest_points(points), brute):
        for field in POINT_FIELDS:
            np.testing.assert_array_equal(getattr(got, field), getattr(other, field), err_msg=field)
    np.testing.assert_array_equal(wide.signed_distance(points, sign="normal"),
                                  brute_normal := binary.signed_distance(points, sign="normal"))
    assert (brute_normal < 0).any()


@pytest.mark.parametrize("lanes, candidates", [(None, None), (None, 1), (8, None)])
def test_points_walked_in_groups_answer_as_one_at_a_time(lanes, candidates, device, monkeypatch):
    """CPU devices' closest points many at a time (point_group.cl's
    walk_wide_point_group: the group's box before each point's bounds, float32
    upper bounds, triangles visited at the end, each group seeded by the one
    before; float16 or float8 lanes) against the walk of one point at a time
    and brute force, bit for bit: on the axis of a torus (a ring of triangles
    at one distance, more than a point keeps to visit: with candidates=1
    nearly every triangle overflows and is visited at once), points far
    outside the box (groups of points far apart), copies of one point, points
    on and near the surface, points beyond max_distance (misses beside hits
    in a group), in chunks that end inside a group; signed distances too."""
    from clrt import config
    from clrt.device import geometry
    from clrt.query import points as point_queries

    for name, value in (("POINT_LANES", lanes), ("POINT_CANDIDATES", candidates)):
        if value is not None:
            monkeypatch.setattr(point_queries, name, value)
    mesh = primitives.torus(1.0, 0.35, 96, 48)
    rng = np.random.default_rng(23)
    corners = mesh.vertices[mesh.faces].astype(np.float64)
    f = rng.integers(len(corners), size=300)
    on = np.einsum("nk,nkj->nj", rng.dirichlet((1, 1, 1), size=300), corners[f])
    lo, hi = mesh.bounds
    axis = np.zeros((120, 3))
    axis[:, 2] = rng.uniform(-0.5, 0.5, 120)
    axis[::3, :2] = 1e-4 * rng.normal(size=(40, 2))
    points = np.concatenate([axis, 40 * rng.normal(size=(200, 3)), np.repeat(rng.uniform(lo, hi, (5, 3)), 30, axis=0),
                             on, on + 0.02 * rng.normal(size=on.shape), lo + rng.random((1500, 3)) * (hi - lo)])
    points = rng.permutation(points).astype(np.float32)
    grouped = clrt.Accel(mesh, device=device, chunk_rays=1000)
    if not grouped.point_defines:
        pytest.skip("the device under test does not walk points in groups")
    assert grouped.point_defines["POINT_CANDIDATES"] == (candidates or config.POINT_CANDIDATES)
    assert grouped.point_defines["POINT_LANES"] == (lanes or config.POINT_LANES)
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())   # one point a work-item
    single = clrt.Accel(mesh, device=device)
    brute = clrt.Accel(mesh, accel="none", device=device)
    assert not single.point_defines
    for max_distance in (np.inf, 0.3):
        got = grouped.closest_points(points, max_distance=max_distance)
        assert 0 < (got.prim < 0).sum() < len(points) / 2 if max_distance < 1 else (got.prim >= 0).all()
        for other in (single, brute):
            want = other.closest_points(points, max_distance=max_distance)
            for field in POINT_FIELDS:
                np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
    for sign in ("normal", "parity"):
        np.testing.assert_array_equal(grouped.signed_distance(points, sign=sign),
                                      single.signed_distance(points, sign=sign))


def test_every_wide_child_s_triangles_lie_in_its_disk():
    """clrt/accel/disks.py against a float64 check: every corner of every
    triangle under each child of each wide node lies within the child's
    cylinder (its radius from the axis, half_height along it), and the axis
    is unit; empty lanes hold zeros."""
    from clrt.accel import build
    from clrt.accel.disks import child_slots, wide_disks
    from clrt.accel.wide import collapse

    mesh = primitives.torus(1.0, 0.35, 48, 24)
    corners = mesh.vertices[mesh.faces].astype(np.float32)
    acceleration = build(corners, "box", "sah", 2)
    slotted = corners[acceleration.slot_order()]
    wide = collapse(acceleration.rows, slotted)
    disks = wide_disks(acceleration.rows, wide.sources, slotted)
    first, size = child_slots(acceleration.rows)
    assert size[0] + size[1] == len(corners)   # the root row's two children hold every slot
    checked = 0
    for node, lanes in enumerate(wide.sources):
        for k, child in enumerate(lanes):
            values = {name: float(disks[name][node][k]) for name in disks.dtype.names}
            if child < 0:
                assert not any(values.values())
                continue
            c = np.array([values["cx"], values["cy"], values["cz"]])
            n = np.array([values["nx"], values["ny"], values["nz"]])
            assert abs(np.linalg.norm(n) - 1) < 1e-6
            x = slotted[first[child]:first[child] + size[child]].reshape(-1, 3).astype(np.float64) - c
            height = x @ n
            assert np.abs(height).max() <= values["half_height"]
            assert np.linalg.norm(x - height[:, None] * n, axis=1).max() <= values["radius"]
            checked += 1
    assert checked > 2 * len(wide.sources)

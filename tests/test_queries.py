"""Ray queries for library users (clrt.trace, clrt.intersector): result arrays and
their sentinels, one input path for every query, culling, counts and all hits
in one traversal, chunked batches, the trimesh-compatible intersector against
trimesh's own numpy intersector, and camera images against closed forms."""

import math

import numpy as np
import pytest
import trimesh

import clrt
from clrt.cli import main
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera

from conftest import TEST_MESHES



def _rays(mesh, count, seed=0, spread=1.2):
    """Rays from a sphere around the mesh towards random points near it: most hit."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo)
    o = rng.normal(size=(count, 3))
    o = centre + 1.5 * radius * o / np.linalg.norm(o, axis=1, keepdims=True)
    target = centre + spread * (rng.random((count, 3)) - 0.5) * (hi - lo)
    return o, target - o


def _all_hits_numpy(o, d, corners, eps=1e-12):
    """Every (ray, triangle, t) with t > 0, Moeller-Trumbore in float64."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    v0, e1, e2 = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    p = np.cross(d[:, None], e2[None])                       # (N, F, 3)
    det = np.einsum("fk,nfk->nf", e1, p)
    ok = np.abs(det) > eps
    inv = np.where(ok, 1 / np.where(ok, det, 1), 0)
    s = o[:, None] - v0[None]
    u = np.einsum("nfk,nfk->nf", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("nk,nfk->nf", d, q) * inv
    t = np.einsum("fk,nfk->nf", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    ray, tri = np.nonzero(hit)
    return ray, tri, t[ray, tri]


@pytest.fixture(scope="module")
def torus_accel(device):
    return clrt.Accel(primitives.torus(1.0, 0.35, 24, 12), device=device)


# --------------------------------------------------------------------------- one input path

def test_single_batched_chunked_and_any_dtype_give_the_same_answers(torus_accel, device):
    acc = torus_accel
    o, d = _rays(acc.mesh, 300, seed=1)
    o16, d16 = o.astype(np.float16), d.astype(np.float16)
    base = acc.trace(o16.astype(np.float64), d16.astype(np.float64))
    small = clrt.Accel(acc.mesh, device=device, chunk_rays=7)
    for hits in (acc.trace(o16, d16), acc.trace(o16.astype(np.float32), d16), small.trace(o16, d16)):
        for field in base._fields:
            assert np.array_equal(getattr(hits, field), getattr(base, field)), field
    for i in (0, 5, 17, 123):   # one ray, shape (3,)
        one = acc.trace(o16[i], d16[i])
        assert one.t.shape == (1,) and one.normal.shape == (1, 3)
        for field in base._fields:
            assert np.array_equal(getattr(one, field)[0], getattr(base, field)[i]), field
    assert np.array_equal(small.any_hit(o16, d16), acc.any_hit(o16, d16))
    assert np.array_equal(small.count(o16, d16), acc.count(o16, d16))
    for a, b in zip(small.all_hits(o16, d16), acc.all_hits(o16, d16)):
        assert np.array_equal(a, b)
    # integer input; one origin broadcast to many directions
    ints = acc.trace(np.array([0, 3, 0]), np.array([[0, -1, 0], [1, -3, 0], [0, 0, 1]]))
    assert np.array_equal(ints.prim, acc.trace([[0.0, 3, 0]] * 3, [[0, -1, 0], [1, -3, 0], [0, 0, 1.0]]).prim)


def test_directions_are_normalised_as_in_float64_also_near_unit_length(torus_accel):
    # rays.cl skips the square root and the division for a direction whose
    # square is within 2^-24 (1 - 2^-12) of 1, where they could not change it.
    # Directions whose lengths straddle that bound must still give the hits of
    # their float64 normalisation (t is measured along it): a bound too wide
    # keeps a direction that is not unit length, and every t moves.
    acc = torus_accel
    o, d = _rays(acc.mesh, 400, seed=11)
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    steps = np.array([0, 1, 3, 5, 7, 8, 9, 12, 16, 40, -1, -3, -5, -7, -8, -9, -12, -16, -40])
    scaled = (unit * (1 + steps[np.arange(len(d)) % len(steps)] * 2.0**-28)[:, None]).astype(np.float32)
    d64 = scaled.astype(np.float64)
    square = d64[:, 0] * d64[:, 0] + d64[:, 1] * d64[:, 1] + d64[:, 2] * d64[:, 2]
    expected = (d64 / np.sqrt(square)[:, None]).astype(np.float32)
    bound = 2.0**-24 * (1 - 2.0**-12)
    e64 = expected.astype(np.float64)
    kept = np.abs((e64 * e64).sum(1) - 1) < bound       # the device takes these as they are
    o, scaled, expected, square = o[kept], scaled[kept], expected[kept], square[kept]
    near = np.abs(square - 1) < bound
    assert 0.3 < near.mean() < 0.9 and (expected[~near] != scaled[~near]).any()
    got, want = acc.trace(o, scaled), acc.trace(o, expected)
    assert got.hit.mean() > 0.5
    for field in want._fields:
        assert np.array_equal(getattr(got, field), getattr(want, field)), field


def test_tmin_tmax_per_call_and_per_ray(torus_accel):
    acc = torus_accel
    o, d = _rays(acc.mesh, 200, seed=2)
    every = acc.all_hits(o, d)
    first = acc.trace(o, d)
    per_ray_tmax = np.where(first.hit, first.t * 0.999, np.inf)
    assert not acc.trace(o, d, tmax=per_ray_tmax).hit[first.hit].any()
    assert not acc.any_hit(o, d, tmax=per_ray_tmax)[first.hit].any()
    assert np.array_equal(acc.trace(o, d, tmax=first.t).prim, first.prim)        # t <= tmax counts
    # starting past the first hit finds the second one
    second = acc.trace(o, d, tmin=np.where(first.hit, first.t, 0))
    counts = np.bincount(every.ray_id, minlength=len(o))
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    two = np.nonzero(counts >= 2)[0]
    assert len(two)
    two = two[every.t[starts[two] + 1] > every.t[starts[two]]]     # a distinct second distance
    assert np.array_equal(second.t[two], every.t[starts[two] + 1])
    # a window keeps exactly the hits inside it
    lo, hi = 2.0, 3.0
    windowed = acc.all_hits(o, d, tmin=lo, tmax=hi)
    inside = (every.t > lo) & (every.t <= hi)
    assert np.array_equal(windowed.ray_id, every.ray_id[inside])
    assert np.array_equal(acc.count(o, d, tmin=lo, tmax=hi), np.bincount(every.ray_id[inside], minlength=len(o)))
    assert ((windowed.t > lo) & (windowed.t <= hi)).all()


@pytest.mark.parametrize("call", [
    lambda a: a.trace([0, 0, 5], [0, 0, 0]),
    lambda a: a.trace([0, 0, np.nan], [0, 0, 1]),
    lambda a: a.trace([0, 0, 5], [np.inf, 0, 1]),
    lambda a: a.trace(np.zeros((3, 3)), np.ones((2, 3))),
    lambda a: a.trace(np.zeros((3, 2)), np.ones((3, 2))),
    lambda a: a.trace(np.zeros((2, 3)), np.ones((2, 3)), tmax=[1.0, 2.0, 3.0]),
    lambda a: a.any_hit(np.zeros((2, 3)), np.ones((2, 3)), tmin=np.nan),
    lambda a: a.count([1j, 0, 0], [0, 0, 1]),
    lambda a: a.all_hits([["a", "b", "c"]], [[0, 0, 1]]),
    lambda a: a.trace([0, 0, 5], [0, 0, -1], cull="sideways"),
    lambda a: a.camera_images(K=np.eye(3), width=4),
    lambda a: a.camera_images(K=np.eye(3), width=4, height=4, pose=np.diag([1, 1, -1, 1.0])),
    lambda a: a.camera_images(K=np.zeros((3, 3)), width=4, height=4),
], ids=["zero dir", "nan origin", "inf dir", "counts differ", "not 3d", "tmax shape", "nan tmin",
        "complex", "strings", "cull", "no height", "reflection pose", "singular K"])
def test_bad_input_is_an_input_error(torus_accel, call):
    with pytest.raises(clrt.InputError):
        call(torus_accel)


@pytest.mark.parametrize("chunk_rays", [None, 7])
def test_the_first_bad_ray_is_named_by_its_index(torus_accel, chunk_rays):
    """The kernels check every ray (rays.cl); the error names the lowest bad ray
    of a batch, in any chunk, and the value the caller gave."""
    acc = clrt.Accel(torus_accel.mesh, chunk_rays=chunk_rays, device=None) if chunk_rays else torus_accel
    o, d = _rays(acc.mesh, 40, seed=3)
    d[23] = 0.0
    d[31] = np.nan
    o[29, 1] = np.inf
    for query in (acc.trace, acc.any_hit, acc.count, acc.all_hits):
        with pytest.raises(clrt.InputError, match=r"^direction 23 is \[0\.0, 0\.0, 0\.0\]: directions must be"):
            query(o, d)
    d[23] = 1.0
    with pytest.raises(clrt.InputError, match=r"^origin 29 is \[.*inf.*\]: origins must be finite"):
        acc.trace(o, d)
    o[29, 1] = 0.0
    tmax = np.full(40, 5.0)
    tmax[17] = np.nan
    with pytest.raises(clrt.InputError, match=r"tmax of ray 17 is nan: tmax must not be NaN"):
        acc.trace(o, d, tmax=tmax)
    with pytest.raises(clrt.InputError, match=r"direction 31"):
        acc.trace(o, d)
    d[31] = 1.0
    assert acc.trace(o, d).t.shape == (40,)          # all good again, the same Accel


def test_fields_and_device_arrays(torus_accel):
    """Only the fields asked for are computed and returned; rays given as device
    arrays give device arrays back, equal to the numpy path."""
    cla = pytest.importorskip("pyopencl.array")
    acc = torus_accel
    o, d = _rays(acc.mesh, 3000, seed=5)
    full = acc.trace(o, d)
    some = acc.trace(o, d, fields=("prim", "t"))
    assert some.u is None and some.normal is None and some.hit is None
    assert np.array_equal(some.t, full.t) and np.array_equal(some.prim, full.prim)
    with pytest.raises(clrt.InputError, match="unknown hit field 'depth'"):
        acc.trace(o, d, fields=("t", "depth"))
    o32, d32 = o.astype(np.float32), d.astype(np.float32)
    o_dev, d_dev = cla.to_device(acc.queue, o32), cla.to_device(acc.queue, d32)
    small = clrt.Accel(acc.mesh, chunk_rays=1000)           # device arrays across several chunks
    for accel in (acc, small):
        on_device = accel.trace(o_dev, d_dev)
        assert isinstance(on_device.t, cla.Array) and isinstance(on_device.normal, cla.Array)
        for name in full._fields:     # the flags come as uint8 0 / 1 on the device
            assert np.array_equal(getattr(on_device, name).get(), getattr(full, name)), name
        assert np.array_equal(accel.any_hit(o_dev, d_dev).get(), full.hit.astype(np.uint8))
        assert np.array_equal(accel.count(o_dev, d_dev).get(), accel.count(o, d))
        # a device array beside host arrays and a single shared origin
        shared = accel.trace(o32[0], d_dev, tmax=cla.to_device(acc.queue, np.full(len(d32), 2.5, np.float32)))
        expected = acc.trace(o32[0], d32, tmax=2.5)
        assert np.array_equal(shared.t.get(), expected.t) and np.array_equal(shared.prim.get(), expected.prim)


def test_results_kept_by_the_caller_are_never_overwritten(torus_accel):
    """Results live in pooled page-locked memory (clrt/device/pinned.py): a block
    is reused only once nothing refers to any of its arrays."""
    acc = torus_accel
    batches = [_rays(acc.mesh, 5000, seed=s) for s in range(6)]
    kept = [acc.trace(o, d) for o, d in batches]             # more results than the pool holds
    copies = [tuple(np.copy(a) for a in h) for h in kept]
    prim_only = kept[0].prim                                  # one field keeps its whole block in use
    del kept[0]
    for o, d in batches:
        acc.trace(o, d)
        acc.any_hit(o, d)
    assert np.array_equal(prim_only, copies[0][clrt.Hits._fields.index("prim")])
    for hits, copy in zip(kept, copies[1:]):
        for a, b in zip(hits, copy):
            assert np.array_equal(a, b)
    assert acc.result_pool.buffers() <= 3


def test_empty_batches(torus_accel):
    acc = torus_accel
    none = np.zeros((0, 3))
    hits = acc.trace(none, none)
    assert hits.t.shape == (0,) and hits.normal.shape == (0, 3)
    assert acc.any_hit(none, none).shape == (0,) and acc.count(none, none).shape == (0,)
    assert all(len(a) == 0 for a in acc.all_hits(none, none))
    with pytest.raises(clrt.InputError):
        clrt.Accel(acc.mesh, chunk_rays=0)


# --------------------------------------------------------------------------- the result arrays

def test_sentinels_normals_front_and_barycentrics(test_mesh, device):
    acc = clrt.Accel(test_mesh, device=device)
    o, d = _rays(test_mesh, 400, seed=3, spread=2.0)
    hits = acc.trace(o, d)
    miss, hit = ~hits.hit, hits.hit
    assert miss.any() and hit.any()
    assert np.array_equal(hits.hit, hits.prim >= 0)
    assert np.isinf(hits.t[miss]).all() and (hits.prim[miss] == -1).all()
    assert (hits.u[miss] == 0).all() and (hits.v[miss] == 0).all()
    assert (hits.normal[miss] == 0).all() and not hits.front[miss].any()
    assert hits.t.dtype == np.float32 and hits.prim.dtype == np.int32 and hits.normal.dtype == np.float32
    face_n = test_mesh.face_normals()
    np.testing.assert_allclose(hits.normal[hit], face_n[hits.prim[hit]], atol=1e-6)
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", face_n[hits.prim[hit]], unit[hit])
    clear = np.abs(cos) > 1e-3
    assert np.array_equal(hits.front[hit][clear], cos[clear] < 0)
    u, v = hits.u[hit], hits.v[hit]
    assert (u >= 0).all() and (v >= 0).all() and (u + v <= 1 + 1e-6).all()
    corners = test_mesh.vertices[test_mesh.faces[hits.prim[hit]]].astype(np.float64)
    point = ((1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + v[:, None] * corners[:, 2])
    np.testing.assert_allclose(point, o[hit] + hits.t[hit][:, None] * unit[hit], atol=2e-5)


def test_culling_on_a_closed_box(device):
    box = primitives.box((2.0, 2.0, 2.0))        # wound outwards
    acc = clrt.Accel(box, device=device)
    rng = np.random.default_rng(4)
    target = rng.uniform(-0.6, 0.6, (200, 3))
    outside = np.tile([0.3, 0.2, 5.0], (200, 1))
    d = target - outside
    none, back, front = (acc.trace(outside, d, cull=c) for c in ("none", "back", "front"))
    assert none.hit.all() and none.front.all()
    assert np.array_equal(back.prim, none.prim) and np.array_equal(back.t, none.t)
    assert front.hit.all() and not front.front.any() and (front.t > none.t).all()
    assert (acc.count(outside, d) == 2).all()
    assert (acc.count(outside, d, cull="back") == 1).all() and (acc.count(outside, d, cull="front") == 1).all()
    assert np.array_equal(acc.all_hits(outside, d, cull="front").t, front.t)
    # from inside, the first wall is seen from behind
    inside = np.zeros((200, 3))
    assert not acc.trace(inside, d, cull="back").hit.any()
    assert not acc.any_hit(inside, d, cull="back").any()
    assert np.array_equal(acc.trace(inside, d, cull="front").prim, acc.trace(inside, d).prim)


def test_queries_agree_with_each_other_and_with_numpy(test_mesh, device):
    acc = clrt.Accel(test_mesh, device=device)
    o, d = _rays(test_mesh, 300, seed=5)
    first, anyhit, count, every = acc.trace(o, d), acc.any_hit(o, d), acc.count(o, d), acc.all_hits(o, d)
    assert every.ray_id.dtype == np.int64 and every.prim.dtype == np.int32 and every.t.dtype == np.float32
    assert np.array_equal(np.bincount(every.ray_id, minlength=len(o)), count)
    assert np.array_equal(count > 0, anyhit) and np.array_equal(anyhit, first.hit)
    order = np.lexsort((every.prim, every.t, every.ray_id))
    assert np.array_equal(order, np.arange(len(order))), "sorted by ray, t, triangle"
    starts = np.r_[0, np.cumsum(count)[:-1]][count > 0]
    assert np.array_equal(every.t[starts], first.t[count > 0])
    ray, tri, t = _all_hits_numpy(o, d, test_mesh.vertices[test_mesh.faces].astype(np.float64))
    assert (np.bincount(ray, minlength=len(o)) == count).mean() >= 0.99
    ours = set(zip(every.ray_id.tolist(), every.prim.tolist()))
    theirs = set(zip(ray.tolist(), tri.tolist()))
    assert len(ours ^ theirs) <= 0.01 * len(theirs)
    numpy_t = dict(zip(zip(ray.tolist(), tri.tolist()), t))
    pairs = list(zip(every.ray_id.tolist(), every.prim.tolist()))
    common = np.array([k in numpy_t for k in pairs])
    np.testing.assert_allclose(every.t[common], [numpy_t[k] for k, c in zip(pairs, common) if c],
                               rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("volume, builder, leaf", [("box", "sah", 1), ("sphere", "paper", 4), ("ellipse", "sah", 4)])
def test_every_bvh_answers_every_query_like_brute_force(volume, builder, leaf, device):
    mesh = TEST_MESHES["crossing"]()
    o, d = _rays(mesh, 300, seed=6, spread=1.5)
    base = clrt.Accel(mesh, accel="none", device=device)
    acc = clrt.Accel(mesh, accel=volume, builder=builder, leaf_size=leaf, device=device)
    for cull in ("none", "back", "front"):
        a, b = acc.trace(o, d, cull=cull), base.trace(o, d, cull=cull)
        for field in a._fields:
            assert np.array_equal(getattr(a, field), getattr(b, field)), (cull, field)
        assert np.array_equal(acc.count(o, d, cull=cull), base.count(o, d, cull=cull))
        for x, y in zip(acc.all_hits(o, d, cull=cull), base.all_hits(o, d, cull=cull)):
            assert np.array_equal(x, y), cull
    assert (base.count(o, d) >= 2).any(), "coincident triangles are both counted"


def _stack_of_quads(layers=12) -> Mesh:
    v, f = [], []
    for k in range(layers):
        base = len(v)
        v += [[-1, -1, k], [1, -1, k], [1, 1, k], [-1, 1, k]]
        f += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return Mesh.from_arrays(np.array(v, float), np.array(f))


def test_all_hits_overflow_and_split_lose_nothing(device):
    mesh = _stack_of_quads()
    rng = np.random.default_rng(7)
    o = np.column_stack([rng.uniform(-0.9, 0.9, (500, 2)), np.full(500, -1.0)])
    d = np.tile([0.0, 0.0, 1.0], (500, 1))
    reference = clrt.Accel(mesh, device=device).all_hits(o, d)
    assert len(reference.t) == 500 * 12 and (np.bincount(reference.ray_id) == 12).all()
    grow = clrt.Accel(mesh, device=device)
    grow._hits_per_ray = 0.01                  # first launch has room for 1,024 of 6,000 hits
    split = clrt.Accel(mesh, device=device, chunk_rays=128)
    split.all_hits_capacity = 100              # fewer than one chunk's hits: chunks are halved
    for acc in (grow, split):
        for a, b in zip(acc.all_hits(o, d), reference):
            assert np.array_equal(a, b)
    assert split.memory()["all_hits"] == 1600                 # 16 bytes a hit
    split.all_hits_capacity = 5
    with pytest.raises(clrt.InputError, match="meets 12 triangles"):
        split.all_hits(o[:1], d[:1])


def test_chunks_respect_the_allocation_limit_and_launch_size(torus_accel, device):
    acc = clrt.Accel(torus_accel.mesh, device=device, chunk_rays=1000)
    o, d = _rays(acc.mesh, 4500, seed=8)
    hits = acc.trace(o, d)
    # Chunk buffers hold 1000 rays: 12 bytes of origin and of direction each, 34 of results.
    assert acc._buffers["in_0"].size <= 1000 * 12 and acc._buffers["in_1"].size <= 1000 * 12
    assert acc._buffers["results"].size <= 1000 * 34
    for field in hits._fields:
        assert np.array_equal(getattr(hits, field), getattr(torus_accel.trace(o, d), field))
    acc.chunk_rays = None
    acc.max_alloc = 34 * 100
    # 100 rays' results fit; where a work-item takes a packet of 8 (CPU devices), whole packets: 96
    assert acc.chunk_size() == (100 if acc.rays_per_item == 1 else 96)
    small = acc.trace(o, d)   # in chunks of at most 100 rays
    assert all(np.array_equal(getattr(small, f), getattr(hits, f)) for f in hits._fields)
    brute = clrt.Accel(acc.mesh, accel="none", device=device)
    assert brute.chunk_size() == min(1 << 20, (1 << 30) // len(acc.mesh.faces))
    assert torus_accel.chunk_size() == 1 << 20
    memory = torus_accel.memory()
    assert memory["chunk"] == (1 << 20) * (32 + 34) and memory["scene"] > 0


# --------------------------------------------------------------------------- trimesh compatibility

class _BoxTree:
    """What trimesh's numpy intersector asks of an rtree index, in plain numpy
    (the rtree package is optional): triangle boxes overlapping a query box."""

    def __init__(self, triangles):
        self.lo, self.hi = triangles.min(axis=1), triangles.max(axis=1)
        self.bounds = np.r_[self.lo.min(axis=0), self.hi.max(axis=0)]

    def intersection(self, box):
        box = np.asarray(box)
        return np.nonzero(((self.lo <= box[3:]) & (self.hi >= box[:3])).all(axis=1))[0]


def _trimesh_numpy(tm):
    """trimesh's own numpy RayMeshIntersector (its r-tree replaced by _BoxTree
    when rtree is not installed)."""
    from trimesh.ray import ray_triangle
    try:
        import rtree  # noqa: F401
        return ray_triangle.RayMeshIntersector(tm)
    except ImportError:
        pass

    class WithoutRtree(ray_triangle.RayMeshIntersector):
        def intersects_id(self, ray_origins, ray_directions, return_locations=False, multiple_hits=True, **kw):
            tri, ray, loc = ray_triangle.ray_triangle_id(
                self.mesh.triangles, ray_origins, ray_directions, tree=_BoxTree(self.mesh.triangles),
                multiple_hits=multiple_hits, triangles_normal=self.mesh.face_normals)
            if not return_locations:
                return tri, ray
            if len(tri) == 0:
                return tri, ray, loc
            unique = trimesh.grouping.unique_rows(np.column_stack((loc, ray)))[0]
            return tri[unique], ray[unique], loc[unique]

    return WithoutRtree(tm)


def _per_ray_sets(ray, tri):
    out = {}
    for r, t in zip(ray.tolist(), tri.tolist()):
        out.setdefault(r, set()).add(t)
    return out


@pytest.mark.parametrize("name", ["icosphere", "torus", "box", "heightfield"])
def test_intersector_matches_trimesh_numpy(name, device):
    mesh = TEST_MESHES[name]()
    tm = trimesh.Trimesh(mesh.vertices.astype(np.float64), mesh.faces, process=False)
    ours, ref = clrt.RayMeshIntersector(tm, device=device), _trimesh_numpy(tm)
    o, d = _rays(mesh, 400, seed=9)
    first, ref_first = ours.intersects_first(o, d), ref.intersects_first(o, d)
    assert first.dtype == np.int64 and first.shape == (400,)
    assert (first == ref_first).mean() >= 0.99
    anyhit = ours.intersects_any(o, d)
    assert anyhit.dtype == bool and (anyhit == ref.intersects_any(o, d)).mean() >= 0.99
    tri, ray = ours.intersects_id(o, d, every_triangle=True)     # as the numpy engine lists them
    ref_tri, ref_ray = ref.intersects_id(o, d)
    assert tri.dtype == np.int64 and ray.dtype == np.int64
    mine, theirs = _per_ray_sets(ray, tri), _per_ray_sets(ref_ray, ref_tri)
    assert sum(mine.get(r) == theirs.get(r) for r in range(len(o))) >= 0.98 * len(o)
    loc, lray, ltri = ours.intersects_location(o, d)
    ref_loc, ref_lray, _ = ref.intersects_location(o, d)
    assert loc.dtype == np.float64 and loc.shape == (len(lray), 3)
    counts, ref_counts = np.bincount(lray, minlength=len(o)), np.bincount(ref_lray, minlength=len(o))
    assert (counts == ref_counts).mean() >= 0.98
    scale = float(np.linalg.norm(tm.extents))
    for r in np.nonzero(counts == ref_counts)[0][:100]:
        a = loc[lray == r]
        b = ref_loc[ref_lray == r]
        b = b[np.argsort(np.linalg.norm(b - o[r], axis=1))]
        np.testing.assert_allclose(a, b, atol=1e-5 * scale)
    first_tri, first_ray, first_loc = ours.intersects_id(o, d, multiple_hits=False, return_locations=True)
    assert np.array_equal(first_ray, np.nonzero(first >= 0)[0]) and np.array_equal(first_tri, first[first >= 0])
    assert len(first_loc) == len(first_ray)
    if tm.is_watertight:
        lo, hi = tm.bounds
        points = np.random.default_rng(10).uniform(lo - 0.1, hi + 0.1, (1000, 3))
        contains = ours.contains_points(points)
        assert contains.any() and (contains == ref.contains_points(points)).mean() >= 0.99


def test_one_line_switch_on_a_trimesh_mesh(device):
    tm = trimesh.creation.icosphere(subdivisions=3)
    points = np.random.default_rng(11).uniform(-1.2, 1.2, (500, 3))
    inside = np.linalg.norm(points, axis=1) < 1
    tm.ray = clrt.RayMeshIntersector(tm, device=device)          # the switch
    near = np.abs(np.linalg.norm(points, axis=1) - 1) < 0.02
    assert np.array_equal(tm.contains(points)[~near], inside[~near])
    loc, ray, tri = tm.ray.intersects_location([[0, 0, 5]], [[0, 0, -1]])
    np.testing.assert_allclose(np.sort(loc[:, 2]), [-1, 1], atol=2e-3)
    assert np.array_equal(ray, [0, 0])
    # a moved mesh is uploaded again
    tm.apply_translation([0, 0, 10])
    loc, _, _ = tm.ray.intersects_location([[0, 0, 20]], [[0, 0, -1]])
    np.testing.assert_allclose(np.sort(loc[:, 2]), [9, 11], atol=2e-3)
    assert tm.ray.intersects_id([[0, 0, 20]], [[0, 0, -1]], max_hits=1)[0].shape == (1,)


# --------------------------------------------------------------------------- camera images

def _quad(z, half, facing_camera=True) -> Mesh:
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
    f = np.array([[0, 2, 1], [0, 3, 2]]) if facing_camera else np.array([[0, 1, 2], [0, 2, 3]])
    return Mesh.from_arrays(v, f)


def _pixel_rays(K, w, h, c=0.0):
    x, y = np.meshgrid(np.arange(w) + c, np.arange(h) + c)
    p = np.stack([x, y, np.ones_like(x)], axis=-1)
    return p @ np.linalg.inv(K).T            # (h, w, 3), z = 1


def test_pinhole_images_of_a_plane(device):
    w, h = 40, 30
    K = np.array([[35.0, 0, 19.5], [0, 35.0, 14.5], [0, 0, 1]])
    plane = _quad(5.0, 2.0)                   # z = 5, wound to face the camera at the origin
    images = clrt.Accel(plane, device=device).camera_images(K=K, width=w, height=h)
    rays = _pixel_rays(K, w, h)
    x, y = rays[..., 0] * 5, rays[..., 1] * 5
    expect_hit = (np.abs(x) < 2) & (np.abs(y) < 2)
    edge = (np.abs(np.abs(x) - 2) < 1e-3) | (np.abs(np.abs(y) - 2) < 1e-3)
    assert np.array_equal(images.hit[~edge], expect_hit[~edge]) and (~expect_hit).any()
    hit = images.hit
    np.testing.assert_allclose(images.depth[hit], 5.0, rtol=1e-6)
    np.testing.assert_allclose(images.t[hit], 5 * np.linalg.norm(rays, axis=-1)[hit], rtol=1e-6)
    np.testing.assert_allclose(images.normal[hit], np.tile([0, 0, -1.0], (int(hit.sum()), 1)), atol=1e-7)
    assert images.front[hit].all()
    assert np.isinf(images.depth[~hit]).all() and (images.prim[~hit] == -1).all()
    assert (images.normal[~hit] == 0).all()
    # the diagonal from (-2,-2) to (2,2) splits the two triangles
    off = np.abs(x - y) > 1e-3
    assert np.array_equal(images.prim[hit & off], np.where(y > x, 1, 0)[hit & off])
    assert images.depth.dtype == np.float32 and images.prim.dtype == np.int32
    assert images.normal.shape == (h, w, 3) and images.hit.dtype == bool
    # back side: the same plane wound the other way
    flipped = clrt.Accel(_quad(5.0, 2.0, facing_camera=False), device=device)
    back = flipped.camera_images(K=K, width=w, height=h)
    assert not back.front[back.hit].any() and np.array_equal(back.hit, images.hit)
    assert not flipped.camera_images(K=K, width=w, height=h, cull="back").hit.any()
    # the other pixel-centre convention moves every ray by half a pixel
    half = clrt.Accel(plane, device=device).camera_images(K=K, width=w, height=h, pixel_center=0.5)
    shifted = _pixel_rays(K, w, h, 0.5)
    np.testing.assert_allclose(half.t[half.hit], 5 * np.linalg.norm(shifted, axis=-1)[half.hit], rtol=1e-6)


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def test_pinhole_images_of_a_sphere_with_a_pose(device):
    w, h, r = 48, 36, 1.0
    centre = np.array([3.0, -1.0, 2.0])
    sphere = primitives.icosphere(5, r, centre)          # faceted: within ~2e-4 of the true sphere
    K = np.array([[40.0, 0, 23.5], [0, 42.0, 17.5], [0, 0, 1]])
    R = _rotation([0.3, 1.0, -0.2], 0.7)
    eye = centre - 4.0 * R[:, 2] + 0.2 * R[:, 0]        # the sphere a little left of the view axis
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R, eye
    images = clrt.Accel(sphere, device=device).camera_images(K=K, pose=pose, width=w, height=h)
    cam = _pixel_rays(K, w, h)
    d = cam @ R.T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = centre - eye
    along = d @ oc
    miss_by = np.linalg.norm(oc - along[..., None] * d, axis=-1)
    expect_hit = miss_by < r
    sure = np.abs(miss_by - r) > 0.01
    assert np.array_equal(images.hit[sure], expect_hit[sure]) and expect_hit.any() and (~expect_hit).any()
    both = images.hit & expect_hit & (miss_by < 0.95 * r)
    t = along - np.sqrt(np.maximum(r * r - miss_by ** 2, 0))
    np.testing.assert_allclose(images.t[both], t[both], atol=1e-3)
    cos = (cam / np.linalg.norm(cam, axis=-1, keepdims=True))[..., 2]
    np.testing.assert_allclose(images.depth[both], (t * cos)[both], atol=1e-3)
    point = eye + t[..., None] * d
    normal = (point - centre) / r
    assert (np.einsum("ij,ij->i", images.normal[both], normal[both]) > 0.999).all()
    assert images.front[both].all()


def test_camera_images_of_our_camera_are_the_renderers_rays(device):
    sphere = primitives.icosphere(4, 1.0, (0.2, 0.1, 0.0))
    camera = Camera((0.5, 0.8, 4.0), (0.0, 0.0, 0.0), fov=40, width=32, height=24)
    acc = clrt.Accel(sphere, device=device)
    images = acc.camera_images(camera)
    frame = clrt.Renderer(clrt.scene_from_mesh(sphere), device=device).render(camera, hits=True)
    assert np.array_equal(images.prim, frame.prim) and np.array_equal(images.t, frame.t)
    assert np.array_equal(acc.trace_camera(camera).prim, frame.prim)
    from clrt.reference import camera_rays
    o, d = camera_rays(camera)
    forward = camera.basis()[0]
    hit = images.hit
    np.testing.assert_allclose(images.depth[hit], (images.t * (d @ forward).reshape(24, 32))[hit], rtol=1e-6)
    # closed form: distance to the sphere along each ray
    oc = np.array([0.2, 0.1, 0.0]) - o[0]
    along = d.astype(np.float64) @ oc
    miss_by = np.linalg.norm(oc - along[:, None] * d, axis=1)
    inner = (miss_by < 0.9).reshape(24, 32)
    t = (along - np.sqrt(np.maximum(1 - miss_by ** 2, 0))).reshape(24, 32)
    np.testing.assert_allclose(images.t[inner], t[inner], atol=3e-3)
    with pytest.raises(clrt.InputError):
        acc.camera_images(camera, K=np.eye(3))


def test_cli_writes_aov_files(tmp_path, device, capsys):
    mesh = primitives.icosphere(2)
    obj = tmp_path / "ball.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    out = tmp_path / "ball.png"
    dev = ["--device", device] if device else []
    code = main(["render", str(obj), "-o", str(out), "--width", "40", "--height", "30",
                 "--aov", "depth,normal,prim,hit", *dev])
    printed = capsys.readouterr().out
    assert code == 0
    assert printed.strip().splitlines()[-1] == str(out.resolve())
    assert "ball.depth.npy" in printed
    depth = np.load(tmp_path / "ball.depth.npy")
    prim = np.load(tmp_path / "ball.prim.npy")
    normal = np.load(tmp_path / "ball.normal.npy")
    hit = np.load(tmp_path / "ball.hit.npy")
    assert depth.shape == (30, 40) and depth.dtype == np.float32 and normal.shape == (30, 40, 3)
    assert np.array_equal(hit, prim >= 0) and hit.any() and (~hit).any()
    assert np.isinf(depth[~hit]).all() and np.isfinite(depth[hit]).all()
    # the pictures show the arrays: decoded, pixel for pixel
    from PIL import Image
    pictures = {name: np.asarray(Image.open(tmp_path / f"ball.{name}.png")) for name in ("depth", "normal",
                                                                                       "prim", "hit")}
    assert np.array_equal(pictures["hit"], np.where(hit, 255, 0))
    near, far = depth[hit].min(), depth[hit].max()
    grey = np.where(hit, np.round(255 - 215 * (depth - near) / (far - near)), 0)   # near bright, misses black
    assert np.abs(pictures["depth"].astype(int) - grey).max() <= 1 and pictures["depth"][hit].max() == 255
    colours = np.where(hit[..., None], np.round((normal + 1) * 127.5), 0)
    assert pictures["normal"].shape == (30, 40, 3)
    assert np.abs(pictures["normal"].astype(int) - colours).max() <= 1
    rgb = pictures["prim"].reshape(-1, 3)
    assert (rgb[~hit.ravel()] == 0).all() and (rgb[hit.ravel()] > 0).any(axis=1).all()
    flat = prim.ravel()
    for p in np.unique(flat[flat >= 0])[:20]:                   # one colour per triangle
        assert len(np.unique(rgb[flat == p], axis=0)) == 1
    assert len(np.unique(rgb[hit.ravel()], axis=0)) > 0.8 * len(np.unique(flat[flat >= 0]))
    hidden = [p.name for p in tmp_path.glob(".*") if not p.name.endswith(".clrt")]   # .clrt: records of .npy
    assert not hidden, f"no temporary files left behind: {hidden}"
    code = main(["render", str(obj), "-o", str(tmp_path / "bad.png"), "--aov", "depth,albedo", *dev])
    err = capsys.readouterr().err
    assert code == 2 and "albedo" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bad.png").exists()


def test_camera_images_of_a_clrt_camera_in_chunks(device):
    """camera_images(camera) keeps the directions the device made as it traces
    them: cut into many chunks the images are the same bit for bit, and the
    depth is the distance along the ray times the ray's cosine to the camera's
    forward axis."""
    from clrt.scene import primitives
    mesh = primitives.torus(n_major=24, n_minor=12)
    camera = clrt.Camera((0.4, 2.5, 3.0), (0.0, 0.0, 0.0), fov=45.0, width=37, height=23)
    whole = clrt.Accel(mesh, device=device).camera_images(camera)
    cut = clrt.Accel(mesh, device=device, chunk_rays=97).camera_images(camera)
    for name in ("depth", "t", "normal", "prim", "hit"):
        assert np.array_equal(getattr(whole, name), getattr(cut, name)), name
    assert whole.hit.any() and not whole.hit.all()
    assert np.array_equal(clrt.Accel(mesh, device=device).trace_camera(camera).t, whole.t)
    cosine = whole.depth[whole.hit] / whole.t[whole.hit]
    corner = np.cos(np.arctan(np.tan(np.radians(22.5)) * np.hypot(1.0, 37 / 23)))   # the widest ray
    assert np.all(cosine <= 1 + 1e-6) and np.all(cosine >= corner - 1e-6)
    assert np.all(np.isinf(whole.depth[~whole.hit]))


def test_bad_query_input_is_a_clrt_error(device, monkeypatch):
    """Every bad value gets clrt's own one-line error, not numpy's, trimesh's or an AttributeError."""
    mesh = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), [[0, 1, 2]])
    pose = np.eye(4)
    pose[0, 3] = 1e39   # an eye past float32
    with pytest.raises(clrt.InputError, match=r"pose\[:3, 3\] must be 3 numbers within \+-1e30"):
        clrt.camera_images(mesh, K=np.eye(3), pose=pose, width=2, height=2, device=device)
    for center in (None, "a", float("nan")):
        with pytest.raises(clrt.InputError, match="pixel_center must be a number"):
            clrt.camera_images(mesh, K=np.eye(3), pose=np.eye(4), width=2, height=2, pixel_center=center,
                               device=device)
    for path in (None, 5):
        with pytest.raises(clrt.MeshLoadError, match="path must be a str or os.PathLike"):
            clrt.load_mesh(path)
    intersector = clrt.RayMeshIntersector(trimesh.creation.box(), device=device)
    with pytest.raises(clrt.InputError, match=r"points must have shape \(3,\) or \(N, 3\)"):
        intersector.contains_points([1, 2])
    with pytest.raises(clrt.InputError, match="point 0 is .*points must be finite"):
        intersector.contains_points([[np.nan, 0, 0]])
    for max_hits in (-1, 1.5):
        with pytest.raises(clrt.InputError, match="max_hits must be an integer >= 1"):
            intersector.intersects_id([[0, 0, -5]], [[0, 0, 1]], max_hits=max_hits)
    # more rays than the host can hold: refused at once, before numpy's MemoryError
    from clrt import checks
    monkeypatch.setattr(checks, "available_host_memory", lambda: 1 << 30)
    many = np.broadcast_to(np.float32([0.2, 0.2, 1]), (10**9, 3))
    with pytest.raises(clrt.TooLargeError, match="a batch of 1,000,000,000 rays needs .* trace them in smaller"):
        clrt.trace(mesh, many, [0, 0, -1], device=device)
    with pytest.raises(clrt.TooLargeError, match="a batch of 4,294,967,296 rays"):
        clrt.camera_images(mesh, K=np.eye(3), pose=np.eye(4), width=65536, height=65536, device=device)

"""The wide BVH that CPU devices walk (clrt/accel/wide.py, accel_wide.cl) answers
every query exactly as the binary walk (accel_bvh.cl) and brute force do.

On PoCL both walks run on the same device: emptying
``clrt.device.geometry.WIDE_BVH_KINDS`` gives the binary one.  Every field of
every query is compared bit for bit -- closest hits for every cull mode, any
hit, counts, all hits -- on random rays, grazing rays (at vertices, along
edges, axis-parallel, from inside), the watertight rays of
test_watertight.py, and the tie scenes of test_ties.py, for every host
builder and the device builder, with leaves of one, four and eight triangles
(two packets).
"""

import functools
from pathlib import Path

import numpy as np
import pytest

import clrt
from clrt.accel.rows import child_refs
from clrt.accel import wide as wide_module
from clrt.accel.topdown import surface_area
from clrt.accel.wide import MERGE, PACKET, WIDE, collapse
from clrt.device import geometry
from clrt.device.acceleration import build_acceleration
from clrt.renderer import Renderer
from clrt.scene import primitives
from clrt.scene.arrays import triangle_corners
from clrt.scene.scene import Camera, scene_from_mesh

from conftest import TEST_MESHES
from test_accel import _hard_rays
from test_ties import SCENES, tie_rays
from test_watertight import watertight_rays

KNOT_FILE = Path(__file__).resolve().parents[1] / "assets" / "meshes" / "knot.obj"


def knot():
    """A closed tube of 4,320 triangles shipped with clrt: a real mesh without ../shared."""
    return clrt.load_mesh(KNOT_FILE)


MESHES = {"knot": knot, "torus": TEST_MESHES["torus"], "crossing": TEST_MESHES["crossing"],
          "heightfield": TEST_MESHES["heightfield"],
          **{f"ties-{name}": (lambda make=make: make(np.random.default_rng(3))) for name, make in SCENES.items()}}


def _walks(mesh, builder, leaf, device, monkeypatch):
    """(wide, binary) Accels of the same tree on the same device."""
    wide = clrt.Accel(mesh, accel="box", builder=builder, leaf_size=leaf, device=device)
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    binary = clrt.Accel(mesh, accel="box", builder=builder, leaf_size=leaf, device=device)
    monkeypatch.undo()
    if wide.geometry.wide is None:
        pytest.skip("the device under test does not walk the wide BVH")
    assert binary.geometry.wide is None and "BVH_WIDE" not in binary.geometry.defines
    assert wide.acceleration.rows.tobytes() == binary.acceleration.rows.tobytes() or builder == "device"
    return wide, binary


def _rays(mesh, rng):
    """origins, directions, tmin: random, grazing, watertight and tie rays."""
    lo, hi = mesh.bounds
    o = [rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (1500, 3))]
    d = [rng.normal(size=(1500, 3))]
    o_hard, d_hard = _hard_rays(mesh, rng, 300)
    o.append(o_hard)
    d.append(d_hard)
    try:
        o_tight, d_tight, _, _ = watertight_rays(mesh, rng, general=600, per_kind=300)
        o.append(o_tight)
        d.append(d_tight)
    except (ValueError, IndexError):    # an open mesh without two-sided edges
        pass
    o_tie, d_tie, tmin_tie = tie_rays(mesh, rng, 60)
    o.append(o_tie)
    d.append(d_tie)
    tmin = np.r_[np.zeros(sum(len(x) for x in o[:-1])), tmin_tie]
    return np.concatenate(o).astype(np.float32), np.concatenate(d).astype(np.float32), tmin


def _same_answers(a, b, o, d, tmin, label):
    diag = float(np.linalg.norm(np.ptp(o, axis=0)))
    for cull in ("none", "back", "front"):
        x, y = a.trace(o, d, tmin=tmin, cull=cull), b.trace(o, d, tmin=tmin, cull=cull)
        for field in x._fields:
            assert np.array_equal(getattr(x, field), getattr(y, field)), (label, cull, field)
        assert np.array_equal(a.count(o, d, tmin=tmin, cull=cull), b.count(o, d, tmin=tmin, cull=cull)), (label, cull)
        for u, v in zip(a.all_hits(o, d, tmin=tmin, cull=cull), b.all_hits(o, d, tmin=tmin, cull=cull)):
            assert np.array_equal(u, v), (label, cull, "all_hits")
    for tmax in (np.inf, 0.05 * diag):
        assert np.array_equal(a.any_hit(o, d, tmin=tmin, tmax=tmax), b.any_hit(o, d, tmin=tmin, tmax=tmax)), \
            (label, "any_hit", tmax)


@pytest.mark.parametrize("name", sorted(MESHES))
@pytest.mark.parametrize("builder, leaf", [("sah", 1), ("sah", 4), ("paper", 8), ("device", 4)])
def test_wide_walk_answers_as_the_binary_walk_and_brute_force(name, builder, leaf, device, monkeypatch):
    mesh = MESHES[name]()
    wide, binary = _walks(mesh, builder, leaf, device, monkeypatch)
    o, d, tmin = _rays(mesh, np.random.default_rng(len(name) + leaf))
    hits = wide.trace(o, d, tmin=tmin)
    assert (hits.prim >= 0).mean() > 0.2 and (hits.prim < 0).any(), "the rays must hit and miss"
    _same_answers(wide, binary, o, d, tmin, f"{name} {builder} leaf {leaf}: wide / binary")
    if builder == "sah" and leaf == 4:
        brute = clrt.Accel(mesh, accel="none", device=device)
        _same_answers(wide, brute, o, d, tmin, f"{name}: wide / brute force")


def test_wide_walk_renders_as_the_binary_walk(device, monkeypatch):
    scene = scene_from_mesh(knot())
    camera = Camera.framing(scene.bounds, 48, 36)
    frames = []
    for kinds in (geometry.WIDE_BVH_KINDS, ()):
        monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", kinds)
        renderer = Renderer(scene, device=device)
        frames.append((renderer.geometry.wide is not None, renderer.render(camera, hits=True)))
    (walked_wide, wide), (_, binary) = frames
    if not walked_wide:
        pytest.skip("the device under test does not walk the wide BVH")
    assert np.array_equal(wide.image, binary.image) and np.array_equal(wide.prim, binary.prim)
    assert np.array_equal(wide.t, binary.t)


def test_refit_keeps_the_wide_walk_exact(device):
    mesh = knot()
    accel = clrt.Accel(mesh, device=device)
    if accel.geometry.wide is None:
        pytest.skip("the device under test does not walk the wide BVH")
    moved = mesh.vertices * np.array([1.3, 0.7, 1.0]) + 0.1 * np.sin(3 * mesh.vertices[:, [1, 2, 0]])
    accel.refit(moved)
    brute = clrt.Accel(clrt.Mesh.from_arrays(moved, mesh.faces), accel="none", device=device)
    o, d, tmin = _rays(accel.mesh, np.random.default_rng(2))
    _same_answers(accel, brute, o, d, tmin, "refitted wide / brute force")


def test_only_cpu_devices_walk_wide_and_only_box_trees_unsplit(device, monkeypatch):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    wide = clrt.Accel(mesh, device=device)
    cpu = wide.queue.device.type & 2    # CL_DEVICE_TYPE_CPU
    assert (wide.geometry.wide is not None) == bool(cpu)
    assert ("BVH_WIDE" in wide.geometry.defines) == bool(cpu)
    for accel in ("sphere", "ellipse", "none"):
        assert clrt.Accel(mesh, accel=accel, device=device).geometry.wide is None, accel
    assert clrt.Accel(mesh, device=device, max_buffer_bytes=16384).geometry.wide is None
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())    # as a GPU: nothing built, nothing passed
    binary = clrt.Accel(mesh, device=device)
    assert binary.geometry.wide is None and "wide" not in binary.geometry.buffers
    assert len(binary.geometry.buffer_args) == 3 and "BVH_WIDE" not in binary.geometry.defines
    if cpu:
        assert len(wide.geometry.buffer_args) == 4


@pytest.mark.parametrize("builder, leaf", [("sah", 1), ("sah", 4), ("paper", 8), ("device", 4)])
def test_collapse_keeps_every_box_and_every_triangle_once(builder, leaf, device):
    corners = triangle_corners(knot()).astype(np.float32)
    acc = build_acceleration(corners, "box", builder, leaf, device)
    wide = collapse(acc.rows, corners[acc.prim_ids])
    nodes, packets = wide.nodes, wide.packets
    # every slot in exactly one packet lane, its corners copied exactly
    slots = packets["slot"]
    assert np.array_equal(np.sort(slots[slots >= 0]), np.arange(len(corners)))
    lane = np.nonzero(slots >= 0)
    for c, name in enumerate(("v0", "v1", "v2")):
        assert np.array_equal(packets[name].transpose(0, 2, 1)[lane], corners[acc.prim_ids][slots[lane]][:, c])
    # every lane's box is bit for bit the binary child it stands for; leaves' packets in range
    rows = acc.rows
    lo = np.stack([rows["left_a"][:, :3], rows["right_a"][:, :3]], 1).reshape(-1, 3)
    hi = np.stack([rows["left_b"][:, :3], rows["right_b"][:, :3]], 1).reshape(-1, 3)
    present = wide.sources >= 0
    assert np.array_equal(present, nodes["count"] >= 0)
    src = wide.sources[present]
    for axis, name in enumerate("xyz"):
        assert np.array_equal(nodes[f"lo_{name}"][present], lo[src, axis])
        assert np.array_equal(nodes[f"hi_{name}"][present], hi[src, axis])
    counts, child = nodes["count"], nodes["child"]
    inner = counts == 0
    assert np.array_equal(np.sort(child[inner]), np.arange(1, len(nodes)))   # each node has one parent
    # the leaves' packet ranges tile the packets; a subtree merged into a leaf
    # has at most MERGE triangles, a binary leaf at most the leaf size
    leaves = counts > 0
    order = np.argsort(child[leaves])
    first, many = child[leaves][order], counts[leaves][order]
    assert first[0] == 0 and np.array_equal(first[1:], (first + many)[:-1]) and many.sum() == len(packets)
    tris = np.array([(slots[f:f + m] >= 0).sum() for f, m in zip(first, many)])
    merged = (child_refs(rows)[:, 1::2].reshape(-1)[wide.sources[leaves]] == 0)[order]
    assert (tris[merged] <= MERGE).all() and (tris[~merged] <= leaf).all()
    assert (many == -(-tris // PACKET)).all()
    assert (present.sum(axis=1) <= WIDE).all()


def _far_and_steep_rays(mesh, rng, count=300):
    """Rays aimed at vertices and edge points from near and very far, many of
    them with direction components of 1e-3 down to 1e-38 and 0: where the box
    test's per-ray bounds (volume_ray, volumes.cl) are widest and where its
    oblique test gives way to the exact one (a zero or subnormal component)."""
    v = mesh.vertices.astype(np.float64)
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    f = mesh.faces[rng.integers(0, len(mesh.faces), count)]
    w = rng.random((count, 1))
    targets = np.concatenate([v[rng.integers(0, len(v), count)], (1 - w) * v[f[:, 0]] + w * v[f[:, 1]]])
    d = rng.normal(size=targets.shape)
    steep = rng.random(len(d)) < 0.6
    axes = rng.integers(0, 3, len(d))
    d[steep, axes[steep]] *= rng.choice([1e-3, 1e-7, 1e-12, 1e-20, 1e-30, 1e-38, 0.0], steep.sum())
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    dist = diag * rng.choice([1e-3, 1.0, 1e3, 1e5], (len(d), 1))
    o = (targets - dist * d).astype(np.float32)
    return o, d.astype(np.float32)


@pytest.mark.parametrize("place", ["as is", "far from the origin", "tiny"])
def test_box_bounds_hold_far_away_and_near_axis_parallel(place, device, monkeypatch):
    """Both walks and brute force agree on rays from far away and rays nearly
    along an axis, on a mesh as shipped, moved 1e5 of its size from the origin
    (box planes large beside the boxes) and shrunk a billion times."""
    mesh = knot()
    v = mesh.vertices.astype(np.float64)
    if place == "far from the origin":
        v = v + 1e5 * np.ptp(v, axis=0).max() * np.array([1.0, -0.7, 0.4])
    elif place == "tiny":
        v = v * 1e-9
    mesh = clrt.Mesh(v.astype(np.float32), mesh.faces, "knot " + place)
    o, d = _far_and_steep_rays(mesh, np.random.default_rng(11))
    tmin = np.zeros(len(o))
    brute = clrt.Accel(mesh, accel="none", device=device)
    hits = brute.trace(o, d)
    assert (hits.prim >= 0).mean() > 0.3 and (hits.prim < 0).any(), "the rays must hit and miss"
    default = clrt.Accel(mesh, accel="box", builder="sah", leaf_size=4, device=device)   # the wide walk on CPU devices
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    binary = clrt.Accel(mesh, accel="box", builder="sah", leaf_size=4, device=device)
    monkeypatch.undo()
    _same_answers(binary, brute, o, d, tmin, f"{place}: binary / brute force")
    _same_answers(default, brute, o, d, tmin, f"{place}: default walk / brute force")
    # Ranges that end at or start just before each ray's hit: where a box test
    # without its slack would drop the hit that brute force finds.
    hit = hits.prim >= 0
    o, d, t = o[hit], d[hit], hits.t[hit]
    just_before = np.nextafter(t, np.float32(-np.inf))
    for walk, label in ((binary, "binary"), (default, "default walk")):
        for name, kwargs in (("tmax = t", {"tmax": t}), ("tmin just before t", {"tmin": just_before})):
            x, y = walk.trace(o, d, **kwargs), brute.trace(o, d, **kwargs)
            for field in x._fields:
                assert np.array_equal(getattr(x, field), getattr(y, field)), (place, label, name, field)
            assert np.array_equal(walk.count(o, d, **kwargs), brute.count(o, d, **kwargs)), (place, label, name)


def _grid(n: int) -> clrt.Mesh:
    """n x n unit squares in the plane z = 0, two triangles each, the squares
    at large y first (low indices far along +y)."""
    xs, ys = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1).astype(np.float32)
    at = lambda i, j: i * (n + 1) + j   # noqa: E731
    faces = np.array([[at(i, j), at(i + 1, j + 1), at(i, j + 1)] for i in range(n) for j in range(n)]
                     + [[at(i, j), at(i + 1, j), at(i + 1, j + 1)] for i in range(n) for j in range(n)])
    return clrt.Mesh(v, faces[::-1].copy(), "grid")


def test_subnormal_ray_components_answer_as_brute_force(device, monkeypatch):
    """A ray 2e-43 off a mesh's plane, nearly in it: with its subnormal
    components the watertight test's t was 1e-3 off while the box tests stayed
    exact, and both walks lost the hit brute force found (rays.cl now reads
    subnormal components as zeros)."""
    mesh = _grid(5)
    o = np.array([[3.7960608, 3.9930122, -1.9758308e-43]], np.float32)
    d = np.array([[0.30945268, 0.95091486, 2.6878306e-41]], np.float32)
    brute = clrt.Accel(mesh, accel="none", device=device)
    default = clrt.Accel(mesh, accel="box", builder="sah", leaf_size=4, device=device)
    monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    binary = clrt.Accel(mesh, accel="box", builder="sah", leaf_size=4, device=device)
    monkeypatch.undo()
    expected = brute.trace(o, d)      # read as z = -0 and dz = +0: in the plane, a miss
    for walk in (default, binary):
        got = walk.trace(o, d)
        for field in got._fields:
            assert np.array_equal(getattr(got, field), getattr(expected, field)), field
        for u, v in zip(walk.all_hits(o, d), brute.all_hits(o, d)):
            assert np.array_equal(u, v)
        assert np.array_equal(walk.count(o, d, tmax=expected.t), brute.count(o, d, tmax=expected.t))
        assert np.array_equal(walk.count(o, d), brute.count(o, d))


def _sah_cost(nodes):
    """The collapse's SAH cost of a wide tree, from its nodes: C_NODE for every
    lane holding a node, C_PACKET for every packet of a leaf lane, each times
    its box's surface area (float64)."""
    lo = np.stack([nodes[f"lo_{a}"] for a in "xyz"], -1).astype(np.float64)
    hi = np.stack([nodes[f"hi_{a}"] for a in "xyz"], -1).astype(np.float64)
    area = surface_area(lo, hi)
    count = nodes["count"]
    return float((area * np.where(count == 0, wide_module.C_NODE, 0.0)).sum()
                 + (area * np.where(count > 0, wide_module.C_PACKET * count, 0)).sum())


def _optimal_cost(rows):
    """The least SAH cost of any collapse of ``rows``, by plain recursion over
    the binary tree (the reference for _plan's vectorised dynamic programme)."""
    refs = child_refs(rows)
    lo = np.stack([rows["left_a"][:, :3], rows["right_a"][:, :3]], 1).reshape(-1, 3).astype(np.float64)
    hi = np.stack([rows["left_b"][:, :3], rows["right_b"][:, :3]], 1).reshape(-1, 3).astype(np.float64)
    area = surface_area(lo, hi)
    ref, count = refs[:, 0::2].reshape(-1), refs[:, 1::2].reshape(-1)

    @functools.lru_cache(maxsize=None)
    def tris(e):
        return int(count[e]) if count[e] > 0 else tris(2 * ref[e]) + tris(2 * ref[e] + 1)

    @functools.lru_cache(maxsize=None)
    def best(e, k):       # binary child e spread over at most k lanes
        if count[e] > 0:
            return area[e] * wide_module.C_PACKET * -(-int(count[e]) // PACKET)
        one = wide_module.C_NODE * area[e] + spread(ref[e], WIDE)
        if tris(e) <= MERGE:
            one = min(one, area[e] * wide_module.C_PACKET * -(-tris(e) // PACKET))
        return min([one] + [spread(ref[e], j) for j in range(2, k + 1)])

    def spread(row, k):
        return min(best(2 * row, i) + best(2 * row + 1, k - i) for i in range(1, k))

    return spread(0, WIDE)


@pytest.mark.parametrize("builder, leaf", [("sah", 1), ("sah", 4), ("paper", 8)])
def test_collapse_is_sah_optimal(builder, leaf, device):
    corners = triangle_corners(knot()).astype(np.float32)
    acc = build_acceleration(corners, "box", builder, leaf, device)
    wide = collapse(acc.rows, corners[acc.prim_ids])
    assert _sah_cost(wide.nodes) == pytest.approx(_optimal_cost(acc.rows), rel=1e-9)
    # the greedy collapse it replaced left nodes half empty (4.3 lanes of 8 on bunny00, 6.4 now)
    lanes = (wide.nodes["count"] >= 0).sum(axis=1)
    assert lanes.mean() > 5.5


@pytest.mark.parametrize("portable", [False, True])
def test_sixteen_lane_bits_and_masks_invert_each_other(portable, device):
    """lanes.cl's lane16_bits and lane16_mask (point_group.cl's groups of
    sixteen points): every set of sixteen lanes gives its bits and back, in
    the AVX-512 form (where the device's compiler defines __AVX512DQ__) and
    the portable one."""
    import pyopencl as cl
    from clrt.device.context import create_context
    from clrt.device.program import build_options, expand_source

    context, queue = create_context(device or "cpu")
    source = expand_source("lanes.cl") + """
    __kernel void probe(__global uint* bits, __global int16* lanes) {
        const uint b = get_global_id(0);
        lanes[b] = lane16_mask(b);
        bits[b] = lane16_bits(lane16_mask(b));
    }"""
    defines = {"PORTABLE_LANE_BITS": None} if portable else {}
    program = cl.Program(context, source).build(options=build_options(context, defines))
    n = 1 << 16
    bits, lanes = np.empty(n, np.uint32), np.empty((n, 16), np.int32)
    bits_buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, bits.nbytes)
    lanes_buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, lanes.nbytes)
    cl.Kernel(program, "probe")(queue, (n,), None, bits_buf, lanes_buf)
    cl.enqueue_copy(queue, bits, bits_buf)
    cl.enqueue_copy(queue, lanes, lanes_buf)
    np.testing.assert_array_equal(lanes, -((np.arange(n)[:, None] >> np.arange(16)) & 1))
    np.testing.assert_array_equal(bits, np.arange(n))


@pytest.mark.parametrize("portable", [False, True])
def test_lane_bits_and_lane_mask_invert_each_other(portable, device):
    """lanes.cl: every set of eight lanes gives its bits and back, in the x86 form
    (vmovmskps, where the device's compiler defines __AVX__) and the portable one."""
    import pyopencl as cl
    from clrt.device.context import create_context
    from clrt.device.program import build_options, expand_source

    context, queue = create_context(device or "cpu")
    source = expand_source("lanes.cl") + """
    __kernel void probe(__global uint* bits, __global int8* lanes) {
        const uint b = get_global_id(0);
        lanes[b] = lane_mask(b);
        bits[b] = lane_bits(lane_mask(b));
    }"""
    defines = {"PORTABLE_LANE_BITS": None} if portable else {}
    program = cl.Program(context, source).build(options=build_options(context, defines))
    bits, lanes = np.empty(256, np.uint32), np.empty((256, 8), np.int32)
    bits_buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, bits.nbytes)
    lanes_buf = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, lanes.nbytes)
    cl.Kernel(program, "probe")(queue, (256,), None, bits_buf, lanes_buf)
    cl.enqueue_copy(queue, bits, bits_buf)
    cl.enqueue_copy(queue, lanes, lanes_buf)
    expected = -((np.arange(256)[:, None] >> np.arange(8)) & 1)
    assert np.array_equal(lanes, expected)
    assert np.array_equal(bits, np.arange(256))

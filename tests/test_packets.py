"""Packets of rays on CPU devices (accel_packet.cl): eight consecutive rays
that travel together walk the wide BVH as one packet, and every ray gets the
single-ray walk's answer bit for bit, and brute force's.

On PoCL both run on the same device: emptying
``clrt.device.geometry.RAY_PACKET_KINDS`` gives the single-ray kernels.  Most
rays come in groups that make packets (one octant, one shear order): camera
pixels; eight rays aimed at one vertex or one point of an edge from
neighbouring origins (rays of one packet meet neighbouring triangles exactly
at their shared corner or edge); directions whose largest components tie
exactly (shear_ray's choice of axis).  Each lane has its own tmin (0,
negative, -inf, or past hits) and tmax.  The tie rays of test_ties.py come
eight times over.  A kernel that walks packets only shows that they are
walked, and not answered by the single-ray walk.
"""

import numpy as np
import pyopencl as cl
import pytest

import clrt
from clrt.device import geometry
from clrt.config import CULL_MODES
from clrt.device.program import build_options, expand_source

from test_ties import tie_rays
from test_wide import MESHES, _same_answers


def _unit(v):
    return (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)


def _camera_rays(centre, radius, eye, width=64, height=24):
    """Row-major pixel rays of a pinhole at ``eye`` looking at ``centre``."""
    forward = _unit(centre - eye).astype(np.float64)
    side = _unit(np.cross(forward, [0.3, 1.0, 0.2])).astype(np.float64)
    up = np.cross(side, forward)
    x = np.linspace(-0.4, 0.4, width)
    y = np.linspace(0.3, -0.3, height)
    px, py = np.meshgrid(x, y)
    d = forward + px[..., None] * side + py[..., None] * up
    return np.broadcast_to(eye, (width * height, 3)).astype(np.float32), _unit(d.reshape(-1, 3))


def _axis_tie_rays(centre, radius, rng):
    """Packets whose directions tie exactly between their largest components
    (|dx| = |dy|, |dx| = |dz|, |dy| = |dz|, all three), from a grid of origins
    across the mesh: shear_ray breaks such ties by its comparisons' order."""
    o, d = [], []
    for big, small in ((np.array([1.0, 1.0, 0.4]), None), (np.array([1.0, 0.3, 1.0]), None),
                       (np.array([0.5, 1.0, 1.0]), None), (np.array([1.0, 1.0, 1.0]), None)):
        for signs in rng.choice([-1.0, 1.0], (2, 3)):
            direction = _unit(big * signs)
            e1 = _unit(np.cross(direction, [0.3, 0.7, 0.1]))
            e2 = np.cross(direction, e1)
            u, v = np.meshgrid(np.linspace(-0.3, 0.3, 8), np.linspace(-0.3, 0.3, 4))
            origins = centre - 2 * radius * direction + radius * (u.reshape(-1, 1) * e1 + v.reshape(-1, 1) * e2)
            o.append(origins.astype(np.float32))
            d.append(np.broadcast_to(direction, origins.shape).astype(np.float32))
    return np.concatenate(o), np.concatenate(d)


def packet_rays(mesh, rng):
    """origins, directions, tmin, tmax, leading: in groups of eight, the first
    ``leading`` rays (camera, vertex, edge and axis-tie packets) travelling
    together; the tie rays after them, axis-parallel most of them, make no
    packets but share the kernels."""
    lo, hi = mesh.bounds
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    o, d = [], []
    for eye in (centre + 1.5 * radius * _unit(rng.normal(size=3)), centre + 0.9 * radius * _unit(rng.normal(size=3)),
                centre + 0.01 * radius):
        co, cd = _camera_rays(centre, radius, eye)
        o.append(co)
        d.append(cd)
    # eight rays at one vertex or one edge point, from origins a little apart
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces[rng.integers(0, len(mesh.faces), 120)]
    w = rng.random((120, 1))
    targets = np.concatenate([v[rng.integers(0, len(v), 120)], (1 - w) * v[f[:, 0]] + w * v[f[:, 1]]])
    base = centre + 2 * radius * _unit(rng.normal(size=targets.shape))
    origins = base[:, None] + 0.02 * radius * rng.normal(size=(len(targets), 8, 3))
    o.append(origins.reshape(-1, 3).astype(np.float32))
    d.append(_unit(targets[:, None] - origins).reshape(-1, 3))
    o_axis, d_axis = _axis_tie_rays(centre, radius, rng)
    o.append(o_axis)
    d.append(d_axis)
    leading = sum(len(x) for x in o)
    # each lane its own tmin: mostly 0, some negative, -inf, or past the nearest hits
    tmin = rng.choice([0.0, 0.0, -0.5 * radius, -np.inf, 1.2 * radius, 2.0 * radius], leading)
    o_tie, d_tie, tmin_tie = tie_rays(mesh, rng, 40)
    o.append(np.repeat(o_tie, 8, axis=0).astype(np.float32))
    d.append(_unit(np.repeat(d_tie, 8, axis=0)))
    tmin = np.r_[tmin, np.repeat(tmin_tie, 8)].astype(np.float32)
    n = len(tmin)
    tmax = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(0.2, 3.0, n) * radius).astype(np.float32)
    return np.concatenate(o), np.concatenate(d), tmin, tmax, leading


def packet_groups(d) -> np.ndarray:
    """(N // 8,) bool: does each group of eight directions meet make_ray_packet's
    rule on directions (one octant, one dominant axis, no zero component)?"""
    g = d[: len(d) // 8 * 8].reshape(-1, 8, 3)
    a = np.abs(g)
    kz = np.where(a[..., 0] >= a[..., 1], np.where(a[..., 0] >= a[..., 2], 0, 2), np.where(a[..., 1] >= a[..., 2], 1, 2))
    return ((np.signbit(g) == np.signbit(g[:, :1])).all(axis=(1, 2)) & (kz == kz[:, :1]).all(axis=1)
            & (g != 0).all(axis=(1, 2)))


def _walks(mesh, builder, leaf, device, monkeypatch):
    """(packets, single) Accels of the same tree on the same device."""
    packets = clrt.Accel(mesh, accel="box", builder=builder, leaf_size=leaf, device=device)
    if packets.rays_per_item == 1:
        pytest.skip("the device under test does not walk packets")
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    single = clrt.Accel(mesh, accel="box", builder=builder, leaf_size=leaf, device=device)
    monkeypatch.undo()
    assert single.rays_per_item == 1
    assert single.geometry.wide is not None    # the same wide walk for the rays that make no packet
    return packets, single


def _same_with_ranges(a, b, o, d, tmin, tmax, label):
    """Every closest-hit field and any hit, with a tmin and a tmax per ray."""
    for cull in ("none", "back", "front"):
        x, y = a.trace(o, d, tmin=tmin, tmax=tmax, cull=cull), b.trace(o, d, tmin=tmin, tmax=tmax, cull=cull)
        for field in x._fields:
            assert np.array_equal(getattr(x, field), getattr(y, field)), (label, cull, field)
        assert np.array_equal(a.any_hit(o, d, tmin=tmin, tmax=tmax, cull=cull),
                              b.any_hit(o, d, tmin=tmin, tmax=tmax, cull=cull)), (label, cull, "any_hit")


@pytest.mark.parametrize("name", sorted(MESHES))
@pytest.mark.parametrize("builder, leaf", [("sah", 1), ("sah", 4), ("paper", 8)])
def test_packets_answer_as_the_single_ray_walk_and_brute_force(name, builder, leaf, device, monkeypatch):
    mesh = MESHES[name]()
    packets, single = _walks(mesh, builder, leaf, device, monkeypatch)
    o, d, tmin, tmax, leading = packet_rays(mesh, np.random.default_rng(len(name) + 10 * leaf))
    assert packet_groups(d[:leading]).mean() > 0.8, "the rays must come in packets"
    hits = packets.trace(o, d, tmin=tmin)
    assert (hits.prim >= 0).mean() > 0.2 and (hits.prim < 0).any(), "the rays must hit and miss"
    _same_answers(packets, single, o, d, tmin, f"{name} {builder} leaf {leaf}: packets / single")
    _same_with_ranges(packets, single, o, d, tmin, tmax, f"{name} {builder} leaf {leaf}: packets / single")
    if builder == "sah" and leaf == 4:
        brute = clrt.Accel(mesh, accel="none", device=device)
        _same_answers(packets, brute, o, d, tmin, f"{name}: packets / brute force")
        _same_with_ranges(packets, brute, o, d, tmin, tmax, f"{name}: packets / brute force")


@pytest.mark.parametrize("count", [1, 7, 8, 9, 8 * 37 + 5])
def test_every_ray_of_a_partial_packet_is_answered(count, device):
    mesh = MESHES["knot"]()
    o, d, tmin, tmax, _ = packet_rays(mesh, np.random.default_rng(count))
    o, d = o[:count], d[:count]
    accel = clrt.Accel(mesh, device=device)
    brute = clrt.Accel(mesh, accel="none", device=device)
    for field in ("t", "prim", "u", "v", "normal", "front"):
        assert np.array_equal(getattr(accel.trace(o, d), field), getattr(brute.trace(o, d), field)), field
    assert np.array_equal(accel.any_hit(o, d), brute.any_hit(o, d))


@pytest.mark.parametrize("count", [64, 61])     # whole packets; the bad ray in the last, partial one
@pytest.mark.parametrize("kind", ["origin", "direction", "zero direction", "tmin", "tmax", "reach"])
def test_a_bad_ray_inside_a_packet_is_reported_by_its_index(kind, count, device):
    mesh = MESHES["knot"]()
    o, d, tmin, tmax, _ = packet_rays(mesh, np.random.default_rng(4))
    o, d, tmin, tmax = o[:count].copy(), d[:count].copy(), tmin[:count].copy(), tmax[:count].copy()
    bad = count - 3          # inside a packet of eight good rays, or in the partial last one
    if kind == "origin":
        o[bad] = np.inf
        message = f"origin {bad} is [inf, inf, inf]: origins must be finite"
    elif kind == "direction":
        d[bad] = np.nan
        message = f"direction {bad} is [nan, nan, nan]: directions must be finite and non-zero"
    elif kind == "reach":    # past the float32 range of the triangle test (clrt.device.reach)
        o[bad] = [0.0, 1e17, 0.0]
        message = (f"origin {bad} is [0.0, 1e+17, 0.0]: it lies 1e17 from the scene's far side, but the "
                   f"device's float32 triangle test overflows and misses hits on this scene's triangles from "
                   f"about 4.9e16: start the rays nearer, or scale the scene down")
    elif kind == "zero direction":
        d[bad] = 0.0
        message = f"direction {bad} is [0.0, 0.0, 0.0]: directions must be finite and non-zero"
    else:
        (tmin if kind == "tmin" else tmax)[bad] = np.nan
        message = f"{kind} of ray {bad} is nan: {kind} must not be NaN"
    o[bad + 1] = np.nan      # a later bad ray is not the one reported
    accel = clrt.Accel(mesh, device=device)
    for query in (accel.trace, accel.any_hit):
        with pytest.raises(clrt.InputError) as error:
            query(o, d, tmin=tmin, tmax=tmax)
        assert str(error.value) == message, (query.__name__, str(error.value))


PACKETS_ONLY = r"""
// Every group of eight rays walked as a packet, or `made` 0 where they make none.
__kernel void packets_only(__global const float* origins, __global const float* dirs,
                           __global const float* tmins, __global const float* tmaxs, __global int* bad,
                           __global int* made, __global float* t_out, __global int* prim_out,
                           __global float* u_out, __global float* v_out, const int query, const int cull,
                           GEOMETRY_PARAMS)
{
    const uint w = get_global_id(0);
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    QueryLaunch launch = {0};
    launch.origin_stride = launch.dir_stride = 3u;
    launch.tmin_stride = launch.tmax_stride = 1u;
    launch.normalise = 1u;
    launch.scene_lo = (float4)(-INFINITY);
    launch.scene_hi = (float4)(INFINITY);
    launch.reach2 = INFINITY;
    const RayInput in = make_ray_input(origins, dirs, tmins, tmaxs, bad, launch);
    RayLanes lanes;
    RayPacket packet;
    made[w] = load_ray_lanes(&in, 8 * w, 8 * w + 8, &lanes);
    if (!made[w])
        return;
    const ShearRayLanes shear = shear_ray_lanes(lanes.dx, lanes.dy, lanes.dz);
    const VolumeRayLanes volume = volume_ray_lanes(lanes.ox, lanes.oy, lanes.oz, lanes.dx, lanes.dy, lanes.dz,
                                                   tree_reach(SPLIT_AT(&g, nodes, 0)));
    made[w] = make_ray_packet(&lanes, &shear, &volume, &packet);
    if (!made[w])
        return;
    Hit hits[8];
    answer_ray_packet(&g, &packet, lanes.tmax, query, cull, hits);
    for (int k = 0; k < 8; ++k) {
        const Hit h = reported_hit(&g, hits[k]);
        t_out[8 * w + k] = h.t;
        prim_out[8 * w + k] = h.prim;
        u_out[8 * w + k] = h.u;
        v_out[8 * w + k] = h.v;
    }
}
"""


def test_packets_are_walked_as_packets_and_answer_as_brute_force(device):
    """The packet walk alone, without the single-ray walk to fall back on."""
    mesh = MESHES["knot"]()
    accel = clrt.Accel(mesh, device=device)
    if accel.rays_per_item == 1:
        pytest.skip("the device under test does not walk packets")
    o, d, tmin, tmax, _ = packet_rays(mesh, np.random.default_rng(6))
    keep = np.repeat(packet_groups(d), 8)      # the groups that make packets, and all of their rays
    o, d, tmin, tmax = o[keep], d[keep], tmin[keep], tmax[keep]
    ctx, queue = accel.context, accel.queue
    program = cl.Program(ctx, expand_source("trace.cl") + PACKETS_ONLY).build(
        options=build_options(ctx, {**accel.geometry.defines, "RAY_PACKETS": 8}))
    packets_only = cl.Kernel(program, "packets_only")
    mf = cl.mem_flags

    def buffer(a):
        return cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

    n = len(o)
    brute = clrt.Accel(mesh, accel="none", device=device)
    ins = [buffer(a) for a in (o, d, tmin, tmax, np.zeros(5, np.int32))]    # alive until the launches end
    for cull in ("none", "back", "front"):
        expected = brute.trace(o, d, tmin=tmin, tmax=tmax, cull=cull)
        expected_any = brute.any_hit(o, d, tmin=tmin, tmax=tmax, cull=cull)
        assert (expected.prim >= 0).mean() > 0.1 and (expected.prim < 0).any()
        for query, code in (("closest", 0), ("any", 1)):
            made = np.zeros(n // 8, np.int32)
            t, prim, u, v = (np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.float32),
                             np.empty(n, np.float32))
            outs = [cl.Buffer(ctx, mf.READ_WRITE, x.nbytes) for x in (made, t, prim, u, v)]
            packets_only.set_args(*ins, *outs, np.int32(code), np.int32(CULL_MODES[cull]),
                                  *accel.geometry.buffer_args, accel.geometry.scene_value())
            cl.enqueue_nd_range_kernel(queue, packets_only, (n // 8,), None)
            for host, dev in zip((made, t, prim, u, v), outs):
                cl.enqueue_copy(queue, host, dev)
            queue.finish()
            assert made.all(), f"{np.count_nonzero(made == 0)} of {len(made)} groups made no packet"
            if query == "closest":
                for name, got in (("t", t), ("prim", prim), ("u", u), ("v", v)):
                    assert np.array_equal(got, getattr(expected, name)), (cull, name)
            else:
                assert np.array_equal(prim >= 0, expected_any), cull


@pytest.mark.parametrize("width, height, max_depth", [(64, 48, None), (61, 37, 0)])
def test_the_renderer_gets_the_same_frame_with_packets(width, height, max_depth, device, monkeypatch):
    """Camera rays and their shadow rays go as packets of rays in the renderer
    too (render.cl); frames and hit records stay those of the single-ray
    kernels, also where a tile row ends in a partial packet (61 pixels)."""
    from clrt.renderer import Renderer
    from clrt.scene.default import default_scene
    scene = default_scene(width, height, coarse=True)
    packets = Renderer(scene, device=device)
    if packets.rays_per_item == 1:
        pytest.skip("the device under test does not walk packets")
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    single = Renderer(scene, device=device)
    assert single.rays_per_item == 1
    a = packets.render(hits=True, samples=2, max_depth=max_depth)
    b = single.render(hits=True, samples=2, max_depth=max_depth)
    assert (a.prim >= 0).mean() > 0.3 and (a.prim < 0).any()
    assert np.array_equal(a.image, b.image)
    assert np.array_equal(a.prim, b.prim) and np.array_equal(a.t, b.t)

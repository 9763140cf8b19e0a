"""The packet walk of CPU devices (accel_packet.cl): eight consecutive rays
that travel together walk the wide BVH as one packet, and every ray gets the
single-ray walk's answer bit for bit, and brute force's.

On PoCL both run on the same device: emptying
``clrt.device.geometry.RAY_PACKET_KINDS`` gives the single-ray kernels.  The
rays come in packets that make packets (one octant, one dominant axis):
camera pixels, eight rays aimed at one vertex or one point of an edge from
neighbouring origins (rays of one packet meet neighbouring triangles exactly
at their shared corner or edge), the tie rays of test_ties.py eight times
over, each lane with its own tmin and tmax.  A kernel that walks packets
only shows that they are walked, and not answered by the single-ray walk.
"""

import numpy as np
import pyopencl as cl
import pytest

import clrt
from clrt.device import geometry
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


def packet_rays(mesh, rng):
    """origins, directions, tmin, tmax, in groups of eight: the first ``leading``
    rays (camera, vertex and edge packets) travel together; the tie rays,
    axis-parallel most of them, make no packets but share their kernels."""
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
    leading = sum(len(x) for x in o)
    o_tie, d_tie, tmin_tie = tie_rays(mesh, rng, 40)
    o.append(np.repeat(o_tie, 8, axis=0).astype(np.float32))
    d.append(_unit(np.repeat(d_tie, 8, axis=0)))
    n = sum(len(x) for x in o)
    tmin = np.r_[np.zeros(n - 8 * len(tmin_tie)), np.repeat(tmin_tie, 8)].astype(np.float32)
    tmax = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(0.2, 2.0, n) * radius).astype(np.float32)
    return np.concatenate(o), np.concatenate(d), tmin, tmax, leading


def packet_groups(d) -> np.ndarray:
    """(N // 8,) bool: does each group of eight directions meet make_packet's
    rule on directions (one octant, one dominant axis, no zero component)?"""
    g = d[: len(d) // 8 * 8].reshape(-1, 8, 3)
    a = np.abs(g)
    kz = np.where(a[..., 0] >= a[..., 1], np.where(a[..., 0] >= a[..., 2], 0, 2), np.where(a[..., 1] >= a[..., 2], 1, 2))
    return ((np.signbit(g) == np.signbit(g[:, :1])).all(axis=(1, 2)) & (kz == kz[:, :1]).all(axis=1)
            & (g != 0).all(axis=(1, 2)))


def _walks(mesh, builder, leaf, device, monkeypatch):
    """(packets, single) Accels of the same tree on the same device."""
    packets = clrt.Accel(mesh, "box", builder, leaf, device=device)
    if packets.geometry.rays_per_item == 1:
        pytest.skip("the device under test does not walk packets")
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    single = clrt.Accel(mesh, "box", builder, leaf, device=device)
    monkeypatch.undo()
    assert single.geometry.rays_per_item == 1 and "RAY_PACKETS" not in single.geometry.defines
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
        brute = clrt.Accel(mesh, "none", device=device)
        _same_answers(packets, brute, o, d, tmin, f"{name}: packets / brute force")
        _same_with_ranges(packets, brute, o, d, tmin, tmax, f"{name}: packets / brute force")


@pytest.mark.parametrize("count", [1, 7, 8, 9, 8 * 37 + 5])
def test_every_ray_of_a_partial_packet_is_answered(count, device):
    mesh = MESHES["knot"]()
    o, d, tmin, tmax, _ = packet_rays(mesh, np.random.default_rng(count))
    o, d = o[:count], d[:count]
    accel = clrt.Accel(mesh, device=device)
    brute = clrt.Accel(mesh, "none", device=device)
    for field in ("t", "prim", "u", "v", "normal", "front"):
        assert np.array_equal(getattr(accel.trace(o, d), field), getattr(brute.trace(o, d), field)), field
    assert np.array_equal(accel.any_hit(o, d), brute.any_hit(o, d))


def test_a_bad_ray_inside_a_packet_is_reported_by_its_index(device):
    mesh = MESHES["knot"]()
    o, d, _, _, _ = packet_rays(mesh, np.random.default_rng(4))
    o, d = o[:64].copy(), d[:64].copy()
    d[21] = np.nan
    o[45] = np.inf
    accel = clrt.Accel(mesh, device=device)
    for query in (accel.trace, accel.any_hit):
        with pytest.raises(clrt.InputError, match="21"):
            query(o, d)


PACKETS_ONLY = r"""
// Every group of eight rays walked as a packet, or `made` 0 where they make none.
__kernel void packets_only(__global const float* origins, __global const float* dirs,
                           __global const float* tmins, __global const float* tmaxs, __global int* bad,
                           __global int* made, __global float* t_out, __global int* prim_out,
                           const int query, GEOMETRY_PARAMS)
{
    const uint w = get_global_id(0);
    const Geometry g = make_geometry(GEOMETRY_ARGS);
    const RayInput in = make_ray_input(origins, 3u, dirs, 3u, tmins, 1u, tmaxs, 1u, 0u, 0u, 1u, bad);
    RayLanes lanes;
    RayPacket packet;
    made[w] = load_ray_lanes(&in, 8 * w, 8 * w + 8, &lanes);
    if (!made[w])
        return;
    const ShearLanes shear = shear_ray_lanes(lanes.dx, lanes.dy, lanes.dz);
    const VolumeRayLanes volume = volume_ray_lanes(lanes.ox, lanes.oy, lanes.oz, lanes.dx, lanes.dy, lanes.dz,
                                                   tree_reach(SPLIT_AT(&g, nodes, 0)));
    made[w] = make_packet(&lanes, &shear, &volume, &packet);
    if (!made[w])
        return;
    PacketHits best;
    best.t = (float8)(INFINITY);
    best.u = best.v = (float8)(0.0f);
    best.slot = best.id = (int8)(-1);
    walk_packet(&g, &packet, lanes.tmax, query, CULL_NONE, &best);
    for (int k = 0; k < 8; ++k) {
        const int slot = best.slot[k];
        t_out[8 * w + k] = slot >= 0 ? best.t[k] : INFINITY;
        prim_out[8 * w + k] = slot >= 0 ? *SPLIT_AT(&g, prim_ids, slot) : -1;
    }
}
"""


def test_packets_are_walked_as_packets_and_answer_as_brute_force(device):
    """The packet walk alone, without the single-ray walk to fall back on."""
    mesh = MESHES["knot"]()
    accel = clrt.Accel(mesh, device=device)
    if accel.geometry.rays_per_item == 1:
        pytest.skip("the device under test does not walk packets")
    o, d, tmin, tmax, _ = packet_rays(mesh, np.random.default_rng(6))
    keep = np.repeat(packet_groups(d), 8)      # the groups that make packets, and all of their rays
    o, d, tmin, tmax = o[keep], d[keep], tmin[keep], tmax[keep]
    ctx, queue = accel.context, accel.queue
    program = cl.Program(ctx, expand_source("trace.cl") + PACKETS_ONLY).build(
        options=build_options(ctx, accel.geometry.defines))
    packets_only = cl.Kernel(program, "packets_only")
    mf = cl.mem_flags

    def buffer(a):
        return cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

    n = len(o)
    brute = clrt.Accel(mesh, "none", device=device)
    expected_hits = brute.trace(o, d, tmin=tmin, tmax=tmax)
    expected_any = brute.any_hit(o, d, tmin=tmin, tmax=tmax)
    for query, code in (("closest", 0), ("any", 1)):
        made = np.zeros(n // 8, np.int32)
        t, prim = np.empty(n, np.float32), np.empty(n, np.int32)
        outs = [cl.Buffer(ctx, mf.READ_WRITE, x.nbytes) for x in (made, t, prim)]
        ins = [buffer(a) for a in (o, d, tmin, tmax, np.zeros(4, np.int32))]    # alive until the launch ends
        packets_only.set_args(*ins, *outs, np.int32(code), *accel.geometry.args)
        cl.enqueue_nd_range_kernel(queue, packets_only, (n // 8,), None)
        for host, dev in zip((made, t, prim), outs):
            cl.enqueue_copy(queue, host, dev)
        queue.finish()
        assert made.all(), f"{np.count_nonzero(made == 0)} of {len(made)} groups made no packet"
        if query == "closest":
            assert np.array_equal(prim, expected_hits.prim) and np.array_equal(t, expected_hits.t)
        else:
            assert np.array_equal(prim >= 0, expected_any)
    assert (expected_hits.prim >= 0).mean() > 0.2 and (expected_hits.prim < 0).any()

"""Two-level scenes (docs/instances.md): an Accel of meshes placed by affine
transforms answers as the flattened scene does.

* Every two-level BVH (each volume shape, each bottom-level builder) gives
  exactly what the two-level brute force gives, bit for bit, in every query
  and cull mode -- grazing rays, ties and mirrors included.
* Both give the hits of the flattened scene, computed in float64 by numpy
  (every mesh moved by its transform, instances in order): the same instance
  and triangle, t, normal and face within float32 rounding, for every ray
  that no rounding could send elsewhere (one far from every edge and from a
  second hit), which is nearly all of them.
* Rays that enter an instance exactly through an edge or corner of its box
  are never lost; exact ties go to the lower instance, then triangle.
* Bad instances are one line each.
"""

import copy
import itertools

import numpy as np
import pytest

import clrt
from clrt import config
from clrt.scene import primitives
from clrt.scene.instances import Instances, as_instances

from conftest import TEST_MESHES


def _rotation(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _affine(linear=np.eye(3), shift=(0.0, 0.0, 0.0)) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = linear, shift
    return m


def _scene_list():
    """Real meshes (the suite's own: a torus, a box, a heightfield and the
    crossing quads with a duplicated triangle), the torus placed three times:
    rotated and stretched, mirrored, and sheared; a mirror among the others."""
    torus, box = TEST_MESHES["torus"](), TEST_MESHES["box"]()
    field, crossing = TEST_MESHES["heightfield"](), TEST_MESHES["crossing"]()
    shear = np.array([[1.0, 0.4, 0.0], [0.0, 1.0, 0.0], [0.3, 0.0, 0.8]])
    return [
        (torus, _affine(_rotation((1, 2, 3), 0.7) @ np.diag([1.5, 0.7, 1.2]), (0.2, -0.3, 0.1))),
        (box, _affine(_rotation((0, 1, 1), 2.1), (2.5, 0.5, -0.5))),
        (torus, _affine(np.diag([-1.0, 1.0, 1.0]) @ _rotation((1, 0, 0), 0.4), (-2.6, 0.4, 0.3))),
        (field, _affine(np.diag([1.0, 1.0, -0.5]), (0.0, 2.8, 0.0))),
        (crossing, _affine(_rotation((0, 0, 1), 0.3) * 0.8, (0.1, -2.4, 0.6))),
        (torus, _affine(shear, (2.4, -2.2, -0.4))),
    ]


def _rays(bounds, count, seed):
    """Rays from a sphere around the scene aimed at random points of its box
    (about a third miss), and a few from inside."""
    rng = np.random.default_rng(seed)
    lo, hi = bounds
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo)
    outside = rng.normal(size=(count, 3))
    origins = centre + radius * outside / np.linalg.norm(outside, axis=1, keepdims=True)
    origins[: count // 10] = rng.uniform(lo, hi, (count // 10, 3))
    targets = rng.uniform(lo, hi, (count, 3))
    return origins, targets - origins


def _flat_reference(instances: Instances, origins, directions):
    """float64 hits of the flattened scene, by brute force: per ray and
    triangle t (inf where missed), the barycentrics' smallest weight
    (signed: negative outside), the cosine of the ray with the triangle's
    plane, and each triangle's instance, row in its mesh, unit normal."""
    corners, inst, prim, normals = [], [], [], []
    for k, (mesh, m) in enumerate(zip((instances.meshes[i] for i in instances.mesh_of), instances.transforms)):
        c = mesh.vertices.astype(np.float64)[mesh.faces] @ m[:3, :3].T + m[:3, 3]
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        corners.append(c)
        normals.append(n / np.linalg.norm(n, axis=1, keepdims=True))
        inst.append(np.full(len(c), k))
        prim.append(np.arange(len(c)))
    c, n = np.concatenate(corners), np.concatenate(normals)
    d = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]                          # (F, 3)
    p = np.cross(d[:, None], e2[None])                                     # (N, F, 3)
    det = np.einsum("nfk,fk->nf", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origins[:, None] - c[None, :, 0]
        u = np.einsum("nfk,nfk->nf", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("nk,nfk->nf", d, q) * inv
        t = np.einsum("fk,nfk->nf", e2, q) * inv
    margin = np.minimum(np.minimum(u, v), 1 - u - v)
    cosine = np.abs(np.einsum("nk,fk->nf", d, n))
    t = np.where((margin >= 0) & (t > 0) & (det != 0), t, np.inf)
    return t, margin, cosine, np.concatenate(inst), np.concatenate(prim), n


def _clear(t, margin, cosine, scale):
    """Rays whose answers no float32 rounding can change: no triangle's edge
    within 1e-4 (barycentric) of the ray in front of it, no grazing triangle,
    and the nearest two hits 1e-4 of the scene apart."""
    ahead = np.isfinite(t) | (np.abs(margin) < 1e-4)
    near_edge = (ahead & (np.abs(margin) < 1e-4)).any(axis=1)
    grazing = (np.isfinite(t) & (cosine < 1e-3)).any(axis=1)
    two = np.sort(t, axis=1)[:, :2]
    with np.errstate(invalid="ignore"):
        close = (two[:, 1] - two[:, 0]) < 1e-4 * scale
    return ~near_edge & ~grazing & ~close


# Every volume shape and every bottom-level builder, each at least once.
VARIANTS = [("box", "sah", 4), ("box", "device", 4), ("sphere", "paper", 1), ("ellipse", "device", 2),
            ("ellipse", "paper", 4), ("sphere", "sah", 4)]


@pytest.fixture(scope="module")
def scene(device):
    """The instances, rays, the float64 flattened reference and the two-level
    brute force's answers."""
    instances = as_instances(_scene_list())
    origins, directions = _rays(instances.bounds, 1500, seed=5)
    brute = clrt.Accel(instances, accel="none", device=device)
    answers = {cull: brute.trace(origins, directions, cull=cull) for cull in config.CULL_MODES}
    answers["count"] = brute.count(origins, directions)
    answers["all"] = brute.all_hits(origins, directions)
    answers["any"] = brute.any_hit(origins, directions, tmax=3.0)
    return instances, origins, directions, answers


def test_the_scene_is_instanced_not_copied(scene):
    instances = scene[0]
    assert len(instances) == 6 and len(instances.meshes) == 4
    assert instances.mesh_of.tolist() == [0, 1, 0, 2, 3, 0]
    assert (np.linalg.det(instances.transforms[:, :3, :3]) < 0).tolist() == [False, False, True, True, False, False]


@pytest.mark.parametrize("volume, builder, leaf", VARIANTS)
def test_every_two_level_bvh_answers_as_brute_force_bit_for_bit(scene, volume, builder, leaf, device):
    instances, origins, directions, want = scene
    accel = clrt.Accel(instances, accel=volume, builder=builder, leaf_size=leaf, device=device)
    assert len(accel.acceleration.bottoms) == 4 and len(accel.acceleration.instances) == 6
    for cull in config.CULL_MODES:
        got = accel.trace(origins, directions, cull=cull)
        for field in got._fields:
            assert np.array_equal(getattr(got, field), getattr(want[cull], field)), (cull, field)
    assert np.array_equal(accel.count(origins, directions), want["count"])
    assert np.array_equal(accel.any_hit(origins, directions, tmax=3.0), want["any"])
    for a, b in zip(accel.all_hits(origins, directions), want["all"]):
        assert np.array_equal(a, b)


def test_hits_are_the_flattened_scenes(scene):
    instances, origins, directions, answers = scene
    t, margin, cosine, inst, prim, normals = _flat_reference(instances, origins, directions)
    bounds = instances.bounds
    scale = float(np.linalg.norm(bounds[1] - bounds[0]))
    clear = _clear(t, margin, cosine, scale)
    nearest = np.argmin(t, axis=1)
    hit = np.isfinite(t.min(axis=1))
    assert clear.mean() > 0.9 and (clear & hit).sum() > 500 and (clear & ~hit).sum() > 100
    got = answers["none"]
    rows = clear & hit
    assert np.array_equal(got.hit[clear], hit[clear])
    assert np.array_equal(got.instance[rows], inst[nearest[rows]])
    assert np.array_equal(got.prim[rows], prim[nearest[rows]])
    assert (got.instance[clear & ~hit] == -1).all() and (got.prim[clear & ~hit] == -1).all()
    assert np.allclose(got.t[rows], t.min(axis=1)[rows], rtol=0, atol=2e-6 * scale)
    assert np.allclose(got.normal[rows], normals[nearest[rows]], rtol=0, atol=1e-5)
    d = directions[rows] / np.linalg.norm(directions[rows], axis=1, keepdims=True)
    front = np.einsum("nk,nk->n", d, normals[nearest[rows]]) < 0      # met against the placed normal
    assert np.array_equal(got.front[rows], front)
    # The mirrored instances (2 and 3) among the hits, seen from both sides.
    assert {2, 3} <= set(got.instance[rows].tolist()) and front.any() and (~front).any()
    # Culling keeps the nearest hit of the faces kept, as in the flattened scene.
    d_all = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    facing = np.einsum("nk,fk->nf", d_all, normals) < 0
    for cull, keep in (("back", facing), ("front", ~facing)):
        kept = np.where(keep, t, np.inf)
        sure = clear & _clear(kept, np.where(keep, margin, 1.0), cosine, scale)
        first = np.argmin(kept, axis=1)
        found = np.isfinite(kept.min(axis=1))
        assert np.array_equal(answers[cull].hit[sure], found[sure]), cull
        rows = sure & found
        assert np.array_equal(answers[cull].instance[rows], inst[first[rows]]), cull
        assert np.array_equal(answers[cull].prim[rows], prim[first[rows]]), cull
    # Every hit along a ray: the flattened scene's, in order.
    ahead = np.isfinite(t)
    assert np.array_equal(answers["count"][clear], ahead[clear].sum(axis=1))
    every = answers["all"]
    mine = np.isin(every.ray_id, np.nonzero(clear)[0])
    ray, k = np.nonzero(ahead & clear[:, None])
    order = np.lexsort((prim[k], inst[k], t[ray, k], ray))
    assert np.array_equal(every.ray_id[mine], ray[order])
    assert np.array_equal(every.instance[mine], inst[k][order])
    assert np.array_equal(every.prim[mine], prim[k][order])


def _grazing_rays(lo, hi, rng, per_line=24):
    """Rays that graze the box lo..hi: axis-parallel rays lying in each face's
    plane (at its edges among others), from both sides, and rays from outside
    through points of its edges and corners; every coordinate on a grid of
    eighths of the box, so that the placements below move them exactly."""
    rays = []
    for axis, along in itertools.permutations(range(3), 2):
        other = 3 - axis - along
        for side in (lo, hi):
            grid = np.concatenate([[0.0, 1.0, 0.5], rng.integers(0, 9, per_line - 3) / 8])
            points = np.zeros((per_line, 3))
            points[:, axis] = side[axis]
            points[:, other] = lo[other] + grid * (hi[other] - lo[other])
            for start, sign in ((lo, 1.0), (hi, -1.0)):
                points[:, along] = start[along] - sign
                d = np.zeros((per_line, 3))
                d[:, along] = sign
                rays.append((points.copy(), d))
    corners = np.array(list(itertools.product(*zip(lo, hi))))
    a, b = corners[rng.integers(0, 8, 300)], corners[rng.integers(0, 8, 300)]
    on_edges = a + rng.integers(0, 9, (300, 1)) / 8 * (b - a)   # corners, edges and diagonals
    origins = lo + (hi - lo) * rng.integers(-16, 25, (300, 3)) / 8
    rays.append((origins, on_edges - origins))
    origins, d = (np.concatenate(x) for x in zip(*rays))
    keep = np.linalg.norm(d, axis=1) > 0
    return origins[keep], d[keep]


@pytest.mark.parametrize("volume", ["box", "sphere", "ellipse"])
def test_rays_grazing_an_instances_box_answer_as_the_flattened_scene(volume, device):
    """A box mesh placed where its faces are its world box's (quarter turns,
    mirrors, scales by powers of two, shifts on a grid: moves that float32
    makes exactly, so that the flattened scene is the same scene): rays in the
    faces' planes and through the edges and corners of each instance's box
    hit what they hit in the flattened scene (brute force) -- none is lost to
    the box, none gained -- the same triangle up to a tie within rounding (at
    a corner: the test shears the ray along other axes in object space, so t
    may round to a neighbouring float), bit for bit for 98 % of them."""
    cube = primitives.box((2.0, 2.0, 2.0))
    quarter, mirror = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), np.diag([-1.0, 1.0, 1.0])
    placements = [_affine(2.0 * np.eye(3), (6.0, 0.0, 0.0)), _affine(0.5 * quarter, (0.0, 5.0, 0.25)),
                  _affine(mirror @ quarter.T, (-6.0, 0.5, -1.0)), _affine(0.25 * mirror @ quarter, (0.0, -5.0, 1.5))]
    instances = as_instances([(cube, m) for m in placements])
    accel = clrt.Accel(instances, accel=volume, device=device)
    flat = clrt.Accel(instances.flattened(), accel="none", device=device)
    rng = np.random.default_rng(11)
    rays = [_grazing_rays(*box, rng) for box in instances.boxes()]
    origins, directions = (np.concatenate(x) for x in zip(*rays))
    got, want = accel.trace(origins, directions), flat.trace(origins, directions)
    assert want.hit.mean() > 0.8 and np.array_equal(got.hit, want.hit)
    faces = len(cube.faces)
    flat_index = np.where(got.hit, got.instance * faces + got.prim, -1)
    # The triangle is one the flattened scene meets within 4 ulps of its nearest hit.
    every = flat.all_hits(origins, directions)
    nearest = want.t[every.ray_id]
    tied = every.t <= nearest + 4 * np.spacing(nearest)
    near = set(zip(every.ray_id[tied].tolist(), every.prim[tied].tolist()))
    assert all((i, int(flat_index[i])) in near for i in np.nonzero(got.hit)[0].tolist())
    assert np.allclose(got.t[got.hit], want.t[got.hit], rtol=5e-7, atol=0)
    same = got.hit & (flat_index == want.prim)
    for field in ("u", "v", "normal"):
        assert np.allclose(getattr(got, field)[same], getattr(want, field)[same], rtol=0, atol=1e-6), field
    assert np.array_equal(got.front[same], want.front[same])
    bitwise = same & (got.t == want.t) & (got.u == want.u) & (got.v == want.v) & (got.normal == want.normal).all(1)
    assert bitwise.sum() > 0.97 * got.hit.sum()


def test_ties_go_to_the_lower_instance_then_triangle(device):
    """The crossing quads (with an exact duplicate of triangle 0 as triangle 4)
    placed twice by the same transform: every hit is instance 0's, never
    triangle 4, in every walk."""
    crossing = TEST_MESHES["crossing"]()
    m = _affine(_rotation((1, 1, 0), 0.5) * 2.0, (0.3, 0.0, 0.0))
    origins, directions = _rays(Instances([crossing], [0], [m]).bounds, 400, seed=3)
    for accel in ("none", "box", "sphere"):
        hits = clrt.Accel([(crossing, m), (crossing, m)], accel=accel, device=device).trace(origins, directions)
        assert hits.hit.sum() > 100
        assert (hits.instance[hits.hit] == 0).all() and (hits.prim[hits.hit] != 4).all(), accel


def test_one_mesh_is_instance_zero_of_itself(device):
    mesh = primitives.icosphere(2)
    origins = np.array([[0.1, 0.2, 5.0], [5.0, 5.0, 5.0]])
    directions = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    one = clrt.Accel(mesh, device=device)
    assert "ACCEL_INSTANCES" not in one.device_scene.defines()
    hits = one.trace(origins, directions)
    assert hits.instance.tolist() == [0, -1]
    assert one.all_hits(origins, directions).instance.tolist() == [0, 0]
    listed = clrt.Accel([mesh], device=device)   # a list of one: one instance, same answers
    assert "ACCEL_INSTANCES" in listed.device_scene.defines()
    again = listed.trace(origins, directions)
    for field in hits._fields:
        assert np.array_equal(getattr(again, field), getattr(hits, field)), field


def test_split_buffers_copies_and_pickles_answer_alike(scene, device):
    import pickle
    instances, origins, directions, answers = scene
    split = clrt.Accel(instances, accel="box", device=device, max_buffer_bytes=32768)
    assert split.geometry.parts() > 1
    for accel in (split, copy.copy(split), pickle.loads(pickle.dumps(split))):
        hits = accel.trace(origins, directions)
        for field in hits._fields:
            assert np.array_equal(getattr(hits, field), getattr(answers["none"], field)), field
    assert "instances" in repr(split)


def _moved(transforms):
    """The transforms turned, shifted and rescaled, one mirrored anew and one
    mirror undone: boxes, flags and the top level all change."""
    rng = np.random.default_rng(11)
    moved = transforms.copy()
    for k, m in enumerate(moved):
        m[:3, :3] = _rotation(rng.normal(size=3), rng.uniform(0.3, 3.0)) @ m[:3, :3] * rng.uniform(0.6, 1.4)
        m[:3, 3] += rng.normal(size=3) * 2.0
    moved[1, :3, :3] = moved[1, :3, :3] @ np.diag([1.0, -1.0, 1.0])
    moved[2, :3, :3] = moved[2, :3, :3] @ np.diag([-1.0, 1.0, 1.0])
    return moved


@pytest.mark.parametrize("volume, builder, split", [("box", "sah", None), ("ellipse", "device", None),
                                                    ("sphere", "paper", 32768), ("box", "device", 32768)])
def test_moved_instances_are_a_fresh_build_of_them_bit_for_bit(scene, volume, builder, split, device):
    """move_instances builds the instance table and the top level again and
    keeps each mesh's rows: the host arrays, the uploaded buffers, the
    program's defines and every answer are those of an Accel made of the
    moved instances."""
    instances = scene[0]
    moved = _moved(instances.transforms)
    accel = clrt.Accel(instances, accel=volume, builder=builder, device=device, max_buffer_bytes=split)
    assert (accel.acceleration.device_top is not None) == (builder == "device")   # the top level's builder
    base = len(accel.acceleration.top.rows)
    meshes_rows = accel.acceleration.rows[base:].copy()
    accel.move_instances(moved)
    assert (accel.acceleration.pending is not None) == (builder == "device")   # (read back when asked for)
    fresh = clrt.Accel(clrt.Instances(instances.meshes, instances.mesh_of, moved), accel=volume, builder=builder,
                       device=device, max_buffer_bytes=split)
    mine, theirs = accel.acceleration, fresh.acceleration
    assert np.array_equal(mine.rows[base:], meshes_rows)
    assert mine.rows.tobytes() == theirs.rows.tobytes() and mine.instances.tobytes() == theirs.instances.tobytes()
    assert accel.device_scene.defines() == fresh.device_scene.defines() and mine.move_ms > 0
    assert np.array_equal(accel.geometry.origin, fresh.geometry.origin)
    import pyopencl as cl
    for name, host in (("nodes", theirs.rows), ("instances", theirs.instances)):
        back = [np.empty_like(host) for _ in range(2)]
        for a, out in zip((accel, fresh), back):
            parts, at = a.geometry.buffers[name], 0
            for part in dict.fromkeys(parts):   # each part once (the last is repeated), in order
                n = min(part.size // host.itemsize, len(host) - at)
                cl.enqueue_copy(a.queue, out[at:at + n], part)
                at += n
        assert back[0].tobytes() == back[1].tobytes() == host.tobytes(), name
    origins, directions = _rays(fresh.instances.bounds, 1500, seed=8)
    directions = fresh.instances.boxes().mean(axis=1)[np.arange(1500) % 6] - origins   # at the instances
    got, want = accel.trace(origins, directions), fresh.trace(origins, directions)
    assert got.hit.mean() > 0.3
    for field in got._fields:
        assert np.array_equal(getattr(got, field), getattr(want, field)), field
    assert np.array_equal(accel.count(origins, directions), fresh.count(origins, directions))


@pytest.mark.parametrize("builder", ["device", "sah"])
def test_bad_moves_are_one_line(scene, builder, device):
    """Refused on the device's path (whose fast checks send doubtful
    transforms to the host's exact ones) as on the host's, with the same
    words as when instances are made; nothing moves."""
    instances = scene[0]
    accel = clrt.Accel(instances, builder=builder, device=device)
    accel.move_instances(instances.transforms)   # moved: its host copies are read from the device when asked
    _one_line_error(lambda: accel.move_instances(instances.transforms[:5]),
                    r"transforms must have shape \(6, 4, 4\), got \(5, 4, 4\)")
    bad = instances.transforms.copy()
    bad[3, 2] = 0.0
    _one_line_error(lambda: accel.move_instances(bad), r"instance 3's transform must be invertible")
    far = instances.transforms.copy()
    far[4, :3, 3] = (9e29, 0, 0)
    far[4, :3, :3] *= 1e29
    _one_line_error(lambda: accel.move_instances(far), r"instance 4's transform takes its mesh to .*, past \+-1e\+30")
    nan = instances.transforms.copy()
    nan[2, 1, 3] = np.nan
    _one_line_error(lambda: accel.move_instances(nan), r"instance 2's transform must be finite, got nan in row 1")
    skew = instances.transforms.copy()
    skew[5, 3, 0] = 0.5
    _one_line_error(lambda: accel.move_instances(skew), r"instance 5's transform must be affine")
    # Near the condition limit the bound sends a transform to the host's singular values, which decide.
    thin = instances.transforms.copy()
    turned = _rotation((1, 2, 0), 0.3), _rotation((0, 1, 1), 1.1)
    thin[1, :3, :3] = turned[0] @ np.diag([1.0, 0.95e-6, 1.0]) @ turned[1]
    _one_line_error(lambda: accel.move_instances(thin),
                    r"instance 1's transform must be invertible .* got one of condition number 1.05e\+06")
    _one_line_error(lambda: clrt.Accel(TEST_MESHES["box"](), device=device).move_instances(instances.transforms),
                    r"move_instances needs an Accel of instances")
    rays = _rays(instances.bounds, 200, seed=1)
    hits = accel.trace(*rays)   # nothing moved by the refusals
    unmoved = clrt.Accel(instances, builder=builder, device=device)
    assert np.array_equal(hits.t, unmoved.trace(*rays).t)
    # nor the host copies, read when asked from the device's buffers (the refused placements were built there)
    assert accel.acceleration.instances.tobytes() == unmoved.acceleration.instances.tobytes()
    assert accel.acceleration.rows.tobytes() == unmoved.acceleration.rows.tobytes()
    thin[1, :3, :3] = turned[0] @ np.diag([1.0, 1.05e-6, 1.0]) @ turned[1]   # condition 9.5e5: it moves
    accel.move_instances(thin)
    fresh = clrt.Accel(Instances(instances.meshes, instances.mesh_of, thin), builder=builder, device=device)
    assert np.array_equal(accel.trace(*rays).t, fresh.trace(*rays).t)
    assert np.array_equal(accel.instances.transforms, thin)


def _many_placements(count, seed):
    """``count`` placements of three of the suite's meshes: turned, stretched
    along three axes, every third mirrored and every third sheared, scattered
    far from the origin (the world's device frame moves there), and eight at
    one place (one Morton code for eight leaves of the device's top level)."""
    rng = np.random.default_rng(seed)
    transforms = np.tile(np.eye(4), (count, 1, 1))
    for k in range(count):
        linear = _rotation(rng.normal(size=3), rng.uniform(0.0, 2.0 * np.pi)) @ np.diag(rng.uniform(0.3, 2.0, 3))
        if k % 3 == 1:
            linear = linear @ np.diag([-1.0, 1.0, 1.0])
        elif k % 3 == 2:
            linear = linear @ np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.3, 0.0, 1.0]])
        transforms[k, :3, :3] = linear
    transforms[:, :3, 3] = rng.uniform(-10.0, 10.0, (count, 3)) + (3000.0, 0.0, -2000.0)
    transforms[count // 2:count // 2 + 8] = transforms[count // 2]
    meshes = [TEST_MESHES["torus"](), TEST_MESHES["box"](), TEST_MESHES["crossing"]()]
    return Instances(meshes, rng.integers(0, 3, count), transforms)


def _check_device_top_level(two):
    """The device's top level of TwoLevel ``two`` is a binary tree whose leaves
    hold every instance once, each row's children fitted (volumes.fit, the
    host's fit, bit for bit) to their exact boxes -- a leaf's the instance's
    world box, an inner node's the union of its children's -- and no deeper
    than the bound its programs' stack was sized for."""
    from clrt.accel.instances import lbvh_depth_bound
    from clrt.accel.rows import child_refs
    from clrt.accel.volumes import fit
    top, table = two.top, two.instances
    count = len(table)
    rows, exact = top.rows, top.exact_rows
    assert len(rows) == max(count - 1, 1) and rows.tobytes() == two.rows[:len(rows)].tobytes()
    refs = child_refs(rows).reshape(-1, 2)                    # (ref, count) of each child, left then right
    leaf, inner = refs[:, 1] == 1, refs[:, 1] == 0
    assert np.array_equal(np.sort(refs[leaf, 0]), np.arange(count))
    assert np.array_equal(np.sort(refs[inner, 0]), np.arange(1, len(rows)))
    assert (leaf | inner).sum() == (2 * count - 2 if count > 1 else 1)
    lo = np.stack([exact["left_a"][:, :3], exact["right_a"][:, :3]], 1).reshape(-1, 3)
    hi = np.stack([exact["left_b"][:, :3], exact["right_b"][:, :3]], 1).reshape(-1, 3)
    assert np.array_equal(lo[leaf], table["lo"][refs[leaf, 0], :3])
    assert np.array_equal(hi[leaf], table["hi"][refs[leaf, 0], :3])
    below = refs[inner, 0]                                    # an inner child's row: its exact box, its children's union
    assert np.array_equal(lo[inner], np.minimum(lo[2 * below], lo[2 * below + 1]))
    assert np.array_equal(hi[inner], np.maximum(hi[2 * below], hi[2 * below + 1]))
    present = leaf | inner
    a, b = fit(top.accel, np.stack([lo[present], hi[present]], axis=1))
    got_a = np.stack([rows["left_a"], rows["right_a"]], 1).reshape(-1, 4)[present]
    got_b = np.stack([rows["left_b"], rows["right_b"]], 1).reshape(-1, 4)[present]
    assert np.array_equal(got_a[:, :3], a[:, :3])
    if top.accel == "sphere":
        assert np.array_equal(got_b[:, 0], a[:, 3])
    else:
        assert np.array_equal(got_b[:, :3], b[:, :3])
    assert top.depth <= lbvh_depth_bound(count)
    assert two.depth == lbvh_depth_bound(count) + 1 + max(m.depth for m in two.bottoms)


@pytest.mark.parametrize("volume", ["box", "sphere", "ellipse"])
def test_the_device_top_level_answers_as_the_hosts(volume, device):
    """The top level built on the device (a linear BVH over its instance
    table) and the host's (binned SAH over the host's table), over 150
    placements turned, stretched, mirrored and sheared, eight at one place:
    the same table bit for bit, a sound tree (_check_device_top_level), and
    the same answers, bit for bit, as each other and as the two-level brute
    force -- hits in every cull mode, counts, every hit along a ray, closest
    points."""
    instances = _many_placements(150, seed=21)
    on_device = clrt.Accel(instances, accel=volume, builder="device", device=device)
    on_host = clrt.Accel(instances, accel=volume, builder="sah", device=device)
    brute = clrt.Accel(instances, accel="none", device=device)
    assert on_device.acceleration.device_top is not None and on_host.acceleration.device_top is None
    assert np.array_equal(on_device.geometry.origin, on_host.geometry.origin) and on_host.geometry.origin.any()
    mine, theirs = on_device.acceleration.instances, on_host.acceleration.instances
    for name in ("to_world", "to_object", "lo", "hi", "mesh", "flags", "min_scale"):
        assert mine[name].tobytes() == theirs[name].tobytes() == brute.acceleration.instances[name].tobytes(), name
    _check_device_top_level(on_device.acceleration)
    boxes = instances.boxes()
    rng = np.random.default_rng(22)
    origins, _ = _rays(instances.bounds, 1500, seed=23)
    directions = boxes.mean(axis=1)[rng.integers(0, 150, 1500)] + rng.normal(size=(1500, 3)) - origins
    for cull in config.CULL_MODES:
        want = brute.trace(origins, directions, cull=cull)
        assert want.hit.mean() > 0.5 and len(set(want.instance[want.hit].tolist())) > 100
        for accel in (on_device, on_host):
            got = accel.trace(origins, directions, cull=cull)
            for field in got._fields:
                assert np.array_equal(getattr(got, field), getattr(want, field)), (cull, field)
    want = brute.count(origins, directions)
    every = brute.all_hits(origins, directions)
    points = rng.uniform(*instances.bounds, (800, 3))
    nearest = brute.closest_points(points)
    for accel in (on_device, on_host):
        assert np.array_equal(accel.count(origins, directions), want)
        for a, b in zip(accel.all_hits(origins, directions), every):
            assert np.array_equal(a, b)
        got = accel.closest_points(points)
        for field in got._fields:
            assert np.array_equal(getattr(got, field), getattr(nearest, field), equal_nan=True), field


@pytest.mark.parametrize("count", [1, 2, 3])
def test_the_fewest_instances_on_the_device(count, device):
    """A top level of one instance (a root row, its leaf on the left), two
    and three, built and moved on the device: sound trees, and the brute
    force's answers."""
    instances = _many_placements(12, seed=31)
    few = Instances(instances.meshes, instances.mesh_of[:count], instances.transforms[:count])
    accel = clrt.Accel(few, accel="box", builder="device", device=device)
    for placed in (few, Instances(instances.meshes, instances.mesh_of[:count], instances.transforms[6:6 + count])):
        if placed is not few:
            accel.move_instances(placed.transforms)
        _check_device_top_level(accel.acceleration)
        origins, directions = _rays(placed.bounds, 400, seed=32)
        want = clrt.Accel(placed, accel="none", device=device).trace(origins, directions)
        got = accel.trace(origins, directions)
        assert want.hit.any()
        for field in got._fields:
            assert np.array_equal(getattr(got, field), getattr(want, field)), field


def test_the_table_bounds_each_transforms_scales():
    """Instance.min_scale is at most the linear part's smallest singular value
    and at most 7 % below it; the condition bound at least the condition
    number (less the slack of float64 rounding that the recheck of moved
    transforms allows for) and at most 15 % above it -- for rotations and uniform scales
    (the loosest case), stretches, shears, mirrors, and the thinnest
    transforms allowed (two singular values a millionth of the third, where
    the determinant loses most to rounding)."""
    from clrt.accel.instances import INVERSE_SLACK, MIN_SCALE_SLACK, linear_part
    rng = np.random.default_rng(41)
    linear = []
    for scales in ([1.0, 1.0, 1.0], [3.0, 0.2, 1.0], [-1.0, 2.0, 0.5], [1.0, 1e-6, 1e-6], [1.0, 1e-3, 1.05e-6],
                   [1.0, 1.0, 1e-6]):
        for _ in range(200):
            linear.append(_rotation(rng.normal(size=3), rng.uniform(0, 7)) @ np.diag(scales)
                          @ _rotation(rng.normal(size=3), rng.uniform(0, 7)) * rng.uniform(0.01, 100.0))
    linear.append(np.array([[1.0, 0.7, 0.0], [0.0, 1.0, 0.0], [0.3, 0.0, 0.9]]))
    linear = np.array(linear)
    singular = np.linalg.svd(linear, compute_uv=False)
    _, det, condition, min_scale = linear_part(np.moveaxis(linear, 0, -1))
    ratio = min_scale / singular[:, 2]
    assert (ratio <= 1.0).all() and ratio.min() > 0.93
    assert ratio.max() > 0.98   # (tight where one singular value stands apart)
    kappa = singular[:, 0] / singular[:, 2]
    slack = MIN_SCALE_SLACK + INVERSE_SLACK * condition * condition   # (as to_recheck allows)
    assert (condition >= kappa * (1.0 - slack)).all() and (condition <= 1.15 * kappa).all()
    assert np.array_equal(det < 0, np.linalg.det(linear) < 0)


@pytest.mark.parametrize("volume, builder", [("box", "sah"), ("sphere", "device"), ("ellipse", "paper")])
def test_closest_points_on_instances(scene, volume, builder, device):
    """Every two-level BVH finds the closest points of the two-level brute
    force, bit for bit; both are the flattened scene's -- the same instance
    and triangle but at near ties (equal distances, within rounding), the
    distance and the point within float32 rounding of the transforms -- under
    rotations, non-uniform scales, shears and mirrors (the walk bounds a
    mesh's volumes by the instance's smallest scale)."""
    instances = scene[0]
    lo, hi = instances.bounds
    points = np.random.default_rng(4).uniform(lo - 0.5, hi + 0.5, (2000, 3))
    brute = clrt.Accel(instances, accel="none", device=device).closest_points(points)
    got = clrt.Accel(instances, accel=volume, builder=builder, device=device).closest_points(points)
    for field in got._fields:
        assert np.array_equal(getattr(got, field), getattr(brute, field), equal_nan=True), field
    want = clrt.Accel(instances.flattened(), device=device).closest_points(points)
    faces = np.array([len(instances.meshes[k].faces) for k in instances.mesh_of])
    first = np.concatenate([[0], np.cumsum(faces)])
    same = first[got.instance] + got.prim == want.prim
    scale = float(np.abs(hi - lo).max())
    assert same.mean() > 0.95 and set(got.instance) == set(range(6))
    assert np.abs(got.distance - want.distance).max() < 1e-6 * scale
    assert np.abs(got.point[same] - want.point[same]).max() < 1e-5 * scale
    far = clrt.Accel(instances, device=device).closest_points(points, max_distance=0.05)
    assert np.array_equal(far.instance == -1, ~(brute.distance <= 0.05)) and (far.instance >= 0).any()


def _one_line_error(call, match):
    with pytest.raises(clrt.InputError, match=match) as info:
        call()
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("transform, match", [
    (np.diag([1.0, 1.0, 0.0, 1.0]), r"instance 1's transform must be invertible .* got a singular one"),
    (np.diag([1.0, 1e-7, 1.0, 1.0]), r"must be invertible .* got one of condition number 1e\+07"),
    (np.array([[1.0, 0, 0, np.nan], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
     r"instance 1's transform must be finite, got nan in row 0, column 3"),
    (np.full((4, 4), np.inf), r"must be finite, got inf in row 0, column 0"),
    (np.eye(3), r"instance 1's transform must be a 4x4 affine matrix, got shape \(3, 3\)"),
    (np.eye(4)[:, :3], r"must be a 4x4 affine matrix, got shape \(4, 3\)"),
    ("not a matrix", r"instance 1's transform must be a 4x4 affine matrix"),
    (np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0.5, 1]]),
     r"must be affine \(last row 0 0 0 1\), got last row \(0, 0, 0.5, 1\)"),
])
def test_a_bad_transform_is_one_line(transform, match):
    mesh = primitives.icosphere(1)
    _one_line_error(lambda: clrt.Accel([mesh, (mesh, transform)]), match)


def test_bad_instances_are_one_line(device, monkeypatch):
    mesh = primitives.icosphere(1)
    _one_line_error(lambda: Instances([mesh], [0, 1]), r"instance 1 names mesh 1, but there is 1 mesh \(0..0\)")
    _one_line_error(lambda: Instances([mesh, mesh], [0, -1]), r"instance 1 names mesh -1, but there are 2 meshes")
    _one_line_error(lambda: Instances([mesh], [0.5]), r"mesh_of must be a non-empty list of mesh indices")
    _one_line_error(lambda: Instances([mesh], [0, 0], np.eye(4)[None]), r"transforms must have shape \(2, 4, 4\)")
    _one_line_error(lambda: clrt.Accel([mesh, 3]), r"instance 1 must be a mesh or a \(mesh, 4x4 transform\) pair")
    monkeypatch.setattr(config, "MAX_INSTANCES", 3)
    _one_line_error(lambda: clrt.Accel([mesh] * 4), r"a scene holds at most 3 instances .* got 4")
    _one_line_error(lambda: Instances([mesh], [0] * 4), r"a scene holds at most 3 instances .* got 4")
    monkeypatch.undo()
    accel = clrt.Accel([(mesh, _affine(100.0 * np.eye(3))), (primitives.box((1.0, 1.0, 1.0)),
                                                             _affine(shift=(3.0, 0.0, 0.0)))], device=device)
    _one_line_error(lambda: accel.refit(mesh.vertices), r"refit of an Accel of 2 meshes needs mesh=: the index of "
                                                        r"the one whose vertices move \(0..1, as instances.meshes")
    _one_line_error(lambda: accel.refit(mesh.vertices, mesh=2), r"mesh must be an integer in 0..1, got 2")
    _one_line_error(lambda: accel.refit(mesh.vertices, mesh=1.0), r"mesh must be an integer in 0..1, got 1.0")
    _one_line_error(lambda: accel.refit(mesh.vertices, mesh=1), r"refit needs vertices of shape \(8, 3\), got ")
    _one_line_error(lambda: clrt.Accel(mesh, device=device).refit(mesh.vertices, mesh=1),
                    r"mesh must be an integer in 0..0, got 1")
    _one_line_error(lambda: accel.refit(mesh.vertices * 1e31, mesh=0), r"vertex coordinates must lie within \+-1e30")
    far = mesh.vertices * 1e29   # within the range, but placed 100 times larger
    _one_line_error(lambda: accel.refit(far, mesh=0), r"instance 0's transform takes its mesh to .*, past \+-1e\+30")
    assert np.array_equal(accel.instances.meshes[0].vertices, mesh.vertices)   # nothing moved by the refusals


# --------------------------------------------------------------------------- glTF files: nodes as instances

def _hierarchy_glb(path, groups=4, per_group=5):
    """A GLB written by trimesh whose node hierarchy places one mesh (a ball)
    groups x per_group times under turned and shifted group nodes, one of each
    group's children mirrored, and a box once at the root."""
    import trimesh
    from trimesh.transformations import rotation_matrix, translation_matrix
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(), geom_name="box", node_name="box")
    scene.add_geometry(trimesh.creation.icosphere(subdivisions=1), geom_name="ball", node_name="ball")
    for g in range(groups):
        scene.graph.update(frame_to=f"group{g}", frame_from=scene.graph.base_frame,
                           matrix=rotation_matrix(0.4 * g, [0, 0, 1]) @ translation_matrix([3.0 * g, 0, 0]))
        for c in range(per_group):
            m = translation_matrix([0.0, 3.0 * c, 2.0]) @ np.diag([1.0, 1.0, -1.0 if c == 1 else 1.5, 1.0])
            scene.graph.update(frame_to=f"ball{g}_{c}", frame_from=f"group{g}", matrix=m, geometry="ball")
    scene.export(path)
    return path


def test_a_gltf_files_mesh_nodes_are_its_instances(tmp_path, device):
    """One glTF mesh placed by many nodes is one bottom-level mesh (a mirrored
    placement another, rewound, as the file reads flattened); instances in
    document order, depth first, transforms composed down the hierarchy: the
    flattened scene of the instances is the file read flattened, corner for
    corner, and the hits name the node's instance."""
    path = _hierarchy_glb(tmp_path / "balls.glb")
    accel = clrt.Accel(path, device=device)
    instances = accel.instances
    assert len(instances) == 22 and len(instances.meshes) == 3      # box, ball, the mirrored ball
    flat = clrt.load_mesh(path)
    mine = instances.flattened()
    assert np.array_equal(mine.vertices[mine.faces], flat.vertices[flat.faces])
    faces = np.array([len(instances.meshes[k].faces) for k in instances.mesh_of])
    first = np.concatenate([[0], np.cumsum(faces)[:-1]])
    origins, directions = _rays(flat.bounds, 2000, seed=9)
    hits, want = accel.trace(origins, directions), clrt.Accel(flat, device=device).trace(origins, directions)
    t, margin, cosine, inst, prim, _ = _flat_reference(instances, origins, directions)
    clear = _clear(t, margin, cosine, float(np.linalg.norm(flat.bounds[1] - flat.bounds[0])))
    assert clear.mean() > 0.9 and len(np.unique(hits.instance[clear & hits.hit])) > 15
    assert np.array_equal(hits.hit[clear], want.hit[clear])
    rows = clear & want.hit
    of = np.searchsorted(first, want.prim[rows], side="right") - 1    # the flattened triangle's instance
    assert np.array_equal(hits.instance[rows], of)
    assert np.array_equal(hits.prim[rows], want.prim[rows] - first[of])
    assert np.array_equal(hits.front[rows], want.front[rows])
    assert np.allclose(hits.t[rows], want.t[rows], rtol=1e-5, atol=0)


def test_a_gltf_file_of_one_mesh_node_stays_one_level(tmp_path, device):
    import trimesh
    path = tmp_path / "one.glb"
    trimesh.Scene(trimesh.creation.icosphere(subdivisions=1)).export(path)
    accel = clrt.Accel(path, device=device)
    assert accel.instances is None and "ACCEL_INSTANCES" not in accel.device_scene.defines()
    assert np.array_equal(accel.mesh.vertices[accel.mesh.faces], clrt.load_mesh(path).vertices[
        clrt.load_mesh(path).faces])


def _rewritten_glb(source, target, change):
    """A copy of a GLB file with ``change(doc)`` applied to its JSON chunk."""
    import json
    import struct
    data = source.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + length])
    change(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + length:]
    target.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(text) + len(rest))
                       + struct.pack("<II", len(text), 0x4E4F534A) + text + rest)
    return target


def test_bad_gltf_instances_are_one_line(tmp_path, device):
    path = _hierarchy_glb(tmp_path / "balls.glb", groups=2, per_group=2)

    def cycle(doc):   # the first group's first child lists the group as its own child
        group = next(i for i, n in enumerate(doc["nodes"]) if n.get("name") == "group0")
        doc["nodes"][doc["nodes"][group]["children"][0]]["children"] = [group]

    def flat(doc):    # a node that scales z to 0
        doc["nodes"][-1]["matrix"] = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1]

    looped = _rewritten_glb(path, tmp_path / "cycle.glb", cycle)
    for read in (lambda: clrt.Accel(looped, device=device), lambda: clrt.load_mesh(looped)):   # render's reader too
        with pytest.raises(clrt.MeshLoadError, match=r"cycle.glb: corrupt GLB file: node \d+ is its own ancestor") \
                as info:
            read()
        assert "\n" not in str(info.value)
    _one_line_error(lambda: clrt.Accel(_rewritten_glb(path, tmp_path / "flat.glb", flat), device=device),
                    r"instance \d+'s transform must be invertible")

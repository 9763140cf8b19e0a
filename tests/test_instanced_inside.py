"""Inside and outside on scenes of instances (docs/instances.md, "Point
queries"): winding numbers, contains, signed distances by every sign rule and
SDF grids of meshes placed by rotations, uneven scales, shears and mirrors,
overlapping and apart, against float64 references computed here from the
flattened scene's triangles (every mesh moved by its transform) and against
the one-level Accel of the flattened scene.

* Winding numbers lie within WINDING_NUMBER_ERROR of the exact sum through
  every two-level BVH (a mesh's far fields mapped by its placement), exact
  without one; contains is >= 1/2 of them, also within 1e-3 of 1/2.
* Signed distances are the distances bit for bit; the winding sign is
  contains, the parity sign the flattened scene's ray crossings, the normal
  sign the side of the closest instance's wound surface -- beside the edges
  and corners of unevenly scaled and sheared placements too.
* Every BVH gives the two-level brute force's signs bit for bit; moved
  instances and split buffers answer as a fresh Accel does.
"""

import numpy as np
import pytest

import clrt
from clrt.query.inside import GRID_MARGIN
from clrt.query.results import WINDING_NUMBER_ERROR
from clrt.scene.instances import as_instances
from clrt.scene.mesh import Mesh
from clrt.scene import primitives

from test_inside import (CLOSED, OPEN, PARITY_DIRECTIONS, _beside_edges, exact_winding_numbers,
                         points_across_one_half)
from test_instances import _affine, _rotation
from test_point_queries import reference


def _placements():
    """Closed and open meshes placed by an uneven scale, a similarity, mirrors,
    a shear and a map of condition number 40 (summed exactly: beyond
    winding_placed.cl's WINDING_PLACED_CONDITION), the ball twice -- once
    overlapping the torus, once (mirrored) the box -- the torus twice."""
    torus, ball, box = CLOSED["torus"](), CLOSED["icosphere"](), CLOSED["box"]()
    tetra, field, cap = CLOSED["tetrahedron"](), OPEN["heightfield"](), OPEN["hemisphere"]()
    shear = np.array([[1.0, 0.4, 0.0], [0.0, 1.0, 0.0], [0.3, 0.0, 0.8]])
    return [
        (torus, _affine(_rotation((1, 2, 3), 0.7) @ np.diag([1.5, 0.7, 1.2]), (0.2, -0.3, 0.1))),
        (ball, _affine(_rotation((0, 1, 1), 2.1) * 0.8, (1.2, 0.0, 0.3))),
        (torus, _affine(np.diag([-1.0, 1.0, 1.0]) @ _rotation((1, 0, 0), 0.4), (-3.0, 0.4, 0.3))),
        (box, _affine(shear, (2.6, -2.2, -0.4))),
        (tetra, _affine(_rotation((1, 1, 0), 0.3) @ np.diag([1.0, 1.0, 0.025]), (-2.5, -2.5, 0.0))),
        (field, _affine(np.diag([1.0, 1.0, -0.5]), (0.0, 2.8, 0.0))),
        (cap, _affine(_rotation((0, 0, 1), 0.3) @ np.diag([1.0, 2.0, 1.0]), (-0.3, -2.6, 1.8))),
        (ball, _affine(-0.45 * np.eye(3), (2.9, -1.9, -0.2))),
    ]


CLOSED_INSTANCES = [0, 1, 2, 3, 4, 7]


def _placed_corners(instances) -> list:
    """Each instance's triangles as it places them, float64."""
    return [instances.meshes[k].vertices.astype(np.float64)[instances.meshes[k].faces] @ m[:3, :3].T + m[:3, 3]
            for k, m in zip(instances.mesh_of, instances.transforms)]


def _points(instances, seed=0) -> np.ndarray:
    """Points in and around the scene's box, far away, and for each instance:
    just under and over its placed faces, beside its edges (leaning from one
    face's normal to the other's) and near its corners; float32."""
    rng = np.random.default_rng(seed)
    lo, hi = instances.bounds
    out = [lo + (rng.random((150, 3)) * 1.2 - 0.1) * (hi - lo),
           (lo + hi) / 2 + 30 * np.linalg.norm(hi - lo) * rng.normal(size=(6, 3))]
    for k, m in zip(instances.mesh_of, instances.transforms):
        mesh = instances.meshes[k]
        c = mesh.vertices.astype(np.float64)[mesh.faces] @ m[:3, :3].T + m[:3, 3]
        size = np.linalg.norm(np.ptp(c.reshape(-1, 3), axis=0))
        f = rng.integers(len(c), size=24)
        normal = np.cross(c[f, 1] - c[f, 0], c[f, 2] - c[f, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        on = np.einsum("nk,nkj->nj", rng.dirichlet((1, 1, 1), size=24), c[f])
        out.append(on + 4e-3 * size * normal * rng.choice([-1, 1], size=(24, 1)))
        beside = _beside_edges(mesh, rng, 10, np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
        out.append(beside @ m[:3, :3].T + m[:3, 3])
        corners = mesh.vertices[rng.integers(len(mesh.vertices), size=10)].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        out.append(corners + 0.03 * size * rng.normal(size=(10, 3)))
    return np.concatenate(out).astype(np.float32)


@pytest.fixture(scope="module")
def scene(device):
    """The instances, the points, each instance's exact winding numbers at them
    (float64, (I, N)) and the two-level brute force."""
    instances = as_instances(_placements())
    points = _points(instances)
    per_instance = np.stack([exact_winding_numbers(points, c) for c in _placed_corners(instances)])
    brute = clrt.Accel(instances, accel="none", device=device)
    return instances, points, per_instance, brute


def test_the_scene(scene):
    instances, points, per_instance, _ = scene
    assert len(instances) == 8 and len(instances.meshes) == 6
    exact = per_instance.sum(axis=0)
    assert (exact > 0.5).sum() > 60 and (exact < -0.5).sum() > 20      # inside, and inside mirrors
    assert (exact > 1.5).sum() > 3                                      # where two instances overlap
    assert ((np.abs(exact - np.round(exact)) > 0.05)).sum() > 20        # the open meshes' fractions


VARIANTS = [("box", "sah", 4), ("box", "device", 4), ("sphere", "paper", 1), ("ellipse", "device", 2)]


@pytest.mark.parametrize("volume, builder, leaf", VARIANTS)
def test_winding_numbers_are_the_flattened_scenes(scene, volume, builder, leaf, device):
    instances, points, per_instance, brute = scene
    exact = per_instance.sum(axis=0)
    accel = clrt.Accel(instances, accel=volume, builder=builder, leaf_size=leaf, device=device)
    w = accel.winding_number(points)
    assert w.dtype == np.float32 and np.abs(w - exact).max() <= WINDING_NUMBER_ERROR
    inside = accel.contains(points)
    np.testing.assert_array_equal(inside, w >= 0.5)
    clear = np.abs(exact - 0.5) > 1e-3
    np.testing.assert_array_equal(inside[clear], exact[clear] >= 0.5)
    # brute force sums every placed triangle exactly
    assert np.abs(brute.winding_number(points) - exact).max() <= 1e-6
    flat = clrt.Accel(instances.flattened(), device=device).winding_number(points)
    assert np.abs(flat - exact).max() <= WINDING_NUMBER_ERROR


def _parity_reference(points, corners, bounds):
    """(inside, clear) by float64 ray crossings of the flattened triangles along
    point.cl's three directions, two of three voting (outside the scene's box:
    outside); clear where no ray passes within 1e-6 (barycentric) of an edge."""
    inside_votes = np.zeros(len(points), int)
    clear = np.ones(len(points), bool)
    c = np.concatenate(corners)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    for d in PARITY_DIRECTIONS.astype(np.float64):
        p = np.cross(d, e2)
        det = np.einsum("fk,fk->f", p, e1)
        s = points.astype(np.float64)[:, None] - c[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.einsum("nfk,fk->nf", s, p) / det
            q = np.cross(s, e1[None])
            v = np.einsum("k,nfk->nf", d, q) / det
            t = np.einsum("fk,nfk->nf", e2, q) / det
        margin = np.minimum(np.minimum(u, v), 1 - u - v)
        crossed = (margin >= 0) & (t > 0)
        clear &= ~((np.abs(margin) < 1e-6) & (t > -1e-6)).any(axis=1)
        inside_votes += crossed.sum(axis=1) % 2
    lo, hi = bounds
    within = ((points >= lo) & (points <= hi)).all(axis=1)
    return (2 * inside_votes > len(PARITY_DIRECTIONS)) & within, clear


def _normal_reference(instances, points, per_instance, scale):
    """(inside, clear) of the normal sign: p is behind the wound surface of its
    closest instance -- for a closed mesh wound outwards (all here) inside it,
    or, mirrored (wound inwards in the world), outside it; clear where that
    instance is closed, nearer than any other by 1e-4 of the scene and the
    point off its surface by as much."""
    distance = np.stack([reference(points, c)[0].min(axis=1) for c in _placed_corners(instances)])
    order = np.argsort(distance, axis=0)
    nearest, rows = order[0], np.arange(len(points))
    gap = distance[order[1], rows] - distance[nearest, rows]
    mirror = np.linalg.det(instances.transforms[:, :3, :3]) < 0
    w = per_instance[nearest, rows]
    inside = np.where(mirror[nearest], w > -0.5, w >= 0.5)
    clear = (np.isin(nearest, CLOSED_INSTANCES) & (gap > 1e-4 * scale)
             & (distance[nearest, rows] > 1e-4 * scale))
    return inside, clear, nearest


def test_signed_distances_by_every_rule(scene, device):
    instances, points, per_instance, brute = scene
    exact = per_instance.sum(axis=0)
    scale = float(np.linalg.norm(np.ptp(instances.bounds, axis=0)))
    accel = clrt.Accel(instances, device=device)
    distance = accel.distance(points)
    flat = clrt.Accel(instances.flattened(), device=device)
    got = {sign: accel.signed_distance(points, sign=sign) for sign in ("winding", "parity", "normal")}
    for sign, values in got.items():
        assert values.dtype == np.float32
        np.testing.assert_array_equal(np.abs(values), distance, err_msg=sign)
        np.testing.assert_array_equal(values, brute.signed_distance(points, sign=sign), err_msg=sign)
    np.testing.assert_array_equal(got["winding"] < 0, accel.contains(points))
    clear = (np.abs(exact - 0.5) > 1e-3) & (distance > 0)
    np.testing.assert_array_equal(got["winding"][clear] < 0, exact[clear] >= 0.5)
    # parity: the flattened scene's crossings (two overlapping balls inside each other count twice: outside)
    inside, clear = _parity_reference(points, _placed_corners(instances), instances.bounds)
    clear &= distance > 1e-4 * scale
    assert clear.sum() > 0.9 * len(points) and inside[clear].sum() > 50
    np.testing.assert_array_equal(got["parity"][clear] < 0, inside[clear])
    np.testing.assert_array_equal(flat.signed_distance(points, sign="parity")[clear] < 0, inside[clear])
    # normal: the side of the nearest instance's surface as wound
    inside, clear, nearest = _normal_reference(instances, points, per_instance, scale)
    assert clear.sum() > 0.6 * len(points) and inside[clear].sum() > 50 and (~inside[clear]).sum() > 50
    for k in (0, 3, 4):   # the uneven placements: their edges and corners are asked in their own space
        assert (clear & (nearest == k)).sum() > 30, k
    np.testing.assert_array_equal(got["normal"][clear] < 0, inside[clear])
    np.testing.assert_array_equal(flat.signed_distance(points, sign="normal")[clear] < 0, inside[clear])


@pytest.mark.parametrize("volume, builder, leaf", VARIANTS[1:])
def test_every_bvh_signs_as_brute_force(scene, volume, builder, leaf, device):
    instances, points, per_instance, brute = scene
    exact = per_instance.sum(axis=0)
    accel = clrt.Accel(instances, accel=volume, builder=builder, leaf_size=leaf, device=device)
    for sign in ("parity", "normal"):
        np.testing.assert_array_equal(accel.signed_distance(points, sign=sign),
                                      brute.signed_distance(points, sign=sign), err_msg=sign)
    away = np.abs(exact - 0.5) > 1e-3
    np.testing.assert_array_equal(accel.signed_distance(points)[away], brute.signed_distance(points)[away])


def test_contains_decides_near_one_half_in_an_unevenly_scaled_instance(device):
    """winding_inside's first walk bounds its error with the placed far fields'
    bounds (the world's area and radius through the map's scales, their
    rounding grown by its condition number): points of an open bowl placed
    by an uneven scale and a shear, whose exact winding numbers lie within
    1e-6 to 1e-3 of 1/2, are inside exactly where winding_number says."""
    bowl = primitives.icosphere(3)
    bowl = Mesh.from_arrays(bowl.vertices, bowl.faces[bowl.vertices[bowl.faces][:, :, 1].min(axis=1) > 0.2], "bowl")
    linear = _rotation((1, 0.5, 0.2), 0.6) @ np.array([[2.0, 0.3, 0.0], [0.0, 0.7, 0.0], [0.0, 0.2, 1.4]])
    m = _affine(linear, (0.4, -0.2, 0.3))
    corners = bowl.vertices.astype(np.float64)[bowl.faces] @ linear.T + m[:3, 3]
    rng = np.random.default_rng(29)
    xz = rng.uniform(-0.5, 0.5, (300, 2))   # vertical segments (in the bowl's space) through its opening
    a = np.stack([xz[:, 0], np.full(300, 0.6), xz[:, 1]], axis=1) @ linear.T + m[:3, 3]
    b = np.stack([xz[:, 0], np.full(300, -0.3), xz[:, 1]], axis=1) @ linear.T + m[:3, 3]
    points = points_across_one_half(a, b, corners)
    exact = exact_winding_numbers(points, corners)
    assert len(points) >= 300 and (np.abs(exact - 0.5) < 1e-4).sum() >= 100
    accel = clrt.Accel([(bowl, m), (primitives.icosphere(1), _affine(shift=(5.0, 0.0, 0.0)))], device=device)
    inside, w = accel.contains(points), accel.winding_number(points)
    assert np.abs(w - exact).max() <= WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(inside, w >= 0.5)
    clear = np.abs(exact - 0.5) > WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(inside[clear], exact[clear] >= 0.5)


def test_sdf_grid_of_instances(scene, device):
    instances = scene[0]
    accel = clrt.Accel(instances, device=device, chunk_rays=500)
    grid = accel.sdf_grid((7, 6, 5), sign="normal")
    lo, hi = instances.bounds
    margin = GRID_MARGIN * np.ptp(instances.bounds, axis=0).max()
    axes = [np.linspace(lo[k] - margin, hi[k] + margin, n) for k, n in enumerate((7, 6, 5))]
    samples = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    np.testing.assert_array_equal(grid.reshape(-1), accel.signed_distance(samples, sign="normal"))
    assert (grid < 0).any() and (grid > 0).any()
    np.testing.assert_array_equal(clrt.sdf_grid(instances, 4, device=device).reshape(-1),
                                  accel.signed_distance(np.stack(np.meshgrid(
                                      *[np.linspace(lo[k] - margin, hi[k] + margin, 4) for k in range(3)],
                                      indexing="ij"), axis=-1).reshape(-1, 3)))


def test_moved_instances_and_split_buffers_answer_as_a_fresh_accel(scene, device):
    """The far fields and normals follow move_instances (made again for the
    moved scene: bit for bit a fresh Accel's), and split buffers answer as
    whole ones."""
    instances, points = scene[0], scene[1]
    rng = np.random.default_rng(3)
    moved = instances.transforms.copy()
    for m in moved:
        m[:3, :3] = _rotation(rng.normal(size=3), rng.uniform(0.3, 2.0)) @ m[:3, :3]
        m[:3, 3] += rng.normal(size=3) * 0.5
    accel = clrt.Accel(instances, device=device)
    before = accel.winding_number(points)
    accel.signed_distance(points, sign="normal")
    accel.move_instances(moved)
    fresh = clrt.Accel(clrt.Instances(instances.meshes, instances.mesh_of, moved), device=device)
    w = accel.winding_number(points)
    assert not np.array_equal(w, before)
    np.testing.assert_array_equal(w, fresh.winding_number(points))
    for sign in ("winding", "parity", "normal"):
        np.testing.assert_array_equal(accel.signed_distance(points, sign=sign),
                                      fresh.signed_distance(points, sign=sign), err_msg=sign)
    split = clrt.Accel(instances, device=device, max_buffer_bytes=32768)
    assert split.geometry.parts() > 1
    whole = clrt.Accel(instances, device=device)
    np.testing.assert_array_equal(split.winding_number(points), whole.winding_number(points))
    for sign in ("parity", "normal"):
        np.testing.assert_array_equal(split.signed_distance(points, sign=sign),
                                      whole.signed_distance(points, sign=sign), err_msg=sign)


def test_queries_of_an_instanced_renderer(scene, device):
    """Accel.from_renderer on a Renderer of placed meshes: the same inside
    answers, on the renderer's buffers."""
    instances, points, per_instance, _ = scene
    renderer = clrt.Renderer(instances, device=device)
    queries = clrt.Accel.from_renderer(renderer)
    exact = per_instance.sum(axis=0)
    assert np.abs(queries.winding_number(points) - exact).max() <= WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(queries.signed_distance(points, sign="parity"),
                                  clrt.Accel(instances, device=device).signed_distance(points, sign="parity"))

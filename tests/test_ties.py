"""Ties: two triangles at exactly the same distance, in different leaves.

The nearest hit of equal distances is the lower triangle index (hit.cl), so the
answer must not depend on the order a BVH visits its leaves.  A BVH shrinks tmax
to the best hit so far and drops a postponed child whose volume starts beyond
it; a child that holds a triangle at exactly that distance must still be opened.
These scenes make such ties on purpose, with every kind of volume and builder:

* exact copies of triangles, far apart in index (and, with leaf size 1, in
  different leaves);
* axis-aligned quads and walls on integer planes, so that leaf boxes share face
  planes, hit by axis-parallel rays exactly on those planes and through shared
  edges and vertices;
* a stack of many coincident copies, spread over many leaves;
* rays that start inside the scene with a negative tmin, so that ties also lie
  behind the origin (the volume tests' rounding slack must widen the interval
  there too).

The reference is the simplest one there is: every hit of the ray (all_hits,
sorted by distance, then index), whose first entry must be what brute force and
every BVH return.
"""

import itertools

import numpy as np
import pytest

import clrt
from clrt.renderer import Renderer
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, scene_from_mesh

from test_accel import VARIANTS, _frames_identical   # every volume x host builder x leaf size 1, 4



def _quad(x0, y0, z, size=1.0) -> np.ndarray:
    """Two triangles of the square [x0, x0 + size] x [y0, y0 + size] at height z."""
    a, b = (x0, y0, z), (x0 + size, y0, z)
    c, d = (x0 + size, y0 + size, z), (x0, y0 + size, z)
    return np.array([[a, b, c], [a, c, d]], np.float64)


def _wall(x, depth, height) -> np.ndarray:
    """Two triangles of the rectangle x = const, 0 <= y <= depth, 0 <= z <= height."""
    a, b, c, d = (x, 0, 0), (x, depth, 0), (x, depth, height), (x, 0, height)
    return np.array([[a, b, c], [a, c, d]], np.float64)


def _mesh(triangles: np.ndarray, name: str) -> Mesh:
    return Mesh.from_arrays(triangles.reshape(-1, 3), np.arange(len(triangles) * 3).reshape(-1, 3), name)


def duplicated_grid(rng) -> Mesh:
    """A 5 x 5 grid of unit quads at integer heights, then a copy of every
    triangle in shuffled order: each triangle's twin is far from it in index."""
    heights = rng.integers(0, 3, (5, 5))
    grid = np.concatenate([_quad(i, j, float(heights[i, j])) for i in range(5) for j in range(5)])
    return _mesh(np.concatenate([grid, grid[rng.permutation(len(grid))]]), "duplicated grid")


def abutting_boxes(rng) -> Mesh:
    """Quads on a 6 x 6 grid at integer heights and walls on the integer x planes:
    the leaves' boxes meet on shared planes, where the rays below cross them.
    A reversed copy of the quads makes every quad a tie, lower index last."""
    heights = rng.integers(0, 4, (6, 6))
    quads = np.concatenate([_quad(i, j, float(heights[i, j])) for i in range(6) for j in range(6)])
    walls = np.concatenate([_wall(float(x), 6.0, 4.0) for x in range(7)])
    triangles = np.concatenate([quads, walls, quads[::-1]])
    return _mesh(triangles[rng.permutation(len(triangles))], "abutting boxes")


def coincident_stack(rng) -> Mesh:
    """40 copies of one 4 x 4 quad at z = 1 among 40 unit quads at other heights,
    in random order: every ray through the big quad meets 40 triangles at one
    distance (80 on its diagonal)."""
    others = np.concatenate([_quad(float(i % 8) - 4, float(i // 8) - 3, float(rng.integers(2, 6)))
                             for i in range(40)])
    copies = np.concatenate([_quad(-2.0, -2.0, 1.0, 4.0)] * 40)
    triangles = np.concatenate([copies, others])
    return _mesh(triangles[rng.permutation(len(triangles))], "coincident stack")


SCENES = {"duplicated-grid": duplicated_grid, "abutting-boxes": abutting_boxes,
          "coincident-stack": coincident_stack}


def tie_rays(mesh: Mesh, rng, count: int = 300):
    """origins, directions, tmin: axis-parallel rays from outside along each axis
    both ways, half of them with coordinates on the integer and half-integer grid
    (through edges and vertices, on box face planes); oblique rays aimed at
    vertices; and rays from inside with tmin = -inf (hits behind the origin)."""
    lo, hi = mesh.bounds
    origins, directions = [], []
    for axis, sign in itertools.product(range(3), (1.0, -1.0)):
        o = rng.uniform(lo - 0.5, hi + 0.5, (count, 3))
        o = np.where(rng.random((count, 3)) < 0.5, np.round(o * 2) / 2, o)
        o[:, axis] = lo[axis] - 2 if sign > 0 else hi[axis] + 2
        d = np.zeros((count, 3))
        d[:, axis] = sign
        origins.append(o)
        directions.append(d)
    v = mesh.vertices[rng.integers(0, len(mesh.vertices), count)]
    far = v + 4 * rng.normal(size=(count, 3))
    origins.append(far)
    directions.append(v - far)
    inside = rng.uniform(lo, hi, (2 * count, 3))
    inside = np.where(rng.random((2 * count, 3)) < 0.5, np.round(inside * 2) / 2, inside)
    inside_dirs = np.eye(3)[rng.integers(0, 3, 2 * count)] * rng.choice([-1.0, 1.0], (2 * count, 1))
    origins.append(inside)
    directions.append(inside_dirs)
    tmin = np.r_[np.zeros(7 * count), np.full(2 * count, -np.inf)]
    return np.concatenate(origins), np.concatenate(directions), tmin


def nearest_of_all_hits(every: clrt.AllHits, n: int):
    """(t, prim) of each ray's first hit in (distance, index) order; (inf, -1) if none,
    and (n,) the number of triangles tied at that distance."""
    t, prim, ties = np.full(n, np.inf, np.float32), np.full(n, -1, np.int32), np.zeros(n, np.int64)
    first = np.r_[True, every.ray_id[1:] != every.ray_id[:-1]]
    rays = every.ray_id[first]
    t[rays], prim[rays] = every.t[first], every.prim[first]
    at_nearest = every.t == t[every.ray_id]
    ties += np.bincount(every.ray_id[at_nearest], minlength=n)
    return t, prim, ties


@pytest.fixture(scope="module", params=sorted(SCENES))
def scene(request, device):
    rng = np.random.default_rng(sorted(SCENES).index(request.param) + 19)
    mesh = SCENES[request.param](rng)
    o, d, tmin = tie_rays(mesh, rng)
    brute = clrt.Accel(mesh, accel="none", device=device)
    return mesh, o, d, tmin, brute.trace(o, d, tmin=tmin)


def test_brute_force_takes_the_lowest_index_of_a_tie(scene, device):
    mesh, o, d, tmin, base = scene
    every = clrt.Accel(mesh, accel="none", device=device).all_hits(o, d, tmin=tmin)
    t, prim, ties = nearest_of_all_hits(every, len(o))
    assert np.array_equal(base.t, t) and np.array_equal(base.prim, prim)
    tied = ties >= 2
    assert tied.sum() > 200, "many rays must end in a tie"
    assert (tied & (tmin < 0)).sum() > 50, "ties behind the origin too"


@pytest.mark.parametrize("volume,builder,leaf", VARIANTS, ids=[f"{v}-{b}-{n}" for v, b, n in VARIANTS])
def test_every_bvh_breaks_ties_as_brute_force(scene, volume, builder, leaf, device):
    mesh, o, d, tmin, base = scene
    accel = clrt.Accel(mesh, accel=volume, builder=builder, leaf_size=leaf, device=device)
    hits = accel.trace(o, d, tmin=tmin)
    for field in ("t", "prim", "u", "v"):
        wrong = np.flatnonzero(getattr(hits, field) != getattr(base, field))
        assert len(wrong) == 0, (field, len(wrong), o[wrong[:3]], d[wrong[:3]], tmin[wrong[:3]])
    # all_hits walks without shrinking tmax; its list starts with the same hit
    every = accel.all_hits(o, d, tmin=tmin)
    t, prim, _ = nearest_of_all_hits(every, len(o))
    assert np.array_equal(t, base.t) and np.array_equal(prim, base.prim)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_bvh_renders_ties_as_brute_force(name, device):
    mesh = SCENES[name](np.random.default_rng(5))
    scene = scene_from_mesh(mesh)
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2
    # looking straight down at the quads: every pixel that hits a quad meets its copy too
    camera = Camera(eye=(centre[0], centre[1], hi[2] + 6.0), target=tuple(centre), up=(0.0, 1.0, 0.0),
                    fov=60.0, width=40, height=30)
    reference = Renderer(scene, device=device, accel="none").render(camera, hits=True)
    assert (reference.prim >= 0).mean() > 0.2
    _frames_identical(scene, camera, device)

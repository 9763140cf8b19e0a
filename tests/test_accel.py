"""No detail loss: every BVH (volume x builder x leaf size) gives exactly what brute force gives.

Brute force (accel="none") is itself checked against the numpy reference in
test_render.py; here every acceleration structure must reproduce it bit for
bit on the same device -- images, hit triangles, distances, barycentrics --
including rays aimed exactly at vertices and along edges, axis-parallel rays
and rays starting inside the mesh.
"""

import itertools

import numpy as np
import pytest

import clrt
from clrt.config import HOST_BUILDERS, VOLUMES
from clrt.reference import intersect
from clrt.renderer import Renderer
from clrt.scene.default import default_scene
from clrt.scene.scene import Camera, scene_from_mesh

from conftest import SHARED_MESHES, TEST_MESHES

VARIANTS = [(v, b, leaf) for v, b in itertools.product(VOLUMES, HOST_BUILDERS)
            for leaf in (1, 4)]


def _frames_identical(scene, camera, device):
    reference = Renderer(scene, device=device, accel="none").render(camera, hits=True)
    for volume, builder, leaf in VARIANTS:
        renderer = Renderer(scene, device=device, accel=volume, builder=builder, leaf_size=leaf)
        frame = renderer.render(camera, hits=True)
        label = f"{volume}/{builder}/leaf {leaf}"
        assert np.array_equal(frame.prim, reference.prim), label
        assert np.array_equal(frame.t, reference.t), label
        assert np.array_equal(frame.image, reference.image), label


@pytest.mark.parametrize("name", sorted(TEST_MESHES))
def test_every_bvh_renders_the_brute_force_image(name, device):
    scene = scene_from_mesh(TEST_MESHES[name]())
    _frames_identical(scene, Camera.framing(scene.bounds, 40, 30), device)


def test_every_bvh_renders_the_default_scene_identically(device):
    scene = default_scene(48, 36, coarse=True)
    _frames_identical(scene, scene.camera, device)


@pytest.mark.skipif(not SHARED_MESHES.is_dir(), reason="../shared/meshes not present")
def test_every_bvh_renders_camel_identically(device):
    scene = scene_from_mesh(clrt.load_mesh(SHARED_MESHES / "camel.off"))
    _frames_identical(scene, Camera.framing(scene.bounds, 48, 48), device)


def _hard_rays(mesh, rng, count=600):
    """Rays that graze: aimed exactly at vertices and at points on edges, from
    random outside points; axis-parallel rays; rays from the centre outwards."""
    lo, hi = mesh.bounds
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo)
    v = mesh.vertices.astype(np.float64)
    at_vertex = v[rng.integers(0, len(v), count)]
    f = mesh.faces[rng.integers(0, len(mesh.faces), count)]
    w = rng.random((count, 1))
    on_edge = (1 - w) * v[f[:, 0]] + w * v[f[:, 1]]
    targets = np.concatenate([at_vertex, on_edge])
    dirs = rng.normal(size=targets.shape)
    origins = centre + 2 * radius * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    axis = np.eye(3)[rng.integers(0, 3, count)] * rng.choice([-1, 1], (count, 1))
    axis_origins = v[rng.integers(0, len(v), count)] - 2 * radius * axis   # through vertices, along axes
    inside = np.broadcast_to(centre, (count, 3))
    inside_dirs = rng.normal(size=(count, 3))
    o = np.concatenate([origins, axis_origins, inside]).astype(np.float32)
    d = np.concatenate([targets - origins, axis, inside_dirs])
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    return o, d


@pytest.mark.parametrize("name", sorted(TEST_MESHES))
def test_trace_is_identical_for_every_bvh_on_grazing_rays(name, device):
    mesh = TEST_MESHES[name]()
    o, d = _hard_rays(mesh, np.random.default_rng(7))
    base = clrt.trace(mesh, o, d, accel="none", device=device)
    base_blocked = clrt.occluded(mesh, o, d, tmax=1e30, accel="none", device=device)
    assert (base.prim >= 0).mean() > 0.3 and (base.prim < 0).any(), "the ray set must hit and miss"
    for volume, builder, leaf in VARIANTS:
        accel = clrt.Accel(mesh, accel=volume, builder=builder, leaf_size=leaf, device=device)
        hits = accel.trace(o, d)
        label = f"{volume}/{builder}/leaf {leaf}"
        for field in ("t", "prim", "u", "v"):
            assert np.array_equal(getattr(hits, field), getattr(base, field)), (label, field)
        assert np.array_equal(accel.occluded(o, d, tmax=1e30), base_blocked), label


def test_trace_matches_numpy_reference(test_mesh, device):
    o, d = _hard_rays(test_mesh, np.random.default_rng(3), 200)
    hits = clrt.trace(test_mesh, o, d, device=device)
    corners = test_mesh.vertices[test_mesh.faces].astype(np.float32)
    t, prim, u, v = intersect(o, d, corners, np.zeros(len(o), np.float32), np.full(len(o), np.inf, np.float32))
    # Rays aimed exactly at shared edges and vertices meet several triangles at
    # (nearly) the same distance; which of them wins may differ by an ulp of
    # device arithmetic, so where the triangle differs the distance must not.
    assert ((hits.prim >= 0) == (prim >= 0)).mean() >= 0.995
    both = (hits.prim >= 0) & (prim >= 0)
    assert np.allclose(hits.t[both], t[both], rtol=1e-5, atol=1e-6)
    same = both & (hits.prim == prim)
    assert same.sum() >= 0.95 * both.sum()
    np.testing.assert_allclose(hits.u[same], u[same], atol=1e-4)
    blocked = clrt.occluded(test_mesh, o, d, tmax=1e30, device=device)
    assert (blocked == intersect(o, d, corners, np.zeros(len(o), np.float32),
                                 np.full(len(o), 1e30, np.float32), any_hit=True)).mean() >= 0.995


def test_trace_inputs(device):
    mesh = TEST_MESHES["icosphere"]()
    accel = clrt.Accel(mesh, device=device)
    one = accel.trace([0, 0, 5], [0, 0, -7])             # a single (3,) ray, unnormalised
    assert one.t.shape == (1,) and abs(one.t[0] - 4.0) < 0.1 and one.prim[0] >= 0
    miss = accel.trace(np.array([[0, 0, 5]], np.float16), [[0, 0, 1]])
    assert miss.prim[0] == -1 and np.isinf(miss.t[0])
    short = accel.trace([0, 0, 5], [0, 0, -1], tmax=3.0)
    assert short.prim[0] == -1
    assert accel.occluded([0, 0, 5], [0, 0, -1], tmax=3.0).tolist() == [False]
    assert accel.occluded([0, 0, 5], [0, 0, -1], tmax=5.0).tolist() == [True]
    for bad in ([0, 0, 0], [np.nan, 0, 1]):
        with pytest.raises(clrt.InputError):
            accel.trace([0, 0, 5], bad)
    with pytest.raises(clrt.InputError):
        accel.trace(np.zeros((3, 3)), np.ones((2, 3)))
    with pytest.raises(clrt.InputError):
        clrt.Accel(mesh, accel="octree", device=device)

"""Refit: a BVH whose triangles moved keeps its tree and gets new volumes on the
device; queries and images then equal brute force on the moved mesh, bit for
bit, for every volume shape and builder."""

import numpy as np
import pytest

import clrt
from clrt.config import BUILDERS, VOLUMES
from clrt.renderer import Renderer
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, scene_from_mesh


def _deformed(mesh: Mesh, amount: float) -> np.ndarray:
    """The vertices twisted about y and swollen in x: large, non-rigid motion."""
    v = mesh.vertices.astype(np.float64)
    angle = amount * v[:, 1]
    c, s = np.cos(angle), np.sin(angle)
    out = np.stack([c * v[:, 0] - s * v[:, 2], v[:, 1], s * v[:, 0] + c * v[:, 2]], axis=1)
    out[:, 0] *= 1.0 + amount * np.sin(3.0 * v[:, 2])
    return out.astype(np.float32)


def _rays(mesh, n=2000, seed=3):
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    o = (lo + hi) / 2 + rng.normal(size=(n, 3)) * 2.0 * np.linalg.norm(hi - lo)
    target = lo + rng.random((n, 3)) * (hi - lo)
    return o, target - o


@pytest.mark.parametrize("volume", VOLUMES)
@pytest.mark.parametrize("builder", BUILDERS)
def test_refit_queries_equal_brute_force(volume, builder, device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    accel = clrt.Accel(mesh, accel=volume, builder=builder, device=device)
    for amount in (0.8, 2.0):   # twice: a refit of a refitted tree
        moved = Mesh.from_arrays(_deformed(mesh, amount), mesh.faces)
        accel.refit(moved.vertices)
        brute = clrt.Accel(moved, accel="none", device=device)
        o, d = _rays(moved)
        got, want = accel.trace(o, d), brute.trace(o, d)
        assert 0 < want.hit.sum() < len(o)
        for name in ("t", "prim", "u", "v", "normal", "front"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), (name, amount)
        assert np.array_equal(accel.any_hit(o, d), brute.any_hit(o, d))
        assert np.array_equal(accel.count(o, d), brute.count(o, d))


def test_refit_rebuild_and_bad_input(device):
    mesh = primitives.icosphere(2)
    accel = clrt.Accel(mesh, device=device)
    moved = _deformed(mesh, 1.5)
    accel.refit(moved, rebuild=True)
    o, d = _rays(mesh)
    brute = clrt.Accel((moved, mesh.faces), accel="none", device=device)
    assert np.array_equal(accel.trace(o, d).prim, brute.trace(o, d).prim)
    with pytest.raises(clrt.InputError, match="refit needs vertices of shape"):
        accel.refit(moved[:-1])
    bad = moved.copy()
    bad[0, 0] = np.nan
    with pytest.raises(clrt.InputError):
        accel.refit(bad)


@pytest.mark.parametrize("builder", ["sah", "device"])
def test_renderer_refit_draws_the_moved_scene(builder, device):
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    moved = Mesh.from_arrays(_deformed(mesh, 1.2), mesh.faces)
    renderer = Renderer(scene_from_mesh(mesh), device=device, builder=builder)
    camera = Camera.framing(moved.bounds, 48, 36)
    scene = scene_from_mesh(moved, {"color": (0.9, 0.2, 0.1)})   # new material values and lights come too
    renderer.refit(scene)
    frame = renderer.render(camera, hits=True)
    reference = Renderer(scene, device=device, accel="none").render(camera, hits=True)
    assert (reference.prim >= 0).sum() > 100, "the moved torus is in view"
    for name in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, name), getattr(reference, name)), name
    with pytest.raises(clrt.InputError, match="same triangles"):
        renderer.refit(scene_from_mesh(primitives.icosphere(1)))


def test_renderer_refit_shows_the_materials_of_the_scene_it_is_given(device):
    """A refit shows the scene it is given: its materials too.  A scene_from_mesh
    without a material has the default one (as the README's example once did,
    silently turning its coloured mesh grey): pass the material again."""
    mesh = primitives.icosphere(2)
    red = clrt.Material(color=(0.9, 0.1, 0.1))
    camera = Camera.framing(mesh.bounds * 1.1, 24, 18)
    renderer = Renderer(scene_from_mesh(mesh, red), device=device)
    moved = (mesh.vertices * 1.1, mesh.faces)
    renderer.refit(scene_from_mesh(moved, red))
    assert renderer.scene.objects[0].material == red
    image = renderer.render(camera).image.astype(int)
    seen = image.sum(axis=2) > 0
    assert (image[..., 0] > 2 * image[..., 1])[seen].mean() > 0.9, "red, as the scene given says"
    renderer.refit(scene_from_mesh(moved))
    assert renderer.scene.objects[0].material == clrt.Material()
    grey = renderer.render(camera).image.astype(int)
    assert (np.abs(grey[..., 0] - grey[..., 1]) <= 1)[seen].all(), "the default material: grey"

"""Reflection, refraction and anti-aliasing on the device against the numpy reference."""

import numpy as np
import pytest

from clrt.reference import SceneData, _bounce, camera_rays, intersect, render_reference, surface
from clrt.renderer import Renderer
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject

GLASS = Material(color=(0.95, 0.97, 1.0), ambient=0.0, diffuse=0.05, specular=0.5, shininess=100,
                 transparency=0.9, ior=1.5)
MIRROR = Material(color=(0.9, 0.9, 0.9), ambient=0.02, diffuse=0.1, specular=0.3, shininess=60,
                  reflectivity=0.85)


def _floor(size=6.0):
    light, dark = primitives.checkerboard(tiles=6, size=size, height=-1.0)
    return [SceneObject(light, Material(color=(0.9, 0.9, 0.85), specular=0, smooth=False)),
            SceneObject(dark, Material(color=(0.1, 0.1, 0.4), specular=0, smooth=False))]


def _agree(scene, camera, device, samples=1, max_depth=5, prim_share=0.999, colour_share=0.99):
    frame = Renderer(scene, device=device).render(camera, linear=True, hits=True, samples=samples,
                                           max_depth=max_depth)
    ref, prim, t = render_reference(scene, camera, samples=samples, max_depth=max_depth)
    assert (frame.prim == prim).mean() >= prim_share
    close = np.abs(frame.image - ref).max(axis=2) <= 3e-3
    assert close.mean() >= colour_share, f"{(~close).sum()} of {close.size} pixels differ"
    return frame, ref


def test_glass_sphere_over_checkerboard(device):
    scene = Scene([*_floor(), SceneObject(primitives.icosphere(3, 1.0, (0, 0, 0)), GLASS)],
                  [Light((3, 5, 4))], background=(0.3, 0.4, 0.6))
    camera = Camera(eye=(0, 1.2, 4.5), target=(0, -0.2, 0), fov=40, width=48, height=36)
    frame, ref = _agree(scene, camera, device)
    flat = Renderer(scene, device=device).render(camera, linear=True, max_depth=0).image
    assert np.abs(frame.image - flat).max() > 0.1, "refraction must change the image"


def test_mirror_reflects_a_sphere(device):
    mirror = Mesh.from_arrays([[-2, -1, -1.5], [2, -1, -1.5], [2, 2, -1.5], [-2, 2, -1.5]],
                              [[0, 1, 2], [0, 2, 3]])
    red = Material(color=(0.9, 0.1, 0.1))
    scene = Scene([*_floor(), SceneObject(mirror, MIRROR),
                   SceneObject(primitives.icosphere(2, 0.5, (0.6, -0.5, 0.5)), red)],
                  [Light((2, 4, 4)), Light((0.5, 1.0, -1.0))])   # the second lights the side the mirror sees
    camera = Camera(eye=(-1.0, 0.5, 4.0), target=(0, 0, -1.5), fov=45, width=48, height=36)
    frame, _ = _agree(scene, camera, device)
    first = len(scene.objects[0].mesh.faces) + len(scene.objects[1].mesh.faces)
    on_mirror = (frame.prim >= first) & (frame.prim < first + 2)
    reddish = frame.image[..., 0] > 2 * frame.image[..., 1] + 0.05
    assert (on_mirror & reddish).sum() > 5, "the red sphere must appear in the mirror"


def test_total_internal_reflection_inside_glass(device):
    # The eye is inside a big glass sphere looking along its wall: most rays meet
    # the wall beyond the critical angle (41.8 degrees for ior 1.5).
    sphere = primitives.icosphere(3, 3.0)
    scene = Scene([SceneObject(sphere, GLASS), *_floor(12.0)], [Light((0, 8, 0))],
                  background=(0.5, 0.6, 0.8))
    camera = Camera(eye=(0, 0, 2.6), target=(2.5, 0.3, 2.6), fov=50, width=40, height=30)
    data = SceneData(scene)
    o, d = camera_rays(camera)
    t, prim, u, v = intersect(o, d, data.corners, np.zeros(len(o), np.float32),
                              np.full(len(o), np.inf, np.float32))
    hit = prim >= 0
    s = surface(data, o[hit], d[hit], t[hit], prim[hit], u[hit], v[hit])
    _, _, fresnel = _bounce(s)
    assert (~s["front"]).all() and (fresnel == 1.0).mean() > 0.3, "the scene must exercise TIR"
    _agree(scene, camera, device)


def test_anti_aliasing_matches_reference_and_smooths_edges(device):
    scene = Scene([SceneObject(primitives.box((1, 1, 1)), Material(color=(1, 1, 1), specular=0))],
                  [Light((2, 3, 4))], background=(0, 0, 0))
    camera = Camera(eye=(1.5, 1.2, 2.5), target=(0, 0, 0), fov=40, width=32, height=24)
    aa, _ = _agree(scene, camera, device, samples=3)
    one = Renderer(scene, device=device).render(camera, linear=True, samples=1).image
    again = Renderer(scene, device=device).render(camera, linear=True, samples=3).image
    assert np.array_equal(aa.image, again), "fixed seed: renders are reproducible"
    # Edge pixels get in-between values only with anti-aliasing.
    partial = lambda img: ((img.max(axis=2) > 0.02) & (img.max(axis=2) < 0.08)).sum()   # noqa: E731
    assert partial(aa.image) > partial(one)


def test_max_depth_zero_is_local_shading_only(device):
    scene = Scene([*_floor(), SceneObject(primitives.icosphere(2), MIRROR)], [Light((3, 5, 4))])
    plain = Scene([*_floor(), SceneObject(primitives.icosphere(2),
                                          Material(**{**MIRROR.__dict__, "reflectivity": 0.0}))],
                  [Light((3, 5, 4))])
    camera = Camera(eye=(0, 1, 4), target=(0, 0, 0), width=24, height=18)
    a = Renderer(scene, device=device).render(camera, max_depth=0).image
    b = Renderer(plain, device=device).render(camera).image
    assert np.array_equal(a, b)


def test_perfect_mirror_shows_the_background(device):
    mirror = Material(color=(1, 1, 1), ambient=0, diffuse=0, specular=0, reflectivity=1.0)
    scene = Scene([SceneObject(primitives.icosphere(2), mirror)], [Light((3, 5, 4))],
                  background=(0.2, 0.4, 0.6))
    camera = Camera(eye=(0, 0, 4), target=(0, 0, 0), width=16, height=16)
    frame = Renderer(scene, device=device).render(camera, linear=True, hits=True)
    seen = frame.image[frame.prim >= 0]
    assert len(seen) > 50
    np.testing.assert_allclose(seen, np.broadcast_to([0.2, 0.4, 0.6], seen.shape), atol=1e-5)


@pytest.mark.parametrize("bad", [{"samples": 0}, {"samples": 17}, {"max_depth": -1}, {"max_depth": 17}])
def test_render_settings_are_validated(bad, device):
    import clrt
    r = Renderer(Scene([SceneObject(primitives.box())], [Light((1, 2, 3))]), device=device)
    with pytest.raises(clrt.InputError):
        r.render(Camera(eye=(0, 0, 3), target=(0, 0, 0), width=4, height=4), **bad)

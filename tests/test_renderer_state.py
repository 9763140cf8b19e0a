"""What a Renderer and the queries made from it keep: the renderer renders its
own copy of the scene (as it was when made or last refitted); queries from
Accel.from_renderer follow its refits; copies of an Accel or a Renderer are new
ones.
(Found by an audit: a renderer read the caller's light count against the
lights it had uploaded -- past the end of that buffer -- and shared queries kept
a rebuilt renderer's old BVH.)"""

import copy
import pickle

import numpy as np
import pytest

import clrt
from clrt.scene import primitives
from clrt.scene.sources import as_mesh

TORUS = primitives.torus(1.0, 0.35, 24, 12)


def _rays(mesh, n=400, seed=7):
    v = np.asarray(mesh.vertices, np.float64)
    c, r = v.mean(axis=0), float(np.ptp(v, axis=0).max())
    rng = np.random.default_rng(seed)
    o = c + rng.normal(size=(n, 3)) * r
    return o, c + rng.normal(size=(n, 3)) * 0.3 * r - o


def _camera(scene, w=48, h=36):
    cam = scene.camera
    return clrt.Camera(cam.eye, cam.target, cam.up, cam.fov, w, h)


def _moved(mesh, shift=(0.6, 0.0, 0.0)):
    return clrt.Mesh(np.asarray(mesh.vertices, np.float64) + shift, mesh.faces, "moved")


def test_the_renderer_shows_its_own_copy_of_the_scene(device):
    base = clrt.scene_from_mesh(TORUS)
    cam = _camera(base)
    l1 = clrt.Light(tuple(np.asarray(cam.eye) + [1.0, 2.0, 0.0]))
    l2 = clrt.Light((-3.0, 0.5, -2.0), (0.9, 0.2, 0.2))

    def fresh(lights):
        scene = clrt.scene_from_mesh(TORUS, lights=lights)
        return clrt.Renderer(scene, device=device).render(cam, linear=True).image

    scene = clrt.scene_from_mesh(TORUS, lights=[l1])
    renderer = clrt.Renderer(scene, device=device)
    first = renderer.render(cam, linear=True).image
    # the caller's Scene changed afterwards: not shown (and never read against the uploaded lights)
    scene.lights = [l1] * 20
    scene.background = (1.0, 0.0, 0.0)
    scene.override_materials(color=(0.0, 1.0, 0.0))
    assert np.array_equal(renderer.render(cam, linear=True).image, first)
    # set_lights changes what the renderer shows, not the caller's Scene
    renderer.set_lights([l2])
    assert np.array_equal(renderer.render(cam, linear=True).image, fresh([l2]))
    renderer.set_lights([l1, l2] * 10)
    assert np.array_equal(renderer.render(cam, linear=True).image, fresh([l1, l2] * 10))
    assert scene.lights == [l1] * 20


@pytest.mark.parametrize("rebuild", [False, True])
def test_queries_from_a_renderer_follow_its_refit(device, rebuild):
    o, d = _rays(TORUS)
    moved_scene = clrt.scene_from_mesh(_moved(TORUS))
    expected = clrt.Accel(as_mesh(moved_scene), device=device).trace(o, d).prim
    scene = clrt.scene_from_mesh(TORUS)
    renderer = clrt.Renderer(scene, device=device)
    queries = clrt.Accel.from_renderer(renderer)
    assert not np.array_equal(queries.trace(o, d).prim, expected)
    renderer.refit(moved_scene, rebuild=rebuild)
    assert np.array_equal(queries.trace(o, d).prim, expected)
    assert np.array_equal(queries.mesh.vertices, as_mesh(moved_scene).vertices)
    cam = _camera(scene)
    assert np.array_equal(renderer.render(cam, hits=True).prim, queries.camera_images(cam).prim)


def test_copies_of_an_accel_are_accels_of_their_own(device):
    o, d = _rays(TORUS)
    original = clrt.Accel(TORUS, device=device)
    before = original.trace(o, d).prim.copy()
    for duplicate in (copy.copy(original), copy.deepcopy(original), pickle.loads(pickle.dumps(original))):
        assert duplicate.geometry is not original.geometry
        assert np.array_equal(duplicate.trace(o, d).prim, before)
        duplicate.refit(_moved(TORUS).vertices)
        assert not np.array_equal(duplicate.trace(o, d).prim, before)
        assert np.array_equal(original.trace(o, d).prim, before)
    shared = clrt.Accel.from_renderer(clrt.Renderer(clrt.scene_from_mesh(TORUS), device=device))
    for make_copy in (copy.copy, copy.deepcopy, pickle.dumps):
        with pytest.raises(clrt.InputError, match="share a Renderer's scene cannot be copied or pickled"):
            make_copy(shared)


def test_copies_of_a_renderer_are_renderers_of_their_own(device):
    """A copy, a deep copy or an unpickled Renderer is made again from the
    renderer's scene as it shows it (lights set and refits included): the
    same frames, its own buffers and lock.  (Before: pickles and deep copies
    failed with a TypeError on an OpenCL context, and copy.copy shared the
    frame buffers.)"""
    scene = clrt.scene_from_mesh(TORUS)
    original = clrt.Renderer(scene, device=device, limits=clrt.TileLimits(max_tile_pixels=600))
    original.refit(clrt.scene_from_mesh(_moved(TORUS)))
    original.set_lights([clrt.Light((2.0, 3.0, 4.0), (1.0, 0.4, 0.2))])
    cam = _camera(scene)
    before = original.render(cam).image.copy()
    assert not np.array_equal(before, clrt.Renderer(scene, device=device).render(cam).image)
    for duplicate in (copy.copy(original), copy.deepcopy(original), pickle.loads(pickle.dumps(original))):
        assert duplicate.geometry is not original.geometry and duplicate._lock is not original._lock
        assert duplicate.limits == original.limits
        frame = duplicate.render(cam)
        assert np.array_equal(frame.image, before) and frame.tiles > 1
        duplicate.set_lights([])
        assert np.array_equal(original.render(cam).image, before)


def test_set_up_timings_are_reported_once_and_frames_report_their_own(device):
    """The set-up's stages are the Renderer's (``Renderer.timings``), made once;
    every frame's ``timings`` hold that frame's stages alone -- the first
    frame's as the later ones', the path tracer's program build (made on its
    first frame) going to the set-up's."""
    set_up = {"initialisation", "acceleration build", "copy to device"}
    frame_stages = {"ray generation", "pixel colour", "read back"}
    scene = clrt.scene_from_mesh(TORUS)
    renderer = clrt.Renderer(scene, device=device)
    assert set(renderer.timings) == set_up and all(ms >= 0.0 for ms in renderer.timings.values())
    made = dict(renderer.timings)
    cam = _camera(scene)
    frames = [renderer.render(cam) for _ in range(2)]
    assert [set(f.timings) for f in frames] == [frame_stages] * 2
    assert renderer.timings == made, "a frame changed the set-up's timings"
    path = renderer.render(cam, integrator="path", spp=1)
    assert set(path.timings) == {"path tracing", "kernels", "read back"}
    assert set(renderer.timings) == set_up | {"program build"}
    again = renderer.render(cam, integrator="path", spp=1)
    assert set(again.timings) == set(path.timings) and set(renderer.timings) == set_up | {"program build"}


def test_frames_follow_the_camera_and_the_renderers_own_changes(device):
    """Renderer._frame_args keeps a frame's camera and scene records while
    nothing they are made of changed: frames of cameras taken in turns, equal
    cameras made anew, and frames after set_lights and a refit are each what a
    fresh renderer shows."""
    scene = clrt.scene_from_mesh(TORUS)
    near, far = _camera(scene), _camera(scene)
    far = clrt.Camera(tuple(2.0 * np.asarray(far.eye)), far.target, far.up, far.fov, far.width, far.height)

    def fresh(scene, cam):
        return clrt.Renderer(scene, device=device).render(cam, linear=True).image

    want_near, want_far = fresh(scene, near), fresh(scene, far)
    assert not np.array_equal(want_near, want_far)
    renderer = clrt.Renderer(scene, device=device)
    for cam, want in [(near, want_near), (far, want_far), (near, want_near), (_camera(scene), want_near)]:
        np.testing.assert_array_equal(renderer.render(cam, linear=True).image, want)
    light = clrt.Light((-3.0, 0.5, -2.0), (0.9, 0.2, 0.2))
    renderer.set_lights([light])
    np.testing.assert_array_equal(renderer.render(near, linear=True).image,
                                  fresh(clrt.scene_from_mesh(TORUS, lights=[light]), near))
    moved = clrt.scene_from_mesh(_moved(TORUS))
    renderer.refit(moved)
    np.testing.assert_array_equal(renderer.render(near, linear=True).image, fresh(moved, near))

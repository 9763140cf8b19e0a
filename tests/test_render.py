"""The OpenCL renderer against the numpy reference tracer, on several meshes."""

import numpy as np
import pytest

import clrt
from clrt.reference import camera_rays, render_reference, srgb8
from clrt.renderer import Renderer
from clrt.scene import primitives
from clrt.scene.default import default_scene
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject, scene_from_mesh


def _compare(scene, camera, device):
    frame = Renderer(scene, device=device).render(camera, linear=True, hits=True)
    ref_color, ref_prim, ref_t = render_reference(scene, camera)
    return frame, ref_color, ref_prim, ref_t


def _assert_agree(frame, ref_color, ref_prim, ref_t):
    same_prim = frame.prim == ref_prim
    assert same_prim.mean() >= 0.999, f"{(~same_prim).sum()} pixels see another triangle"
    both = same_prim & (ref_prim >= 0)
    np.testing.assert_allclose(frame.t[both], ref_t[both], rtol=1e-5)
    close = np.abs(frame.image - ref_color).max(axis=2) <= 2e-3
    assert close.mean() >= 0.995, f"{(~close).sum()} pixels differ in colour"


def test_meshes_match_reference(test_mesh, device):
    scene = scene_from_mesh(test_mesh)
    camera = Camera.framing(scene.bounds, 64, 48)
    frame, *ref = _compare(scene, camera, device)
    _assert_agree(frame, *ref)
    hit = frame.prim >= 0
    assert 0.05 < hit.mean() < 0.95, "the framing should show the mesh and some background"


def test_default_scene_matches_reference(device):
    scene = default_scene(48, 36, coarse=True)
    frame, *ref = _compare(scene, scene.camera, device)
    _assert_agree(frame, *ref)
    # Shadows and highlights exist: the image is not just ambient + diffuse.
    assert len(np.unique(frame.prim)) > 100


@pytest.mark.parametrize("samples", [1, 3])
def test_srgb_output_is_encoded_linear(device, samples):
    """The last sample's pixel colour writes the sRGB image from the sum of
    all samples: the linear frame encoded, to a code (float32 pow on the device)."""
    scene = default_scene(40, 30, coarse=True)
    r = Renderer(scene, device=device)
    linear = r.render(linear=True, samples=samples).image
    encoded = r.render(samples=samples).image
    assert encoded.dtype == np.uint8 and encoded.shape == (30, 40, 3)
    diff = np.abs(encoded.astype(int) - srgb8(linear).astype(int))
    assert diff.max() <= 1 and (diff == 0).mean() > 0.99


def test_coincident_triangles_resolve_to_lower_index(device):
    quad = primitives.box((1, 1, 1))
    doubled = Mesh.from_arrays(quad.vertices, np.concatenate([quad.faces, quad.faces]))
    camera = Camera.framing(doubled.bounds, 48, 48)
    frame = Renderer(scene_from_mesh(doubled), device=device).render(camera, hits=True)
    hit = frame.prim >= 0
    assert hit.mean() > 0.2
    assert (frame.prim[hit] < len(quad.faces)).all(), "a copy with the higher index was drawn"
    assert frame.prim.max() < len(quad.faces)


def test_shadow_of_a_box_on_the_floor(device):
    floor = Mesh.from_arrays([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]])
    block = primitives.box((1, 1, 1), center=(0, 1.5, 0))
    scene = Scene([SceneObject(floor, Material(specular=0)), SceneObject(block)], [Light((3, 6, 0))])
    camera = Camera(eye=(0, 12, 0.01), target=(0, 0, 0), fov=40, width=64, height=64)
    frame = Renderer(scene, device=device).render(camera, linear=True, hits=True)
    origins, dirs = camera_rays(camera)
    x, z = (origins + frame.t.reshape(-1, 1) * dirs)[:, [0, 2]].T
    on_floor = frame.prim.ravel() < 2
    lum = frame.image.sum(axis=2).ravel()
    # The light at x = 3 casts the box's shadow onto the floor between x = -2.25 and -0.5.
    shadow = on_floor & (x > -1.8) & (x < -1.0) & (abs(z) < 0.3)
    lit = on_floor & (x > 1.0) & (x < 1.8) & (abs(z) < 0.3)
    assert shadow.sum() > 5 and lit.sum() > 5
    ambient_only = 0.1 * 0.8 * 3
    np.testing.assert_allclose(lum[shadow], ambient_only, rtol=1e-4)
    assert lum[lit].min() > 3 * ambient_only


def test_miss_is_background(device):
    scene = scene_from_mesh(primitives.icosphere(1), background=(0.25, 0.5, 0.75))
    camera = Camera(eye=(0, 0, 5), target=(5, 0, 5), width=8, height=8)   # looking away
    with pytest.warns(clrt.NothingVisibleWarning, match="out of the camera's view"):   # and it says so
        frame = Renderer(scene, device=device).render(camera, linear=True, hits=True)
    assert (frame.prim == -1).all() and np.isinf(frame.t).all() and not frame.visible
    np.testing.assert_allclose(frame.image, np.broadcast_to([0.25, 0.5, 0.75], (8, 8, 3)), atol=1e-6)


def test_render_api_accepts_mesh_arrays_and_sizes(device):
    sphere = primitives.icosphere(1)
    image = clrt.render((sphere.vertices, sphere.faces), width=32, height=24, device=device)
    assert image.shape == (24, 32, 3) and image.dtype == np.uint8
    # the same frame as a Renderer of the mesh's default scene, framed at that size
    scene = scene_from_mesh(sphere)
    expected = Renderer(scene, device=device).render(Camera.framing(scene.bounds, 32, 24))
    assert np.array_equal(image, expected.image)
    assert (image != image[0, 0]).any(axis=2).mean() > 0.1, "the sphere shows"
    linear = clrt.render(sphere, width=32, height=24, device=device, linear=True)
    assert linear.dtype == np.float32 and linear.shape == (24, 32, 3)
    assert np.abs(srgb8(linear).astype(int) - image.astype(int)).max() <= 1


def test_renderer_reuses_device_state_across_frames(device):
    scene = scene_from_mesh(primitives.icosphere(1))
    r = Renderer(scene, device=device)
    cam = Camera.framing(r.arrays.bounds, 24, 16)
    first = r.render(cam)
    # what the scene and a frame of this size hold on the device, as objects
    scene_buffers = [b for parts in r.geometry.buffers.values() for b in parts] + [r.tables]
    frame_buffers = dict(r._frame_buffers)
    kernels = dict(r.kernels)
    second = r.render(cam)
    assert np.array_equal(first.image, second.image)
    now = [b for parts in r.geometry.buffers.values() for b in parts] + [r.tables]
    assert all(a is b for a, b in zip(now, scene_buffers)) and len(now) == len(scene_buffers)
    assert all(r._frame_buffers[k] is b for k, b in frame_buffers.items()), "frame buffers not remade"
    assert all(r.kernels[k] is kernel for k, kernel in kernels.items())
    small = Camera.framing(r.arrays.bounds, 12, 8)
    third = r.render(small)
    assert all(a is b for a, b in zip(now, scene_buffers))      # a new size: new frame buffers only
    assert np.array_equal(third.image, Renderer(scene, device=device).render(small).image)


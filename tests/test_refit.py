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


# --------------------------------------------------------------------------- a mesh among instances

def _placed(torus, ball):
    """The torus placed turned and stretched, mirrored and sheared, the ball
    between them: the torus is mesh 0 of two."""
    from test_instances import _affine, _rotation
    shear = np.array([[1.0, 0.4, 0.0], [0.0, 1.0, 0.0], [0.3, 0.0, 0.8]])
    return [(torus, _affine(_rotation((1, 2, 3), 0.7) @ np.diag([1.5, 0.7, 1.2]), (0.2, -0.3, 0.1))),
            (ball, _affine(_rotation((0, 1, 1), 2.1), (2.5, 0.5, -0.5))),
            (torus, _affine(np.diag([-1.0, 1.0, 1.0]) @ _rotation((1, 0, 0), 0.4), (-2.6, 0.4, 0.3))),
            (torus, _affine(shear, (2.4, -2.2, -0.4)))]


@pytest.mark.parametrize("volume, builder, split", [("box", "sah", None), ("sphere", "device", None),
                                                    ("ellipse", "paper", None), ("box", "sah", 32768)])
def test_refit_of_a_mesh_among_instances_is_a_fresh_build_of_it(volume, builder, split, device):
    """refit(vertices, mesh=0) moves every placement of the torus: its slots and
    rows are refitted, the instance table and the top level built again over
    the new boxes -- the table, the top level and the device frame those of a
    fresh build of the moved instances, bit for bit, and every answer the
    two-level brute force's (winding numbers within their error); twice, the
    second a refit of a refitted tree.  Split buffers are built anew."""
    from clrt.query.results import WINDING_NUMBER_ERROR
    from clrt.scene.instances import Instances, as_instances
    from test_instances import _rays
    torus, ball = primitives.torus(1.0, 0.35, 24, 12), primitives.icosphere(2)
    instances = as_instances(_placed(torus, ball))
    accel = clrt.Accel(instances, accel=volume, builder=builder, device=device, max_buffer_bytes=split)
    ball_rows = accel.acceleration.rows[accel.acceleration.instances["root"][1]:].copy()
    for amount in (0.8, 2.0):
        vertices = _deformed(torus, amount)
        accel.refit(vertices, mesh=0)
        moved = Instances([Mesh.from_arrays(vertices, torus.faces), ball], instances.mesh_of, instances.transforms)
        fresh = clrt.Accel(moved, accel=volume, builder=builder, device=device, max_buffer_bytes=split)
        brute = clrt.Accel(moved, accel="none", device=device)
        mine, theirs = accel.acceleration, fresh.acceleration
        base = len(theirs.top.rows)
        assert mine.rows[:base].tobytes() == theirs.rows[:base].tobytes()   # the top level, over the new boxes
        for name in mine.instances.dtype.names:   # (a refitted tree may have as many rows as a rebuilt one, or not)
            if name != "root" or split:
                assert np.array_equal(mine.instances[name], theirs.instances[name]), name
        assert np.array_equal(accel.geometry.origin, fresh.geometry.origin)
        assert np.array_equal(accel.instances.meshes[0].vertices, vertices)
        if not split:   # the ball's rows are not touched
            assert mine.rows[mine.instances["root"][1]:].tobytes() == ball_rows.tobytes()
        origins, directions = _rays(moved.bounds, 1500, seed=4)
        got, want = accel.trace(origins, directions), brute.trace(origins, directions)
        assert want.hit.sum() > 300
        for field in got._fields:
            assert np.array_equal(getattr(got, field), getattr(want, field)), (field, amount)
        assert np.array_equal(accel.count(origins, directions), brute.count(origins, directions))
        points = origins[:300] * 0.3
        for field, values in accel.closest_points(points)._asdict().items():
            assert np.array_equal(values, getattr(brute.closest_points(points), field), equal_nan=True), field
        assert np.abs(accel.winding_number(points) - brute.winding_number(points)).max() <= WINDING_NUMBER_ERROR
        assert np.array_equal(accel.signed_distance(points, sign="normal"),
                              brute.signed_distance(points, sign="normal"))


def test_refit_of_instances_rebuilds_when_asked_and_follows_moved_instances(device):
    from clrt.scene.instances import Instances, as_instances
    from test_instances import _rays
    torus, ball = primitives.torus(1.0, 0.35, 24, 12), primitives.icosphere(2)
    instances = as_instances(_placed(torus, ball))
    accel = clrt.Accel(instances, device=device)
    turned = instances.transforms.copy()
    turned[:, :3, 3] *= 1.5
    accel.move_instances(turned)
    swollen = ball.vertices * 1.6
    accel.refit(swollen, mesh=1, rebuild=True)
    moved = Instances([torus, Mesh.from_arrays(swollen, ball.faces)], instances.mesh_of, turned)
    origins, directions = _rays(moved.bounds, 800, seed=6)
    want = clrt.Accel(moved, accel="none", device=device).trace(origins, directions)
    got = accel.trace(origins, directions)
    assert accel.instances.meshes[1].vertices.max() > 1.5 and np.array_equal(accel.instances.transforms, turned)
    for field in got._fields:
        assert np.array_equal(getattr(got, field), getattr(want, field)), field


def test_renderer_refit_of_placed_meshes_draws_the_moved_scene(device):
    """A Renderer of placed meshes refitted to the scene with the torus's
    vertices moved (and one placement moved): the frame a new Renderer of
    that scene draws, pixel for pixel, and its queries follow."""
    from clrt.scene.scene import Material, Scene, SceneObject
    torus, ball = primitives.torus(1.0, 0.35, 24, 12), primitives.icosphere(2)
    placed = _placed(torus, ball)

    def scene_of(mesh, shift, other=None):
        red, blue = Material(color=(0.9, 0.2, 0.1), smooth=False), Material(color=(0.2, 0.3, 0.9))
        transforms = [m.copy() for _, m in placed]
        transforms[1][:3, 3] += shift
        return Scene([SceneObject(mesh, red, (), transforms[0]), SceneObject(ball, blue, (), transforms[1]),
                      SceneObject(other or mesh, red, (), np.stack(transforms[2:]))], [])

    scene = scene_of(torus, 0.0)
    moved = scene_of(Mesh.from_arrays(_deformed(torus, 1.2), torus.faces), (0.0, 0.8, 0.0))
    renderer = Renderer(scene, device=device)
    queries = clrt.Accel.from_renderer(renderer)
    camera = Camera.framing(moved.bounds, 64, 48)
    renderer.refit(moved)
    frame = renderer.render(camera, hits=True)
    reference = Renderer(moved, device=device, accel="none").render(camera, hits=True)
    assert (reference.prim >= 0).sum() > 150
    for name in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, name), getattr(reference, name)), name
    o, d = np.tile(camera.eye, (200, 1)), np.random.default_rng(1).normal(size=(200, 3)) * 0.1 + (
        np.asarray(camera.target) - camera.eye)
    want = clrt.Accel(renderer.instances, accel="none", device=device).trace(o, d)
    assert np.array_equal(queries.trace(o, d).prim, want.prim) and np.array_equal(queries.trace(o, d).t, want.t)
    with pytest.raises(clrt.InputError, match="same placements of the same meshes") as err:
        renderer.refit(scene_of(torus, 0.0, primitives.torus(1.0, 0.35, 24, 12)))   # two meshes of one
    assert "\n" not in str(err.value)
    with pytest.raises(clrt.InputError, match="same triangles"):
        renderer.refit(scene_from_mesh(torus))

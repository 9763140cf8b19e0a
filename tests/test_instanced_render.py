"""The renderer on scenes of placed meshes (docs/instances.md): each distinct
mesh uploaded once and placed by the instance table, never flattened, and
the image that of the flattened twin (``Scene.flattened``: every placement
moved into the world in float64, its vertex normals by the inverse
transpose).

* Whitted: the same camera hits (instance and triangle) pixel for pixel, and
  the colours within float32 rounding of the transforms -- not bit for bit:
  the instanced scene shades the triangle's corners as the float32 maps
  place them and traces rays that leave it in the mesh's own space (their
  origins moved a little farther off: shading.cl's instance_spawn_error),
  where the twin holds corners rounded from float64 -- a few pixels where a
  shadow or a reflection ray grazes an edge may differ more.
* The path tracer: emitters seen directly (max_depth 1) bit for bit; deeper
  paths statistically equal with the same seed, not equal: the light table
  lists the placed emitters in another order than the twin's slots, so one
  random number picks another light.
* Where placements come from: lists, clrt.Instances, a glTF file whose nodes
  share a mesh, a scene file's [[instances]]; the instance AOV; bad input.
"""

import numpy as np
import pytest

import clrt
from clrt.cli import main
from clrt.scene import primitives
from clrt.scene.emitters import emitting_triangles
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject

from test_instances import _affine, _hierarchy_glb, _rotation

SHEAR = np.array([[1.0, 0.4, 0.0], [0.0, 1.0, 0.0], [0.3, 0.0, 0.8]])


def _whitted_scene() -> Scene:
    """A smooth torus placed rotated and stretched, mirrored, and (in another
    material: another object, the same mesh) sheared; a mirror-like box placed
    turned and mirrored upside down; a stretched glass ball; a floor that is
    no instance; two lights (shadows)."""
    torus = primitives.torus(1.0, 0.35, 32, 16)
    box = primitives.box((1, 1, 1))
    floor = primitives.box((12, 0.2, 12)).transformed(_affine(shift=(0, -1.3, 0)))
    objects = [
        SceneObject(torus, Material(color=(0.9, 0.2, 0.1), specular=0.5, shininess=40),
                    (), [_affine(_rotation((1, 2, 3), 0.7) @ np.diag([1.5, 0.7, 1.2]), (-2.4, 0.2, 0.0)),
                         _affine(np.diag([-1.0, 1.0, 1.0]) @ _rotation((1, 0, 0), 0.9), (0.0, 0.1, 0.3))]),
        SceneObject(torus, Material(color=(0.2, 0.5, 0.9)), (), [_affine(SHEAR, (2.4, 0.0, -0.5))]),
        SceneObject(box, Material(color=(0.9, 0.9, 0.9), reflectivity=0.4, smooth=False), (),
                    [_affine(_rotation((0, 1, 1), 2.1), (-1.0, 0.0, -2.5)),
                     _affine(np.diag([1.6, -0.8, 1.0]), (1.8, -0.2, 2.0))]),
        SceneObject(primitives.icosphere(2, 0.6), Material(color=(0.95, 0.95, 1.0), transparency=0.7, diffuse=0.1,
                                                           ior=1.4), (), _affine(np.diag([1.0, 1.4, 1.0]),
                                                                                 (0.5, 1.5, 1.8))),
        SceneObject(floor, Material(color=(0.7, 0.7, 0.7), smooth=False)),
    ]
    return Scene(objects, [Light((4, 8, 6)), Light((-5, 6, 2), (0.4, 0.4, 0.5))])


CAMERA = Camera((0.5, 4.5, 9.0), (0, 0, 0), width=96, height=72)


def _flat_prim(instances, images):
    """The camera images' (instance, triangle) as the flattened twin's triangle index."""
    faces = np.array([len(instances.meshes[k].faces) for k in instances.mesh_of])
    first = np.concatenate([[0], np.cumsum(faces)])
    return np.where(images.hit, first[np.maximum(images.instance, 0)] + images.prim, -1)


def test_whitted_renders_placed_meshes_as_their_flattened_twin(device):
    scene = _whitted_scene()
    renderer = clrt.Renderer(scene, device=device)
    instances = renderer.instances
    # Not flattened: each distinct mesh once on the device (the torus under two
    # materials is one mesh), placed 7 times.
    assert len(instances) == 7 and len(instances.meshes) == 4
    assert int(renderer.geometry.num_tris) == sum(len(m.faces) for m in instances.meshes) < scene.num_triangles
    twin = clrt.Renderer(scene.flattened(), device=device)
    image = renderer.render(CAMERA, linear=True).image
    want = twin.render(CAMERA, linear=True).image
    mine = clrt.Accel.from_renderer(renderer).camera_images(CAMERA)
    theirs = clrt.Accel.from_renderer(twin).camera_images(CAMERA)
    assert np.array_equal(_flat_prim(instances, mine), theirs.prim)
    assert set(np.unique(mine.instance)) == {-1, *range(7)}
    differ = np.abs(image - want).max(axis=2)
    assert image.mean() > 0.1 and (differ > 1e-4).mean() < 0.002 and differ.max() < 0.02


def _path_scene() -> Scene:
    """Emissive boxes placed flattened, and mirrored and turned; a torus placed
    three times (a mirror and a stretch among them); a floor."""
    white = Material(color=(0.8, 0.8, 0.8))
    lamp = Material(color=(0.8, 0.8, 0.8), emission=(4.0, 4.0, 3.0))
    floor = primitives.box((10, 0.1, 10)).transformed(_affine(shift=(0, -0.6, 0)))
    return Scene([
        SceneObject(primitives.torus(1.0, 0.35, 24, 12), white, (),
                    [_affine(), _affine(np.diag([-1.0, 1.0, 1.0]), (2.5, 0, 0)),
                     _affine(np.diag([1.5, 0.7, 1.2]), (-2.5, 0, 0))]),
        SceneObject(primitives.box((1, 1, 1)), lamp, (),
                    [_affine(np.diag([1, 0.1, 1]), (0, 2, 0)),
                     _affine(np.diag([-1, 0.1, 1]) @ _rotation((0, 1, 0), 0.5), (2, 2.5, 0))]),
        SceneObject(floor, white)], [], integrator="path")


def test_the_path_tracer_renders_placed_meshes_as_their_flattened_twin(device):
    scene = _path_scene()
    renderer = clrt.Renderer(scene, device=device)
    twin = clrt.Renderer(scene.flattened(), device=device)
    camera = Camera((0, 4, 8), (0, 0, 0), width=48, height=36)
    # The light table: each placed emitting triangle once (the lamp's 12, twice).
    _, _, slots, instances = emitting_triangles(renderer.arrays, renderer.acceleration.slot_order())
    assert sorted(np.bincount(instances)[3:5]) == [12, 12] and len(slots) == 24
    direct = [r.render(camera, linear=True, spp=4, seed=3, max_depth=1).image for r in (renderer, twin)]
    assert np.array_equal(*direct) and direct[0].max() > 1.0
    image, want = (r.render(camera, linear=True, spp=16, seed=3).image for r in (renderer, twin))
    other = twin.render(camera, linear=True, spp=16, seed=4).image
    # No 6 x 6 block, nor the image, differs from the twin's by more than
    # another seed changes it (a lamp's light lost or misplaced: 2.5 times).
    blocks = lambda a: a.reshape(6, 6, 8, 6, 3).mean(axis=(1, 3))   # noqa: E731
    assert np.abs(blocks(image) - blocks(want)).max() < np.abs(blocks(other) - blocks(want)).max()
    assert np.abs(image - want).mean() < np.abs(other - want).mean()
    assert abs(image.mean() / want.mean() - 1) < 0.02


def test_lists_and_instances_render_as_placed_meshes(device):
    """A list of meshes or of (mesh, transform) pairs, or a clrt.Instances:
    one mesh object listed twice is one mesh on the device; instance k is
    the k-th entry (the instance image says which pixel sees which)."""
    ball = primitives.icosphere(2, 0.8)
    pairs = [(ball, _affine(shift=(-1.0, 0, 0))), (ball, _affine(np.diag([1.0, 1.5, 1.0]), (1.0, 0, 0)))]
    camera = Camera((0, 0, 6), (0, 0, 0), width=40, height=24)
    instances = clrt.Instances([ball], [0, 0], [m for _, m in pairs])
    images = []
    for source in (pairs, instances):
        renderer = clrt.Renderer(source, device=device)
        assert len(renderer.instances) == 2 and int(renderer.geometry.num_tris) == len(ball.faces)
        images.append(renderer.render(camera).image)
        seen = clrt.Accel.from_renderer(renderer).camera_images(camera).instance
        assert (seen[:, :16] <= 0).all() and (seen[:, 24:] != 0).all() and {0, 1} <= set(seen.ravel())
    assert np.array_equal(*images)
    assert clrt.Renderer([ball, ball], device=device).geometry.num_tris == len(ball.faces)


def test_a_gltf_file_whose_nodes_share_a_mesh_renders_as_instances(tmp_path, device):
    """Its mesh nodes are instances, numbered as clrt.Accel numbers them (the
    instance images agree), its materials the file's; the image is its
    flattened twin's."""
    path = _hierarchy_glb(tmp_path / "balls.glb", groups=3, per_group=3)
    renderer = clrt.Renderer(path, device=device)
    assert len(renderer.instances) == 11 and len(renderer.instances.meshes) == 3   # box, ball, mirrored ball
    camera = renderer.scene.camera
    camera = Camera(camera.eye, camera.target, camera.up, camera.fov, 64, 48)
    mine = clrt.Accel.from_renderer(renderer).camera_images(camera)
    assert np.array_equal(mine.instance, clrt.Accel(path, device=device).camera_images(camera).instance)
    assert len(np.unique(mine.instance)) > 5
    image = renderer.render(camera, linear=True).image
    want = clrt.Renderer(renderer.scene.flattened(), device=device).render(camera, linear=True).image
    assert image.max() > 0.2 and (np.abs(image - want).max(axis=2) > 1e-4).mean() < 0.002


SCENE_FILE = """
[camera]
eye = [0, 4, 9]
target = [0, 0, 0]
width = 48
height = 36

[materials.gold]
color = [0.9, 0.7, 0.2]
reflectivity = 0.3

[[objects]]
type = "torus"
name = "ring"
rotate = [20, 0, 0]
show = false

[[objects]]
type = "box"
size = [10, 0.1, 10]
translate = [0, -0.6, 0]

[[instances]]
object = "ring"
translate = [-2.2, 0, 0]

[[instances]]
object = "ring"
scale = [-1, 1, 1]
rotate = [0, 30, 0]
material = "gold"

[[instances]]
object = "ring"
matrix = [[1.5, 0, 0, 2.2], [0, 0.7, 0, 0], [0, 0, 1.2, 0], [0, 0, 0, 1]]
"""


def test_a_scene_files_instances_place_one_object(tmp_path, device, capsys):
    """[[instances]] place the object they name (after its own transform), in
    a material of their own or its; the object itself is hidden (show =
    false); the file renders as its flattened twin, and --aov instance
    writes which placement each pixel sees."""
    path = tmp_path / "rings.toml"
    path.write_text(SCENE_FILE)
    scene = clrt.load_scene(path)
    assert [o.placements for o in scene.objects] == [1, 1, 1, 1] and scene.objects[0].transforms is None
    rings = scene.objects[1:]
    assert rings[0].mesh is rings[1].mesh is rings[2].mesh and rings[1].material.color == (0.9, 0.7, 0.2)
    tilt = _affine(_rotation((1, 0, 0), np.radians(20)))
    assert np.allclose(rings[1].transforms[0], _affine(_rotation((0, 1, 0), np.radians(30)) @ np.diag([-1, 1, 1]))
                       @ tilt)
    assert np.allclose(rings[2].transforms[0], _affine(np.diag([1.5, 0.7, 1.2]), (2.2, 0, 0)) @ tilt)
    camera = scene.camera
    image = clrt.Renderer(scene, device=device).render(camera, linear=True).image
    want = clrt.Renderer(scene.flattened(), device=device).render(camera, linear=True).image
    assert (np.abs(image - want).max(axis=2) > 1e-4).mean() < 0.002
    out = tmp_path / "rings.png"
    assert main(["render", str(path), "-o", str(out), "--aov", "instance"]
                + (["--device", device] if device else [])) == 0
    said = capsys.readouterr().out
    assert "triangles, 4 placements (" in said and "path tracing" not in said   # (Whitted, --aov or not)
    seen = np.load(tmp_path / "rings.instance.npy")
    assert seen.shape == (36, 48) and set(np.unique(seen)) == {-1, 0, 1, 2, 3}
    assert (tmp_path / "rings.instance.png").exists()


@pytest.mark.parametrize("entry, message", [
    ('object = "rnig"', r"instances\[0\]\.object: unknown object 'rnig' \(did you mean 'ring'\?\)"),
    ('object = "ring"\nscale = [1, 0, 1]', r"instances\[0\]\.scale must be a number or 3 numbers, not 0"),
    ('object = "ring"\nmatrix = [[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]',
     r"instances\[0\]\.matrix must be invertible .* got a singular one"),
    ('object = "ring"\nmatrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]',
     r"instances\[0\]\.matrix must be affine \(last row 0 0 0 1\)"),
    ('object = "ring"\nmatrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]',
     r"instances\[0\]\.matrix must be 4 rows of 4 numbers"),
    ('object = "ring"\ntranslate = [1, 0, 0]\nmatrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]',
     r"instances\[0\]\.matrix: give matrix or translate, not both"),
    ('object = "ring"\ntranslate = [9e29, 0, 0]\nscale = 2e29',
     r"instances\[0\]: ring: placement 0 takes it to 1.17e\+30, past"),
    ('object = "ring"\nscale = 1e20\ntranslate = [1e20, 0, 0]',   # (named by the placement, where it is)
     r"object 'ring', placement 0 reaches \(2.35e20, 3.5e19, 1.35e20\), .*: the scene is too large"),
    ('object = "box"', r"objects\[0\]\.show: is false, but no \[\[instances\]\] table names the object"),
])
def test_bad_instance_entries_are_one_line_and_exit_2(tmp_path, entry, message, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(f'[[objects]]\ntype = "torus"\nname = "ring"\nshow = false\n'
                    f'[[objects]]\ntype = "box"\nname = "box"\n[[instances]]\n{entry}\n')
    out = tmp_path / "bad.png"
    assert main(["render", str(path), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and not out.exists()
    assert __import__("re").search(message, err), err


def test_moved_placements_render_as_a_new_renderer_of_them(device):
    """Renderer.move_instances: the next frames -- Whitted's and the path
    tracer's, its emitters moved with them -- and the queries that follow it
    are those of a Renderer made of the moved scene, bit for bit; the
    meshes' rows and shading arrays stay."""
    scene = _path_scene()
    renderer = clrt.Renderer(scene, device=device)
    queries = clrt.Accel.from_renderer(renderer)
    camera = Camera((0, 4, 8), (0, 0, 0), width=40, height=30)
    renderer.render(camera, spp=2)   # (light tables made before the move)
    moved = renderer.instances.transforms.copy()
    moved[3:, :3, 3] += (0.6, 0.4, -0.3)                        # the lamps
    moved[0, :3, :3] = _rotation((0, 0, 1), 0.5) @ np.diag([1.0, -1.0, 1.0])   # a torus turned and mirrored
    tri_info = renderer.geometry.buffers["tri_info"]
    renderer.move_instances(moved)
    assert renderer.geometry.buffers["tri_info"] is tri_info and np.array_equal(renderer.instances.transforms, moved)
    fresh = clrt.Renderer(renderer.scene, device=device)
    for integrator in ("whitted", "path"):
        frames = [r.render(camera, linear=True, integrator=integrator, spp=4, seed=2).image for r in (renderer, fresh)]
        assert np.array_equal(*frames), integrator
    mine, theirs = queries.camera_images(camera), clrt.Accel.from_renderer(fresh).camera_images(camera)
    assert np.array_equal(mine.instance, theirs.instance) and np.array_equal(mine.t, theirs.t)
    with pytest.raises(clrt.InputError, match="move_instances needs a scene of placed meshes"):
        clrt.Renderer(primitives.box((1, 1, 1)), device=device).move_instances(moved)


def test_many_placements_of_one_mesh_stay_one_mesh_on_the_device(device):
    """6^3 placements of a torus of 20,000 triangles (4.3M triangles
    flattened, about 0.5 GB on the device): the triangles, their shading
    rows and BVH are uploaded once, the instance table holds a row each, and
    the frame shows them (docs/instances.md has 2,197 placements of 75k
    triangles: 8 MiB, 0.05 s a Whitted frame on PoCL)."""
    torus = primitives.torus(1.0, 0.35, 125, 80)
    cells = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), -1).reshape(-1, 3) * 3.0
    placed = np.tile(np.eye(4), (len(cells), 1, 1))
    placed[:, :3, 3] = cells
    placed[::2, :3, :3] = _rotation((1, 0, 0), 1.2)   # every other one stood up
    renderer = clrt.Renderer(clrt.Instances([torus], np.zeros(len(cells), int), placed), device=device)
    buffers, f = renderer.geometry.buffers, len(torus.faces)
    assert f == 20_000 and renderer.scene.num_triangles == 216 * f
    assert int(renderer.geometry.num_tris) == f and len(renderer.arrays.corners) == f
    assert buffers["tris"][0].size == 48 * f and buffers["tri_info"][0].size == 16 * f
    assert buffers["instances"][0].size == 216 * 160
    two = renderer.acceleration   # the top level's 215 rows, then the one mesh's
    assert len(two.bottoms) == 1 and len(two.rows) == 215 + len(two.bottoms[0].rows) < f
    assert renderer.device_bytes < 6e6                         # flattened: about 5e8
    camera = Camera((24.0, 19.0, 30.0), (7.5, 7.5, 7.5), width=64, height=48)
    image = renderer.render(camera).image
    seen = clrt.Accel.from_renderer(renderer).camera_images(camera).instance
    assert image.mean() > 20 and len(np.unique(seen)) > 60


def test_normal_maps_of_placed_meshes_bend_as_the_twins(device):
    """The path tracer's normal maps take their tangent frame from the
    triangle as placed (material.cl's mapped_normal): the first hits' mean
    shading normal, under a stretch and under a turned mirror, is the
    flattened twin's within float32 rounding."""
    from test_path_normal_maps import LAMBERT, _squares
    from clrt.scene.texture import Texture
    codes = np.random.default_rng(3).integers(60, 255, (8, 8, 3)).astype(np.uint8)
    codes[..., 2] = 255
    material = Material(**LAMBERT, normal_texture=Texture(codes))
    placed = [_affine(np.diag([1.3, 0.8, 1.0]), (-1.2, 0, 0)),
              _affine(_rotation((0, 1, 0), 0.4) @ np.diag([-1.0, 1.0, 1.0]), (1.2, 0, 0))]
    scene = Scene([SceneObject(_squares(), material, (), placed)], [Light((0, 0, 10), (100.0,) * 3)],
                  integrator="path")
    camera = Camera((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), width=48, height=32, fov=25)
    mine, twin = (clrt.Renderer(s, device=device).render(camera, linear=True, spp=4, seed=1)
                  for s in (scene, scene.flattened()))
    seen = np.abs(mine.normal).sum(axis=2) > 0
    bent = np.abs(mine.normal[..., :2]).max(axis=2) > 0.05    # the map tilts most seen pixels' normals
    assert seen.mean() > 0.2 and bent[seen].mean() > 0.5 and np.abs(mine.normal - twin.normal).max() < 1e-5

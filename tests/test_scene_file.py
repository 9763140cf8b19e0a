"""TOML scene files: the example scene, transforms, path resolution and every validation error."""

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from clrt.errors import InputError
from clrt.renderer import Renderer
from clrt.scene.scene import Camera, Material
from clrt.scene.scene_file import load_scene, transform_matrix

ROOT = Path(__file__).resolve().parents[1]
SHOWCASE = ROOT / "assets" / "scenes" / "showcase.toml"

SPHERE = '[[objects]]\ntype = "sphere"\nsubdivisions = 1\n'


def write(tmp_path, text, name="scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture(scope="module")
def showcase():
    return load_scene(SHOWCASE)


def by_name(scene, name):
    return next(o for o in scene.objects if o.mesh.name == name)


def test_showcase_loads(showcase):
    # floor (two halves), glass ball, mirror ball, mirror slab, torus, knot
    assert len(showcase.objects) == 7
    assert all(len(o.mesh.faces) > 0 for o in showcase.objects)
    assert showcase.num_triangles > 4000
    assert (showcase.max_depth, showcase.samples) == (6, 2)
    assert len(showcase.lights) == 2
    np.testing.assert_allclose(showcase.lights[1].color, (0.28, 0.32, 0.4))   # colour x intensity
    assert (showcase.camera.width, showcase.camera.height) == (800, 600)


def test_showcase_materials(showcase):
    glass = by_name(showcase, "glass ball").material
    assert (glass.transparency, glass.ior, glass.diffuse) == (0.9, 1.5, 0.05)
    assert by_name(showcase, "mirror ball").material.reflectivity == 0.8
    assert by_name(showcase, "mirror slab").material is by_name(showcase, "mirror ball").material
    assert by_name(showcase, "red torus").material.color == (0.85, 0.15, 0.1)
    assert by_name(showcase, "red torus").material.ior == Material().ior   # unset -> default
    tiles = [by_name(showcase, f"floor tiles {k}").material for k in (0, 1)]
    assert tiles[0].color != tiles[1].color and not tiles[0].smooth


def test_showcase_transforms(showcase):
    centre = by_name(showcase, "glass ball").mesh.bounds.mean(axis=0)
    np.testing.assert_allclose(centre, (-1.3, 1.0, 1.4), atol=1e-5)
    knot = by_name(showcase, "knot").mesh
    np.testing.assert_allclose(knot.bounds.mean(axis=0), (-0.2, 0.8, -1.6), atol=0.02)
    # the knot lies in the xz plane in its file; rotate x 90 stands it up in the xy plane
    extent = np.ptp(knot.bounds, axis=0)
    assert extent[2] < 0.5 * extent[1]


def test_showcase_renders(showcase):
    c = showcase.camera
    frame = Renderer(showcase).render(Camera(c.eye, c.target, c.up, c.fov, 32, 24))
    assert frame.image.shape == (24, 32, 3)
    background = np.round(255 * np.asarray(showcase.background) ** (1 / 2.2))
    differs = np.abs(frame.image.astype(int) - background).max(axis=2) > 8
    assert differs.mean() > 0.3


def test_rotation_convention(tmp_path):
    # Documented: right-handed, degrees, X then Y then Z; 90 about y takes +x to -z.
    np.testing.assert_allclose(transform_matrix(rotate=(0, 90, 0)) @ [1, 0, 0, 1], [0, 0, -1, 1], atol=1e-12)
    np.testing.assert_allclose(transform_matrix(rotate=(90, 0, 0)) @ [0, 1, 0, 1], [0, 0, 1, 1], atol=1e-12)
    # X is applied before Z: +y -> +z (X), which Z leaves alone.
    np.testing.assert_allclose(transform_matrix(rotate=(90, 0, 90)) @ [0, 1, 0, 1], [0, 0, 1, 1], atol=1e-12)
    # scale -> rotate -> translate
    np.testing.assert_allclose(transform_matrix((1, 2, 3), (0, 90, 0), (2, 1, 1)) @ [1, 0, 0, 1], [1, 2, 1, 1],
                               atol=1e-12)
    # the same through a file: a box 2 long in x, rotated 90 about y, is 2 long in z
    scene = load_scene(write(tmp_path, """
        [[objects]]
        type = "box"
        size = [2.0, 0.5, 0.5]
        rotate = [0, 90, 0]
        translate = [5, 0, 0]
        """))
    np.testing.assert_allclose(scene.objects[0].mesh.bounds, [[4.75, -0.25, -1], [5.25, 0.25, 1]], atol=1e-6)


def test_defaults_and_primitives(tmp_path):
    scene = load_scene(write(tmp_path, """
        [[objects]]
        type = "plane"
        size = [4, 2]
        [[objects]]
        type = "checkerboard"
        tiles = 2
        [[objects]]
        type = "torus"
        scale = [1, 2, 1]
        """))
    plane, light, dark, torus = scene.objects
    np.testing.assert_allclose(plane.mesh.bounds, [[-2, 0, -1], [2, 0, 1]])
    assert np.allclose(plane.mesh.face_normals(), [0, 1, 0])
    assert len(light.mesh.faces) == len(dark.mesh.faces) == 4
    assert light.material == Material() and dark.material != light.material
    np.testing.assert_allclose(np.ptp(torus.mesh.bounds, axis=0)[1], 4 * 0.35, rtol=1e-3)   # non-uniform scale
    assert (scene.max_depth, scene.depth, scene.samples, scene.background) == (None, 5, 1, (0.0, 0.0, 0.0))
    assert scene.camera is not None and len(scene.lights) == 1   # framed, default light


def test_camera_without_eye_is_framed(tmp_path):
    scene = load_scene(write(tmp_path, SPHERE + "[camera]\nwidth = 64\nheight = 32\nfov = 30\n"))
    assert (scene.camera.width, scene.camera.height, scene.camera.fov) == (64, 32, 30)
    np.testing.assert_allclose(scene.camera.target, (0, 0, 0), atol=1e-6)


def test_mesh_path_is_relative_to_scene_file(tmp_path, monkeypatch):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene_dir = tmp_path / "scenes"
    scene_dir.mkdir()
    path = write(scene_dir, '[[objects]]\ntype = "mesh"\npath = "../meshes/tri.obj"\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert len(load_scene(path).objects[0].mesh.faces) == 1
    monkeypatch.chdir(scene_dir)
    assert len(load_scene("scene.toml").objects[0].mesh.faces) == 1
    # absolute paths are used as they are
    absolute = write(elsewhere, f'[[objects]]\ntype = "mesh"\npath = "{(tmp_path / "meshes" / "tri.obj").as_posix()}"\n')
    assert len(load_scene(absolute).objects[0].mesh.faces) == 1


@pytest.mark.parametrize("text, where, expected", [
    ('[materials.m]\ncolour = [1, 0, 0]\n' + SPHERE, "materials.m.colour",
     "unknown key 'colour' (did you mean 'color'?)"),
    (SPHERE + 'translate = [1, 2, 3]\ncentr = [0, 0, 0]\n', "objects[0].centr", "did you mean 'centre'?"),
    (SPHERE + 'raduis = 2\n', "objects[0].raduis", "did you mean 'radius'?"),
    ('[camra]\nfov = 40\n' + SPHERE, "camra", "did you mean 'camera'?"),
    (SPHERE + 'size = [1, 1, 1]\n', "objects[0].size", "does not apply to type 'sphere'"),
    (SPHERE + 'radius = "big"\n', "objects[0].radius", "must be a number > 0, got 'big'"),
    (SPHERE + 'radius = -1\n', "objects[0].radius", "must be a number > 0"),
    ('[[objects]]\ntype = "sphere"\nsubdivisions = 2.0\n', "objects[0].subdivisions", "must be an integer in 0..7"),
    (SPHERE + 'translate = [1, 2]\n', "objects[0].translate", "must be 3 numbers"),
    (SPHERE + 'rotate = [1, 2, "x"]\n', "objects[0].rotate", "must be 3 numbers"),
    (SPHERE + 'scale = [1, 0, 1]\n', "objects[0].scale", "must be 3 numbers > 0"),
    (SPHERE + 'material = { color = [2, 0, 0] }\n', "objects[0].material.color",
     "must be 3 numbers in 0..1"),
    (SPHERE + 'material = { smooth = 1 }\n', "objects[0].material.smooth", "must be true or false"),
    ('[materials.glass]\nior = 0.5\n' + SPHERE, "materials.glass.ior", "must be a number in 1..100"),
    ('[materials.glass]\ntransparency = 1.5\n' + SPHERE, "materials.glass.transparency", "in 0..1"),
    ('[materials.glass]\n' + SPHERE + 'material = "glas"\n', "objects[0].material",
     "unknown material 'glas' (did you mean 'glass'?)"),
    (SPHERE + 'material = 3\n', "objects[0].material", "expected a material name or an inline table"),
    ('[[objects]]\ntype = "cube"\n', "objects[0].type", "unknown object type 'cube' (expected one of"),
    ('[[objects]]\nradius = 1\n', "objects[0].type", "missing"),
    ('[[objects]]\ntype = "mesh"\n', "objects[0].path", "missing"),
    ('[[objects]]\ntype = "mesh"\npath = "nope.obj"\n', "objects[0].path", "mesh file not found: "),
    ('[[objects]]\ntype = "mesh"\npath = "/etc"\n', "objects[0].path", "is a folder, not a mesh file: /etc"),
    ('[[objects]]\ntype = "mesh"\npath = "."\n', "objects[0].path", "is a folder, not a mesh file: "),
    ('[[objects]]\ntype = "mesh"\npath = ""\n', "objects[0].path", "is empty (give the mesh file's path), got ''"),
    ('[[objects]]\ntype = "mesh"\npath = " "\n', "objects[0].path", "is empty (give the mesh file's path), got ' '"),
    (SPHERE + '[[lights]]\nposition = [1, 2]\n', "lights[0].position", "must be 3 numbers"),
    (SPHERE + '[[lights]]\ncolor = [1, 1, 1]\n', "lights[0].position", "missing"),
    (SPHERE + '[[lights]]\nposition = [0, 5, 0]\nintensity = -1\n', "lights[0].intensity", ">= 0"),
    ('[render]\nsamples = 17\n' + SPHERE, "render.samples", "must be an integer in 1..16, got 17"),
    ('[render]\nsamples = 0\n' + SPHERE, "render.samples", "must be an integer in 1..16"),
    ('[render]\nmax_depth = -1\n' + SPHERE, "render.max_depth", "must be an integer in 0..16"),
    ('[render]\nbackground = [0, 0, 0, 1]\n' + SPHERE, "render.background", "must be 3 numbers"),
    ('[camera]\nfov = 180\n' + SPHERE, "camera.fov", "must be a number > 0 and < 180"),
    ('[camera]\neye = [0, 0, 5]\n' + SPHERE, "camera.target", "give both eye and target"),
    ('[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 5]\n' + SPHERE, "camera", "eye and target must differ"),
    ('[camera]\nwidth = true\n' + SPHERE, "camera.width", "must be an integer in 1..65536"),
    ('[render]\n', "objects", "no objects"),
    ('objects = []\n', "objects", "no objects"),
    ('objects = 3\n', "objects", "expected an array of tables"),
    ('render = 3\n' + SPHERE, "render", "expected a table"),
])
def test_validation_errors(tmp_path, text, where, expected):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_scene(path)
    message = str(info.value)
    # Structural problems read "FILE: KEY: ...", values "FILE: KEY must be ..." (clrt.checks).
    assert message.startswith((f"{path}: {where}: ", f"{path}: {where} must be ")), message
    assert expected in message, message
    assert "\n" not in message


def test_toml_syntax_error_names_the_line(tmp_path):
    path = write(tmp_path, SPHERE + "radius 2\n")
    with pytest.raises(InputError, match=r"scene\.toml: invalid TOML: .*line 4"):
        load_scene(path)


def test_a_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + SPHERE.encode())
    assert len(load_scene(path).objects) == 1


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(InputError, match="scene file not found"):
        load_scene(tmp_path / "nothing.toml")
    with pytest.raises(InputError, match="is a directory"):
        load_scene(tmp_path)
    (tmp_path / "bad.toml").write_bytes(b'[[objects]]\ntype = "\xff"\n')
    with pytest.raises(InputError, match="not UTF-8"):
        load_scene(tmp_path / "bad.toml")


def test_corrupt_mesh_file_names_the_key(tmp_path):
    (tmp_path / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    path = write(tmp_path, '[[objects]]\ntype = "mesh"\npath = "broken.obj"\n')
    with pytest.raises(InputError, match=r"objects\[0\]\.path: .*broken\.obj"):
        load_scene(path)


def test_docs_example_loads(tmp_path):
    # The example in docs/scene-files.md must stay valid.
    text = (ROOT / "docs" / "scene-files.md").read_text()
    example = text.split("## Example", 1)[1].split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "knot.obj").write_bytes((ROOT / "assets" / "meshes" / "knot.obj").read_bytes())
    (tmp_path / "scenes").mkdir()
    scene = load_scene(write(tmp_path / "scenes", example))
    assert len(scene.objects) == 6 and len(scene.lights) == 2


@pytest.mark.parametrize("text, largest", [
    ('[[objects]]\ntype = "sphere"\nradius = 1e20\nscale = 1e20\n', "1e40"),
    ('[camera]\nwidth = 64\n[[objects]]\ntype = "sphere"\nradius = 1e20\nscale = 1e20\n', "1e40"),
    ('[[objects]]\ntype = "plane"\nsize = [1e30, 1e30]\nscale = 1e10\n', "5e39"),
    ('[[objects]]\ntype = "box"\ntranslate = [1e30, 0, 0]\nscale = 1e29\n', "1.05e30"),
    ('[[objects]]\ntype = "torus"\nmajor = 1e30\n', "1.00000002e30"),   # 1e30 in float32
    (SPHERE + '[[objects]]\ntype = "sphere"\nradius = 1e30\n', "1.00000002e30"),
])
def test_an_object_past_float32_names_the_object(tmp_path, text, largest, capsys):
    # Not the camera or a light framed from infinite bounds, and no numpy warnings.
    path = write(tmp_path, text)
    index = text.count("[[objects]]") - 1
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError) as info:
            load_scene(path)
    said = (f"{path}: objects[{index}]: vertex coordinates must lie within +-1e30 after its "
            f"transform (the device computes in float32), got up to {largest}")
    # and the first vertex beyond, by index and coordinates
    assert re.fullmatch(re.escape(said) + r" \(the first beyond: vertex \d+ at \([^()]*\)\)", str(info.value)), info.value
    from clrt import cli
    assert cli.main(["render", str(path), "-o", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err == f"clrt: {info.value}\n"


def test_a_primitive_past_float32_names_the_object(tmp_path):
    path = write(tmp_path, '[[objects]]\ntype = "checkerboard"\nsize = 1e300\n')
    with pytest.raises(InputError, match=r"^.*scene\.toml: objects\[0\]: vertex coordinates must lie within"):
        load_scene(path)


def test_a_scene_too_large_to_frame_says_so(tmp_path):
    # Each vertex is in range, but the framed camera would not be.
    big = '[[objects]]\ntype = "sphere"\nradius = 9e29\n'
    with pytest.raises(InputError, match=r"scene\.toml: camera: cannot frame the scene: the camera would stand "
                                         r"at .* past \+-1e30 .*; give camera.eye and camera.target$"):
        load_scene(write(tmp_path, big))
    # The file's own camera is used as it is; the default light, a scene diagonal
    # from the eye at most, comes nearer so as to stay in range.
    placed = '[camera]\neye = [0, 0, 9e29]\ntarget = [0, 0, 0]\n' + big
    scene = load_scene(write(tmp_path, placed))
    assert scene.camera.eye == (0, 0, 9e29) and not scene.camera_framed
    (light,) = scene.lights
    assert max(map(abs, light.position)) <= 1e30 and light.position[1] > 9e29   # above the eye
    scene = load_scene(write(tmp_path, placed + '[[lights]]\nposition = [0, 9e29, 9e29]\n'))
    assert scene.lights[0].position == (0, 9e29, 9e29)


def test_the_default_light_stays_in_range_and_keeps_its_side():
    """One diagonal above-left of the eye where that is in range; else as far
    along the same way as the range allows."""
    from clrt.scene.scene import default_light
    near = default_light(np.array([[-1, -1, -1], [1, 1, 1]]), Camera((0, 0, 5), (0, 0, 0)))
    np.testing.assert_allclose(near.position, (-0.5 * 12 ** 0.5, 0.8 * 12 ** 0.5, 5), rtol=1e-12)
    far = default_light(np.array([[-9e29] * 3, [9e29] * 3]), Camera((0, 0, 9.5e29), (0, 0, 0)))
    x, y, z = far.position
    assert y == pytest.approx(1e30) and x == pytest.approx(-0.5 / 0.8 * 1e30) and z == 9.5e29


def test_a_mesh_too_large_to_frame_renders_from_a_placed_camera(tmp_path):
    from clrt.scene.render_setup import render_camera, render_scene
    (tmp_path / "huge.obj").write_text("v 0 0 0\nv 9e29 0 0\nv 0 9e29 0\nf 1 2 3\n")
    scene = render_scene(str(tmp_path / "huge.obj"))
    assert scene.camera is None
    with pytest.raises(InputError, match="cannot frame the scene"):
        render_camera(scene)
    camera = render_camera(scene, eye=(3e29, 3e29, 2e29), target=(3e29, 3e29, 0))
    assert camera.eye == (3e29, 3e29, 2e29)


def test_the_default_light_of_a_file_without_lights_follows_the_camera(tmp_path):
    """A scene file without [[lights]] is lit as a mesh is: by the default light
    of the camera the image is rendered from (--eye, a turntable view of clrt
    batch render, a camera given to clrt.render), not of the file's camera."""
    import clrt
    from clrt.scene.render_setup import render_camera, render_lights, render_scene, turntable
    from clrt.scene.scene import default_light
    path = str(write(tmp_path, SPHERE))
    scene = render_scene(path)
    moved = render_camera(scene, width=32, height=24, eye=(0.0, 0.5, -4.0), target=(0.0, 0.0, 0.0))
    assert render_lights(scene.bounds, moved, scene.lights) == [default_light(scene.bounds, moved)]
    behind = turntable(render_camera(scene), 2, 4)
    assert render_lights(scene.bounds, behind, scene.lights) == [default_light(scene.bounds, behind)]
    # the API's one call lights it the same way: as rendered with that light set by hand
    by_hand = load_scene(path)
    by_hand.lights = [default_light(by_hand.bounds, moved)]
    assert np.array_equal(clrt.render(path, moved), clrt.render(by_hand, moved))
    # a file's own lights stay where the file puts them
    lit = render_scene(str(write(tmp_path, SPHERE + '[[lights]]\nposition = [0, 5, 5]\n', "lit.toml")))
    assert [light.position for light in render_lights(lit.bounds, moved, lit.lights)] == [(0, 5, 5)]


def test_a_gltf_file_whose_nodes_share_a_mesh_is_read_as_instances(tmp_path, device):
    """A mesh object naming a glTF file whose nodes place one mesh many times
    is the file's placements, as the renderer reads the file itself
    (clrt.scene.placed.gltf_scene): each glTF mesh one mesh, not flattened,
    placed by its nodes after the object's own transform; an [[instances]]
    table places them all again, in its material; the flattened scene is the
    file read flattened and moved.  A glTF file whose nodes each place their
    own mesh still reads as one mesh."""
    import trimesh
    import clrt
    from clrt.scene.mesh import Mesh
    from clrt.scene.placed import gltf_scene, scene_instances
    from test_instances import _hierarchy_glb
    glb = _hierarchy_glb(tmp_path / "balls.glb")
    path = write(tmp_path, """
        [[objects]]
        type = "mesh"
        name = "balls"
        path = "balls.glb"
        rotate = [0, 30, 0]
        translate = [0, 0, 5]

        [[objects]]
        type = "box"
        size = [30, 0.1, 30]
        translate = [0, -3, 0]

        [[instances]]
        object = "balls"
        translate = [20, 0, 0]
        material = { color = [0.2, 0.3, 0.8] }
    """)
    scene = load_scene(path)
    direct, placed = scene_instances(gltf_scene(glb)), scene_instances(scene)
    n = len(direct)
    own = transform_matrix((0, 0, 5), (0, 30, 0), (1, 1, 1))
    assert n > 20 and len(placed) == 2 * n + 1 and len(placed.meshes) == len(direct.meshes) + 1 == 4
    assert np.allclose(placed.transforms[:n], own @ direct.transforms)
    assert np.allclose(placed.transforms[n + 1:], transform_matrix((20, 0, 0), (0, 0, 0), (1, 1, 1)) @ own
                       @ direct.transforms)
    file_meshes = placed.mesh_of[:n]
    assert np.array_equal(placed.mesh_of[n + 1:], file_meshes)
    assert len(np.unique(file_meshes)) == 3 and np.array_equal(np.unique(file_meshes, return_inverse=True)[1],
                                                             np.unique(direct.mesh_of, return_inverse=True)[1])
    again = [o for o in scene.objects[-len(scene.objects) // 2:] if o.transforms is not None]
    assert all(o.material.color == (0.2, 0.3, 0.8) for o in again)
    flat = clrt.load_mesh(glb)
    mine = Mesh.concatenate([o.mesh for o in scene.flattened().objects[:n]])   # a flattened object a placement
    want = flat.vertices.astype(np.float64)[flat.faces] @ own[:3, :3].T + own[:3, 3]
    assert mine.faces.shape == flat.faces.shape
    np.testing.assert_allclose(mine.vertices[mine.faces], want, atol=1e-5)
    renderer = Renderer(path, device=device)
    assert len(renderer.instances) == 2 * n + 1
    assert int(renderer.geometry.num_tris) == sum(len(m.faces) for m in renderer.instances.meshes) \
        < 2 * len(flat.faces)
    frame = renderer.render(Camera((10, 8, 30), (10, 0, 3), width=48, height=36), hits=True)
    assert (frame.prim >= 0).mean() > 0.3
    single = tmp_path / "one.glb"
    trimesh.Scene([trimesh.creation.icosphere(subdivisions=1), trimesh.creation.box()]).export(single)
    lone = load_scene(write(tmp_path, '[[objects]]\ntype = "mesh"\npath = "one.glb"\n', "one.toml"))
    assert len(lone.objects) == 1 and not lone.instanced and lone.objects[0].transforms is None

"""trimesh objects keep their looks: ``Renderer(trimesh.load(path))`` renders
what ``Renderer(path)`` renders -- textures, materials, colours, node
transforms -- because what trimesh keeps goes through the file readers' own
mappings (clrt/scene/formats/trimesh_objects.py).

Every asset is written here, into tmp_path, with trimesh, numpy and Pillow;
the images are 32 x 24 pixels.
"""

import io

import numpy as np
import pytest
import trimesh
from PIL import Image

from clrt.errors import MeshLoadError
from clrt.renderer import Renderer
from clrt.scene.formats.gltf import pbr_from_gltf, whitted_from_pbr
from clrt.scene.formats.trimesh_objects import asset_of
from clrt.scene.load import load_asset, load_mesh
from clrt.scene.scene import Camera, scene_from_mesh
from clrt.scene.sources import as_mesh
from clrt.scene.texture import Texture

RNG = np.random.default_rng(34)
IMAGE = RNG.integers(0, 256, (6, 8, 3), dtype=np.uint8)
PBR = trimesh.visual.material.PBRMaterial
SIMPLE = trimesh.visual.material.SimpleMaterial


def _cube(material, uv_range=(-0.5, 1.5)) -> trimesh.Trimesh:
    """A unit cube, a vertex per face corner, with UVs running past 0..1 (wrapping shows)."""
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v = box.vertices[box.faces].reshape(-1, 3)
    uv = np.random.default_rng(3).uniform(*uv_range, (len(v), 2))
    return trimesh.Trimesh(v, np.arange(len(v)).reshape(-1, 3), process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material))


def _sphere_with_colours() -> trimesh.Trimesh:
    """An icosphere with vertex colours of middle values (sRGB and linear readings differ)."""
    sphere = trimesh.creation.icosphere(2)
    colours = np.zeros((len(sphere.vertices), 4), np.uint8)
    colours[:, 0] = np.where(sphere.vertices[:, 0] > 0, 230, 40)
    colours[:, 1] = 120
    colours[:, 2] = 255 - colours[:, 0]
    colours[:, 3] = 255
    return trimesh.Trimesh(sphere.vertices, sphere.faces, vertex_colors=colours, process=False)


def _renders(path, source, device):
    """Frames (image and prim) of ``Renderer(path)`` and ``Renderer(source)``, through one camera."""
    camera = Camera.framing(scene_from_mesh(path).bounds, 32, 24)
    return (Renderer(path, device=device).render(camera, linear=True, hits=True),
            Renderer(source, device=device).render(camera, linear=True, hits=True))


def _same_image(path, source, device, order=None):
    """``Renderer(source)`` renders ``Renderer(path)``'s image bit for bit; its
    triangle ids are the file's, or ``order(file's ids)`` (-1 kept for misses)."""
    by_path, by_object = _renders(path, source, device)
    assert np.array_equal(by_object.image, by_path.image), np.abs(by_object.image - by_path.image).max()
    expected = by_path.prim if order is None else np.where(by_path.prim < 0, -1, order(by_path.prim))
    assert np.array_equal(by_object.prim, expected)
    assert (by_path.prim >= 0).mean() > 0.1, "the object is in view"
    return by_path


def _without_texture(fields: dict) -> dict:
    return {k: v for k, v in fields.items() if k != "texture"}


# ---------------------------------------------------------------------------- renders


@pytest.mark.parametrize("force", ["mesh", None])
def test_textured_gltf_with_a_pbr_material(tmp_path, device, force):
    """baseColorFactor (multiples of 1/255: trimesh keeps 8 bits), the texture
    with its UVs past 0..1, metallic and roughness: a mirror share shows."""
    material = PBR(baseColorTexture=Image.fromarray(IMAGE), baseColorFactor=[255, 204, 153, 255],
                   metallicFactor=0.4, roughnessFactor=0.3)
    _cube(material).export(tmp_path / "cube.glb")
    loaded = trimesh.load(tmp_path / "cube.glb", force=force) if force else trimesh.load(tmp_path / "cube.glb")
    _same_image(tmp_path / "cube.glb", loaded, device)
    _, (fields,) = asset_of(loaded)
    assert fields["reflectivity"] > 0.2 and np.array_equal(fields["texture"].pixels, IMAGE)


@pytest.mark.parametrize("force", ["mesh", None])
def test_obj_mtl_png_with_a_simple_material(tmp_path, device, force):
    """Kd, Ks, Ns and the map_Kd image, as trimesh exports them, and the
    statements trimesh keeps aside (d, Ni, illum 3: a mirror share)."""
    material = SIMPLE(image=Image.fromarray(IMAGE), diffuse=[250, 200, 100, 255], specular=[60, 60, 60, 255],
                      glossiness=40.0)
    _cube(material).export(tmp_path / "cube.obj")
    mtl = tmp_path / "material.mtl"
    mtl.write_text(mtl.read_text() + "\nd 0.9\nNi 1.3\nillum 3\n")
    loaded = trimesh.load(tmp_path / "cube.obj", force=force) if force else trimesh.load(tmp_path / "cube.obj")
    _same_image(tmp_path / "cube.obj", loaded, device)
    _, (fields,) = asset_of(loaded)
    assert fields["transparency"] == pytest.approx(0.1) and fields["reflectivity"] > 0.2


@pytest.mark.parametrize("colours", ["vertex", "face"])
def test_coloured_ply(tmp_path, device, colours):
    """ColorVisuals, sRGB as the PLY reader takes them; trimesh.load merges
    the file's vertices (process=True), which leaves the triangles as they are
    (its joining, force="mesh", of a face-coloured mesh needs scipy, which clrt does not)."""
    sphere = _sphere_with_colours()
    if colours == "face":
        sphere = trimesh.Trimesh(sphere.vertices, sphere.faces, process=False,
                                 face_colors=sphere.visual.vertex_colors[sphere.faces[:, 0]])
    (tmp_path / "c.ply").write_bytes(sphere.export(file_type="ply", encoding="binary"))
    loaded = trimesh.load(tmp_path / "c.ply", **({"force": "mesh"} if colours == "vertex" else {}))
    assert loaded.visual.kind == colours
    by_path = _same_image(tmp_path / "c.ply", loaded, device)
    image = by_path.image[by_path.prim >= 0]
    assert (image[:, 0] > 2 * image[:, 2]).sum() > 10 and (image[:, 2] > 2 * image[:, 0]).sum() > 10


def test_two_node_gltf_scene(tmp_path, device):
    """A textured cube and a vertex-coloured sphere (glTF's COLOR_0 is linear:
    trimesh's glTF meshes say so in their metadata) on a mirroring node: each
    placed by its node, with its own looks.  trimesh's scene graph lists the
    file's two root nodes in reverse order, so the sphere's triangles come first."""
    cube = _cube(PBR(baseColorTexture=Image.fromarray(IMAGE), baseColorFactor=[255, 204, 153, 255],
                     metallicFactor=0.0, roughnessFactor=0.5))
    scene = trimesh.Scene()
    scene.add_geometry(cube, node_name="cube")
    mirror = trimesh.transformations.translation_matrix([1.8, 0.2, 0.0]) @ np.diag([-1.0, 1.0, 1.0, 1.0])
    scene.add_geometry(_sphere_with_colours(), node_name="sphere", transform=mirror)
    scene.export(tmp_path / "two.glb")
    loaded = trimesh.load(tmp_path / "two.glb")
    assert list(loaded.graph.nodes_geometry) == ["sphere", "cube"]
    n_cube, n_sphere = 12, len(_sphere_with_colours().faces)
    by_path = _same_image(tmp_path / "two.glb", loaded, device,
                          order=lambda prim: np.where(prim < n_cube, prim + n_sphere, prim - n_cube))
    assert len(np.unique(by_path.prim[by_path.prim >= n_cube])) > 20, "the sphere is in view"


def test_two_node_gltf_scene_joined_by_trimesh(tmp_path, device):
    """One textured mesh on two nodes, one mirroring: trimesh.load(force="mesh")
    joins them (the shared material kept), placing the vertices itself, so the
    corners may differ from clrt's placement by float rounding: the image
    within 1e-5, the triangle ids (reversed node order) where the hits are."""
    cube = _cube(PBR(baseColorTexture=Image.fromarray(IMAGE), metallicFactor=0.3, roughnessFactor=0.4))
    scene = trimesh.Scene()
    scene.add_geometry(cube, node_name="a", geom_name="cube")
    mirror = trimesh.transformations.translation_matrix([2.5, 0.0, 0.0]) @ np.diag([-1.0, 1.0, 1.0, 1.0])
    scene.add_geometry(cube, node_name="b", geom_name="cube", transform=mirror)
    scene.export(tmp_path / "inst.glb")
    order = lambda prim: (prim + 12) % 24   # noqa: E731
    _same_image(tmp_path / "inst.glb", trimesh.load(tmp_path / "inst.glb"), device, order=order)
    by_path, joined = _renders(tmp_path / "inst.glb", trimesh.load(tmp_path / "inst.glb", force="mesh"), device)
    np.testing.assert_allclose(joined.image, by_path.image, atol=1e-5)
    expected = np.where(by_path.prim < 0, -1, order(by_path.prim))
    assert (joined.prim == expected).mean() >= 0.99


# ---------------------------------------------------------------------------- the mappings


@pytest.mark.parametrize("values", [
    {},
    {"baseColorFactor": [51, 102, 255, 255], "metallicFactor": 0.0, "roughnessFactor": 0.5},
    {"baseColorFactor": [255, 0, 0, 128], "metallicFactor": 1.0, "roughnessFactor": 0.0},
    {"metallicFactor": 0.7, "roughnessFactor": 0.2},
    {"roughnessFactor": 0.9},
])
def test_pbr_material_is_mapped_as_the_gltf_reader_maps_it(tmp_path, values):
    """trimesh's PBRMaterial (None: glTF's default) against the glTF reader's
    fields for the file trimesh writes of it, and against whitted_from_pbr and pbr_from_gltf."""
    cube = _cube(PBR(baseColorTexture=Image.fromarray(IMAGE), **values))
    cube.export(tmp_path / "m.glb")
    _, (by_path,) = load_asset(tmp_path / "m.glb")
    for source in (cube, trimesh.load(tmp_path / "m.glb")):
        _, (fields,) = asset_of(source)
        assert _without_texture(fields) == _without_texture(by_path)
        assert np.array_equal(fields["texture"].pixels, by_path["texture"].pixels)
        assert (fields["texture"].wrap_s, fields["texture"].wrap_t) == ("repeat", "repeat")
    pbr = {k: (np.asarray(v) / 255).tolist() if k == "baseColorFactor" else v for k, v in values.items()}
    assert _without_texture(fields) == {**whitted_from_pbr(pbr), **pbr_from_gltf({"pbrMetallicRoughness": pbr}, "")}


@pytest.mark.parametrize("mtl", [
    "Kd 0.5 0.25 0.1\nKs 0.3 0.2 0.1\nNs 50\nd 0.6\nNi 1.4\nillum 3",
    "Ks 0.5 0.5 0.5",                       # no Kd, no Ns: clrt's defaults, not trimesh's grey
    "Kd 0.123456 0.654321 1\nTr 0.25",      # not multiples of 1/255: the file's numbers
    "Ka 0.2 0.2 0.2\nKd 1 1 1\nillum 2",
])
def test_simple_material_is_mapped_as_the_mtl_reader_maps_it(tmp_path, mtl):
    (tmp_path / "m.mtl").write_text(f"newmtl look\n{mtl}\nmap_Kd t.png\n")
    Image.fromarray(IMAGE).save(tmp_path / "t.png")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                    "usemtl look\nf 1/1 2/2 3/3\n")
    _, (by_path,) = load_asset(tmp_path / "m.obj")
    _, (fields,) = asset_of(trimesh.load(tmp_path / "m.obj"))
    assert _without_texture(fields) == _without_texture(by_path)
    assert np.array_equal(fields["texture"].pixels, IMAGE)


def test_simple_material_made_in_python_is_mapped_as_its_obj_export(tmp_path):
    """diffuse, specular and glossiness as trimesh's OBJ export writes them
    (Kd, Ks, Ns), and as the MTL reader reads that file; ambient is not used (Ka is not)."""
    material = SIMPLE(image=Image.fromarray(IMAGE), diffuse=[10, 200, 30, 255], ambient=[255, 0, 0, 255],
                      specular=[90, 90, 90, 255], glossiness=12.5)
    cube = _cube(material)
    cube.export(tmp_path / "cube.obj")
    _, (by_path,) = load_asset(tmp_path / "cube.obj")
    _, (fields,) = asset_of(cube)
    assert fields.keys() == by_path.keys()
    for key in fields.keys() - {"texture"}:
        assert fields[key] == pytest.approx(by_path[key], rel=1e-7), key   # the MTL has 8 decimals


def test_uvs_without_a_material_and_multimaterials():
    """UVs alone (trimesh's placeholder material) are no material, as a PLY
    with UVs by path; a MultiMaterial gives each face its own."""
    box = trimesh.creation.box()
    plain = trimesh.Trimesh(box.vertices, box.faces, process=False,
                            visual=trimesh.visual.TextureVisuals(uv=box.vertices[:, :2]))
    mesh, materials = asset_of(plain)
    assert mesh.uv is not None and mesh.face_material is None and materials == []
    multi = trimesh.visual.material.MultiMaterial([PBR(baseColorFactor=[255, 0, 0, 255]),
                                                   SIMPLE(diffuse=[0, 0, 255, 255])])
    visual = trimesh.visual.TextureVisuals(uv=box.vertices[:, :2], material=multi, face_materials=[0, 1] * 6)
    mesh, materials = asset_of(trimesh.Trimesh(box.vertices, box.faces, visual=visual, process=False))
    assert mesh.face_material.tolist() == [0, 1] * 6
    assert [m["color"] for m in materials] == [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)]


@pytest.mark.parametrize("mode", ["RGB", "RGBA", "L", "LA", "P", "I;16"])
def test_images_of_every_mode_become_textures_as_files_do(tmp_path, mode):
    grey = RNG.integers(0, 256, (5, 7), dtype=np.uint8)
    image = {"RGB": Image.fromarray(IMAGE), "RGBA": Image.fromarray(IMAGE).convert("RGBA"),
             "L": Image.fromarray(grey), "LA": Image.fromarray(grey).convert("LA"),
             "P": Image.fromarray(IMAGE).convert("P"),
             "I;16": Image.fromarray(grey.astype(np.uint16) * 257 + 100)}[mode]
    assert image.mode == mode
    image.save(tmp_path / "t.png")
    _, (fields,) = asset_of(_cube(SIMPLE(image=image)))
    assert np.array_equal(fields["texture"].pixels, Texture.read(tmp_path / "t.png").pixels)


def test_a_trimesh_scene_is_a_mesh_placed_by_its_nodes(tmp_path):
    """as_mesh (Accel, the ray queries) takes a trimesh.Scene: the file's
    triangles, in the scene graph's node order."""
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(), node_name="a")
    scene.add_geometry(trimesh.creation.icosphere(1), node_name="b",
                       transform=trimesh.transformations.rotation_matrix(0.5, [0, 1, 0]) @ np.diag([2, 2, -2, 1.0]))
    scene.export(tmp_path / "s.glb")
    by_path = load_mesh(tmp_path / "s.glb")
    mesh = as_mesh(trimesh.load(tmp_path / "s.glb"))
    np.testing.assert_allclose(mesh.vertices[mesh.faces][:80], by_path.vertices[by_path.faces][12:], atol=1e-6)
    np.testing.assert_allclose(mesh.vertices[mesh.faces][80:], by_path.vertices[by_path.faces][:12], atol=1e-6)


# ---------------------------------------------------------------------------- bad objects


def _broken(name):
    box = trimesh.creation.box()
    png = io.BytesIO()
    Image.fromarray(IMAGE).save(png, format="PNG")
    uv, material = np.zeros((8, 2)), PBR(baseColorFactor=[255, 0, 0, 255])
    if name == "nan uv":
        uv = np.full((8, 2), np.nan)
    elif name == "truncated image":
        material = PBR(baseColorTexture=Image.open(io.BytesIO(png.getvalue()[:70])))
    elif name == "not an image":
        material = PBR(baseColorTexture="texture.png")
    elif name == "face materials":
        material = trimesh.visual.material.MultiMaterial([material])
        return trimesh.Trimesh(box.vertices, box.faces, process=False, visual=trimesh.visual.TextureVisuals(
            uv=uv, material=material, face_materials=[0, 1]))
    elif name == "nan factor":
        material.metallicFactor = float("nan")
    elif name == "bad mtl number":
        material = SIMPLE(diffuse=[1, 1, 1], d=["half"])
    return trimesh.Trimesh(box.vertices, box.faces, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material))


@pytest.mark.parametrize("name, says", [
    ("nan uv", "uv contain NaN"),
    ("truncated image", "cannot read its texture image"),
    ("not an image", "must be a PIL image, got str"),
    ("face materials", "face_materials must be 12 integers"),
    ("nan factor", "metallicFactor must be a finite number"),
    ("bad mtl number", "d must be a finite number, got"),
])
def test_a_broken_trimesh_object_gets_a_one_line_error(name, says):
    with pytest.raises(MeshLoadError) as caught:
        scene_from_mesh(_broken(name))
    message = str(caught.value)
    assert message.startswith("trimesh.Trimesh") and says in message and "\n" not in message, message

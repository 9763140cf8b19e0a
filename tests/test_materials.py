"""Materials of the path tracer (issue #35): the PBR fields of clrt.Material, the
MATERIAL rows the host fills, the Phong -> PBR mapping, and bad values."""

import math

import numpy as np
import pytest

from clrt import config
from clrt.errors import InputError
from clrt.layouts import MATERIAL
from clrt.scene import primitives
from clrt.scene.arrays import flatten_scene
from clrt.scene.scene import Material, Scene, SceneObject
from clrt.scene.texture import Texture
from glb import edit_glb_file


def _texture(seed: int) -> Texture:
    return Texture(np.random.default_rng(seed).integers(0, 256, (2, 3, 3), dtype=np.uint8))


def _rows(*materials, uv=True, pbr_textures=True):
    mesh = primitives.icosphere(1, 1.0)
    if uv:
        mesh = mesh.with_detail(uv=np.zeros((len(mesh.faces), 3, 2)))
    scene = Scene([SceneObject(mesh, m, ()) for m in materials], [(0.0, 5.0, 0.0)])
    return flatten_scene(scene, pbr_textures)


def _lane(rows, field):
    """The int32 bits of a float4 field's w lane, per row."""
    return rows[field].view(np.int32).reshape(len(rows), 4)[:, 3]


def test_material_row_is_112_bytes_with_the_whitted_part_first():
    assert MATERIAL.itemsize == 112
    offsets = {name: MATERIAL.fields[name][1] for name in MATERIAL.names}
    assert offsets == {"color": 0, "ambient": 16, "diffuse": 20, "specular": 24, "shininess": 28, "flags": 32,
                       "reflectivity": 36, "transparency": 40, "ior": 44, "emission": 48, "metallic": 64,
                       "roughness": 68, "specular_weight": 72, "transmission": 76, "specular_color": 80,
                       "normal_texture": 96, "normal_scale": 100, "pad": 104}


def test_phong_materials_map_to_pbr_as_documented():
    m = Material(color=(0.5, 0.25, 1.0), specular=0.3, shininess=32.0, reflectivity=0.2, transparency=0.6)
    pbr = m.pbr_values()
    assert pbr.metallic == 0.2 and pbr.transmission == 0.6 and pbr.specular_weight == 0.3
    # the GGX roughness whose highlight is as wide as Phong's exponent, sharpened by the mirror/refraction share
    assert math.isclose(pbr.roughness, 65.0 ** -0.25 * 0.4, rel_tol=1e-12)
    # the inverse of the glTF reader's roughness -> shininess mapping
    from clrt.scene.formats.gltf import whitted_from_pbr
    for r in (0.2, 0.5, 0.7):   # (rougher ones meet the reader's floor, shininess 1)
        n = whitted_from_pbr({"roughnessFactor": r, "metallicFactor": 0.0})["shininess"]
        assert math.isclose(Material(shininess=n).pbr_values().roughness, r, rel_tol=1e-9)
    assert Material(specular=0.0).pbr_values().specular_weight == 0.0    # no highlight: pure Lambert
    assert Material(specular=7.0).pbr_values().specular_weight == 1.0
    assert Material(shininess=0.0).pbr_values().roughness == 1.0
    # a value given is kept, the others still come from Phong
    given = Material(reflectivity=0.5, metallic=0.0, roughness=0.7).pbr_values()
    assert (given.metallic, given.roughness, given.transmission) == (0.0, 0.7, 0.0)


def test_the_host_fills_every_pbr_field_and_shares_texture_rows():
    base, mr, normal, glow = (_texture(k) for k in range(4))
    phong = Material(color=(0.2, 0.4, 0.6), specular=0.5, shininess=10.0, reflectivity=0.25, smooth=False)
    pbr = Material(color=(1.0, 0.5, 0.0), texture=base, emission=(3.0, 2.0, 0.5), emission_texture=glow,
                   double_sided=True, metallic=0.75, roughness=0.125, metallic_roughness_texture=mr,
                   specular_weight=0.5, specular_color=(2.0, 1.0, 0.5), transmission=0.25, ior=1.33,
                   normal_texture=normal, normal_scale=-0.5)
    shares = Material(texture=base, normal_texture=base, metallic=1.0)   # one Texture, two fields
    a = _rows(phong, pbr, shares)
    rows = a.materials
    assert rows.dtype == MATERIAL and len(rows) == 3
    # the Phong material: its own Phong fields, the mapping's PBR ones, no textures
    p = phong.pbr_values()
    assert rows[0]["flags"] == 0
    np.testing.assert_array_equal(rows[0]["color"][:3], np.float32(phong.color))
    assert [rows[0][k] for k in ("metallic", "roughness", "specular_weight", "transmission")] == [
        np.float32(v) for v in (p.metallic, p.roughness, p.specular_weight, p.transmission)]
    np.testing.assert_array_equal(rows[0]["emission"][:3], 0.0)
    np.testing.assert_array_equal(rows[0]["specular_color"][:3], 1.0)
    assert rows[0]["normal_scale"] == 1.0
    # the PBR material as given
    assert rows[1]["flags"] == config.MATERIAL_SMOOTH | config.MATERIAL_DOUBLE_SIDED
    np.testing.assert_array_equal(rows[1]["emission"][:3], np.float32([3.0, 2.0, 0.5]))
    np.testing.assert_array_equal(rows[1]["specular_color"][:3], np.float32([2.0, 1.0, 0.5]))
    assert [rows[1][k] for k in ("metallic", "roughness", "specular_weight", "transmission", "ior",
                                 "normal_scale")] == [np.float32(v) for v in (0.75, 0.125, 0.5, 0.25, 1.33, -0.5)]
    # texture rows: one per Texture and decoding, in order of first use, whichever
    # materials refer to it; colours (base, emission) sRGB, data (metallicRoughness, normal) linear
    textures = a.detail.textures
    assert list(_lane(rows, "color")) == [-1, 0, 0]
    assert list(_lane(rows, "emission")) == [-1, 1, -1]
    assert list(_lane(rows, "specular_color")) == [-1, 2, -1]
    assert list(rows["normal_texture"]) == [-1, 3, 4]
    assert list(textures["linear"]) == [0, 0, 1, 1, 1]
    # the texels of each image once: `base` read as colour (row 0) and as data (row 4) shares them
    assert len(a.detail.texels) == 4 * 6
    assert textures["first"][4] == textures["first"][0] == 0
    for row, tex in enumerate((base, glow, mr, normal)):
        first = textures["first"][row]
        np.testing.assert_array_equal(a.detail.texels[first:first + 6, :3], tex.pixels.reshape(-1, 3))
    assert (rows["pad"] == 0).all()
    # for the Whitted renderer only base colour textures, so that a scene with none keeps the plain program
    whitted = _rows(phong, pbr, shares, pbr_textures=False)
    assert list(_lane(whitted.materials, "color")) == [-1, 0, 0] and len(whitted.detail.textures) == 1
    assert (_lane(whitted.materials, "emission") == -1).all() and (whitted.materials["normal_texture"] == -1).all()
    assert (_lane(whitted.materials, "specular_color") == -1).all()
    assert _rows(Material(normal_texture=normal), pbr_textures=False).detail is None
    # without texture coordinates no texture applies
    plain = _rows(pbr, uv=False).materials
    assert list(_lane(plain, "color")) + list(_lane(plain, "emission")) + list(_lane(plain, "specular_color")) \
        + list(plain["normal_texture"]) == [-1] * 4


@pytest.mark.parametrize("fields, words", [
    ({"emission": (1.0, -0.5, 0.0)}, "material emission"),
    ({"emission": (1.0, float("nan"), 0.0)}, "material emission must be 3 finite numbers"),
    ({"emission": (1.0, float("inf"), 0.0)}, "material emission must be 3 finite numbers"),
    ({"metallic": 1.5}, "material metallic"),
    ({"roughness": -0.1}, "material roughness"),
    ({"roughness": float("nan")}, "material roughness"),
    ({"specular_weight": 2.0}, "material specular_weight"),
    ({"transmission": 1.01}, "material transmission"),
    ({"specular_color": (0.5, -1.0, 0.5)}, "material specular_color"),
    ({"normal_scale": float("inf")}, "material normal_scale"),
    ({"double_sided": 1}, "material double_sided"),
    ({"normal_texture": "bumps.png"}, "material normal_texture"),
])
def test_bad_pbr_values_are_one_line_errors(fields, words):
    with pytest.raises(InputError) as info:
        Material(**fields)
    assert words in str(info.value) and "\n" not in str(info.value)


def _quad_obj(tmp_path, mtl: str, materials=("a", "b")) -> "tuple":
    """A two-triangle OBJ with texture coordinates, one triangle per material, and its MTL text."""
    lines = ["mtllib m.mtl", "v 0 0 0", "v 1 0 0", "v 1 1 0", "v 0 1 0", "vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1"]
    lines += [f"usemtl {materials[0]}", "f 1/1 2/2 3/3", f"usemtl {materials[1]}", "f 1/1 3/3 4/4"]
    (tmp_path / "quad.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "m.mtl").write_text(mtl)
    from clrt.scene.load import load_asset
    return load_asset(tmp_path / "quad.obj")


def test_an_image_that_several_mtl_materials_name_is_one_texture(tmp_path):
    from PIL import Image
    Image.fromarray(np.random.default_rng(5).integers(0, 256, (4, 4, 3), dtype=np.uint8)).save(tmp_path / "t.png")
    _, materials = _quad_obj(tmp_path, "newmtl a\nmap_Kd t.png\nnewmtl b\nKd 1 0 0\nmap_Kd ./t.png\n")
    assert materials[0]["texture"] is materials[1]["texture"]


# ---------------------------------------------------------------------------- glTF


def _image(seed: int, size=(4, 4)):
    from PIL import Image
    return Image.fromarray(np.random.default_rng(seed).integers(0, 256, (*size, 3), dtype=np.uint8))


def _pbr_glb(tmp_path, **material):
    """A textured quad exported by trimesh as GLB with a PBRMaterial of ``material``."""
    import trimesh
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    pbr = trimesh.visual.material.PBRMaterial(name="look", **material)
    quad = trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], visual=trimesh.visual.TextureVisuals(uv=uv, material=pbr),
                           process=False)
    path = tmp_path / "quad.glb"
    quad.export(path)
    return path


def test_gltf_metallic_roughness_materials_are_read_whole(tmp_path):
    """Every PBR field and texture of a glTF material, from a file trimesh writes
    (factors, emissive, doubleSided, four textures) and extensions added to it."""
    from clrt.scene.load import load_asset
    images = {key: _image(k) for k, key in enumerate(("baseColorTexture", "metallicRoughnessTexture",
                                                      "normalTexture", "emissiveTexture"))}
    path = _pbr_glb(tmp_path, baseColorFactor=[1.0, 0.5, 0.25, 1.0], metallicFactor=0.75, roughnessFactor=0.375,
                    emissiveFactor=[0.5, 0.25, 1.0], doubleSided=True, **images)

    def extend(doc):
        m = doc["materials"][0]
        m["normalTexture"]["scale"] = 0.625
        m["pbrMetallicRoughness"]["baseColorFactor"] = [1.0, 0.5, 0.25, 1.0]   # (trimesh wrote 8 bits of it)
        m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": 8.0},
                           "KHR_materials_specular": {"specularFactor": 0.5, "specularColorFactor": [1.5, 1.0, 0.25]},
                           "KHR_materials_transmission": {"transmissionFactor": 0.875},
                           "KHR_materials_ior": {"ior": 1.25}}
    edit_glb_file(path, extend)
    mesh, (fields,) = load_asset(path)
    material = Material(**fields)
    assert material.color == (1.0, 0.5, 0.25)
    assert (material.metallic, material.roughness) == (0.75, 0.375)
    assert material.emission == (4.0, 2.0, 8.0)          # emissiveFactor x emissiveStrength, linear
    assert material.double_sided is True
    assert (material.specular_weight, material.specular_color) == (0.5, (1.5, 1.0, 0.25))
    assert (material.transmission, material.ior, material.normal_scale) == (0.875, 1.25, 0.625)
    for field, key in (("texture", "baseColorTexture"), ("metallic_roughness_texture", "metallicRoughnessTexture"),
                       ("normal_texture", "normalTexture"), ("emission_texture", "emissiveTexture")):
        assert np.array_equal(getattr(material, field).pixels, np.asarray(images[key])), field
    # Whitted keeps its own mapping of the same factors (gltf.whitted_from_pbr)
    assert material.transparency == 0.875 and material.reflectivity == 0.75 * (1 - 0.375)
    # on the device: colours sRGB, data linear, in the rows of the contract
    rows = flatten_scene(Scene([SceneObject(mesh, Material(), [material])], [(0.0, 0.0, 5.0)]), pbr_textures=True)
    table, row = rows.detail.textures, rows.materials[1]
    assert [table["linear"][_lane(rows.materials, f)[1]] for f in ("color", "emission", "specular_color")] == [0, 0, 1]
    assert table["linear"][row["normal_texture"]] == 1
    assert row["flags"] & config.MATERIAL_DOUBLE_SIDED


def test_gltf_defaults_and_shared_textures(tmp_path):
    """A glTF material without PBR keys has glTF's defaults (metal, rough, no emission,
    one-sided), not the Phong mapping; an image two materials use is one Texture."""
    from clrt.scene.load import load_asset
    path = _pbr_glb(tmp_path, baseColorTexture=_image(1))

    def second_material(doc):
        doc["materials"].append({"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
                                 "emissiveTexture": {"index": 0}})
        doc["meshes"][0]["primitives"][0]["material"] = 1
        doc["materials"][0]["pbrMetallicRoughness"] = {"baseColorTexture": {"index": 0}}
    edit_glb_file(path, second_material)
    _, (first, second) = load_asset(path)
    assert first["texture"] is second["texture"] is second["emission_texture"]
    m = Material(**first)
    assert (m.metallic, m.roughness, m.specular_weight, m.specular_color, m.transmission) == (
        1.0, 1.0, 1.0, (1.0, 1.0, 1.0), 0.0)
    assert (m.emission, m.double_sided, m.normal_scale) == ((0.0, 0.0, 0.0), False, 1.0)
    assert m.pbr_values() == Material(**first).pbr_values() and m.pbr_values().metallic == 1.0


@pytest.mark.parametrize("edit, words", [
    (lambda m: m.update(emissiveFactor=[1.0, -0.5, 0.0]), "emissiveFactor must be 3 numbers >= 0"),
    (lambda m: m.update(emissiveFactor=[1.0, float("nan"), 0.0]), "emissiveFactor must be 3 finite numbers"),
    (lambda m: m.update(extensions={"KHR_materials_emissive_strength": {"emissiveStrength": -2}}),
     "emissiveStrength must be a number in 0..1e30, got -2"),
    (lambda m: m["pbrMetallicRoughness"].update(metallicFactor=2.0), "metallicFactor must be a number in 0..1, got 2"),
    (lambda m: m["pbrMetallicRoughness"].update(roughnessFactor=float("nan")), "roughnessFactor"),
    (lambda m: m.update(extensions={"KHR_materials_specular": {"specularFactor": -1}}), "specularFactor"),
    (lambda m: m.update(extensions={"KHR_materials_specular": {"specularColorFactor": [1, 1]}}),
     "specularColorFactor must be 3 numbers"),
    (lambda m: m.update(extensions={"KHR_materials_transmission": {"transmissionFactor": 1.5}}),
     "transmissionFactor"),
    (lambda m: m.update(doubleSided="yes"), "doubleSided must be true or false"),
])
def test_bad_gltf_pbr_values_are_one_line_errors_naming_file_and_material(tmp_path, edit, words):
    from clrt.errors import MeshLoadError
    from clrt.scene.load import load_asset
    path = _pbr_glb(tmp_path, metallicFactor=0.5)
    edit_glb_file(path, lambda doc: edit(doc["materials"][0]))
    with pytest.raises(MeshLoadError) as info:
        load_asset(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and "materials[0] 'look'" in message
    assert words in message, message


def test_the_cli_refuses_a_negative_emission_with_exit_2_and_no_file(tmp_path, device, capsys):
    from clrt.cli import main
    path = _pbr_glb(tmp_path, emissiveFactor=[1.0, 1.0, 1.0])
    edit_glb_file(path, lambda doc: doc["materials"][0].update(emissiveFactor=[1.0, -1.0, 1.0]))
    out = tmp_path / "out.png"
    code = main(["render", str(path), "-o", str(out), "--width", "8", "--height", "8",
                 *(["--device", device] if device else [])])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "emissiveFactor" in err
    assert not out.exists()


# ---------------------------------------------------------------------------- OBJ/MTL


def _save(tmp_path, name, pixels):
    from PIL import Image
    Image.fromarray(np.asarray(pixels, np.uint8)).save(tmp_path / name)
    return np.asarray(pixels, np.uint8)


def test_mtl_pbr_statements_are_read(tmp_path):
    rng = np.random.default_rng(8)
    rough = _save(tmp_path, "rough.png", np.repeat(rng.integers(0, 256, (4, 4, 1)), 3, axis=2))
    metal = _save(tmp_path, "metal.png", np.repeat(rng.integers(0, 256, (2, 2, 1)), 3, axis=2))
    glow = _save(tmp_path, "glow.png", rng.integers(0, 256, (3, 5, 3)))
    normal = _save(tmp_path, "normal.png", rng.integers(0, 256, (4, 4, 3)))
    _save(tmp_path, "height.png", np.repeat(rng.integers(0, 256, (4, 4, 1)), 3, axis=2))
    rma = _save(tmp_path, "rma.png", rng.integers(0, 256, (2, 3, 3)))
    _, (a, b) = _quad_obj(tmp_path, "\n".join([
        "newmtl a", "Kd 0.5 0.5 0.5", "Pr 0.25", "Pm 0.75", "Ke 2 1 0.5", "map_Ke glow.png",
        "map_Pr rough.png", "map_Pm metal.png", "map_Bump -bm 0.5 normal.png", "Tf 0.5 0.5 0.8", "Ni 1.4", "d 0.9",
        "newmtl b", "map_RMA rma.png", "map_Ke glow.png", "bump height.png", "Tf 1 1 1", "d 0.75", ""]))
    a, b = Material(**a), Material(**b)
    assert (a.roughness, a.metallic, a.emission, a.normal_scale, a.ior) == (0.25, 0.75, (2.0, 1.0, 0.5), 0.5, 1.4)
    assert a.transmission == pytest.approx(0.6)      # Tf in a PBR material: the transmission weight
    assert a.transparency == pytest.approx(0.1)      # (Whitted still reads d)
    assert np.array_equal(a.emission_texture.pixels, glow) and np.array_equal(a.normal_texture.pixels, normal)
    mr = a.metallic_roughness_texture.pixels         # G roughness, B metallic (nearest texel of the 2x2 map)
    assert np.array_equal(mr[:, :, 1], rough[:, :, 0]) and (mr[:, :, 0] == 0).all()
    assert np.array_equal(mr[:, :, 2], np.repeat(np.repeat(metal[:, :, 0], 2, axis=0), 2, axis=1))
    # map_RMA: R roughness, G metallic; factors 1 (the map alone); map_Ke alone: emission 1; a grey bump map
    # is a height map, not a normal map; a PBR material's Tf is its transmission (d is Whitted's)
    assert (b.roughness, b.metallic, b.emission, b.normal_texture) == (1.0, 1.0, (1.0, 1.0, 1.0), None)
    assert np.array_equal(b.metallic_roughness_texture.pixels[:, :, 1:], rma[:, :, :2])
    assert b.emission_texture is a.emission_texture  # one image, one texture
    assert (b.transmission, b.transparency) == (1.0, 0.25)


def test_mtl_without_pbr_statements_takes_the_phong_mapping(tmp_path):
    _, (a, b) = _quad_obj(tmp_path, "newmtl a\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 20\nillum 3\n"
                                    "newmtl b\nTf 1 1 1\nd 0.75\n")
    a = Material(**a)
    assert (a.metallic, a.roughness, a.specular_weight, a.transmission) == (None,) * 4
    assert a.pbr_values() == Material(color=(1, 0, 0), specular=0.5, shininess=20.0, reflectivity=0.5).pbr_values()
    # Tf in a classic material is a filter colour, not read: transmission = 1 - d, as Whitted's transparency
    assert Material(**b).transmission is None and Material(**b).pbr_values().transmission == 0.25


@pytest.mark.parametrize("statement, words", [
    ("Pr 1.5", "material 'a': Pr must be a number in 0..1, got 1.5"),
    ("Pm -0.5", "material 'a': Pm must be a number in 0..1"),
    ("Ke 1 -1 1", "material 'a': Ke must be 3 numbers >= 0"),
    ("Ke 1 nan 1", "material 'a': Ke must be 3 finite numbers"),
    ("Pr 0.5\nTf 2 2 2", "material 'a': Tf must be 3 numbers in 0..1"),
    ("Pr x", "malformed Pr line"),
])
def test_bad_mtl_pbr_values_are_one_line_errors(tmp_path, statement, words):
    from clrt.errors import MeshLoadError
    with pytest.raises(MeshLoadError) as info:
        _quad_obj(tmp_path, f"newmtl a\n{statement}\nnewmtl b\n")
    message = str(info.value)
    assert "\n" not in message and "quad.obj" in message and words in message, message


# ---------------------------------------------------------------------------- TOML


def test_toml_materials_take_pbr_keys_and_texture_files(tmp_path):
    from clrt.scene.scene_file import load_scene
    rng = np.random.default_rng(9)
    images = {name: _save(tmp_path, f"{name}.png", rng.integers(0, 256, (2, 2, 3)))
              for name in ("base", "mr", "normal", "glow")}
    _quad_obj(tmp_path, "newmtl a\nnewmtl b\n")
    (tmp_path / "scene.toml").write_text("""
[materials.lamp]
emission = [4, 3, 2]
emission_texture = "glow.png"
double_sided = true
[materials.gold]
color = [1, 0.8, 0.3]
texture = "base.png"
metallic = 1
roughness = 0.3
metallic_roughness_texture = "mr.png"
normal_texture = "normal.png"
normal_scale = 0.5
specular_weight = 0.5
specular_color = [1, 0.5, 2]
transmission = 0.25
[[objects]]
type = "mesh"
path = "quad.obj"
material = "gold"
[[objects]]
type = "mesh"
path = "quad.obj"
material = "lamp"
[[objects]]
type = "sphere"
material = { emission = [1, 1, 1], texture = "./base.png" }
""")
    scene = load_scene(tmp_path / "scene.toml")
    gold, lamp, ball = (o.material for o in scene.objects)
    assert (gold.metallic, gold.roughness, gold.normal_scale, gold.specular_weight, gold.transmission) == (
        1.0, 0.3, 0.5, 0.5, 0.25)
    assert gold.specular_color == (1.0, 0.5, 2.0) and gold.emission == (0.0, 0.0, 0.0) and not gold.double_sided
    for field, name in (("texture", "base"), ("metallic_roughness_texture", "mr"), ("normal_texture", "normal")):
        assert np.array_equal(getattr(gold, field).pixels, images[name])
    assert lamp.emission == (4.0, 3.0, 2.0) and lamp.double_sided
    assert np.array_equal(lamp.emission_texture.pixels, images["glow"])
    assert ball.texture is gold.texture                   # one image file, one texture
    # a material without PBR keys: the Phong mapping
    assert (lamp.metallic, lamp.roughness) == (None, None) and lamp.pbr_values().metallic == 0.0


@pytest.mark.parametrize("key, words", [
    ("emission = [1, -1, 0]", "materials.m.emission must be 3 numbers >= 0"),
    ("emission = [1, nan, 0]", "materials.m.emission must be 3 finite numbers"),
    ("metallic = 2", "materials.m.metallic must be a number in 0..1"),
    ("roughness = -1", "materials.m.roughness"),
    ("transmission = 1.5", "materials.m.transmission"),
    ("specular_color = [1, 1]", "materials.m.specular_color must be 3 numbers"),
    ("double_sided = 1", "materials.m.double_sided must be true or false"),
    ("normal_texture = 'missing.png'", "no such texture file"),
    ("texture = 3", "materials.m.texture must be a string"),
])
def test_bad_toml_pbr_keys_are_one_line_errors(tmp_path, key, words):
    from clrt.scene.scene_file import load_scene
    (tmp_path / "scene.toml").write_text(f"[materials.m]\n{key}\n[[objects]]\ntype = 'sphere'\nmaterial = 'm'\n")
    with pytest.raises(InputError) as info:
        load_scene(tmp_path / "scene.toml")
    message = str(info.value)
    assert "\n" not in message and "scene.toml" in message and words in message, message


# ---------------------------------------------------------------------------- closed meshes


def _brute_force_closed(mesh, faces) -> bool:
    """Every undirected edge (welded by position) met once each way, counted in Python."""
    count = {}
    for f in faces:
        p = [tuple(mesh.vertices[v]) for v in mesh.faces[f]]
        for i in range(3):
            a, b = p[i], p[(i + 1) % 3]
            if a != b:
                count[(a, b)] = count.get((a, b), 0) + 1
    return all(count.get((b, a), 0) == n for (a, b), n in count.items())


def test_transmitting_materials_need_closed_meshes():
    from clrt.scene.closed import check_closed_transmission
    from clrt.scene.mesh import Mesh
    sphere = primitives.icosphere(2, 1.0)
    glass = Material(transparency=0.9)
    light = [(0.0, 5.0, 0.0)]
    # closed (crease-split and welded back by position): fine, transmission from Phong or PBR alike
    for material in (glass, Material(transmission=0.5), Material(transmission=0.5, smooth=False)):
        check_closed_transmission(Scene([SceneObject(sphere, material)], light))
    open_cap = Mesh.from_arrays(sphere.vertices, sphere.faces[1:], "cup")
    assert not _brute_force_closed(open_cap, range(len(open_cap.faces)))
    check_closed_transmission(Scene([SceneObject(open_cap, Material())], light))   # opaque: no need
    with pytest.raises(InputError) as info:
        check_closed_transmission(Scene([SceneObject(open_cap, glass)], light, source="cup.toml"))
    message = str(info.value)
    assert message.startswith("cup.toml: object 'cup' (its material, transmission 0.9): ") and "\n" not in message
    assert "3 edges are open" in message
    # a face turned the other way: closed, but not one inside
    flipped = sphere.faces.copy()
    flipped[7] = flipped[7][[0, 2, 1]]
    turned = Mesh.from_arrays(sphere.vertices, flipped, "turned")
    assert not _brute_force_closed(turned, range(len(flipped)))
    with pytest.raises(InputError, match="3 edges join faces that face opposite ways"):
        check_closed_transmission(Scene([SceneObject(turned, Material(transmission=1.0, smooth=False))], light))
    # only the transmitting faces must close: a file's opaque part may be open
    ids = np.zeros(len(sphere.faces), np.int64)
    ids[0] = 1
    parts = sphere.with_detail(face_material=ids)
    check_closed_transmission(Scene([SceneObject(parts, Material(), [Material(), Material()])], light))
    with pytest.raises(InputError, match=r"object 'icosphere' \(file material 0, transmission 0.25\)"):
        check_closed_transmission(Scene([SceneObject(parts, Material(), [Material(transmission=0.25), Material()])],
                                        light))
    assert _brute_force_closed(sphere, range(len(sphere.faces)))


# ---------------------------------------------------------------------------- Whitted unchanged


def test_whitted_renders_ignore_the_pbr_fields_bit_for_bit(device):
    """The Whitted kernels read bytes 0..47 of a Material row only: the same
    scene with every PBR field and texture set renders the image it renders
    without them, to the bit (a textured scene too; the Whitted renderer
    uploads base colour textures only: flatten_scene's pbr_textures)."""
    from dataclasses import replace
    from clrt.renderer import Renderer
    from clrt.scene.scene import Camera
    sphere = primitives.icosphere(2, 1.0)
    sphere = sphere.with_detail(uv=np.random.default_rng(2).random((len(sphere.faces), 3, 2)))
    floor = primitives.box((4.0, 0.2, 4.0))
    floor = floor.__class__(floor.vertices - [0.0, 1.2, 0.0], floor.faces, "floor")
    base = _texture(1)
    plain = [Material(color=(0.9, 0.5, 0.2), texture=base, reflectivity=0.3),
             Material(color=(0.8, 0.8, 0.8), transparency=0.6, specular=0.5, shininess=80.0)]
    pbr = dict(emission=(3.0, 2.0, 1.0), emission_texture=_texture(2), double_sided=True, metallic=0.9,
               roughness=0.2, metallic_roughness_texture=base, specular_weight=0.4, specular_color=(2.0, 1.0, 0.5),
               transmission=0.7, normal_texture=_texture(3), normal_scale=-2.0)
    images = []
    for materials in (plain, [replace(m, **pbr) for m in plain]):
        scene = Scene([SceneObject(sphere, materials[0]), SceneObject(floor, materials[1])],
                      [(2.0, 4.0, 3.0), (-3.0, 2.0, 1.0)], background=(0.1, 0.2, 0.3))
        camera = Camera((0.5, 1.5, 4.0), (0.0, -0.3, 0.0), width=48, height=36)
        images.append(Renderer(scene, device=device).render(camera, linear=True).image)
    assert np.array_equal(images[0], images[1])
    assert images[0].std() > 0.05   # the scene is in view

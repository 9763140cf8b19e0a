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


def _texture(seed: int) -> Texture:
    return Texture(np.random.default_rng(seed).integers(0, 256, (2, 3, 3), dtype=np.uint8))


def _rows(*materials, uv=True):
    mesh = primitives.icosphere(1, 1.0)
    if uv:
        mesh = mesh.with_detail(uv=np.zeros((len(mesh.faces), 3, 2)))
    scene = Scene([SceneObject(mesh, m, ()) for m in materials], [(0.0, 5.0, 0.0)])
    return flatten_scene(scene)


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

"""The path tracer's reference scene and image (docs/path-tracing.md, "Reference images"): the
committed Cornell box is what benchmarks/scenes.py writes and what clrt reads back, Mitsuba's
reference image was rendered from exactly that file and is laid out as clrt's images are, and the
noise-aware comparison of tests/path_reference.py passes noise and catches bias."""

import hashlib
import json

import numpy as np
import pytest

import path_reference
from benchmarks import scenes
from clrt.scene.load import file_camera, load_asset


def test_the_committed_cornell_box_is_what_the_script_writes(tmp_path):
    written = scenes.write_gltf(scenes.cornell_box(), tmp_path / "cornell-box.gltf")
    assert written.read_bytes() == scenes.CORNELL_BOX_FILE.read_bytes(), \
        "assets/scenes/cornell-box.gltf is stale: python -m benchmarks.scenes (and make the reference again)"


def test_clrt_reads_the_cornell_box_as_built():
    box = scenes.cornell_box()
    mesh, materials = load_asset(scenes.CORNELL_BOX_FILE)
    built = np.concatenate([s.vertices[s.faces] for s in box.shapes])   # (F, 3, 3), in the file's order
    np.testing.assert_array_equal(mesh.vertices[mesh.faces], built)
    colours = np.concatenate([[s.surface.base_color] * len(s.faces) for s in box.shapes])
    np.testing.assert_allclose([materials[m]["color"] for m in mesh.face_material], colours, rtol=1e-6)
    # clrt's PBR fields: pure Lambert everywhere, Mitsuba's radiance on the light's faces only.
    emission = np.concatenate([[s.surface.emission] * len(s.faces) for s in box.shapes])
    np.testing.assert_allclose([materials[m]["emission"] for m in mesh.face_material], emission, rtol=1e-12)
    assert {(m["metallic"], m["roughness"], m["specular_weight"], m["double_sided"]) for m in materials} == {
        (0.0, 1.0, 0.0, False)}
    # Fronts (counter-clockwise) face into the box for the walls, out of the boxes, down for the light.
    n = np.cross(built[:, 1] - built[:, 0], built[:, 2] - built[:, 0])
    centre_of = {s.name: s.vertices.mean(axis=0) for s in box.shapes}
    names = np.concatenate([[s.name] * len(s.faces) for s in box.shapes])
    towards_centre = np.einsum("ij,ij->i", n, -built.mean(axis=1))
    walls = np.isin(names, ["floor", "ceiling", "back", "red wall", "green wall"])
    assert (towards_centre[walls] > 0).all()
    for box_name in ("tall box", "short box"):
        rows = names == box_name
        assert (np.einsum("ij,ij->i", n[rows], built[rows].mean(axis=1) - centre_of[box_name]) > 0).all()
    assert (n[names == "light"][:, 1] < 0).all()
    view = file_camera(scenes.CORNELL_BOX_FILE)
    np.testing.assert_allclose(view["eye"], box.view.eye, atol=1e-12)
    np.testing.assert_allclose(view["forward"], [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(view["up"], box.view.up, atol=1e-12)
    assert view["fov"] == pytest.approx(39.3077) and view["aspect"] == 1.0


def test_the_light_emits_mitsubas_radiance_as_linear_emissive_factor_times_strength():
    doc = json.loads(scenes.CORNELL_BOX_FILE.read_text())
    light = next(m for m in doc["materials"] if "emissiveFactor" in m)
    strength = light["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"]
    assert max(light["emissiveFactor"]) == 1.0 and not light["doubleSided"]
    np.testing.assert_allclose(np.multiply(light["emissiveFactor"], strength), (18.387, 13.9873, 6.75357), rtol=1e-12)
    for material in doc["materials"]:   # pure Lambert, as Mitsuba's diffuse BSDF
        assert material["pbrMetallicRoughness"]["metallicFactor"] == 0.0
        assert material["pbrMetallicRoughness"]["roughnessFactor"] == 1.0
        assert material["extensions"]["KHR_materials_specular"]["specularFactor"] == 0.0


@pytest.mark.parametrize("max_depth", [2, 3, 8])
def test_the_reference_was_rendered_from_this_file_in_clrts_layout(max_depth):
    ref = path_reference.load_reference(max_depth)
    assert ref.meta["scene_sha256"] == hashlib.sha256(scenes.CORNELL_BOX_FILE.read_bytes()).hexdigest(), \
        "the scene changed since the reference was made: make it again (tests/data/README.md)"
    assert ref.image.shape == ref.sample_std.shape == (64, 64, 3) and ref.spp == 65536
    assert np.isfinite(ref.image).all() and (ref.image >= 0).all() and (ref.sample_std >= 0).all()
    # Row 0 at the top, column 0 at the left: the red wall (x = -1) fills the left columns, the
    # green wall the right ones, and the light is seen near the top.
    left, right = ref.image[16:48, :3].mean(axis=(0, 1)), ref.image[16:48, -3:].mean(axis=(0, 1))
    assert left[0] > 3 * left[1] and right[1] > 2 * right[0]
    light_row = np.unravel_index(np.argmax(ref.image.sum(axis=2)), (64, 64))[0]
    assert light_row < 16   # upside down it would be near row 54


def test_the_comparison_passes_noise_and_catches_bias():
    ref = path_reference.load_reference(8)
    rng = np.random.default_rng(35)

    def render(spp, scale=1.0):   # an unbiased estimate with the reference's own noise (Gaussian)
        return ref.image * scale + rng.normal(size=ref.image.shape) * ref.sample_std / np.sqrt(spp)

    for _ in range(5):
        path_reference.assert_matches(render(256), ref, spp=256)
        path_reference.assert_matches(np.stack([render(64) for _ in range(4)]), ref)   # variance measured
    assert not path_reference.compare(render(256, 1.02), ref, spp=256).agrees()
    local = render(256)
    local[24:32, 8:16] *= 1.1
    result = path_reference.compare(local, ref, spp=256)
    assert not result.agrees() and np.unravel_index(np.argmax(np.abs(result.z)), result.z.shape)[:2] == (3, 1)
    with pytest.raises(AssertionError, match="beyond noise"):
        path_reference.assert_matches(render(256)[:, ::-1], ref, spp=256)   # mirrored: red and green swap

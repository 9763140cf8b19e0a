"""Real assets look like themselves: materials, textures, colours and normals
from the files, on the device and in the reference tracer alike.

Every asset is written here, into tmp_path, with trimesh, numpy and Pillow.
"""


import numpy as np
import pyopencl as cl
import pytest
import trimesh
from PIL import Image

from glb import edit_glb_file

import clrt
from clrt import cli, config
from clrt.device.args import scene_value
from clrt.device.context import create_context
from clrt.device.program import build_options, expand_source
from clrt.layouts import LIGHT, MATERIAL
from clrt.reference import render_reference, sample_texture
from clrt.renderer.kernels import pack_tables
from clrt.renderer import Renderer
from clrt.scene.arrays import flatten_scene
from clrt.scene import primitives
from clrt.scene.load import load_asset
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject, scene_from_mesh
from clrt.scene.texture import Texture

RNG = np.random.default_rng(16)
IMAGE = RNG.integers(0, 256, (6, 8, 3), dtype=np.uint8)   # small and irregular: every texel shows


def _textured_cube() -> trimesh.Trimesh:
    """A unit cube, a vertex per face corner, with UVs running past 0..1 (wrapping shows)."""
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v = box.vertices[box.faces].reshape(-1, 3)
    uv = np.random.default_rng(3).random((len(v), 2)) * 2.0 - 0.5
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(IMAGE),
                                                   baseColorFactor=[1.0, 0.8, 0.6, 1.0],
                                                   metallicFactor=0.0, roughnessFactor=0.5)
    return trimesh.Trimesh(v, np.arange(len(v)).reshape(-1, 3),
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material), process=False)


def _agree(scene, device, size=(40, 30), **render):
    camera = Camera.framing(scene.bounds, *size)
    frame = Renderer(scene, device=device, **render).render(camera, linear=True, hits=True)
    ref, prim, _ = render_reference(scene, camera)
    assert (frame.prim == prim).mean() >= 0.999
    close = np.abs(frame.image - ref).max(axis=2) <= 2e-3
    assert close.mean() >= 0.995, f"{(~close).sum()} pixels differ"
    return frame


# ---------------------------------------------------------------------------- sampling


def test_texture_sampling_on_the_device_is_the_reference_bit_for_bit(device):
    """texture.cl's sample_texture against reference.sample_texture at many
    coordinates, inside, outside and far outside 0..1, for every wrap mode,
    each image read as sRGB colour and as linear data (two rows, one copy of
    the texels)."""
    textures = [Texture(IMAGE, s, t) for s in config.TEXTURE_WRAPS for t in config.TEXTURE_WRAPS]
    scene = Scene([SceneObject(Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
                               .with_detail(uv=np.zeros((1, 3, 2))), Material(texture=t, normal_texture=t))
                   for t in textures], [Light((0, 0, 1))])
    detail = flatten_scene(scene, pbr_textures=True).detail
    assert list(detail.textures["linear"]) == [0, 1] * len(textures)
    assert len(detail.texels) == len(textures) * IMAGE.shape[0] * IMAGE.shape[1]
    uv = np.concatenate([RNG.uniform(-3, 4, (4000, 2)), RNG.uniform(-1e9, 1e9, (50, 2)),
                         [[np.inf, -np.inf], [np.nan, 0.5], [0, 0], [1, 1], [0.5 / 8, 1 - 0.5 / 6]]]).astype(np.float32)
    context, queue = create_context(device)
    source = expand_source("texture.cl") + """
    __kernel void probe(__global const float2* uv, __global float4* out, const int index,
                        __global const uchar* tables, const SceneInfo scene, __global const uchar4* texels) {
        const TextureSet ts = make_texture_set(tables, scene, TEXTURE_ARGS);
        const uint i = get_global_id(0);
        out[i] = (float4)(sample_texture(&ts, index, uv[i]), 0.0f);
    }"""
    program = cl.Program(context, source).build(options=build_options(context, {"SURFACE_DETAIL": None}))
    mf = cl.mem_flags
    tables, offsets = pack_tables(np.zeros(0, MATERIAL), np.zeros(0, LIGHT), detail.textures, detail.srgb_table)
    bufs = [cl.Buffer(context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in (uv, tables, detail.texels)]
    bufs.insert(2, scene_value(0, **offsets))   # the SceneInfo value: where the tables lie
    out = np.empty((len(uv), 4), np.float32)
    out_buf = cl.Buffer(context, mf.WRITE_ONLY, out.nbytes)
    probe = cl.Kernel(program, "probe")
    for index in range(2 * len(textures)):
        texture, linear = textures[index // 2], index % 2 == 1
        probe(queue, (len(uv),), None, bufs[0], out_buf, np.int32(index), *bufs[1:])
        cl.enqueue_copy(queue, out, out_buf)
        expected = sample_texture(texture, uv, linear)
        assert np.array_equal(out[:, :3], expected), (texture, linear, np.abs(out[:, :3] - expected).max())
    # Texel centres give the texel's own colour, decoded from sRGB.
    centre = sample_texture(textures[0], np.array([[0.5 / 8, 1 - 0.5 / 6]], np.float32))
    c = IMAGE[0, 0] / 255
    np.testing.assert_allclose(centre[0], np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4),
                               atol=1e-6)   # the float32 centre is 2e-7 texels off
    # ... and read as data, the code / 255.
    centre = sample_texture(textures[0], np.array([[0.5 / 8, 1 - 0.5 / 6]], np.float32), linear=True)
    np.testing.assert_allclose(centre[0], c, atol=1e-6)


# ---------------------------------------------------------------------------- files


def test_textured_cube_as_glb_and_as_obj_mtl_png(tmp_path, device):
    cube = _textured_cube()
    cube.export(tmp_path / "cube.glb")
    cube.export(tmp_path / "cube.obj")   # writes material.mtl and material_0.png beside it
    assert (tmp_path / "material_0.png").is_file()
    for name in ("cube.glb", "cube.obj"):
        mesh, materials = load_asset(tmp_path / name)
        assert mesh.uv is not None and mesh.face_material is not None
        np.testing.assert_allclose(mesh.uv.reshape(-1, 2), cube.visual.uv, atol=1e-6)
        assert np.array_equal(materials[0]["texture"].pixels, IMAGE)
        np.testing.assert_allclose(materials[0]["color"], (1.0, 0.8, 0.6))
        scene = scene_from_mesh(tmp_path / name)
        frame = _agree(scene, device)
        camera = Camera.framing(scene.bounds, 40, 30)
        o = scene.objects[0]
        plain = Scene([SceneObject(o.mesh, o.material, [m.with_overrides(texture=None) for m in o.materials])],
                      scene.lights)
        untextured = Renderer(plain, device=device).render(camera, linear=True).image
        assert (np.abs(frame.image - untextured).max(axis=2) > 0.05).mean() > 0.2, "the texture shows"
    # --color replaces the colour, the texture with it.
    scene = scene_from_mesh(tmp_path / "cube.glb")
    scene.override_materials(color=(1.0, 0.0, 0.0))
    assert flatten_scene(scene).detail is None


def test_glb_samplers_transmission_and_ior(tmp_path, device):
    cube = _textured_cube()
    cube.export(tmp_path / "glass.glb")

    def edit(doc):
        doc["samplers"] = [{"wrapS": 33648, "wrapT": 33071}]
        for texture in doc["textures"]:
            texture["sampler"] = 0
        doc["materials"][0]["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": 0.7},
                                             "KHR_materials_ior": {"ior": 1.33}}
        doc["materials"][0]["pbrMetallicRoughness"].update(metallicFactor=1.0, roughnessFactor=0.0)
    edit_glb_file(tmp_path / "glass.glb", edit)
    _, (m,) = load_asset(tmp_path / "glass.glb")
    assert (m["texture"].wrap_s, m["texture"].wrap_t) == ("mirror", "clamp")
    assert m["transparency"] == 0.7 and m["ior"] == 1.33
    assert m["reflectivity"] == 1.0 and m["diffuse"] == 0.0 and m["shininess"] == 1000.0
    _agree(scene_from_mesh(tmp_path / "glass.glb"), device)

    def rough(doc):   # roughness 0.5: Blinn-Phong's 2 / 0.5^4 - 2 = 30, a Phong exponent of 7.5
        doc["materials"][0]["pbrMetallicRoughness"].update(metallicFactor=0.0, roughnessFactor=0.5)
    edit_glb_file(tmp_path / "glass.glb", rough)
    _, (m,) = load_asset(tmp_path / "glass.glb")
    assert m["shininess"] == 7.5 and m["specular"] == 0.5 and m["reflectivity"] == 0.0


def _coloured_ply(path, encoding):
    sphere = trimesh.creation.icosphere(2)
    colours = np.zeros((len(sphere.vertices), 4), np.uint8)
    colours[:, 0] = np.where(sphere.vertices[:, 0] > 0, 255, 30)
    colours[:, 2] = 255 - colours[:, 0]
    colours[:, 3] = 255
    mesh = trimesh.Trimesh(sphere.vertices, sphere.faces, vertex_colors=colours, process=False)
    path.write_bytes(mesh.export(file_type="ply", encoding=encoding))
    return mesh


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_vertex_coloured_ply(tmp_path, device, encoding):
    source = _coloured_ply(tmp_path / "c.ply", encoding)
    mesh = clrt.load_mesh(tmp_path / "c.ply")
    c = source.visual.vertex_colors[:, :3] / 255
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(mesh.colors, linear[source.faces], atol=1e-6)
    frame = _agree(scene_from_mesh(tmp_path / "c.ply"), device)
    image = frame.image[frame.prim >= 0]
    assert (image[:, 0] > 2 * image[:, 2]).sum() > 20 and (image[:, 2] > 2 * image[:, 0]).sum() > 20


def test_off_face_colours_and_trimesh_colour_visuals(tmp_path, device):
    (tmp_path / "q.off").write_text("OFF\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0.5 0\n"
                                    "4 0 1 2 3 255 0 0\n3 1 4 2 0 0 255\n")
    mesh = clrt.load_mesh(tmp_path / "q.off")
    assert mesh.colors.tolist() == [[[1, 0, 0]] * 3] * 2 + [[[0, 0, 1]] * 3]
    box = trimesh.creation.box()
    box.visual.face_colors = np.tile([[0, 255, 0, 255], [255, 255, 255, 255]], (6, 1))
    assert clrt.scene.load.as_mesh(box).colors[[0, 1], 0].tolist() == [[0, 1, 0], [1, 1, 1]]
    _agree(Scene([SceneObject(box)], [Light((2, 3, 4))]), device)


def test_obj_normals_materials_and_the_flat_option(tmp_path, device):
    """Authored normals survive the crease split and shade; usemtl picks per-face
    materials; faces before any usemtl get the default; --flat forces face normals."""
    sphere = primitives.icosphere(2)
    normals = sphere.vertex_normals() + 0.3 * np.array([1.0, 0.0, 0.0])   # visibly not the computed ones
    n = len(sphere.faces)
    lines = ["mtllib two.mtl"] + [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in sphere.vertices]
    lines += [f"vn {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in normals]
    for k, (a, b, c) in enumerate(sphere.faces + 1):
        if k in (n // 3, 2 * n // 3):
            lines.append("usemtl red" if k == n // 3 else "usemtl glass")
        lines.append(f"f {a}//{a} {b}//{b} {c}//{c}")
    (tmp_path / "s.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "two.mtl").write_text("newmtl red\nKd 0.9 0.1 0.1\nKs 0.2 0.2 0.2\nNs 50\n"
                                      "newmtl glass\nKd 0.9 0.9 1\nd 0.2\nNi 1.45\n")
    mesh, materials = load_asset(tmp_path / "s.obj")
    np.testing.assert_allclose(mesh.vertex_normals(), normals / np.linalg.norm(normals, axis=1)[:, None],
                               atol=1e-6)
    assert mesh.split_at_creases() is mesh
    assert materials == [{"color": (0.9, 0.1, 0.1), "specular": pytest.approx(0.2), "shininess": 50.0},
                         {"color": (0.9, 0.9, 1.0), "transparency": pytest.approx(0.8), "ior": 1.45}]
    assert mesh.face_material.tolist() == [-1] * (n // 3) + [0] * (2 * n // 3 - n // 3) + [1] * (n - 2 * n // 3)
    scene = scene_from_mesh(tmp_path / "s.obj")
    frame = _agree(scene, device)
    computed = Renderer(scene_from_mesh(sphere), device=device)
    camera = Camera.framing(scene.bounds, 40, 30)
    assert np.abs(computed.render(camera, linear=True).image - frame.image).max() > 0.1
    # --flat: face normals, the file's materials kept
    flat, smooth = (cli.main(["render", str(tmp_path / "s.obj"), "-o", str(tmp_path / f"{k}.png"), "-q",
                              "--width", "40", "--height", "30", *extra, *(["--device", device] if device else [])])
                    for k, extra in (("flat", ["--flat"]), ("smooth", [])))
    assert flat == smooth == 0
    a, b = (np.asarray(Image.open(tmp_path / f"{k}.png")).astype(int) for k in ("flat", "smooth"))
    assert (np.abs(a - b).max(axis=2) > 8).sum() > 30


def test_split_buffers_render_the_same_detail(device):
    cube = _textured_cube()
    colours = RNG.random((len(cube.faces), 3, 3))
    mesh = clrt.scene.load.as_mesh(cube).with_detail(colors=colours)
    big = RNG.integers(0, 256, (32, 32, 3), dtype=np.uint8)   # 4 KiB of texels: several parts
    scene = Scene([SceneObject(mesh, Material(texture=Texture(big, "mirror", "clamp")))], [Light((2, 3, 4))])
    camera = Camera.framing(scene.bounds, 32, 24)
    whole = Renderer(scene, device=device).render(camera, linear=True)
    split = Renderer(scene, device=device, max_buffer_bytes=1024)
    assert split.geometry.parts() > 1 and len(set(split.geometry.buffers["texels"])) > 1
    assert np.array_equal(split.render(camera, linear=True).image, whole.image)


def test_bad_texture_is_a_one_line_error(tmp_path):
    (tmp_path / "t.obj").write_text("mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\n")
    (tmp_path / "t.mtl").write_text("newmtl a\nmap_Kd broken.png\n")
    (tmp_path / "broken.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(clrt.MeshLoadError, match=r"t\.obj: .*broken\.png: cannot read the texture") as info:
        load_asset(tmp_path / "t.obj")
    assert "\n" not in str(info.value)
    (tmp_path / "broken.png").unlink()   # a missing one is skipped, with a warning: the material has no texture
    with pytest.warns(clrt.MeshLoadWarning, match=r"t\.obj: .*broken\.png") as record:
        assert "texture" not in load_asset(tmp_path / "t.obj")[1][0]
    assert len(record) == 1 and "\n" not in str(record[0].message)


MISSING = "mtllib {mtl}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl a\nf 1/1 2/1 3/1\n"


def test_missing_mtl_file_or_texture_is_a_warning_naming_both_files(tmp_path):
    """The mesh still loads (the faces keep the default material, or the
    material its colour), with one warning line naming the OBJ and the file it
    names that is not there."""
    obj = tmp_path / "t.obj"
    obj.write_text(MISSING.format(mtl="gone.mtl"))
    with pytest.warns(clrt.MeshLoadWarning) as record:
        mesh, materials = load_asset(obj)
    assert materials == [] and len(record) == 1
    message = str(record[0].message)
    assert str(obj) in message and str(tmp_path / "gone.mtl") in message and "\n" not in message
    (tmp_path / "here.mtl").write_text("newmtl a\nKd 1 0 0\nmap_Kd -clamp on gone.png\n")
    obj.write_text(MISSING.format(mtl="here.mtl"))
    with pytest.warns(clrt.MeshLoadWarning) as record:
        mesh, materials = load_asset(obj)
    assert materials == [{"color": (1.0, 0.0, 0.0)}] and len(record) == 1
    message = str(record[0].message)
    assert str(obj) in message and str(tmp_path / "gone.png") in message and "here.mtl" in message


def test_the_cli_prints_a_missing_texture_as_one_warning_line(tmp_path, device, capsys):
    (tmp_path / "here.mtl").write_text("newmtl a\nKd 1 0 0\nmap_Kd gone.png\n")
    (tmp_path / "t.obj").write_text(MISSING.format(mtl="here.mtl"))
    code = cli.main(["render", str(tmp_path / "t.obj"), "-o", str(tmp_path / "t.png"), "--width", "16",
                     "--height", "12", *(["--device", device] if device else [])])
    err = capsys.readouterr().err
    assert code == 0, err
    warned = [line for line in err.splitlines() if "gone.png" in line]
    assert warned == [line for line in err.splitlines() if "warning" in line.lower()]
    assert len(warned) == 1 and warned[0].startswith("clrt: warning: ") and str(tmp_path / "t.obj") in warned[0]
    assert "Traceback" not in err and "warnings.warn" not in err


# ---------------------------------------------------------------------------- notebooks


def test_frame_shows_in_notebooks(device):
    scene = scene_from_mesh((trimesh.creation.box().vertices, trimesh.creation.box().faces))
    r = Renderer(scene, device=device)
    camera = Camera.framing(scene.bounds, 16, 12)
    for linear in (False, True):
        frame = r.render(camera, linear=linear)
        png = frame._repr_png_()
        assert png.startswith(b"\x89PNG")
        import io
        shown = np.asarray(Image.open(io.BytesIO(png)))
        srgb = r.render(camera).image
        assert shown.shape == (12, 16, 3) and np.abs(shown.astype(int) - srgb).max() <= 1


def test_obj_mtllib_naming_several_libraries(tmp_path):
    (tmp_path / "a.mtl").write_text("newmtl a\nKd 1 0 0\n")
    (tmp_path / "b.mtl").write_text("newmtl b\nKd 0 1 0\n")
    (tmp_path / "c d.mtl").write_text("newmtl c\nKd 0 0 1\n")
    body = "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl b\nf 1 2 3\nusemtl a\nf 1 3 2\nusemtl c\nf 2 1 3\n"
    (tmp_path / "m.obj").write_text("mtllib a.mtl  b.mtl\nmtllib c d.mtl\n" + body)
    mesh, materials = load_asset(tmp_path / "m.obj")
    assert [materials[i]["color"] for i in mesh.face_material] == [(0.0, 1.0, 0.0), (1.0, 0.0, 0.0),
                                                                   (0.0, 0.0, 1.0)]


@pytest.mark.parametrize("mode", ["I;16", "I;16B", "I"])
def test_16_bit_greyscale_textures_are_scaled_to_8_bits(tmp_path, mode):
    grey = np.array([[0, 0x8080], [0x0101, 65535]], np.uint16)
    image = Image.fromarray(grey).convert(mode) if mode != "I;16" else Image.fromarray(grey)
    if mode == "I;16B":
        image = Image.frombytes("I;16B", (2, 2), grey.astype(">u2").tobytes())
    expected = [[[0] * 3, [128] * 3], [[1] * 3, [255] * 3]]
    assert Texture.from_image(image).pixels.tolist() == expected
    Image.fromarray(grey).save(tmp_path / "g16.png")   # a 16-bit PNG file, and as map_Kd
    assert Texture.read(tmp_path / "g16.png").pixels.tolist() == expected
    (tmp_path / "g.mtl").write_text("newmtl g\nmap_Kd g16.png\n")
    (tmp_path / "g.obj").write_text("mtllib g.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl g\nf 1/1 2/1 3/1\n")
    assert load_asset(tmp_path / "g.obj")[1][0]["texture"].pixels.tolist() == expected

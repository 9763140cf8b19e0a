"""Normal maps in the path tracer (material.cl's mapped_normal) against numpy:
the first hits' mean shading normal (Frame.normal, the EXR's normal.X/Y/Z)
where every sample of a pixel sees the same mapped normal, worked out by
hand for texture layouts turned, mirrored and sheared (glTF's convention:
x along increasing u, y along increasing v, z the surface normal; the
scale on x and y), from the front and from the back; a point light's direct
light follows the mapped normal's cosine; a flat (128, 128, 255) map
changes nothing but its code's 0.3 degree tilt; and a map that varies is
looked up where the texture coordinates say (bilinear, clamped), against
clrt.reference's numpy sampler.  And the path tracer's textures reach it at
all (a Renderer of a path-traced scene uploads them)."""

import numpy as np
import pytest

from clrt.errors import InputError
from clrt.reference import camera_rays, sample_texture
from clrt.renderer import Renderer
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject
from clrt.scene.texture import Texture

LAMBERT = dict(color=(0.5, 0.5, 0.5), specular=0.0, metallic=0.0, specular_weight=0.0, roughness=1.0, smooth=False)
FRONT = Camera((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), width=32, height=32, fov=14)
BACK = Camera((0.0, 0.0, -10.0), (0.0, 0.0, 0.0), width=32, height=32, fov=14)

# Four unit squares in the plane z = 0 (front faces +z), each with its own
# texture layout of its local coordinates (x, y) about its centre, and the
# world directions of the tangent-space x and y axes that layout gives.
LAYOUTS = {  # centre: (uv of (x, y), tangent x, tangent y)
    (-0.5, 0.5): (lambda x, y: (x, y), (1, 0, 0), (0, 1, 0)),             # as is
    (0.5, 0.5): (lambda x, y: (y, -x), (0, 1, 0), (-1, 0, 0)),            # turned a quarter
    (-0.5, -0.5): (lambda x, y: (-x, y), (-1, 0, 0), (0, 1, 0)),          # mirrored in u
    (0.5, -0.5): (lambda x, y: (2 * x + y, 0.5 * y), (1, 0, 0), (0, 1, 0)),  # sheared: y stays N x T
}


def _squares() -> Mesh:
    vertices, faces, uv = [], [], []
    local = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    for (cx, cy), (layout, _, _) in LAYOUTS.items():
        base = len(vertices)
        vertices += [(cx + x, cy + y, 0.0) for x, y in local]
        corners = [layout(x, y) for x, y in local]
        for tri in ((0, 1, 2), (0, 2, 3)):   # counter-clockwise seen from +z
            faces.append([base + k for k in tri])
            uv.append([corners[k] for k in tri])
    mesh = Mesh.from_arrays(np.array(vertices), np.array(faces))
    return mesh.with_detail(uv=np.array(uv, np.float32))


def _tangent_normal(code, scale=1.0):
    """glTF's decoding of an 8-bit normal-map texel, float64."""
    c = 2.0 * np.asarray(code, np.float64) / 255.0 - 1.0
    c[:2] *= scale
    return c / np.linalg.norm(c)


def _footprints(camera):
    """Per pixel: the square (centre) all four corners of its footprint on
    z = 0 lie in, at least 0.02 inside it, else None; and its centre's hit."""
    hits = []
    for ox, oy in ((0, 0), (1, 0), (0, 1), (1, 1), (0.5, 0.5)):
        o, d = camera_rays(camera, ox, oy)
        o, d = o.astype(np.float64), d.astype(np.float64)
        hits.append(o - (o[:, 2] / d[:, 2])[:, None] * d)
    corners, centre = np.stack(hits[:4]), hits[4]
    owner = []
    for k in range(corners.shape[1]):
        p = corners[:, k, :2]
        found = None
        for c in LAYOUTS:
            if (np.abs(p - np.array(c)) < 0.48).all():
                found = c
        owner.append(found)
    return owner, centre


def _expected_normals(camera, code, scale=1.0, back=False):
    """Per pixel the mapped normal (facing the camera), NaN where a pixel is not inside one square."""
    c = _tangent_normal(code, scale)
    owner, _ = _footprints(camera)
    out = np.full((len(owner), 3), np.nan)
    for k, centre in enumerate(owner):
        if centre is not None:
            _, tx, ty = LAYOUTS[centre]
            n = c[0] * np.array(tx, float) + c[1] * np.array(ty, float) + c[2] * np.array([0.0, 0.0, 1.0])
            out[k] = -n if back else n
    return out.reshape(camera.height, camera.width, 3)


def _renderer(device, material, lights=(), mesh=None):
    scene = Scene([SceneObject(_squares() if mesh is None else mesh, material)], list(lights),
                  background=(0.0, 0.0, 0.0), integrator="path", max_depth=2)
    return Renderer(scene, device=device)


CODE = (200, 90, 230)
LIGHT = Light((0.0, 0.0, 100.0), (1e4, 1e4, 1e4))   # irradiance 1 at the squares, straight down


def test_normal_maps_bend_the_shading_normal_by_the_texture_layout(device):
    bumps = Texture(np.array([[CODE]], np.uint8))
    for scale in (1.0, -0.5):
        renderer = _renderer(device, Material(normal_texture=bumps, normal_scale=scale, **LAMBERT), [LIGHT])
        for camera, back in ((FRONT, False), (BACK, True)):
            frame = renderer.render(camera, linear=True, spp=4, seed=1)
            expected = _expected_normals(camera, CODE, scale, back)
            inside = ~np.isnan(expected[..., 0])
            assert inside.sum() > 400
            np.testing.assert_allclose(frame.normal[inside], expected[inside], atol=2e-6)
            if back:
                continue
            # Direct light of the point light (delta: no noise): albedo / pi x the mapped normal's cosine.
            _, centre = _footprints(camera)
            to_light = np.asarray(LIGHT.position) - centre
            distance = np.linalg.norm(to_light, axis=1)
            cosine = np.einsum("ij,ij->i", expected.reshape(-1, 3), to_light / distance[:, None])
            radiance = (0.5 / np.pi * 1e4 * cosine / distance ** 2).reshape(expected.shape[:2])
            np.testing.assert_allclose(frame.image[..., 1][inside], radiance[inside], rtol=1e-3)   # (jitter moves l by < 1e-3)
            assert radiance[inside].max() < 0.95 * 0.5 / np.pi   # the bend shows: unbent, every pixel is 0.5 / pi


def test_a_flat_normal_map_changes_nothing(device):
    """(128, 128, 255) decodes to (1, 1, 255) / 255, a tilt of 0.32 degrees:
    normals within that of the plane's, and the image of the plain material
    within the cosine of that tilt."""
    flat = Texture(np.array([[(128, 128, 255)]], np.uint8))
    mapped = _renderer(device, Material(normal_texture=flat, **LAMBERT), [LIGHT]).render(
        FRONT, linear=True, spp=4, seed=1)
    plain = _renderer(device, Material(**LAMBERT), [LIGHT]).render(FRONT, linear=True, spp=4, seed=1)
    expected = _expected_normals(FRONT, (128, 128, 255))
    inside = ~np.isnan(expected[..., 0])
    np.testing.assert_allclose(mapped.normal[inside], expected[inside], atol=2e-6)
    np.testing.assert_allclose(plain.normal[inside], np.broadcast_to([0.0, 0.0, 1.0], expected[inside].shape),
                               atol=1e-6)
    assert np.abs(mapped.normal - plain.normal).max() < 0.006
    np.testing.assert_allclose(mapped.image, plain.image, rtol=1e-4)


def test_a_varying_normal_map_is_read_where_the_coordinates_say(device):
    """A 2x2 map (clamped) over one square [-1, 1]^2, uv = ((x + 1) / 2, (y + 1) / 2):
    pixels whose footprint lies in a corner quarter of the square see one
    texel alone, exactly; elsewhere the mean of the bilinear map's normals
    over the pixel, from an 8x8 grid of points in numpy."""
    codes = np.array([[(60, 200, 220), (220, 170, 200)],      # top row of the image: v near 1
                      [(128, 40, 210), (190, 100, 250)]], np.uint8)
    texture = Texture(codes, wrap_s="clamp", wrap_t="clamp")
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    square = Mesh.from_arrays(v, np.array([[0, 1, 2], [0, 2, 3]]))
    square = square.with_detail(uv=((v[[[0, 1, 2], [0, 2, 3]], :2] + 1.0) / 2.0).astype(np.float32))
    camera = Camera((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), width=24, height=24, fov=10)
    frame = _renderer(device, Material(normal_texture=texture, **LAMBERT), mesh=square).render(
        camera, linear=True, spp=64, seed=2)
    grid = (np.arange(8) + 0.5) / 8
    normals = []
    for oy in grid:
        for ox in grid:
            o, d = camera_rays(camera, ox, oy)
            o, d = o.astype(np.float64), d.astype(np.float64)
            p = o - (o[:, 2] / d[:, 2])[:, None] * d
            c = 2.0 * sample_texture(texture, (p[:, :2] + 1.0) / 2.0, linear=True).astype(np.float64) - 1.0
            normals.append(c / np.linalg.norm(c, axis=1, keepdims=True))
    normals = np.stack(normals)
    expected = normals.mean(axis=0).reshape(24, 24, 3)
    one_texel = (np.ptp(normals, axis=0).max(axis=1) == 0).reshape(24, 24)   # pixels in a corner quarter
    assert one_texel.sum() > 40 and (~one_texel).sum() > 200
    np.testing.assert_allclose(frame.normal[one_texel], expected[one_texel], atol=2e-6)
    # The corner quarters hold the four texels: top-left of the image at the top left of the square.
    for (row, col), code in np.ndenumerate(codes[..., 0]):
        pixel = (2 + 19 * row, 2 + 19 * col)
        assert one_texel[pixel]
        np.testing.assert_allclose(frame.normal[pixel], _tangent_normal(codes[row, col]), atol=2e-6)
    # Between them, 64 jittered samples against the 8x8 grid: within their noise.
    diff = np.abs(frame.normal - expected)[~one_texel]
    assert diff.max() < 0.02 and diff.mean() < 0.003, (diff.max(), diff.mean())


def test_the_path_tracers_textures_are_uploaded_for_path_traced_scenes(device):
    """A Renderer of a path-traced scene uploads the emission (and metallic-
    roughness, normal) textures: an emissive square seen directly (max_depth
    1) shows emission x the sRGB-decoded texel.  One made for Whitted, which
    reads base colours only, says so instead of path-tracing without them."""
    glow = Texture(np.array([[(255, 128, 0), (0, 64, 255)]], np.uint8), wrap_s="clamp", wrap_t="clamp")
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    square = Mesh.from_arrays(v, np.array([[0, 1, 2], [0, 2, 3]]))
    square = square.with_detail(uv=((v[[[0, 1, 2], [0, 2, 3]], :2] + 1.0) / 2.0).astype(np.float32))
    material = Material(emission=(2.0, 2.0, 2.0), emission_texture=glow, **{**LAMBERT, "color": (0, 0, 0)})
    camera = Camera((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), width=16, height=8, fov=5)
    scene = Scene([SceneObject(square, material)], [], background=(0.0, 0.0, 0.0), integrator="path")
    image = Renderer(scene, device=device).render(camera, linear=True, spp=2, max_depth=1).image
    left, right = (2.0 * sample_texture(glow, np.array([[u, 0.5]], np.float32))[0] for u in (0.1, 0.9))
    np.testing.assert_allclose(image[:, :3].reshape(-1, 3), np.broadcast_to(left, (24, 3)), rtol=1e-6)
    np.testing.assert_allclose(image[:, -3:].reshape(-1, 3), np.broadcast_to(right, (24, 3)), rtol=1e-6)
    scene.integrator = "whitted"
    with pytest.raises(InputError, match="were not uploaded: this Renderer was made for the Whitted"):
        Renderer(scene, device=device).render(camera, integrator="path", spp=1)

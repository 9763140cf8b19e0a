"""Rays that leave a surface: shadow, reflection and refraction rays start off
it by the float32 error of their hit point (shading.cl's spawn_origin) and
take only hits certainly in front of them (triangle.cl's certain_t_error).

docs/limits.md's scene -- a torus 2.7 across standing 0.25 above a square
ground, lit from 5 above -- keeps its shadow on grounds up to 2e6 across and
far from the origin, where one offset for the whole scene (1e-4 of its
diagonal plus 1e-6 of its largest coordinate, the rule before) washed it out
or lifted the rays past the light; and no ray finds its own surface again
(acne), on large tilted triangles and far from the origin too.
"""

from fractions import Fraction

import math

import numpy as np
import pytest

import clrt
from clrt.reference import _shear, camera_rays, certain_error_of, intersect, point_and_offset, spawn_origin, watertight
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject

MATTE = Material(color=(0.8, 0.8, 0.8), ambient=0.1, diffuse=0.7, specular=0.0)
AMBIENT_ONLY = 0.1 * 0.8 * 3          # a shadowed pixel's r + g + b (ambient light 1)
LIGHT = np.array([1.5, 5.0, 1.0])


def _rotation(tilt: float) -> np.ndarray:
    """About x by ``tilt`` degrees, then about z by 0.7 of it."""
    a, b = np.radians(tilt), np.radians(0.7 * tilt)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    return rz @ rx


def _ground(half: float, shift, tilt: float = 0.0, material=MATTE) -> SceneObject:
    corners = np.array([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]])
    return SceneObject(Mesh.from_arrays(corners @ _rotation(tilt).T + shift, [[0, 2, 1], [0, 3, 2]]), material)


def _torus_scene(half: float, shift: float = 0.0) -> tuple[Scene, Camera]:
    """docs/limits.md's scene on a ground ``2 * half`` across, everything moved by
    (shift, 0, shift), and a camera looking at the torus and its shadow."""
    s = np.array([shift, 0.0, shift])
    torus = primitives.torus(1.0, 0.35, 16, 8)
    torus = Mesh.from_arrays(torus.vertices.astype(np.float64) + [0.0, 0.6, 0.0] + s, torus.faces)
    scene = Scene([SceneObject(torus, MATTE), _ground(half, s)], [Light(tuple(LIGHT + s))])
    return scene, Camera(tuple(s + [0.0, 3.0, 5.0]), tuple(s + [0.0, 0.3, 0.0]), fov=50, width=48, height=36)


def _truth(scene: Scene, camera: Camera):
    """Float64: which pixels see the (level) ground, and which of those points the
    torus hides from the light (the corners as the device holds them, float32)."""
    o, d = (a.astype(np.float64) for a in camera_rays(camera))
    ground = scene.objects[1].mesh.vertices.astype(np.float32).astype(np.float64)
    t = (ground[0, 1] - o[:, 1]) / d[:, 1]
    p = o + t[:, None] * d
    torus = scene.objects[0].mesh
    tri = torus.vertices.astype(np.float32).astype(np.float64)[torus.faces]
    light = np.asarray(scene.lights[0].position, np.float32).astype(np.float64)
    to_light = light - p
    dist = np.linalg.norm(to_light, axis=1)
    w = to_light / dist[:, None]
    # Moller-Trumbore, every point against every triangle
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    pv = np.cross(w[:, None, :], e2[None])
    det = np.einsum("ijk,jk->ij", pv, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        sv = p[:, None, :] - v0[None]
        u = np.einsum("ijk,ijk->ij", sv, pv) * inv
        q = np.cross(sv, e1[None])
        v = np.einsum("ijk,ik->ij", q, w) * inv
        tt = np.einsum("ijk,jk->ij", q, e2) * inv
        blocked = ((u >= 0) & (v >= 0) & (u + v <= 1) & (tt > 0) & (tt < dist[:, None])).any(axis=1)
    shape = (camera.height, camera.width)
    return (t > 0).reshape(shape), blocked.reshape(shape)


def _dark(scene: Scene, camera: Camera, device):
    """(on the ground, ambient only) per pixel, as rendered."""
    frame = clrt.Renderer(scene, device=device).render(camera, linear=True, hits=True)
    ground = frame.prim >= len(scene.objects[0].mesh.faces)
    return ground, ground & (frame.image.sum(axis=2) <= AMBIENT_ONLY * (1 + 1e-4))


def _edge(mask: np.ndarray) -> np.ndarray:
    """Pixels with both values of ``mask`` among their 3 x 3 neighbours."""
    padded = np.pad(mask, 1, mode="edge")
    near = [padded[1 + dy:1 + dy + mask.shape[0], 1 + dx:1 + dx + mask.shape[1]]
            for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    return np.any(near, axis=0) & ~np.all(near, axis=0)


@pytest.mark.parametrize("half", [1e3, 1e4, 1e6])
def test_the_shadow_stays_on_a_large_ground(half, device):
    """Before, the rays started 0.28, 2.8 and 280 off the ground: the shadow lost
    an eighth of its pixels, all of them, and (past the light) the ground went dark."""
    scene, camera = _torus_scene(half)
    ground, dark = _dark(scene, camera, device)
    seen, shadowed = _truth(scene, camera)
    shadowed &= ground & seen
    assert shadowed.sum() > 40, "the shadow must be in view"
    wrong = ground & (dark != shadowed)
    # the hit point carries its own float32 error (along the ground, 1e-7 of
    # its size), which may move the shadow's edge by a pixel; nothing else differs
    assert not (wrong & ~_edge(shadowed)).any(), f"{wrong.sum()} pixels differ, not all on the shadow's edge"
    assert 0.9 * shadowed.sum() <= dark.sum() <= 1.1 * shadowed.sum(), (dark.sum(), shadowed.sum())


@pytest.fixture(params=["device frame", "caller's frame"])
def frame_choice(request, monkeypatch):
    """Scenes far from the origin are moved near it for the device
    (clrt.scene.arrays.device_origin); the far-off cases run both ways, so
    that the offsets and the bound are also held at large coordinates."""
    if request.param == "caller's frame":
        from clrt.scene import arrays
        monkeypatch.setattr(arrays, "RECENTRE_DISTANCE", math.inf)
    return request.param


@pytest.mark.parametrize("half", [10.0, 1e3])
def test_the_shadow_stays_far_from_the_origin(half, device, frame_choice):
    """Moved to 1e7, where float32 holds whole units: the torus's corners snap to
    them, and so do the points the camera rays hit, so the shadow keeps its size
    but not its float64 edge.  Before, the rays started 10 off the ground, past
    the torus: no shadow, and (the light 5 above) no light either."""
    scene, camera = _torus_scene(half, shift=1e7)
    ground, dark = _dark(scene, camera, device)
    seen, shadowed = _truth(scene, camera)
    shadowed &= ground & seen
    assert shadowed.sum() > 20
    assert 0.6 * shadowed.sum() <= dark.sum() <= 1.4 * shadowed.sum(), (dark.sum(), shadowed.sum())
    assert (ground & ~dark).sum() > 0.8 * ground.sum()


def _lit_ground_scene(half, shift, tilt, material=MATTE):
    """A ground alone (tilted by ``tilt`` degrees about x and 0.7 of that about
    z, moved to ``shift``), the light 5 above it, the camera 3 above."""
    r = _rotation(tilt)
    up = r @ [0.0, 1.0, 0.0]
    s = np.asarray(shift, np.float64)
    scene = Scene([_ground(half, s, tilt, material)], [Light(tuple(s + r @ LIGHT))], background=(0.2, 0.3, 0.4))
    camera = Camera(tuple(s + r @ [0.0, 3.0, 5.0]), tuple(s + r @ [0.0, 0.0, 2.0]), up=tuple(up), fov=50,
                    width=32, height=24)
    return scene, camera


GROUNDS = [(1e3, 0.0, 0.0), (1e6, 0.0, 0.0), (1e6, 0.0, 30.0), (1e6, 0.0, 3.0), (1e3, 1e7, 0.0), (1e3, 1e7, 30.0),
           (1e6, 3e6, 17.0)]


@pytest.mark.parametrize("half, shift, tilt", GROUNDS)
def test_no_acne_on_large_tilted_grounds(half, shift, tilt, device, frame_choice):
    """Every pixel of a lit ground is lit: no shadow ray finds the ground again.
    The triangles are up to 2e6 across (from an origin near the middle, the
    triangle test rounds their corners by ~0.1: without certain_t_error a
    quarter of the rays leaving them would meet them again), tilted, and up
    to 1e7 from the origin."""
    scene, camera = _lit_ground_scene(half, (shift, 0.5 * shift, -0.3 * shift), tilt)
    frame = clrt.Renderer(scene, device=device).render(camera, linear=True, hits=True)
    ground = frame.prim >= 0
    assert ground.all(), "the ground fills the view"
    lum = frame.image.sum(axis=2)
    assert (lum > 1.5 * AMBIENT_ONLY).all(), f"{(lum <= 1.5 * AMBIENT_ONLY).sum()} pixels in shadow"


@pytest.mark.parametrize("half, shift, tilt", GROUNDS)
def test_a_large_mirror_does_not_reflect_itself(half, shift, tilt, device, frame_choice):
    """Reflection rays leave a mirror ground for the background: every pixel is
    the ground's own colour plus kr times the background, none the ground seen
    in itself."""
    mirror = Material(color=(0.8, 0.8, 0.8), ambient=0.1, diffuse=0.7, specular=0.0, reflectivity=0.5)
    scene, camera = _lit_ground_scene(half, (shift, 0.5 * shift, -0.3 * shift), tilt, mirror)
    frame = clrt.Renderer(scene, device=device).render(camera, linear=True, hits=True)
    matte = clrt.Renderer(Scene([SceneObject(scene.objects[0].mesh, MATTE)], scene.lights,
                                background=scene.background), device=device).render(camera, linear=True).image
    assert (frame.prim >= 0).all(), "the ground fills the view"
    expected = matte + 0.5 * np.asarray(scene.background, np.float32)
    assert np.abs(frame.image - expected).max() < 1e-5


def test_rays_from_spawned_origins_never_meet_their_own_triangle():
    """The rule itself, in the numpy reference (which mirrors the kernels):
    rays leaving random points of large tilted triangles, near and far from the
    origin, in random directions.  Without certain_t_error many of them meet
    their triangle again; with it, none."""
    rng = np.random.default_rng(5)
    base = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -0.3], [0.2, 0.0, 1.0]])
    # (size, centre, tilt, whether the plain test meets the triangle again): a
    # tilted triangle's points are so imprecise across it that their own offset
    # clears the test's rounding; a level one's are exact in height
    for size, centre, tilt, plain_fails in [(1e6, 0.0, 0.0, True), (1e6, 0.0, 30.0, False), (1e4, 0.0, 3.0, True),
                                            (1e3, 1e7, 30.0, False), (1.0, 1e7, 60.0, False)]:
        corners = (base * size @ _rotation(tilt).T + [centre, 0.3 * centre, -0.5 * centre]).astype(np.float32)
        tri = corners.astype(np.float64)
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        n /= np.linalg.norm(n)
        k = 4000
        # Points within 1 (or a tenth of the triangle) of (centre, 0.3 centre,
        # -0.5 centre), inside the triangle: there the corners are far, and
        # near the coordinates' origin the point is precise; and points
        # anywhere on it.
        near = [centre, 0.3 * centre, -0.5 * centre] + rng.uniform(-1, 1, (k // 2, 3)) * min(1.0, 0.1 * size)
        e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
        uv = np.linalg.lstsq(np.stack([e1, e2], axis=1), (near - tri[0]).T, rcond=None)[0].T
        w = np.concatenate([np.column_stack([1 - uv.sum(axis=1), uv]), rng.dirichlet([1, 1, 1], k // 2)])
        assert (w > 0).all()
        u, v = w[:, 1].astype(np.float32), w[:, 2].astype(np.float32)
        d = rng.normal(size=(k, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        side = np.where(d @ n < 0, -1.0, 1.0)
        ng = side[:, None] * n                       # the side each ray leaves to
        o = spawn_origin(point_and_offset(np.broadcast_to(corners, (k, 3, 3)), u, v, ng), d)
        assert ((o.astype(np.float64) - tri[0]) @ n * side > 0).all(), "every origin on the side it leaves"
        d32 = d.astype(np.float32)
        zeros, inf = np.zeros(k, np.float32), np.full(k, np.inf, np.float32)
        plain = intersect(o, d32, corners[None], zeros, inf, any_hit=True)
        certain = intersect(o, d32, corners[None], zeros, inf, any_hit=True, spawned=True)
        assert not certain.any(), (size, centre, tilt, certain.sum())
        if plain_fails:
            assert plain.sum() > 5, "the plain test must show the problem"


def _exact_t(origin, perm, shear, corners):
    """Where the ray the watertight test traces (its shear constants taken as
    exact) meets the plane of the triangle, in exact rational arithmetic; None
    where the plane lies along the ray."""
    o = [Fraction(float(x)) for x in origin]
    sx, sy, sz = (Fraction(float(s)) for s in shear)
    x, y, z = [], [], []
    for corner in corners:
        p = [Fraction(float(corner[i])) - o[i] for i in perm]
        x.append(p[0] - sx * p[2])
        y.append(p[1] - sy * p[2])
        z.append(sz * p[2])
    e = [x[2] * y[1] - y[2] * x[1], x[0] * y[2] - y[0] * x[2], x[1] * y[0] - y[1] * x[0]]
    return None if sum(e) == 0 else sum(a * b for a, b in zip(e, z)) / sum(e)


def test_the_error_bound_holds():
    """certain_t_error against exact arithmetic, for rays the test says hit:
    triangles up to 2e6 across and 1e7 from the origin, tilted, origins from
    1e-9 to 10 times the triangle's scale off its plane on either side, a third
    of the rays within a few degrees of the plane.  (The bound came out 5 to
    a few hundred times the real error when written.)"""
    rng = np.random.default_rng(11)
    base = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -0.3], [0.2, 0.0, 1.0]])
    checked = 0
    for size, centre, tilt in [(1e6, 0.0, 0.0), (1e6, 0.0, 30.0), (1e4, 0.0, 3.0), (1e3, 1e7, 30.0), (1.0, 1e7, 60.0),
                               (1.0, 0.0, 10.0), (1e-3, 5.0, 45.0), (1e5, 1e6, 80.0)]:
        corners = (base * size @ _rotation(tilt).T + [centre, 0.3 * centre, -0.5 * centre]).astype(np.float32)
        tri = corners.astype(np.float64)
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        n /= np.linalg.norm(n)
        k = 600
        scale = max(size, abs(centre))
        off = np.exp(rng.uniform(np.log(1e-9), np.log(10.0), k)) * scale * rng.choice([-1.0, 1.0], k)
        o = (rng.dirichlet([1, 1, 1], k) @ tri + off[:, None] * n).astype(np.float32)
        d = rng.normal(size=(k, 3))
        graze = rng.random(k) < 0.3
        d[graze] -= 0.999 * np.outer(d[graze] @ n, n)
        d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
        perm, shear = _shear(d)
        w = watertight(o, perm, shear, corners[None])
        error = certain_error_of(w, shear)[:, 0]
        t = w["t"][:, 0]
        hits = np.nonzero(w["inside"][:, 0] & (w["det"][:, 0] != 0) & np.isfinite(error))[0]
        assert len(hits) > 20
        for i in hits[:120]:
            exact = _exact_t(o[i], perm[i], shear[i], corners)
            if exact is not None:
                assert abs(Fraction(float(t[i])) - exact) <= Fraction(float(error[i])), (size, centre, tilt, i)
                checked += 1
    assert checked > 800

"""The camera model, anti-aliasing pattern and sRGB encoding against
independent numpy code (docs: vertical fov, pixel centres, row 0 at the top,
N x N jittered cells hashed by lowbias32, IEC 61966-2-1 curve)."""

import numpy as np
import pytest

import clrt

from numpy_whitted import SPAWN_EPS, Tracer, camera_dir, project, quad, srgb8

M = 0xFFFFFFFF


def _grid(n=24, size=6.0):
    xs = np.linspace(-size / 2, size / 2, n + 1)
    v = np.array([(x, y, 0.3 * x + 0.2 * y) for y in xs for x in xs], float)
    f = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            f += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    return v, np.array(f)


@pytest.mark.parametrize("w,h,eye,target,up,fov", [
    (48, 36, (0.3, 0.2, 6), (0.3, 0.2, 0), (0, 1, 0), 45),
    (36, 48, (0.3, 0.2, 6), (0.1, -0.2, 0), (0, 1, 0), 30),
    (40, 23, (-1, 2, 5), (0.2, 0.1, 0), (1, 1, 0.3), 60),
])
def test_camera_rays_match_pinhole(device, w, h, eye, target, up, fov):
    v, f = _grid()
    cam = clrt.Camera(eye=eye, target=target, up=up, fov=fov, width=w, height=h)
    scene = clrt.Scene([clrt.SceneObject((v, f))], [(0, 0, 10)])
    frame = clrt.Renderer(scene, device=device).render(cam, hits=True)
    tr = Tracer(v[f], [{}] * len(f), [])
    for py in range(h):
        for px in range(w):
            t, i = tr.intersect(np.array(eye, float), camera_dir(eye, target, up, fov, w, h, px, py))
            assert frame.prim[py, px] == i, (px, py)
            if i >= 0:
                assert frame.t[py, px] == pytest.approx(t, rel=1e-5)
    # a vertex projects (continuous coordinates) into a pixel showing one of its triangles
    x, y = project(eye, target, up, fov, w, h, v[312])
    assert frame.prim[int(y), int(x)] in set(np.where((f == 312).any(1))[0])


def _h32(x):
    x &= M
    x ^= x >> 16
    x = (x * 0x7FEB352D) & M
    x ^= x >> 15
    x = (x * 0x846CA68B) & M
    return x ^ (x >> 16)


def _offset(pixel, s, n, seed):
    key = (_h32(seed) ^ ((pixel * n * n + s) * 2)) & M
    jx, jy = (_h32(key) >> 8) / 2**24, (_h32((key + 1) & M) >> 8) / 2**24
    return (float(np.float32((np.float32(s % n) + np.float32(jx)) / np.float32(n))),
            float(np.float32((np.float32(s // n) + np.float32(jy)) / np.float32(n))))


def test_antialiasing_is_mean_of_documented_subpixel_rays(device):
    w, h, n, seed = 48, 36, 3, 7
    cam = clrt.Camera(eye=(0, 3, 3), target=(0, 0, 0), fov=45, width=w, height=h)
    v, f = quad((0, 0, 0), (6, 6), "+y")
    bv, bf = quad((0.3, 1.0, 0.2), (0.6, 0.4), "+y")
    mat = dict(color=(0.6, 0.5, 0.4), ambient=0.2, diffuse=0.7, specular=0.5, shininess=20, smooth=False)
    scene = clrt.Scene([clrt.SceneObject((v, f), mat), clrt.SceneObject((bv, bf), dict(smooth=False))],
                       [clrt.Light((1.0, 2.0, 0.5), (1.0, 0.8, 0.6))])
    r = clrt.Renderer(scene, device=device)
    a = r.render(cam, linear=True, samples=n, seed=seed).image
    assert np.array_equal(a, r.render(cam, linear=True, samples=n, seed=seed).image)
    assert not np.array_equal(a, r.render(cam, linear=True, samples=n, seed=seed + 1).image)
    tris = np.concatenate([v[f], bv[bf]])
    mats = [dict(mat)] * 2 + [dict(color=(0.8, 0.8, 0.8), ambient=0.1, diffuse=0.7, specular=0.3, shininess=32)] * 2
    tr = Tracer(tris, mats, [((1.0, 2.0, 0.5), (1.0, 0.8, 0.6))], eps=SPAWN_EPS)
    edges = np.argwhere(np.abs(np.diff(a.sum(2), axis=1)) > 0.02)
    assert len(edges) > 10
    for py, px in edges[:: max(1, len(edges) // 30)]:
        py, px = int(py), int(px)
        cols = [tr.trace(np.array(cam.eye, float),
                         camera_dir(cam.eye, cam.target, cam.up, cam.fov, w, h, px, py,
                                    *_offset(py * w + px, s, n, seed))) for s in range(n * n)]
        assert np.abs(np.mean(cols, 0) - a[py, px]).max() < 2e-5, (px, py)


def test_srgb8_is_iec_curve_rounded(device):
    cam = clrt.Camera(eye=(0, 3, 3), target=(0, 0, 0), fov=60, width=48, height=36)
    v, f = quad((0, 0, 0), (10, 10), "+y")
    scene = clrt.Scene([clrt.SceneObject((v, f), dict(color=(0.9, 0.3, 0.02), ambient=0.0, diffuse=1.0,
                                                       specular=0.8, shininess=5, smooth=False))],
                       [clrt.Light((0.5, 1.0, 0.5), (3.0, 0.5, 0.05))], background=(0.001, 0.0, 2.0),
                       ambient_light=(0, 0, 0))
    r = clrt.Renderer(scene, device=device)
    linear = r.render(cam, linear=True).image
    assert (linear > 1).any() and ((linear > 0) & (linear < 0.0031308)).any()
    assert np.array_equal(r.render(cam).image, srgb8(linear.astype(np.float64)))

"""clrt's pixels against an independent numpy Whitted tracer
(tests/numpy_whitted.py), written from the documented shading model:
Phong ambient + Lambert + (R.V)^n specular, hard shadows, no attenuation,
colour = local + kr C(refl) + kt [F C(refl) + (1 - F) colour C(refr)],
Schlick F, rays below weight 1e-3 dropped, max_depth bounces."""

import math

import numpy as np
import pytest

import clrt
from clrt.scene import primitives
from numpy_whitted import SPAWN_EPS, Tracer, camera_dir, quad

W, H = 48, 36
TOL = 2e-5
DEFAULTS = dict(ambient=0.1, diffuse=0.7, specular=0.3, shininess=32, color=(0.8, 0.8, 0.8))


def _build(objs, lights, cam, **kw):
    so, tris, mats, vn = [], [], [], []
    for v, f, m in objs:
        so.append(clrt.SceneObject((v, f), clrt.Material(**m)))
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        acc = np.zeros_like(v)
        for k in range(3):
            np.add.at(acc, f[:, k], n)       # area-weighted vertex normals
        acc /= np.linalg.norm(acc, axis=1, keepdims=True)
        for face in f:
            tris.append(v[face])
            mats.append(dict(DEFAULTS, **m))
            vn.append(acc[face])
    scene = clrt.Scene(so, [clrt.Light(p, c) for p, c in lights], **kw)
    tr = Tracer(np.array(tris), mats, lights, ambient_light=kw.get("ambient_light", (1, 1, 1)),
                background=kw.get("background", (0, 0, 0)), eps=SPAWN_EPS,
                max_depth=kw.get("max_depth", 5))
    tr.vnormals = np.array(vn)
    return scene, tr


def _worst(scene, tr, cam, device):
    frame = clrt.Renderer(scene, device=device).render(cam, linear=True, hits=True)
    worst = 0.0
    for y in range(cam.height):
        for x in range(cam.width):
            d = camera_dir(cam.eye, cam.target, cam.up, cam.fov, cam.width, cam.height, x, y)
            expected = tr.trace(np.array(cam.eye, float), d, cutoff=1e-3)
            worst = max(worst, float(np.abs(expected - frame.image[y, x]).max()))
    return worst


FLOOR = dict(color=(0.6, 0.5, 0.4), ambient=0.2, diffuse=0.7, specular=0.5, shininess=20, smooth=False)
GLASS = dict(color=(0.95, 0.97, 1.0), ambient=0.0, diffuse=0.05, specular=0.9, shininess=200,
             transparency=0.9, ior=1.5, smooth=False)
TOP = clrt.Camera(eye=(0, 3, 3), target=(0, 0, 0), fov=45, width=W, height=H)
SIDE = clrt.Camera(eye=(0.7, 1.2, 4), target=(0, 0.8, 0), fov=45, width=W, height=H)


def _floor_and_blocker(blocker=None):
    v, f = quad((0, 0, 0), (6, 6), "+y")
    bv, bf = quad((0.3, 1.0, 0.2), (0.6, 0.4), "+y")
    return [(v, f, FLOOR), (bv, bf, blocker or dict(color=(0.2, 0.9, 0.2), smooth=False))]


def _walls():
    v, f = quad((0, 0, 0), (6, 6), "+y")
    out = [(v, f, dict(smooth=False))]
    for k, col in enumerate([(0.9, 0.1, 0.1), (0.1, 0.9, 0.1), (0.1, 0.1, 0.9), (0.9, 0.9, 0.1)]):
        wv, wf = quad((-1.5 + k, 1.0, -2.0), (1.0, 2.0), "+z")
        out.append((wv, wf, dict(color=col, smooth=False)))
    return out


@pytest.mark.parametrize("light", [(1.0, 2.0, 0.5), (1.0, -1.0, 0.5), (1.0, 0.0, 0.5), (0.2, 0.9, 0.3)],
                         ids=["above", "below", "in-plane", "under-blocker"])
def test_phong_shadow_matches_numpy(device, light):
    scene, tr = _build(_floor_and_blocker(), [(light, (1.0, 0.8, 0.6))], TOP,
                       ambient_light=(0.3, 0.4, 0.5), background=(0.1, 0.2, 0.3))
    assert _worst(scene, tr, TOP, device) < TOL


@pytest.mark.parametrize("kr", [1.0, 0.5])
def test_mirror_matches_numpy(device, kr):
    objs = _walls()
    objs[0] = (objs[0][0], objs[0][1], dict(color=(0.7, 0.7, 0.7), ambient=0.05, diffuse=0.1, reflectivity=kr,
                                            smooth=False))
    scene, tr = _build(objs, [((-1.0, 3.0, 2.0), (1, 1, 1))], SIDE, background=(0.2, 0.3, 0.4))
    assert _worst(scene, tr, SIDE, device) < TOL


@pytest.mark.parametrize("max_depth", [1, 5])
def test_glass_slab_matches_numpy(device, max_depth):
    slab = primitives.box((1.6, 1.2, 0.5), (0, 0.8, 0.5))
    objs = _walls() + [(slab.vertices.astype(float), slab.faces, GLASS)]
    scene, tr = _build(objs, [((-2.0, 4.0, 3.0), (1, 1, 1))], SIDE, background=(0.2, 0.3, 0.4), max_depth=max_depth)
    assert _worst(scene, tr, SIDE, device) < TOL


@pytest.mark.parametrize("material", [dict(color=(0.7, 0.3, 0.3), specular=0.6, crease=180),
                                      dict(GLASS, smooth=True, crease=180)], ids=["phong", "glass"])
def test_smooth_sphere_matches_numpy(device, material):
    s = primitives.icosphere(2, 0.7, (0, 0.8, 0.3))
    objs = _walls() + [(s.vertices.astype(float), s.faces, material)]
    scene, tr = _build(objs, [((-2.0, 4.0, 3.0), (1, 1, 1))], SIDE, background=(0.2, 0.3, 0.4))
    assert _worst(scene, tr, SIDE, device) < TOL


def test_oracle_obeys_snell():
    """The oracle's refraction itself: n1 sin(i) = n2 sin(t) through a slab's top face."""
    tri = np.array([[[-5, 0, -5], [-5, 0, 5], [5, 0, 5]], [[-5, 0, -5], [5, 0, 5], [5, 0, -5]]], float)
    tr = Tracer(tri, [dict(DEFAULTS, transparency=1.0, ior=1.5)] * 2, [], eps=0.0, max_depth=1)
    seen = []
    orig = tr.trace

    def spy(o, d, depth=0, info=None, weight=None, cutoff=0.0):
        seen.append(d)
        return orig(o, d, depth, info, weight, cutoff)
    tr.trace = spy
    d = np.array([math.sin(0.6), -math.cos(0.6), 0.0])
    tr.trace(np.array([0.0, 1.0, 0.0]), d)
    refracted = [s for s in seen[1:] if s[1] < 0][0]
    assert math.sin(0.6) == pytest.approx(1.5 * math.hypot(refracted[0], refracted[2]), rel=1e-12)

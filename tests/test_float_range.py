"""The float32 range of the triangle test: rays that would overflow it are refused.

Woop's test multiplies a triangle's (sheared) area by the depths of its
corners, all measured from the ray's origin, so a large triangle seen from far
away overflows float32 and is silently missed.  clrt.device.reach bounds that
product; the queries check each batch's origins against it and the renderer
its eye and the scene's own rays.  These tests measure the real overflow on the
device (with the check switched off) and hold the check to it: it admits
nothing that loses a hit, and refuses no more than a few times too early.
"""

import math

import numpy as np
import pytest

import clrt
from clrt import cli
from clrt.device import reach as reach_module
from clrt.scene import primitives
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Scene, SceneObject

SIZES = [1e11, 1e12, 1e13, 1e14]                      # across the triangle
DISTANCES = [1e10, 1e12, 3e12, 1e13, 3e13, 1e14, 3e14, 1e15, 3e15, 1e16, 3e16, 1e17]   # from (0, 0, 0)


def _triangle_and_rays(size: float, distance: float, n: int = 200):
    """A triangle ``size`` across in the plane z = ``distance``, and unit rays from
    the origin aimed well inside it (barycentric weights >= 0.05)."""
    v = np.array([[-size / 2, -0.4 * size, distance], [size / 2, -0.4 * size, distance], [0.0, 0.4 * size, distance]])
    mesh = Mesh.from_arrays(v, [[0, 1, 2]])
    w = 0.05 + 0.85 * np.random.default_rng(3).dirichlet([1, 1, 1], n)
    return mesh, w @ mesh.vertices.astype(np.float64)


def _refused(accel) -> bool:
    """Does the check refuse rays from (0, 0, 0) on this scene (as it refuses a
    camera's eye there)?"""
    try:
        accel.geometry.reach.check(np.zeros(3), np.zeros(3), "the rays start")
    except clrt.InputError as exc:
        assert "float32 triangle test overflows" in str(exc) and "\n" not in str(exc)
        return True
    return False


def test_the_check_admits_no_lost_hit_and_refuses_only_near_the_overflow(device):
    refused, worked, lost = [], {}, {}   # per size: the farthest corner's distance of rays that worked / lost hits
    for size in SIZES:
        for distance in DISTANCES:
            mesh, directions = _triangle_and_rays(size, distance)
            accel = clrt.Accel(mesh, accel="none", device=device)
            is_refused = _refused(accel)
            # what the device does (a batch's origins are not checked)
            hit, blocked = accel.trace(np.zeros(3), directions).hit, accel.any_hit(np.zeros(3), directions)
            label = f"triangle {size:g} across at {distance:g}"
            assert is_refused or hit.all(), f"{label}: admitted, but {(~hit).sum()} of {len(hit)} hits lost"
            assert is_refused or blocked.all(), f"{label}: admitted, but any_hit lost {(~blocked).sum()}"
            refused.append(is_refused)
            rho = math.hypot(distance, 0.64 * size)
            if hit.all() and blocked.all():
                worked[size] = max(worked.get(size, 0.0), rho)
            else:
                lost[size] = min(lost.get(size, math.inf), rho)
    assert 10 <= sum(refused) <= len(refused) - 10, "the grid must hold both"
    assert set(lost) == set(SIZES) and len(worked) >= 3, (worked, lost)
    # Not too early: the distance the check allows lies between the farthest
    # rays that worked, over 8, and the nearest that lost hits.
    for size in worked:
        mesh, _ = _triangle_and_rays(size, 0.0)
        allowed = reach_module.Reach(mesh.vertices[mesh.faces].astype(np.float32)).limit()
        assert worked[size] / 8 < allowed < lost[size], (size, allowed, worked[size], lost[size])


def test_far_origins_and_eyes_get_one_line(device):
    mesh = primitives.icosphere(2)
    accel = clrt.Accel(mesh, device=device)
    near = accel.trace([0.0, 0.0, 1e15], [0.0, 0.0, -1.0])   # far, but within range: traced
    assert near.hit[0] and near.t[0] == pytest.approx(1e15, rel=1e-6)
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, -1e17]
    with pytest.raises(clrt.InputError, match=r"^the camera's eye lies 1e17 from the scene's far side"):
        accel.camera_images(K=np.diag([100.0, 100.0, 1.0]), pose=pose, width=4, height=4)
    with pytest.raises(clrt.InputError, match=r"^the camera's eye lies 1e17 from the scene's far side, but the "
                                              r"device's float32 triangle test overflows .* from past 4\.\de16: "):
        accel.camera_images(Camera((0.0, 0.0, 1e17), (0.0, 0.0, 0.0), width=4, height=4))
    # A refit moves the scene, and the range with it.
    accel.refit(mesh.vertices.astype(np.float64) * 1e13)
    with pytest.raises(clrt.InputError, match=r"^the camera's eye lies 1\.1e14 .* from past 1\.\de13: "):
        accel.camera_images(Camera((0.0, 0.0, 1e14), (0.0, 0.0, 0.0), width=4, height=4))


def _ground_scene(half: float) -> Scene:
    """A unit torus on a square ground ``2 * half`` across, lit from above."""
    ground = Mesh.from_arrays([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]],
                              [[0, 2, 1], [0, 3, 2]])
    torus = primitives.torus(1.0, 0.35, 24, 12)
    torus = Mesh.from_arrays(torus.vertices.astype(np.float64) + [0.0, 0.6, 0.0], torus.faces)
    return Scene([SceneObject(torus), SceneObject(ground)], [Light((1.5, 5.0, 1.0))])


def test_a_scene_too_large_for_the_triangle_test_is_refused_when_rendered(device, tmp_path, capsys):
    camera = Camera((0.0, 3.0, 5.0), (0.0, 0.3, 0.0), width=16, height=12)
    frame = clrt.Renderer(_ground_scene(1e12), device=device).render(camera, hits=True)   # within range
    assert (frame.prim >= 0).any()
    renderer = clrt.Renderer(_ground_scene(1e13), device=device)
    with pytest.raises(clrt.InputError, match=r"^the camera's rays and the rays between the scene's surfaces "
                                              r"start up to 2\.8e13 from the scene's far side, .* from past "
                                              r"2\.\de11: "):
        renderer.render(camera)
    # The same from the command line: one line, exit 2, nothing written.
    scene = tmp_path / "ground.toml"
    scene.write_text('[camera]\neye = [0, 3, 5]\ntarget = [0, 0.3, 0]\nwidth = 16\nheight = 12\n'
                     '[[objects]]\ntype = "sphere"\n[[objects]]\ntype = "plane"\nsize = [2e13, 2e13]\n')
    code = cli.main(["render", str(scene), "-o", str(tmp_path / "out.png"), *(["--device", device] if device else [])])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "float32 triangle test overflows" in err, err
    assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("scale, offset", [(1e-6, 0.0), (1e-9, 0.0), (1e-12, 0.0), (1.0, 1e5), (1e-9, 1e-3)])
def test_automatic_framing_fills_the_frame_at_any_scale(scale, offset, device):
    """A mesh framed by clrt covers as much of the image whether it is a metre,
    a micron or a nanometre across, at the origin or far from it (the framing
    once kept the camera at least 1e-6 away: a nanometre mesh was a speck)."""
    sphere = primitives.icosphere(2)
    unit = clrt.Renderer(sphere, device=device).render(hits=True)
    moved = Mesh.from_arrays(sphere.vertices.astype(np.float64) * scale + offset * np.array([1.0, 0.6, -0.4]),
                             sphere.faces)
    frame = clrt.Renderer(moved, device=device).render(hits=True)
    covered, expected = (frame.prim >= 0).mean(), (unit.prim >= 0).mean()
    assert 0.1 < expected < 0.5 and abs(covered - expected) < 0.01 * expected, (covered, expected)


@pytest.mark.parametrize("accel", ["none", "box"])
def test_an_overflowed_triangle_test_is_no_hit_for_any_query(accel, device):
    """Past the float32 range (a triangle 1e13 across seen from 3e15, origins
    that a batch does not check) the test's T overflows to t = inf: the closest
    hit never took that as a hit, and any-hit, counts and all hits now agree."""
    size, distance = 1e13, 3e15
    mesh, directions = _triangle_and_rays(size, distance)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    queries = clrt.Accel(mesh, accel=accel, device=device)
    origin = np.zeros(3)
    hits = queries.trace(origin, directions).hit
    assert not hits.any()
    assert np.array_equal(queries.any_hit(origin, directions), hits)
    assert not queries.count(origin, directions).any()
    assert len(queries.all_hits(origin, directions).t) == 0

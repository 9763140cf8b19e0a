"""Scenes far from the origin go to the device moved near it (clrt.scene.arrays.device_origin).

The subtraction of the device origin c is exact for every vertex, and for
every ray origin near the scene, so every answer is the one the scene gives
where it lies: the same mesh and rays moved by 1e4 or 1e6 (on a grid where
the move is exact) answer bit for bit as at the origin, with or without the
move, through every query, BVH, walk, refit and the renderer -- only faster
(docs/limits.md, "Precision").  Rays from far away round once more, by as much
as the triangle test rounds them anyway.
"""

import math

import numpy as np
import pytest

import clrt
from clrt.device import geometry
from clrt.scene import arrays, primitives
from clrt.scene.arrays import device_origin
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject

GRID = 1.0 / 16        # float32 step at 1e6: coordinates on it move there exactly
SHIFT = np.array([1.0, -0.5, 0.25])
OFFSETS = [0.0, 1e4, 1e6]


def _snapped(vertices) -> np.ndarray:
    return np.round(np.asarray(vertices, np.float64) / GRID) * GRID


def _torus(scale: float = 4.0) -> Mesh:
    t = primitives.torus(1.0, 0.35, 24, 12)
    return Mesh.from_arrays(_snapped(t.vertices.astype(np.float64) * scale), t.faces)


def _moved(mesh: Mesh, offset: float) -> Mesh:
    return Mesh.from_arrays(mesh.vertices.astype(np.float64) + offset * SHIFT, mesh.faces)


def _rays(mesh: Mesh, n: int = 600, seed: int = 5):
    """Origins on the grid around the mesh (some inside it), random directions
    and directions at vertices (rays through corners and edges)."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    centre, size = (lo + hi) / 2, hi - lo
    o = _snapped(centre + rng.uniform(-0.8, 0.8, (n, 3)) * size)
    d = rng.normal(size=(n, 3))
    at_vertex = rng.random(n) < 0.3
    targets = mesh.vertices[rng.integers(0, len(mesh.vertices), n)].astype(np.float64)
    d[at_vertex] = (targets - o)[at_vertex]
    return o, d.astype(np.float32)


def _answers(accel, o, d) -> dict:
    hits = accel.trace(o, d)
    every = accel.all_hits(o, d, tmin=-np.inf)
    out = {name: getattr(hits, name) for name in ("t", "prim", "u", "v", "normal", "front", "hit")}
    out.update(any=accel.any_hit(o, d), back=accel.trace(o, d, cull="back").prim,
               count=accel.count(o, d, tmin=-1.0), all_ray=every.ray_id, all_prim=every.prim, all_t=every.t)
    return out


def _assert_same(a: dict, b: dict, label: str) -> None:
    for name in a:
        assert np.array_equal(a[name], b[name]), f"{label}: {name} differs"


def _no_recentring(monkeypatch):
    monkeypatch.setattr(arrays, "RECENTRE_DISTANCE", math.inf)


# ----------------------------------------------------------------------- the origin chosen

def test_scenes_near_the_origin_keep_their_frame():
    for bounds in ([[-1, -1, -1], [1, 1, 1]], [[10, 10, 10], [12, 12, 12]], [[-3e4, 5, 5], [3e4, 6, 6]],
                   [[1e4, -1, -1], [1e4 + 1e3, 1, 1]]):
        assert not device_origin(np.array(bounds, np.float64)).any(), bounds


@pytest.mark.parametrize("seed", range(40))
def test_the_origin_moves_every_vertex_exactly(seed):
    """Random boxes of random sizes at random distances (up to the float32
    range), random float32 vertices in them: v - c in float32 is v - c."""
    rng = np.random.default_rng(seed)
    size = 10.0 ** rng.uniform(-12, 6)
    distance = size * 10.0 ** rng.uniform(0, 8) * rng.choice([-1, 1], 3)
    v = (distance + rng.uniform(-0.5, 0.5, (500, 3)) * size * rng.uniform(0, 1, 3)).astype(np.float32)
    bounds = np.stack([v.min(axis=0), v.max(axis=0)]).astype(np.float64)
    c = device_origin(bounds)
    diagonal = np.linalg.norm(bounds[1] - bounds[0])
    moved = (v - c.astype(np.float32)).astype(np.float64)
    assert np.array_equal(moved, v.astype(np.float64) - c), seed
    far = np.minimum(abs(bounds[0]), abs(bounds[1])) >= arrays.RECENTRE_DISTANCE * diagonal
    far &= bounds[0] * bounds[1] > 0
    assert np.array_equal(c != 0, far), (c, bounds)
    assert (abs(c - bounds.mean(axis=0))[far] <= diagonal / 8 + np.spacing(abs(c[far]).astype(np.float32))).all()


def test_the_origin_of_odd_scenes():
    point = np.array([[1e6 + 0.5, -3.0, 7e-3]] * 2, np.float32).astype(np.float64)   # every vertex at one point
    assert np.array_equal(device_origin(point), point[0])
    tiny = np.array([[1e-3, 1e-3, 1e-3], [1e-3 + 2e-9, 1e-3 + 2e-9, 1e-3 + 2e-9]]).astype(np.float32)
    c = device_origin(tiny.astype(np.float64))
    assert c.all() and (abs(c - tiny.mean(axis=0)) <= 1e-9).all()
    huge = np.array([[-1e30, 0, 0], [-1e30 + 1e24, 1, 1]], np.float32).astype(np.float64)
    assert device_origin(huge)[0] != 0 and not device_origin(huge)[1:].any()
    assert not device_origin(np.array([[0, 0, 0], [np.inf, 1, 1]])).any()


# ----------------------------------------------------------------------- queries

@pytest.mark.parametrize("accel, builder", [("box", "sah"), ("box", "device"), ("sphere", "paper"),
                                            ("ellipse", "sah"), ("none", "sah")])
def test_a_moved_mesh_answers_every_query_as_at_the_origin(accel, builder, device, monkeypatch):
    base = _torus()
    o, d = _rays(base)
    expected = _answers(clrt.Accel(base, accel=accel, builder=builder, device=device), o, d)
    assert expected["hit"].mean() > 0.3 and (~expected["hit"]).any() and expected["count"].max() >= 4
    for offset in OFFSETS[1:]:
        mesh = _moved(base, offset)
        assert np.array_equal(mesh.vertices.astype(np.float64), base.vertices + offset * SHIFT)   # exact
        moved = clrt.Accel(mesh, accel=accel, builder=builder, device=device)
        assert np.array_equal(moved.geometry.origin, offset * SHIFT)
        _assert_same(expected, _answers(moved, o + offset * SHIFT, d), f"moved by {offset:g}")
    _no_recentring(monkeypatch)   # as before the move: the same answers, slower
    unmoved = clrt.Accel(_moved(base, 1e6), accel=accel, builder=builder, device=device)
    assert not unmoved.geometry.origin.any()
    _assert_same(expected, _answers(unmoved, o + 1e6 * SHIFT, d), "not moved")


@pytest.mark.parametrize("walk", ["single rays", "binary"])
def test_every_walk_answers_a_moved_mesh_as_at_the_origin(walk, device, monkeypatch):
    """The CPU walks (packets of rays, the wide BVH) and the single-ray, binary
    ones: each moves its rays' origins the same way."""
    monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    if walk == "binary":
        monkeypatch.setattr(geometry, "WIDE_BVH_KINDS", ())
    base = _torus()
    o, d = _rays(base, seed=9)
    expected = _answers(clrt.Accel(base, device=device), o, d)
    moved = clrt.Accel(_moved(base, 1e6), device=device)
    _assert_same(expected, _answers(moved, o + 1e6 * SHIFT, d), walk)


def _moller_trumbore(o, d, corners):
    """float64 closest hits: t (inf), prim (-1), and how near each ray passes to
    an edge ahead of it (the smallest |barycentric weight|)."""
    o, d, corners = (np.asarray(x, np.float64) for x in (o, d, corners))
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    v0, e1, e2 = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    p = np.cross(d[:, None], e2[None])
    det = np.einsum("nfk,fk->nf", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = o[:, None] - v0[None]
        u = np.einsum("nfk,nfk->nf", s, p) / det
        q = np.cross(s, e1[None])
        v = np.einsum("nk,nfk->nf", d, q) / det
        t = np.einsum("fk,nfk->nf", e2, q) / det
    weight = np.minimum(np.minimum(u, v), 1 - u - v)      # >= 0 inside the triangle
    ok = (weight >= 0) & (t > 0)
    # how near each ray passes to an edge of a triangle ahead of it
    margin = np.where(t > 0, np.abs(weight), np.inf).min(axis=1)
    t = np.where(ok, t, np.inf)
    prim = np.argmin(t, axis=1)
    rows = np.arange(len(o))
    hit = np.isfinite(t[rows, prim])
    return np.where(hit, t[rows, prim], np.inf), np.where(hit, prim, -1), margin


def test_rays_from_far_away_answer_as_float64(device, monkeypatch):
    """Origins that do not move exactly (far from the mesh, on the other side of
    the world origin) round once: the answers are those of float64 on the
    snapped mesh, as they are without the move."""
    mesh = _moved(_torus(1000.0), 1e6)     # 5,400 across: seen from 1e6 away, float32 sees 0.1 sharp
    rng = np.random.default_rng(12)
    o = rng.uniform(-3, 3, (400, 3)) + [3.3, 1.7, 0.2]
    targets = mesh.vertices[rng.integers(0, len(mesh.vertices), 400)].astype(np.float64)
    d = targets + rng.normal(scale=300.0, size=(400, 3)) - o
    o32 = o.astype(np.float32).astype(np.float64)
    t, prim, margin = _moller_trumbore(o32, d.astype(np.float32), mesh.vertices[mesh.faces])
    clear = margin > 1e-3                 # well inside or well off every triangle
    moved = clrt.Accel(mesh, device=device)
    assert moved.geometry.origin.any()
    hits = moved.trace(o, d)
    assert clear.mean() > 0.5 and np.isfinite(t[clear]).mean() > 0.3 and (~np.isfinite(t[clear])).any()
    assert np.array_equal(hits.prim[clear], prim[clear])
    assert np.allclose(hits.t[clear & np.isfinite(t)], t[clear & np.isfinite(t)], rtol=3e-7)
    _no_recentring(monkeypatch)
    plain = clrt.Accel(mesh, device=device).trace(o, d)
    assert np.array_equal(plain.prim[clear], hits.prim[clear])


def test_a_refit_moves_the_frame_with_the_mesh(device):
    """A refit to vertices far away (or back) chooses the frame a new Accel
    would, and answers as one."""
    base = _torus()
    o, d = _rays(base, 300, seed=2)
    expected = _answers(clrt.Accel(base, device=device), o, d)
    accel = clrt.Accel(_moved(base, 1e4), device=device)
    for offset in (1e6, 0.0, 1e4):
        accel.refit(_moved(base, offset).vertices)
        assert np.array_equal(accel.geometry.origin, offset * SHIFT)
        assert np.array_equal(accel.geometry.reach.lo, _moved(base, offset).bounds[0])   # the caller's frame
        _assert_same(expected, _answers(accel, o + offset * SHIFT, d), f"refit to {offset:g}")


def test_cameras_and_locations_speak_the_callers_coordinates(device):
    base = _torus()
    offset = 1e6 * SHIFT
    at_origin, moved = clrt.Accel(base, device=device), clrt.Accel(_moved(base, 1e6), device=device)
    camera = Camera((3.0, 9.0, 12.0), (0.0, 0.0, 0.0), width=40, height=30)
    far_camera = Camera(tuple(np.array(camera.eye) + offset), tuple(offset), width=40, height=30)
    a, b = at_origin.camera_images(camera), moved.camera_images(far_camera)
    assert (a.prim >= 0).mean() > 0.2
    for name in a._fields:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    pose = np.eye(4)
    pose[:3, 3] = [0.5, 0.25, -12.0]
    K = np.array([[40.0, 0, 20], [0, 40.0, 15], [0, 0, 1]])
    far_pose = pose.copy()
    far_pose[:3, 3] += offset
    a = at_origin.camera_images(K=K, pose=pose, width=40, height=30)
    b = moved.camera_images(K=K, pose=far_pose, width=40, height=30)
    assert (a.hit).mean() > 0.1 and np.array_equal(a.t, b.t) and np.array_equal(a.prim, b.prim)
    o, d = _rays(base, 200, seed=4)
    near = clrt.RayMeshIntersector(base, device=device).intersects_location(o, d)
    far = clrt.RayMeshIntersector(_moved(base, 1e6), device=device).intersects_location(o + offset, d)
    assert np.array_equal(near[1], far[1]) and np.array_equal(near[2], far[2])
    assert np.allclose(far[0] - offset, near[0], atol=0.07)   # locations in the caller's frame (step 1/16)
    # The range of the triangle test is measured in the caller's frame too.
    with pytest.raises(clrt.InputError, match=r"^origin 0 is \[1e\+17, .*it lies 1e17 from"):
        moved.trace([1e17, offset[1], offset[2]], [-1.0, 0.0, 0.0])


# ----------------------------------------------------------------------- frames

def _ground_and_torus(offset) -> Scene:
    """A mirror torus over a ground, on the grid, lit from above, moved by ``offset``."""
    ground = Mesh.from_arrays(np.array([[-6, -1.5, -6], [6, -1.5, -6], [6, -1.5, 6], [-6, -1.5, 6]]) + offset,
                              [[0, 2, 1], [0, 3, 2]])
    torus = _moved(_torus(1.5), 0.0)
    torus = Mesh.from_arrays(torus.vertices.astype(np.float64) + offset, torus.faces)
    shiny = Material(color=(0.9, 0.6, 0.3), reflectivity=0.3)
    return Scene([SceneObject(torus, shiny), SceneObject(ground)], [Light(tuple(np.array([2.0, 6.0, 3.0]) + offset))])


def _frame(scene: Scene, offset, device):
    camera = Camera(tuple(np.array([1.0, 4.0, 9.0]) + offset), tuple(np.array([0.0, -0.5, 0.0]) + offset),
                    width=48, height=36)
    renderer = clrt.Renderer(scene, device=device)
    return renderer, renderer.render(camera, hits=True, samples=2)


@pytest.mark.parametrize("offset", [1e4, 1e6])
def test_a_moved_scene_renders_the_image_it_renders_at_the_origin(offset, device, monkeypatch):
    _, expected = _frame(_ground_and_torus(0.0), 0.0, device)
    assert (expected.prim >= 0).mean() > 0.5 and (expected.prim < 0).any()
    move = offset * SHIFT
    renderer, frame = _frame(_ground_and_torus(move), move, device)
    assert np.array_equal(renderer.geometry.origin, move)
    assert np.array_equal(frame.image, expected.image)
    assert np.array_equal(frame.prim, expected.prim) and np.array_equal(frame.t, expected.t)
    # Queries on the renderer's scene follow its frame.
    queries = clrt.Accel.from_renderer(renderer)
    o, d = _rays(_torus(1.5), 100, seed=1)
    near = clrt.Accel.from_renderer(_frame(_ground_and_torus(0.0), 0.0, device)[0])
    _assert_same(_answers(near, o, d), _answers(queries, o + move, d), "from_renderer")
    if offset == 1e6:   # the test has teeth: without the move the image is not the same
        _no_recentring(monkeypatch)
        assert not np.array_equal(_frame(_ground_and_torus(move), move, device)[1].image, expected.image)


def test_a_renderer_refit_moves_the_frame_with_the_scene(device):
    _, expected = _frame(_ground_and_torus(0.0), 0.0, device)
    renderer = clrt.Renderer(_ground_and_torus(1e4 * SHIFT), device=device)
    for offset in (1e6, 0.0):
        move = offset * SHIFT
        renderer.refit(_ground_and_torus(move))
        assert np.array_equal(renderer.geometry.origin, move)
        camera = Camera(tuple(np.array([1.0, 4.0, 9.0]) + move), tuple(np.array([0.0, -0.5, 0.0]) + move),
                        width=48, height=36)
        frame = renderer.render(camera, hits=True, samples=2)
        assert np.array_equal(frame.image, expected.image), offset
        assert np.array_equal(frame.t, expected.t)


def test_the_offsets_benchmark_runs_and_finds_the_same_answers(device, capsys):
    from benchmarks import offsets
    assert offsets.main(["--offsets", "0,1e5", "--rays", "500", "--repeat", "1",
                         *(["--device", device] if device else [])]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| 0 ") or line.startswith("| 100000 ")]
    assert len(rows) == 2 and all(row.rstrip().endswith("| yes |") for row in rows), out
    assert "| 100000 | 100000, 100000, 100000 |" in out

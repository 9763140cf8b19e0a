"""The float32 range of the triangle test: rays that would overflow it are refused.

Woop's test multiplies a triangle's (sheared) area by the depths of its
corners, all measured from the ray's origin, so a large triangle seen from far
away overflows float32 and is silently missed.  clrt.device.reach bounds that
product; the queries check each batch's origins against it (on the device,
rays.cl) and a camera's eye (on the host), the renderer its eye and the
scene's own rays.  These tests measure the real overflow on the device (with
the check switched off) and hold the check to it: it admits nothing that
loses a hit, and refuses no more than a few times too early.
"""

import math

import numpy as np
import pytest

import clrt
from clrt import cli
from conftest import write_icosphere_obj
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


@pytest.fixture
def unchecked_batches(monkeypatch):
    """The kernels' check of batch origins switched off: what the device does."""
    monkeypatch.setattr(reach_module.Reach, "batch_limit", lambda self: math.inf)


def test_the_check_admits_no_lost_hit_and_refuses_only_near_the_overflow(device, unchecked_batches):
    refused, worked, lost = [], {}, {}   # per size: the farthest corner's distance of rays that worked / lost hits
    for size in SIZES:
        for distance in DISTANCES:
            mesh, directions = _triangle_and_rays(size, distance)
            accel = clrt.Accel(mesh, accel="none", device=device)
            is_refused = _refused(accel)
            # what the device does (the kernels' check of batch origins switched off)
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
                                              r"device's float32 triangle test overflows .* from about 4\.\de16: "):
        accel.camera_images(Camera((0.0, 0.0, 1e17), (0.0, 0.0, 0.0), width=4, height=4))
    # A refit moves the scene, and the range with it.
    accel.refit(mesh.vertices.astype(np.float64) * 1e13)
    with pytest.raises(clrt.InputError, match=r"^the camera's eye lies 1\.1e14 .* from about 1\.\de13: "):
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
    with pytest.raises(clrt.InputError, match=r"^the camera's rays start up to 1e17 from the scene's far side, "
                                              r"but the device's float32 triangle test overflows"):
        clrt.Renderer(_ground_scene(1e12), device=device).render(Camera((0.0, 0.0, 1e17), (0.0, 0.0, 0.0)))
    # Too large whatever the camera: the error names the geometry that makes it so.
    renderer = clrt.Renderer(_ground_scene(1e13), device=device)
    with pytest.raises(clrt.InputError, match=r"^object 1, triangle 0 has a vertex at \(-1e13, 0, -1e13\), "
                                              r"1\.41e13 from the middle of the scene \(2 triangles that far out\): "
                                              r"the scene is too large: the device's float32 triangle test "
                                              r"overflows .* from about 2\.\de11 away, and rays between its "
                                              r"surfaces start up to 2\.8e13 from its far side: "):
        renderer.render(camera)
    # The same from the command line: one line, exit 2, nothing written.
    scene = tmp_path / "ground.toml"
    scene.write_text('[camera]\neye = [0, 3, 5]\ntarget = [0, 0.3, 0]\nwidth = 16\nheight = 12\n'
                     '[[objects]]\ntype = "sphere"\n[[objects]]\ntype = "plane"\nsize = [2e13, 2e13]\n')
    code = cli.main(["render", str(scene), "-o", str(tmp_path / "out.png"), *(["--device", device] if device else [])])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "float32 triangle test overflows" in err, err
    assert err.startswith(f"clrt: {scene}: object 'objects[1] (plane)', triangle 0 has a vertex at (-1e13, 0, "), err
    assert not (tmp_path / "out.png").exists()


def test_a_stray_vertex_is_named_with_its_file_and_triangle(device, tmp_path, capsys):
    """One corrupt vertex (y = -4.4e28) among a sphere's: the error named the
    camera's rays and no file or vertex; now the file, the object, the first
    triangle that reaches out there and the vertex's coordinates."""
    sphere = primitives.icosphere(2)
    v = np.concatenate([sphere.vertices, [[0.0, -4.4e28, 0.0]]])
    f = sphere.faces.copy()
    f[70, 1] = len(v) - 1   # triangles 70 and 90 use the stray vertex
    f[90, 2] = len(v) - 1
    path = tmp_path / "corrupt.obj"
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v.astype(np.float64).tolist())
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f))
    expected = (f"{path}: object 'corrupt', triangle 70 has a vertex at (0, -4.4e28, 0), 4.4e28 from the middle "
                "of the scene (2 triangles that far out): the scene is too large: the device's float32 triangle "
                "test overflows")
    with pytest.raises(clrt.InputError) as info:
        clrt.render(str(path), width=8, height=6, device=device)
    assert str(info.value).startswith(expected), str(info.value)
    code = cli.main(["render", str(path), "-o", str(tmp_path / "x.png"), "--width", "8", "--height", "6",
                     *(["--device", device] if device else [])])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"clrt: {expected}"), err
    assert not (tmp_path / "x.png").exists()


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
def test_an_overflowed_triangle_test_is_no_hit_for_any_query(accel, device, unchecked_batches):
    """Past the float32 range (a triangle 1e13 across seen from 3e15, with the
    kernels' check of batch origins off) the test's T overflows to t = inf: the closest
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


# ----------------------------------------------------------------------- batch origins, checked on the device

FAR_MESSAGE = (r"^origin {i} is \[{value}\]: it lies {rho} from the scene's far side, but the device's float32 "
               r"triangle test overflows and misses hits on this scene's triangles from about 4\.9e16: "
               r"start the rays nearer, or scale the scene down$")


def _rays_with_far_origins(n: int = 40):
    """``n`` rays down onto a unit icosphere, origins 29 and 33 far past the limit."""
    rng = np.random.default_rng(8)
    origins = np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)), np.full(n, 3.0)])
    directions = np.tile([0.0, 0.0, -1.0], (n, 1))
    origins[29] = [1e17, 0.0, 0.0]
    origins[33] = [0.0, -3e17, 0.0]
    return origins, directions


@pytest.mark.parametrize("walk", ["packets", "single rays"])
@pytest.mark.parametrize("chunk_rays", [None, 8])
def test_far_batch_origins_are_refused_by_every_query(walk, chunk_rays, device, monkeypatch):
    """Every query kind, the one-call forms and the trimesh drop-in refuse a
    batch whose origins lie past the limit, naming the lowest such ray (in any
    chunk, in packets of eight or one by one), in one line."""
    from clrt.device import geometry
    if walk == "single rays":
        monkeypatch.setattr(geometry, "RAY_PACKET_KINDS", ())
    mesh = primitives.icosphere(2)
    accel = clrt.Accel(mesh, device=device, chunk_rays=chunk_rays)
    o, d = _rays_with_far_origins()
    message = FAR_MESSAGE.format(i=29, value=r"1e\+17, 0\.0, 0\.0", rho=r"1e17")
    queries = {"trace": lambda: accel.trace(o, d), "trace t": lambda: accel.trace(o, d, fields=("t",)),
               "any_hit": lambda: accel.any_hit(o, d), "count": lambda: accel.count(o, d),
               "all_hits": lambda: accel.all_hits(o, d),
               "clrt.trace": lambda: clrt.trace(mesh, o, d, device=device),
               "clrt.occluded": lambda: clrt.occluded(mesh, o, d, device=device),
               "clrt.count_hits": lambda: clrt.count_hits(mesh, o, d, device=device),
               "clrt.all_hits": lambda: clrt.all_hits(mesh, o, d, device=device)}
    intersector = clrt.RayMeshIntersector(mesh, device=device)
    for name in ("intersects_first", "intersects_any", "intersects_id", "intersects_location"):
        queries[name] = lambda m=getattr(intersector, name): m(o, d)
    for name, query in queries.items():
        with pytest.raises(clrt.InputError, match=message) as error:
            query()
        assert "\n" not in str(error.value), name
    o[29] = [0.0, 0.0, 3.0]   # then ray 33 is the first
    with pytest.raises(clrt.InputError, match=FAR_MESSAGE.format(i=33, value=r"0\.0, -3e\+17, 0\.0", rho=r"3e17")):
        accel.trace(o, d)
    o[33] = [0.0, 0.0, 3.0]
    assert accel.trace(o, d).hit.all() and accel.count(o, d).min() == 2   # all good again


def test_the_device_refuses_exactly_the_origins_past_the_limit(device):
    """Origins just inside the limit are traced, just outside refused, whichever
    side of the scene they lie on; the device's distance is the host's."""
    mesh = Mesh.from_arrays(primitives.icosphere(1).vertices.astype(np.float64) * 2 + [5.0, -3.0, 1.0],
                            primitives.icosphere(1).faces)
    accel = clrt.Accel(mesh, device=device)
    reach = accel.geometry.reach
    limit = reach.limit()
    for k, axis in enumerate(np.vstack([np.eye(3), -np.eye(3), [[1.0, -2.0, 0.5]]])):
        axis = axis / np.linalg.norm(axis)
        for ratio, refused in ((1 - 1e-5, False), (1 + 1e-5, True)):
            # the point at `ratio` times the limit from the box's far side along `axis`
            far_corner = np.where(axis > 0, reach.lo, reach.hi)
            origin = far_corner + axis * ratio * limit
            assert reach.farthest(origin) == pytest.approx(ratio * limit, rel=1e-9)
            direction = (mesh.bounds.mean(axis=0) - origin) / np.linalg.norm(mesh.bounds.mean(axis=0) - origin)
            try:
                accel.count(origin, direction)
            except clrt.InputError as exc:
                assert refused and str(exc).startswith("origin 0 is"), (k, ratio, str(exc))
            else:
                assert not refused, (k, ratio)


def test_far_origins_on_the_device_are_refused_with_their_value(device):
    cla = pytest.importorskip("pyopencl.array")
    accel = clrt.Accel(primitives.icosphere(2), device=device)
    o, d = _rays_with_far_origins()
    o_dev, d_dev = (cla.to_device(accel.queue, a.astype(np.float32)) for a in (o, d))
    with pytest.raises(clrt.InputError, match=FAR_MESSAGE.format(i=29, value=r"1e\+17, 0\.0, 0\.0", rho="1e17")):
        accel.trace(o_dev, d_dev)
    shared = cla.to_device(accel.queue, np.array([2e17, 0.0, 0.0], np.float32))   # one origin for all rays
    with pytest.raises(clrt.InputError, match=FAR_MESSAGE.format(i=0, value=r"2e\+17, 0\.0, 0\.0", rho="2e17")):
        accel.any_hit(shared, d_dev)


def test_a_ray_file_with_far_origins_exits_2(tmp_path, capsys, device):
    from benchmarks import raysets
    mesh = write_icosphere_obj(tmp_path / "sphere.obj")
    o, d = _rays_with_far_origins()
    rows = np.hstack([o, d]).astype("<f4")
    (tmp_path / "far.f32").write_bytes(rows.tobytes())
    code = raysets.main([str(mesh), "--read", str(tmp_path / "far.f32"), "--repeat", "1", "--warmup", "0",
                         *(["--device", device] if device else [])])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "float32 triangle test overflows" in err, err



def test_an_origin_past_float32_says_it_overflows(device):
    """1e39 is finite as a Python float but infinite on the device: the error
    says it overflows float32, not merely that origins must be finite."""
    accel = clrt.Accel(primitives.icosphere(1), device=device)
    with pytest.raises(clrt.InputError, match=r"^origin 1 is \[1e\+39, 0\.0, 0\.0\]: 1e39 overflows float32 "
                                              r"\(the largest float32 is about 3\.4e38\); origins must be finite"):
        accel.trace([[0.0, 0.0, 5.0], [1e39, 0.0, 0.0]], [0.0, 0.0, -1.0])
    with pytest.raises(clrt.InputError, match=r"^origin 0 is \[inf, 0\.0, 0\.0\]: origins must be finite$"):
        accel.trace([np.inf, 0.0, 0.0], [0.0, 0.0, -1.0])
    with pytest.raises(clrt.InputError, match=r"1e39 overflows float32"):
        clrt.Camera((1e39, 0.0, 0.0), (0.0, 0.0, 0.0))

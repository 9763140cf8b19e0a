"""The path tracer's rays recorded for benchmarks (PathTracer.record_rays,
path.cl -DPATH_RECORD_RAYS) are the rays it traces: bounces from points on
the surface, shadow rays from the surface to the light; and
benchmarks.path_rays times them beside the random set."""

import numpy as np
import pytest

import clrt
from benchmarks import path_rays
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, scene_from_mesh

from conftest import TEST_MESHES


def _recorded(device, max_depth, capacity=100_000):
    torus = TEST_MESHES["torus"]()
    # far from the origin, where the renderer moves the scene to a frame of its own
    mesh = Mesh.from_arrays(torus.vertices + (400.0, 0.0, 0.0), torus.faces, "far torus")
    camera = Camera.framing(mesh.bounds, 48, 32)
    scene = scene_from_mesh(mesh)
    return mesh, scene, path_rays.recorded_rays(mesh, camera, device, 2, max_depth, 7, capacity)


def test_recorded_rays_start_on_the_surface_and_shadow_rays_end_at_the_light(device):
    mesh, scene, out = _recorded(device, 3)
    (bounce_o, bounce_d), (shadow_o, shadow_d, shadow_t) = out["bounce"], out["shadow"]
    assert out["traced"] == {"bounce": len(bounce_o), "shadow": len(shadow_o)}
    assert len(bounce_o) > 100 and len(shadow_o) > 100
    diagonal = float(np.linalg.norm(np.subtract(*mesh.bounds)))
    accel = clrt.Accel(mesh, device=device)
    for origins, directions in ((bounce_o, bounce_d), (shadow_o, shadow_d)):
        assert accel.distance(origins).max() < 1e-4 * diagonal    # from a path vertex, the scene's coordinates
        assert np.abs(np.linalg.norm(directions, axis=1) - 1).max() < 1e-5
    # leaving the closed torus outward: what they meet, they meet from outside
    # (beyond the first 1e-4: the path tracer traces them as spawned rays,
    # which do not meet the surface they leave; the Accel, in a frame of its
    # own, may)
    hits = accel.trace(bounce_o, bounce_d, fields=("prim", "front", "t"))
    away = (hits.prim >= 0) & (hits.t > 1e-4 * diagonal)
    assert away.any() and hits.front[away].all()
    (light,) = scene.lights                                       # the default point light
    ends = shadow_o.astype(np.float64) + shadow_t[:, None] * shadow_d
    assert np.abs(ends - np.asarray(light.position)).max() < 1e-4 * diagonal


def test_paths_of_depth_one_trace_nothing_and_the_capacity_caps_the_record(device):
    assert _recorded(device, 1)[2]["traced"] == {"bounce": 0, "shadow": 0}
    _, _, capped = _recorded(device, 3, capacity=50)
    assert len(capped["bounce"][0]) == len(capped["shadow"][0]) == 50
    assert capped["traced"]["bounce"] > 50 and capped["traced"]["shadow"] > 50


def _torus_file(tmp_path):
    mesh = TEST_MESHES["torus"]()
    path = tmp_path / "torus.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    return path


def _rows(out, *starts):
    return [[c.strip() for c in line.split("|")[1:-1]] for line in out.splitlines()
            if any(line.startswith(f"| {start}") for start in starts)]


def test_the_benchmark_prints_each_set_and_closest_agrees_with_any_hit(device, tmp_path, capsys):
    assert path_rays.main([str(_torus_file(tmp_path)), "--device", device or "cpu", "--size", "48x32", "--spp", "2",
                           "--repeat", "1", "--warmup", "0", "--builder", "auto,sah"]) == 0
    rows = _rows(capsys.readouterr().out, "auto", "sah")
    assert [(r[0], r[1]) for r in rows] == [(b, s) for b in ("auto", "sah") for s in ("bounce", "shadow", "random")]
    for row in rows:
        assert int(row[2].replace(",", "")) > 0
        assert row[10] == "yes"           # a closest hit within tmax exactly where any hit is
    assert [r[9] for r in rows[:3]] == [r[9] for r in rows[3:]]   # the same hits from either tree


def test_embree_hits_the_same_rays_alike(device, tmp_path, capsys):
    """--embree: the same sets through Embree, the shadow rays each up to its
    own length (raysets._embree_limits takes one a ray)."""
    pytest.importorskip("embreex", reason="Embree comparison needs the raybench extra (the test extra has it)")
    assert path_rays.main([str(_torus_file(tmp_path)), "--device", device or "cpu", "--size", "48x32", "--spp", "2",
                           "--repeat", "1", "--warmup", "0", "--embree"]) == 0
    out = capsys.readouterr().out
    ours, theirs = _rows(out, "auto"), _rows(out, "Embree")
    assert [r[1] for r in theirs] == [r[1] for r in ours] == ["bounce", "shadow", "random"]
    assert [r[9] for r in theirs] == [r[9] for r in ours]

"""benchmarks.points --turns: clrt and Open3D taking turns on the same points
(the timing itself is not tested: the table's shape, the answers' agreement
and the errors are)."""

import sys

import pytest

from benchmarks import points as bench_points


def test_turns_without_open3d_is_one_line(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "open3d", None)     # as where Open3D is not installed
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SystemExit, match=r"^benchmarks.points: --turns needs Open3D: pip install open3d-cpu$"):
        bench_points.main([str(mesh), "--turns"])


def test_turns_take_turns_on_the_same_points(device, capsys, tmp_path):
    pytest.importorskip("open3d")
    from clrt.scene import primitives
    mesh = primitives.torus(1.0, 0.35, 32, 16)
    path = tmp_path / "torus.obj"
    path.write_text("".join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in mesh.vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
    argv = [str(path), "--turns", "--points", "3K", "--repeat", "2", "--warmup", "0"]
    assert bench_points.main(argv + (["--device", device] if device else [])) == 0
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in capsys.readouterr().out.splitlines()
            if line.startswith("| torus.obj")]
    assert [r[2] for r in rows] == list(bench_points.TURN_QUERIES)
    for r in rows:
        assert float(r[-1]) < 1e-5          # both libraries found the same distances
        assert r[5].startswith("**") and r[5].split("x**")[0].strip("*").replace(".", "").isdigit()

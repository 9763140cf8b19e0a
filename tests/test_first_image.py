"""benchmarks.first_image runs on the test device and prints its wall times and stage table."""

from benchmarks import first_image
from clrt.scene import primitives

ROWS = ["python start", "import numpy", "import pyopencl", "import clrt", "cl.get_platforms()",
        "device list", "cl.Context + CommandQueue", "one more CommandQueue alone", "mesh load",
        "crease split", "renderer (flatten, build, upload, program)", "acceleration build",
        "first frame", "pixel colour", "PNG write", "device: ", "total", "process exit"]


def test_first_image_bench_prints_wall_times_and_every_stage(tmp_path, device, capsys):
    mesh = primitives.icosphere(1)
    path = tmp_path / "ico.off"
    path.write_text(f"OFF\n{len(mesh.vertices)} {len(mesh.faces)} 0\n"
                    + "".join(f"{x} {y} {z}\n" for x, y, z in mesh.vertices)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in mesh.faces))
    args = [str(path), "--size", "32x24", "--runs", "1"] + (["--device", device] if device else [])
    assert first_image.main(args) == 0
    out = capsys.readouterr().out
    assert "wall  median" in out
    table = out[out.index("stages of one more fresh process"):]
    for name in ROWS:
        assert name in table, f"no row {name!r} in\n{out}"
    assert table.index("import numpy") < table.index("mesh load") < table.index("PNG write")

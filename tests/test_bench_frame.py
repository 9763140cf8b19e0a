"""benchmarks.frame times whole frames of its variants side by side, no BVH
among them, and says whether each variant's image is the first one's."""

from pathlib import Path

import pytest

from benchmarks import frame

KNOT = str(Path(__file__).resolve().parent.parent / "assets" / "meshes" / "knot.obj")


def test_frame_bench_without_and_with_a_bvh(device, capsys):
    code = frame.main([KNOT, "--accel", "none", "--accel", "box", "--size", "48x32", "--repeat", "1",
                       "--warmup", "0", "--device", device or "cpu"])
    assert code == 0
    out = capsys.readouterr().out
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in out.splitlines()
            if line.startswith("| none ") or line.startswith("| box ")]
    assert [(r[0], r[1], r[2]) for r in rows] == [("none", "-", "48x32"), ("box", "sah", "48x32")]
    assert all(r[-1] == "yes" for r in rows)        # the BVH's image is brute force's, pixel for pixel
    for r in rows:   # the whole call beside its stages, the frame's wall beside its stages
        build, copy, made, gen, colour, read, wall, host, above = (float(c.split()[0]) for c in r[3:12])
        assert made >= build + copy - 0.2
        assert host == pytest.approx(wall - gen - colour - read, abs=0.01)
        assert above == pytest.approx(wall - gen - colour, abs=0.01) and above >= host - 0.01


@pytest.mark.parametrize("module, args", [
    ("frame", ["--repeat", "0"]), ("frame", ["--warmup", "-1"]), ("frame", ["--repeat", "x"]),
    ("speed", ["--repeat", "0"]), ("speed", ["--warmup", "-2"]),
    ("build", ["--repeat", "-1"]), ("scale", ["--repeat", "0"]),
    ("raysets", ["--repeat", "0"]), ("rays", ["--repeat", "0"]), ("host_stages", ["--repeat", "0"]),
])
def test_benchmarks_refuse_bad_counts_in_one_line(module, args, capsys):
    """A benchmark's counts are checked while parsing: one line naming the
    option, exit code 2, before any mesh is loaded or device touched."""
    import importlib
    bench = importlib.import_module(f"benchmarks.{module}")
    with pytest.raises(SystemExit) as exit_info:
        bench.main(args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"python -m benchmarks.{module}: error:") and args[0] in err[-1]

"""clrt.bench.frame times whole frames of its variants side by side, no BVH
among them, and says whether each variant's image is the first one's."""

from pathlib import Path

from clrt.bench import frame

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

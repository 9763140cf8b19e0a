"""benchmarks.point_stages prints each point query under each variant of the
input and output path, and the queue's commands of one call, on the test
device; the variants change no answer (the timing itself is not tested)."""

import numpy as np
import pytest

from benchmarks import point_stages


def test_point_stages_print_every_variant_and_the_queue(device, capsys):
    variants = ["as is", "pageable results", "two chunks", "float64 points"]
    assert point_stages.main(["--points", "2K", "--repeat", "1", "--warmup", "0", "--variants",
                              ",".join(variants)] + (["--device", device] if device else [])) == 0
    out = capsys.readouterr().out
    rows = [[c.strip() for c in line.split("|")[1:-1]] for line in out.splitlines() if line.startswith("| ")]
    timed = {(r[0], r[1]) for r in rows if len(r) == 5 and r[1] in variants}
    assert timed == {(q, v) for q in point_stages.QUERIES for v in variants}
    commands = [r[0] for r in rows if len(r) == 5 and r[0] not in point_stages.QUERIES]
    for kernel in ("query_signed_distance_normal", "query_closest_point", "query_winding_number"):
        assert f"kernel {kernel}" in commands, kernel
    assert any(c.startswith("upload 0.02 MB") for c in commands)      # 2,000 float32 points: 24 kB
    # the points' order: point_order.cl's atomics (below POINT_RUN_POINTS points on a CPU device too)
    assert "kernel point_cells" in commands


def test_point_stages_variants_give_the_same_answers(device):
    import clrt
    from benchmarks.points import make_points
    from clrt.scene import primitives
    mesh = primitives.torus(1.0, 0.35, 24, 12)
    points = make_points(mesh, 3000)
    accel = clrt.Accel(mesh, device=device)
    for ask in point_stages.QUERIES.values():
        want = ask(accel, points)
        for name in point_stages.VARIANTS[1:]:
            with point_stages.variant(name, accel, points) as given:
                got = ask(accel, given)
            pairs = zip(got, want) if isinstance(want, tuple) else [(got, want)]
            assert all(np.array_equal(a, b) for a, b in pairs), name


def test_point_stages_refuse_bad_options_in_one_line(capsys):
    with pytest.raises(SystemExit) as exit_info:
        point_stages.main(["--repeat", "0"])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith("python -m benchmarks.point_stages: error:")
    with pytest.raises(SystemExit, match="--variants must name some of as is, "):
        point_stages.main(["--variants", "as is,fast"])

"""The incoherent ray sets of ``benchmarks.raysets``: seeded, shareable as files,
and traced alike by every traversal variant and by the brute-force reference."""

import numpy as np
import pytest

import clrt
from benchmarks import peer_turns, raysets
from clrt.config import BUILDERS, VOLUMES
from clrt.errors import InputError
from clrt.reference import intersect
from clrt.scene.scene import Camera

from conftest import TEST_MESHES


@pytest.fixture(scope="module")
def torus():
    return TEST_MESHES["torus"]()


@pytest.fixture(scope="module")
def sets(torus, device):
    accel = clrt.Accel(torus, device=device)
    camera = Camera.framing(torus.bounds, 48, 32, 45.0)
    return {kind: raysets.make_ray_set(kind, torus, 600, 11, accel, camera) for kind in raysets.RAY_SETS}


def test_sets_are_seeded_unit_and_placed(torus, sets, device):
    accel = clrt.Accel(torus, device=device)
    camera = Camera.framing(torus.bounds, 48, 32, 45.0)
    for kind in ("random", "diffuse", "ao"):
        o, d, _ = raysets.make_ray_set(kind, torus, 600, 11, accel, camera)
        assert np.array_equal(o, sets[kind][0]) and np.array_equal(d, sets[kind][1]), kind
        other = raysets.make_ray_set(kind, torus, 600, 12, accel, camera)
        assert not np.array_equal(other[1], d), kind
        assert o.dtype == d.dtype == np.float32 and o.shape == d.shape == (600, 3)
        assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6)
    lo, hi = np.asarray(torus.bounds)
    o = sets["random"][0]
    margin = 0.05 * (hi - lo)
    assert (o >= lo - margin - 1e-6).all() and (o <= hi + margin + 1e-6).all()
    assert (o < lo).any() and (o > hi).any(), "the box is enlarged"
    assert len(sets["camera"][0]) == 48 * 32
    assert sets["ao"][2] == pytest.approx(raysets.AO_REACH * np.linalg.norm(hi - lo))
    # AO rays come in groups from one point; diffuse rays leave the surface outwards
    ao_o = sets["ao"][0][:raysets.AO_RAYS_PER_POINT * 10].reshape(10, raysets.AO_RAYS_PER_POINT, 3)
    assert (ao_o == ao_o[:, :1]).all()
    hits = accel.trace(sets["diffuse"][0], -sets["diffuse"][1])   # backwards: into the surface just left
    assert hits.hit.mean() > 0.95


def test_cosine_hemisphere_is_cosine_weighted():
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(100_000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[:3] = [[0, 0, 1], [0, 0, -1], [1, 0, 0]]   # the basis's special cases
    d = raysets._cosine_hemisphere(normals, rng)
    cos = np.einsum("ij,ij->i", d, normals)
    assert (cos >= -1e-12).all() and np.allclose(np.linalg.norm(d, axis=1), 1)
    assert cos.mean() == pytest.approx(2 / 3, abs=0.005)           # E[cos] of p = cos / pi
    assert (cos ** 2).mean() == pytest.approx(1 / 2, abs=0.005)


def test_every_variant_traces_the_sets_as_brute_force(torus, sets, device):
    corners = torus.vertices[torus.faces].astype(np.float32)
    variants = [("none", "sah")] + [(v, b) for v in VOLUMES for b in BUILDERS]
    for kind, (o, d, reach) in sets.items():
        t_ref, prim_ref, _, _ = intersect(o, d, corners, np.zeros(len(o), np.float32),
                                          np.full(len(o), reach, np.float32))
        assert (prim_ref >= 0).any(), kind
        base = None
        for volume, builder in variants:
            m = raysets.measure(clrt.Accel(torus, accel=volume, builder=builder, device=device), o, d, reach,
                                repeat=1, warmup=0)
            label = f"{kind} {volume}/{builder}"
            assert m["any_agrees"], label
            if base is None:
                base = m
                hit = prim_ref >= 0
                assert np.array_equal(m["prim"] >= 0, hit), label
                assert (m["prim"] == prim_ref).mean() >= 0.998, label
                assert np.allclose(m["t"][hit], t_ref[hit], rtol=1e-5, atol=1e-6), label
            else:   # every BVH gives bit for bit what the loop over all triangles gives
                assert np.array_equal(m["prim"], base["prim"]), label
                assert np.array_equal(m["t"], base["t"]), label
                assert (m["hits"], m["sum_t"]) == (base["hits"], base["sum_t"]), label


def test_ray_files_round_trip_and_run_the_same(torus, sets, tmp_path, device):
    o, d, reach = sets["ao"]
    path = tmp_path / "ao.f32"
    raysets.write_rays(path, o, d)
    assert path.stat().st_size == len(o) * 24
    back_o, back_d = raysets.read_rays(path)
    assert np.array_equal(back_o, o) and np.array_equal(back_d, d)
    assert np.array_equal(np.fromfile(path, "<f4").reshape(-1, 6), np.concatenate([o, d], 1))
    accel = clrt.Accel(torus, device=device)
    a = raysets.measure(accel, o, d, reach, repeat=1, warmup=0)
    b = raysets.measure(accel, back_o, back_d, reach, repeat=1, warmup=0)
    assert (a["hits"], a["sum_t"]) == (b["hits"], b["sum_t"])


def test_embree_traces_the_sets_alike(torus, sets, device):
    pytest.importorskip("embreex", reason="Embree comparison needs the raybench extra (the test extra has it)")
    accel = clrt.Accel(torus, device=device)
    for kind, (o, d, reach) in sets.items():
        ours = raysets.measure(accel, o, d, reach, repeat=1, warmup=0)
        theirs = raysets.embree_measure(torus, o, d, reach, repeat=1, warmup=0)
        assert theirs["any_agrees"], kind
        assert ((ours["prim"] >= 0) == (theirs["prim"] >= 0)).mean() >= 0.995, kind
        assert theirs["sum_t"] == pytest.approx(ours["sum_t"], rel=1e-3), kind


def test_embree_on_several_cores_times_every_share(torus, sets):
    pytest.importorskip("embreex", reason="Embree comparison needs the raybench extra (the test extra has it)")
    o, d, reach = sets["ao"]
    m = raysets.embree_processes_measure(torus, o[:2000], d[:2000], reach, processes=2, repeat=1, warmup=0)
    assert m["closest_wall_ms"] > 0 and m["any_wall_ms"] > 0


def test_clrt_and_embree_take_turns(torus, sets, device, monkeypatch):
    """--embree-processes: clrt's queries run between Embree's, one of each per
    repetition and query, and the speed ratios come from those pairs."""
    pytest.importorskip("embreex", reason="Embree comparison needs the raybench extra (the test extra has it)")
    o, d, reach = sets["random"]
    accel = clrt.Accel(torus, device=device)
    calls = []
    for name in ("trace", "any_hit"):
        method = getattr(accel, name)
        monkeypatch.setattr(accel, name, lambda *a, _m=method, _n=name, **k: (calls.append(_n), _m(*a, **k))[1])
    m = peer_turns.measure_in_turns(accel, torus, o[:4000], d[:4000], reach, open3d=False, embree_processes=2,
                                    repeat=3, warmup=1)
    assert calls == ["trace", "any_hit"] * 4
    for query in ("closest", "any"):
        assert len(m["times"]["clrt"][query]) == len(m["times"]["Embree x2"][query]) == 3
        assert min(m["times"]["clrt"][query] + m["times"]["Embree x2"][query]) > 0
        # the processes' hits, summed over their shares, are clrt's hits
        assert m["hits"]["Embree x2"][query] == m["hits"]["clrt"][query] > 0


@pytest.mark.parametrize("content, message", [
    (b"", "not a ray file"),
    (b"\0" * 25, "not a ray file"),
    (np.array([[0, 0, 0, np.nan, 0, 1]], "<f4").tobytes(), "not finite"),
    (np.array([[0, 0, 0, 0, 0, 2]], "<f4").tobytes(), "must be unit"),
])
def test_bad_ray_files_are_refused(tmp_path, content, message):
    path = tmp_path / "bad.f32"
    path.write_bytes(content)
    with pytest.raises(InputError, match=message):
        raysets.read_rays(path)


def test_command_writes_reads_and_refuses(tmp_path, capsys, device):
    mesh = tmp_path / "torus.off"
    mesh.write_text(_off())
    common = ["--repeat", "1", "--warmup", "0", "--size", "24x16"] + (["--device", device] if device else [])
    assert raysets.main([str(mesh), "--rays", "300", "--set", "random", "--set", "ao",
                         "--write", str(tmp_path / "rays")] + common) == 0   # the folder is made
    first = capsys.readouterr().out
    assert (tmp_path / "rays" / "random.f32").stat().st_size == 300 * 24
    assert raysets.main([str(mesh), "--read", str(tmp_path / "rays" / "random.f32")] + common) == 0
    again = capsys.readouterr().out
    row = lambda text, name: next(line for line in text.splitlines() if line.startswith(f"| {name} "))  # noqa: E731
    # same hits and sum of distances from the file as when generated
    assert row(first, "random").split("|")[10:12] == row(again, "random.f32").split("|")[10:12]
    from benchmarks.common import rate
    for cell in (row(first, "random").split("|")[k].strip() for k in (7, 9, 13)):   # Mrays/s, 3 figures
        assert float(cell.replace(",", "")) > 0 and rate(float(cell.replace(",", ""))) == cell, cell
    (tmp_path / "bad.f32").write_bytes(b"\0" * 10)
    assert raysets.main([str(mesh), "--read", str(tmp_path / "bad.f32")] + common) == 2
    err = capsys.readouterr().err
    assert err.startswith("clrt: ") and "not a ray file" in err and err.count("\n") == 1
    with pytest.raises(SystemExit):   # --write names a folder, not a file
        raysets.main([str(mesh), "--write", str(tmp_path / "bad.f32")] + common)
    assert "is not a folder" in capsys.readouterr().err


def _off() -> str:
    m = TEST_MESHES["torus"]()
    lines = ["OFF", f"{len(m.vertices)} {len(m.faces)} 0"]
    lines += [" ".join(f"{x:.9g}" for x in v) for v in m.vertices]
    lines += ["3 " + " ".join(str(i) for i in f) for f in m.faces]
    return "\n".join(lines) + "\n"


def test_a_fixed_query_work_group_gives_the_same_hits(device, monkeypatch):
    """QUERY_GROUP (PACKET_GROUP) rounds the launch up: the work-items past the last ray do nothing."""
    from clrt.query import Accel
    from clrt.query import accel as query_accel
    from clrt.scene import primitives
    mesh = primitives.torus(n_major=24, n_minor=12)
    o, d = raysets.random_rays(mesh, 1001, seed=4)
    accel = Accel(mesh, device=device)
    base = accel.trace(o, d)
    monkeypatch.setattr(query_accel, "QUERY_GROUP", {"gpu": 64, "cpu": 64})
    monkeypatch.setattr(query_accel, "PACKET_GROUP", {"gpu": 64, "cpu": 64})   # where a work-item takes 8 rays
    grouped = accel.trace(o, d)
    assert np.array_equal(grouped.prim, base.prim) and np.array_equal(grouped.t, base.t)
    assert np.array_equal(accel.occluded(o, d), base.prim >= 0)


def test_a_failing_embree_process_ends_the_turns_with_its_reason(torus, sets):
    """A worker that fails (here: float64 rays, which embreex refuses) stops the
    turns at once with its error, instead of leaving the others waiting."""
    pytest.importorskip("embreex", reason="Embree comparison needs the raybench extra (the test extra has it)")
    o, d, reach = sets["random"]
    turns = []
    with pytest.raises(InputError, match="Embree failed: ValueError: Buffer dtype mismatch"):
        raysets.embree_processes_measure(torus, o[:2000].astype(np.float64), d[:2000], reach, processes=2,
                                         repeat=1, warmup=0, turn=lambda query, counted: turns.append(query))
    assert turns == ["closest"]


def test_an_embree_process_that_dies_ends_the_turn():
    """A worker that dies without a word (a crash) is noticed while waiting for
    its time: a one-line error with its exit code, not a hang."""
    import multiprocessing
    import sys
    context = multiprocessing.get_context("spawn")
    worker = context.Process(target=sys.exit, args=(3,))
    worker.start()
    worker.join()
    with pytest.raises(InputError, match=r"an Embree process died \(exit code 3\)"):
        raysets._turn_times([worker], context.Queue())


@pytest.mark.parametrize("group", ["0", "-4", "abc", "5000", "64,"])
def test_bad_work_group_sizes_fail_in_one_line(group, capsys):
    with pytest.raises(SystemExit) as exit_info:
        raysets.main(["--group", group, "--rays", "1K"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("python -m benchmarks.raysets: error: argument --group: expected work-group sizes")


def test_a_work_group_larger_than_the_device_takes_fails_in_one_line(torus, device):
    import pyopencl as cl
    accel = clrt.Accel(torus, device=device)
    limit = min(accel.kernels[name].get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, accel.queue.device)
                for name in ("query_closest", "query_any"))
    raysets._check_groups(accel, ["driver", 1, limit])
    with pytest.raises(InputError, match=f"--group {limit + 1}: .* at most"):
        raysets._check_groups(accel, [limit + 1])


def test_write_keeps_a_users_file_and_bad_counts_fail_in_one_line(tmp_path, capsys, device):
    """--write follows clrt's overwrite rule (a user's file needs -f; clrt's own
    is replaced), checked before the mesh is even loaded."""
    common = ["--set", "random", "--rays", "50", "--size", "8x8", "--repeat", "1", "--warmup", "0"]
    common += ["--device", device] if device else []
    (tmp_path / "random.f32").write_bytes(b"precious")
    assert raysets.main([str(tmp_path / "missing.off"), *common, "--write", str(tmp_path)]) == 2
    assert "random.f32 exists and was not written by clrt" in capsys.readouterr().err
    assert (tmp_path / "random.f32").read_bytes() == b"precious"
    mesh = tmp_path / "torus.off"
    mesh.write_text(_off())
    assert raysets.main([str(mesh), *common, "--write", str(tmp_path), "-f"]) == 0
    assert (tmp_path / "random.f32").stat().st_size == 50 * 24
    assert raysets.main([str(mesh), *common, "--write", str(tmp_path)]) == 0    # clrt's own file
    capsys.readouterr()
    for bad in (["--rays", "inf"], ["--seed", "-1"], ["--repeat", "0"]):
        with pytest.raises(SystemExit) as exit_info:
            raysets.main([str(mesh), *bad])
        assert exit_info.value.code == 2
        assert capsys.readouterr().err.strip().splitlines()[-1].startswith(
            f"python -m benchmarks.raysets: error: argument {bad[0]}: expected")


def test_rays_beyond_host_memory_fail_before_any_work(monkeypatch, capsys):
    from clrt import checks
    monkeypatch.setattr(checks, "available_host_memory", lambda: 1 << 30)
    assert raysets.main(["/nonexistent.off", "--rays", "100M", "--set", "random"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clrt: making 100,000,000 rays needs") and "only 1.0 GiB is available" in err


def test_rates_are_printed_to_three_significant_figures():
    """Mrays/s of brute force is well below 0.1 on a CPU: shown as 0.0123, not
    0.0; large rates keep their thousands separators."""
    from benchmarks.common import rate
    assert [rate(x) for x in (0.012345, 0.0004, 1.5, 9.996, 32.45, 873.2, 12345.6, 0.0)] == [
        "0.0123", "0.000400", "1.50", "10.0", "32.5", "873", "12,346", "0"]
    assert rate(float("inf")) == "inf"

"""benchmarks.build runs its variants side by side (here on the test device,
on the generated 50k-triangle scene) and, with --embree, Embree's build."""

import pytest

from benchmarks import build


def test_build_bench_prints_every_variant(device, capsys, monkeypatch):
    pytest.importorskip("embreex")            # the raybench extra, which the test command installs
    monkeypatch.setattr(build, "DEVICE_VARIANTS", dict(build.DEVICE_VARIANTS))
    code = build.main(["--device", device or "cpu", "--meshes", "knot50k", "--builders",
                       "device,device/treelets=7,device/tail=64,device/sah-top=128", "--repeat", "1", "--no-trace",
                       "--embree",
                       "--profile"])
    assert code == 0
    out = capsys.readouterr().out
    table, calls = out.split("whole calls")     # the builds' table, then the whole calls' (the device builder's)
    rows = [line.split("|") for line in table.splitlines() if line.startswith("| knot50k ")]
    assert [line.split("|")[3].strip() for line in calls.splitlines() if line.startswith("| knot50k ")] == ["device"]
    assert [r[3].strip() for r in rows] == ["device", "device/treelets=7", "device/tail=64", "device/sah-top=128",
                                            "Embree (embreex, host CPU)"]
    assert all(r[2].strip() == "50,048" for r in rows)
    sah = {r[3].strip(): float(r[8]) for r in rows[:4]}
    assert sah["device/tail=64"] == sah["device"]          # the hand-over does not change the tree
    assert sah["device/sah-top=128"] == sah["device"]      # the default SAH top
    assert sah["device/treelets=7"] <= sah["device"]        # restructured (the GPU default) or better
    assert all(float(r[5].replace(",", "")) > 0 for r in rows)            # warm build ms
    # --profile: one launch-by-launch table per device variant, the sort's passes in it
    assert out.count("one warm build:") == 4
    # (the sort's passes: radix_scatter_lookback's on GPUs; on CPU devices the host sorts, and PLOC's
    # last iterations are one work-item's: ploc_tail_serial)
    assert "| radix_scatter_lookback | 8 |" in out or "| radix_scatter |" not in out
    assert "| ploc_tail | 1 |" in out or "| ploc_tail_serial | 1 |" in out
    assert "| ploc_top | 1 |" in out


def test_random_rays_are_traced_beside_the_primary_rays(device, capsys, monkeypatch):
    """--random: each tree's kernel ms for the random rays' closest hits and
    their hits, the same for every tree; device/as-gpu, the tree a GPU
    builds (treelets), no dearer than the device's own."""
    monkeypatch.setattr(build, "TRACE_ROUNDS", 2)
    code = build.main(["--device", device or "cpu", "--meshes", "knot50k", "--builders", "sah,device,device/as-gpu",
                       "--repeat", "1", "--random", "20K", "--calls", ""])
    assert code == 0
    out = capsys.readouterr().out
    assert "and 20,000 random rays" in out
    header = next(line for line in out.splitlines() if line.startswith("| scene "))
    columns = [c.strip() for c in header.split("|")]
    rows = {r[3].strip(): r for r in (line.split("|") for line in out.splitlines() if line.startswith("| knot50k "))}
    assert list(rows) == ["sah", "device", "device/as-gpu"]
    random_ms, hits, sah = (columns.index(name) for name in ("random ms", "hits", "SAH cost"))
    assert all(float(r[random_ms]) > 0 for r in rows.values())
    assert len({r[hits] for r in rows.values()}) == 1 and 0 < int(rows["sah"][hits]) < 20_000
    assert float(rows["device/as-gpu"][sah]) <= float(rows["device"][sah])


def test_whole_calls_are_printed_beside_the_build(device, capsys):
    """The second table: for each builder, the warm build of the first beside
    the upload alone, Accel() and Renderer() walls and their ratios to build
    + upload -- numbers that add up, and whole calls no shorter than the
    build they contain."""
    code = build.main(["--device", device or "cpu", "--meshes", "knot50k", "--builders", "sah,device",
                       "--repeat", "1", "--no-trace"])
    assert code == 0
    table, calls = capsys.readouterr().out.split("whole calls")
    warm = {r[3].strip(): float(r[5].replace(",", "")) for r in (line.split("|") for line in table.splitlines())
            if r[1:2] == [" knot50k "]}
    rows = [line.split("|") for line in calls.splitlines() if line.startswith("| knot50k ")]
    assert [r[3].strip() for r in rows] == ["sah", "device"]
    for r in rows:
        build_ms, upload, target, accel, ratio, scene, renderer, renderer_ratio = (
            float(x.replace(",", "")) for x in r[4:12])
        assert build_ms == warm[r[3].strip()] and upload > 0 and scene > 0
        # each printed figure is rounded (ms to 0.1, ratios to 0.01): the sums and ratios of the
        # printed figures hold within those roundings
        total = build_ms + upload
        assert target == pytest.approx(1.5 * total, abs=1.5 * 0.1 + 0.05)
        assert accel >= build_ms * 0.5 and renderer >= build_ms * 0.5      # they contain a build (noise aside)
        for whole, printed in ((accel, ratio), (renderer, renderer_ratio)):
            assert printed == pytest.approx(whole / total, abs=(0.05 + 0.1 * whole / total) / total + 0.005)


def test_settings_combine_in_one_variant(device, capsys, monkeypatch):
    """device/NAME=N/NAME=N: several settings in one variant, each applied
    (here: reinsertion after the treelets lowers the SAH cost)."""
    monkeypatch.setattr(build, "DEVICE_VARIANTS", dict(build.DEVICE_VARIANTS))
    code = build.main(["--device", device or "cpu", "--meshes", "knot50k", "--builders",
                       "device/treelets=7/reinsert=0,device/treelets=7/reinsert=2", "--repeat", "0", "--no-trace",
                       "--calls", ""])
    assert code == 0
    assert build.DEVICE_VARIANTS["device/treelets=7/reinsert=2"] == {"treelet_leaves": 7, "reinsert_iterations": 2}
    rows = [line.split("|") for line in capsys.readouterr().out.splitlines() if line.startswith("| knot50k ")]
    sah = {r[3].strip(): float(r[8]) for r in rows}
    assert sah["device/treelets=7/reinsert=2"] < sah["device/treelets=7/reinsert=0"], sah


def test_the_ploc_radius_is_set_for_the_variant_alone(device, capsys, monkeypatch):
    """device/ploc-radius=N: PLOC searches N clusters on each side on either
    kind of device for that variant's builds (another tree here), and the
    module's own radii are back after it."""
    from clrt.device import build as device_build
    monkeypatch.setattr(build, "DEVICE_VARIANTS", dict(build.DEVICE_VARIANTS))
    saved = dict(device_build.PLOC_RADIUS)
    code = build.main(["--device", device or "cpu", "--meshes", "knot50k", "--builders",
                       "device/treelets=0/reinsert=0,device/treelets=0/reinsert=0/ploc-radius=1", "--repeat", "0",
                       "--no-trace", "--calls", ""])
    assert code == 0 and device_build.PLOC_RADIUS == saved
    assert build.DEVICE_CONSTANTS["device/treelets=0/reinsert=0/ploc-radius=1"] == {"PLOC_RADIUS": {"gpu": 1, "cpu": 1}}
    rows = [line.split("|") for line in capsys.readouterr().out.splitlines() if line.startswith("| knot50k ")]
    sah = {r[3].strip(): float(r[8]) for r in rows}
    assert sah["device/treelets=0/reinsert=0/ploc-radius=1"] != sah["device/treelets=0/reinsert=0"], sah


@pytest.mark.parametrize("builder, message", [
    ("device/treelets=abc", "error: --builders: 'device/treelets=abc' needs an integer after '='"),
    ("device/tail=inf", "error: --builders: 'device/tail=inf' needs an integer after '='"),
    ("device/tail-group=0", "clrt: tail_group must be an integer in 1.."),
    ("device/tail-group=3", "clrt: tail_group must be a power of two in 1.."),
    ("device/sah-top=0", "clrt: top_clusters must be an integer in 1..256, got 0"),
    ("device/treelets=-3", "clrt: treelet_leaves must be an integer in 0..8, got -3"),
    ("device/treelets=2", "clrt: treelet_leaves must be 0 (none) or an integer in 3..8, got 2"),
    ("device/reinsert=65", "clrt: reinsert_iterations must be an integer in 0..64, got 65"),
    ("device/ploc-radius=0", "error: --builders: 'device/ploc-radius=0': ploc-radius must be in 1..24"),
    ("device/ploc-radius=25", "error: --builders: 'device/ploc-radius=25': ploc-radius must be in 1..24"),
    ("device/treelets=0/reinsert=x", "error: --builders: 'device/treelets=0/reinsert=x' needs an integer after '='"),
    ("device/treelets=0/colour=3", "error: --builders: 'device/treelets=0/colour=3': unknown setting 'colour'"),
])
def test_bad_builder_settings_fail_in_one_line(builder, message, device, capsys, monkeypatch):
    monkeypatch.setattr(build, "DEVICE_VARIANTS", dict(build.DEVICE_VARIANTS))
    try:
        code = build.main(["--device", device or "cpu", "--meshes", "knot50k", "--builders", builder,
                           "--repeat", "0", "--no-trace"])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and len([line for line in err if line.startswith(("clrt:", "Traceback"))]) <= 1


def test_help_lists_every_mesh_it_accepts(capsys):
    """--meshes accepts the generated knot50k as well as the mesh files; --help
    names them all (from the same list the check uses)."""
    assert "knot50k" in build.GENERATED
    with pytest.raises(SystemExit):
        build.main(["--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    for name in [*build.CASES, *build.GENERATED]:
        assert name in help_text
    with pytest.raises(SystemExit):
        build.main(["--meshes", "nosuch"])
    assert "choose from bunny00, camel, knot50k" in capsys.readouterr().err

"""`clrt bench` (clrt.bench.paper), its report (clrt.bench.paper_report) and its mesh suite
(clrt.bench.paper_meshes)."""

import argparse
import csv
import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clrt.bench import paper, paper_meshes, paper_report as report
from clrt.bench.paper_meshes import GENERATED, MeshSuite, write_mesh
from clrt.scene.load import load_mesh

# The paper's face counts of the meshes we generate (its Tables 1-5).
PAPER_FACES = {"triangle": 1, "triangle2": 2, "triangle3": 3, "triangle4": 4, "box1": 8, "diamond": 33,
               "icosphere": 80, "sphere": 960, "ellipse": 960, "teapot": 6320}


@pytest.fixture(scope="module")
def generated():
    return {name: g.make() for name, g in GENERATED.items()}


def test_generated_face_counts_match_the_paper(generated):
    assert {name: len(m.faces) for name, m in generated.items()} == PAPER_FACES
    for name, g in GENERATED.items():
        assert g.faces == PAPER_FACES[name] == report.PAPER[name].faces


@pytest.mark.parametrize("name", sorted(PAPER_FACES))
def test_generated_meshes_are_valid(generated, name):
    m = generated[name]
    assert np.all(np.isfinite(m.vertices))
    assert m.faces.min() >= 0 and m.faces.max() < len(m.vertices)
    tri = m.vertices[m.faces].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert area.min() > 1e-6 * area.max(), "no zero-area triangles"
    # Consistent winding: no directed edge is walked twice.
    f = m.faces
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    assert len(np.unique(edges, axis=0)) == len(edges)


def test_teapot_is_newells(generated):
    control = paper_meshes.teapot_control_points()
    assert control.shape == (32, 4, 4, 3)
    # Rim, body and lid: each patch is the previous one turned a quarter about z;
    # handle and spout: the second patch of a pair mirrors the first in y.
    quarter = np.stack([control[..., 1], -control[..., 0], control[..., 2]], -1)
    for group in (0, 4, 8, 20, 24):
        for k in range(group, group + 3):
            np.testing.assert_array_equal(quarter[k], control[k + 1])
    for a in (12, 14, 16, 18):
        np.testing.assert_array_equal((control[a] * [1, -1, 1])[:, ::-1], control[a + 1])
    lo, hi = generated["teapot"].bounds
    np.testing.assert_allclose(lo, [-3.0, 0.0, -2.0], atol=1e-6)   # y up, spout towards +x
    np.testing.assert_allclose(hi[1], 3.15, atol=1e-6)
    # Outward: the enclosed (signed) volume is positive.
    tri = generated["teapot"].vertices[generated["teapot"].faces].astype(np.float64)
    assert np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() > 0


@pytest.mark.parametrize("fmt", ["obj", "off"])
def test_written_meshes_read_back_bit_for_bit(generated, tmp_path, fmt):
    m = generated["diamond"]
    back = load_mesh(write_mesh(m, tmp_path / f"diamond.{fmt}"))
    np.testing.assert_array_equal(back.vertices, m.vertices)
    np.testing.assert_array_equal(back.faces, m.faces)


def test_reduction_is_the_papers_formula_8():
    assert report.reduction(667, 632) == pytest.approx(5.2474, abs=1e-4)       # Table 1, triangle.obj: 5.25%
    assert report.reduction(7158953, 901752) == pytest.approx(87.40, abs=0.01)  # dragon.ply: 87.40%
    assert report.reduction(100.0, 150.0) == -50.0
    assert report.reduction(10.0, 0.0) == 100.0


def test_paper_times_lookup():
    assert report.paper_time("teapot", 6320, "basic") == 1254613
    assert report.paper_time("teapot", 6320, "gpu") == 397596
    assert report.paper_time("teapot", 6320, "bvh-sphere") == 371324
    assert report.paper_time("teapot", 6320, "bvh-gpu-ellipse") == 18332
    assert report.paper_time("icosphere", 80, "bvh-gpu-box") is None    # not in the paper's Table 5
    assert report.paper_time("camel", 19536, "basic") is None           # not the paper's face count
    assert report.paper_time("cow", 5804, "basic") is None


def _sphere_off(path, segments, stacks):
    write_mesh(paper_meshes.uv_sphere(segments, stacks), path)


def test_suite_reads_scans_from_a_folder(tmp_path):
    _sphere_off(tmp_path / "camel.off", 16, 8)        # 224 faces: fewer than the paper's 4,884
    _sphere_off(tmp_path / "cow.off", 8, 4)
    (tmp_path / "readme.txt").write_text("not a mesh")
    suite = MeshSuite(tmp_path)
    assert "camel-full" in suite and "cow" in suite and "camel" not in suite
    # What --list says of it is what happens: no decimation (with or without the
    # package) and no subdivision up to the paper's count, only camel-full.
    (note,) = [n for n in suite.notes if n.startswith("camel:")]
    assert note == ("camel: camel.off has 224 faces, not more than the paper's 4,884: not decimated (nor "
                    "subdivided); it runs at full size as camel-full only"), note
    assert len(suite.make("cow").faces) == 2 * 8 * 3
    with pytest.raises(Exception, match="camel"):
        suite["camel"]
    assert MeshSuite(tmp_path / "missing").names() == list(GENERATED)


def test_suite_decimates_to_the_papers_count(tmp_path):
    pytest.importorskip("fast_simplification")
    _sphere_off(tmp_path / "bunny00.off", 96, 64)     # 12,096 faces
    suite = MeshSuite(tmp_path)
    assert suite["bunny"].faces == 6966
    bunny = suite.make("bunny")
    assert abs(len(bunny.faces) - 6966) <= 2
    assert len(suite.make("bunny-full").faces) == 2 * 96 * 63


def _parse(argv):
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    paper.add_bench_parser(sub)
    return parser.parse_args(["bench", *argv])


def test_tiny_bench_run_writes_the_tables(tmp_path, monkeypatch, device, capsys):
    # Pretend there is no GPU, so that the run must say so and go on with the CPU programs.
    monkeypatch.setattr(paper, "_available_kinds", lambda cpu, gpu: {"CPU": True, "GPU": False})
    out = tmp_path / "results"
    args = _parse(["--meshes", "triangle2,icosphere", "--programs", "basic,bvh-box,bvh-ellipse,gpu",
                   "--builder", "paper", "--size", "16x16", "--repeat", "1", "--warmup", "1",
                   "--out", str(out), "--mesh-dir", str(tmp_path),
                   "--cpu-device", device or "cpu", "--detail-meshes", "triangle2,icosphere"])
    assert paper.run_bench(args) == 0
    err = capsys.readouterr().err
    assert "no GPU OpenCL device" in err and "[6/6]" in err

    with open(out / "times.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == report.CSV_COLUMNS
    assert [(r["mesh"], r["program"], r["builder"]) for r in rows] == [
        (m, p, b) for m in ("triangle2", "icosphere")
        for p, b in (("basic", "-"), ("bvh-box", "paper"), ("bvh-ellipse", "paper"))]
    for r in rows:
        parts = sum(float(r[k]) for k in ("load_ms", "init_ms", "build_ms", "upload_ms", "frame_wall_ms"))
        assert float(r["total_ms"]) == pytest.approx(parts, rel=1e-4)
        assert float(r["kernel_ms"]) > 0 and float(r["mrays_wall"]) > 0
        assert r["width"] == r["height"] == "16"
        assert float(r["paper_ms"]) == report.paper_time(r["mesh"], int(r["faces"]), r["program"])

    md = (out / "tables.md").read_text()
    assert "no GPU OpenCL device" in md and "clrt bench --meshes triangle2,icosphere" in md
    assert "## Table 4 of the paper: basic vs BVH on the CPU device, builder paper" in md
    assert "Not run: needs both the basic and the gpu program." in md
    header = "| mesh | faces | basic | BVH | BVH ms | reduction | paper BVH | paper reduction | speed-up | Mrays/s |"
    assert header in md
    assert "| icosphere | 80 |" in md and "| 3,803 | 73.31% |" in md    # paper's icosphere box: 3803 ms
    assert "sah" not in md.split("## All measurements")[1].split("## Detail")[0]

    for png in ("time-vs-faces.png", "kernel-vs-faces.png", "detail-loss.png"):
        with Image.open(out / png) as im:
            assert im.format == "PNG" and im.width > 300
    assert sorted(p.name for p in (out / "meshes").glob("[!.]*")) == ["icosphere.obj", "triangle2.obj"]
    # no temporary files left behind; beside each file the record that clrt wrote it
    assert sorted(p.name for p in out.glob(".*")) == sorted(f".{p.name}.clrt" for p in out.iterdir()
                                                            if p.is_file() and not p.name.startswith("."))

    with open(out / "detail-loss.csv", newline="") as fh:
        detail = list(csv.DictReader(fh))
    assert len(detail) == 2 * 3
    assert {d["placement"].split(":")[0] for d in detail} == {"apel.obj", "sample1.3DS"}
    assert all(d["differ_from_basic"] == "0" and d["differ_same_device"] == "0" for d in detail)
    assert "every program draws the same image" in md


def test_unknown_names_are_input_errors(tmp_path):
    from clrt.errors import InputError
    with pytest.raises(InputError, match="unknown program"):
        paper.run_bench(_parse(["--programs", "fastest", "--out", str(tmp_path)]))
    with pytest.raises(InputError, match="not available"):
        paper.run_bench(_parse(["--meshes", "apel", "--out", str(tmp_path)]))


def test_chart_draws_without_data_and_with_one_point():
    empty = np.asarray(Image.open(io.BytesIO(report.loglog_chart([], "t", "ms"))).convert("RGB"))
    assert empty.shape == (640, 1000, 3)
    ink = (empty < 128).all(axis=2)                   # black text on white
    assert ink[320:335, 90:160].any(), "'no data' is written at mid-height"
    assert (empty.max(axis=2) - empty.min(axis=2)).max() == 0, "only greys without a series"
    colour = (31, 119, 180)                           # #1f77b4
    png = report.loglog_chart([("basic", "#1f77b4", False, [(80, 1.5)])], "t", "ms")
    chart = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    # axes: faces 10..100 over x pixels 90..750, ms 1..10 over y pixels 570..50 (log)
    x = 90 + (np.log10(80) - 1) * (750 - 90)
    y = 570 - np.log10(1.5) * (570 - 50)
    is_colour = (chart == colour).all(axis=2)
    rows, cols = np.nonzero(is_colour[:, :760])        # the plot, legend left out
    assert len(rows) > 10
    assert abs(cols.mean() - x) < 1.5 and abs(rows.mean() - y) < 1.5, "the point sits at (80, 1.5)"
    assert is_colour[50:70, 760:800].any(), "the legend shows the series"


def test_outputs_are_checked_before_any_work(tmp_path, capsys):
    """A user's file in --out is never replaced without --force, and nothing is
    written when an option is bad: every check comes before the first output."""
    from clrt.errors import DeviceError, InputError, OutputError
    tiny = ["--meshes", "triangle", "--programs", "basic", "--size", "8x8", "--repeat", "1", "--warmup", "0",
            "--no-detail"]
    out = tmp_path / "out"
    out.mkdir()
    (out / "tables.md").write_text("precious")
    with pytest.raises(OutputError, match="tables.md exists and was not written by clrt.*another --out"):
        paper.run_bench(_parse([*tiny, "--out", str(out)]))
    assert sorted(p.name for p in out.iterdir()) == ["tables.md"]
    assert paper.run_bench(_parse([*tiny, "--out", str(out), "-f"])) == 0
    assert (out / "tables.md").read_text() != "precious"
    assert paper.run_bench(_parse([*tiny, "--out", str(out)])) == 0       # its own files: replaced
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="it is a file, not a folder"):
        paper.run_bench(_parse([*tiny, "--out", str(tmp_path / "file")]))
    fresh = tmp_path / "fresh"
    with pytest.raises(InputError, match="--cpu-device must be"):
        paper.run_bench(_parse([*tiny, "--programs", "cpu", "--out", str(fresh), "--cpu-device", "foo"]))
    with pytest.raises(DeviceError, match="does not exist"):
        paper.run_bench(_parse([*tiny, "--programs", "cpu", "--out", str(fresh), "--cpu-device", "9:9"]))
    with pytest.raises(InputError, match="--mesh-dir .*: no such folder"):
        paper.run_bench(_parse([*tiny, "--out", str(fresh), "--mesh-dir", str(tmp_path / "none")]))
    with pytest.raises(SystemExit):
        _parse([*tiny, "--out", str(fresh), "--leaf-size", "300"])
    assert not fresh.exists()


def _run(mesh, faces, program, builder, total=10.0):
    return report.Run(mesh, faces, "generated", program, builder, "CPU", "cpu", 200, 200, 1, 1,
                     1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 1.0, total - 4.0, total, 4.0, 20.0)


def _report(runs, builders=("paper", "sah", "device")):
    args = argparse.Namespace(leaf_size=4, warmup=1, repeat=1, force=False)
    r = report.Report(Path("/nonexistent"), "clrt bench", 200, 200, list(builders), args, [])
    r.runs = list(runs)
    return r


def test_chart_series_of_each_builder_look_different():
    """time-vs-faces.png / kernel-vs-faces.png: colour per program, line style
    and marker per builder, so the legend tells every series apart."""
    runs = [_run("sphere", 960, "bvh-box", b) for b in ("paper", "sah", "device")]
    runs += [_run("sphere", 960, "bvh-sphere", b) for b in ("paper", "sah", "device")]
    series = _report(runs).series("total_ms")
    styles = {label: (colour, style) for label, colour, style, _ in series}
    assert len(set(styles.values())) == len(styles) == 6, styles
    assert {s for _, s in styles.values()} == {"solid", "dashed", "dotted"}
    png = report.loglog_chart(series, "t", "ms")             # draws every style, legend included
    assert Image.open(io.BytesIO(png)).size == (1000, 640)


def test_table4_keeps_bvh_rows_when_basic_was_skipped():
    """--max-brute-faces skips basic, as the paper did for ddboat, whose BVH
    times the paper's Table 4 still lists: the BVH rows stay, with basic and
    reduction blank, and the paper's BVH time is shown without its basic time."""
    runs = [_run("diamond", 33, "basic", "-"), _run("diamond", 33, "bvh-box", "sah", total=6.0),
            _run("sphere", 960, "bvh-box", "sah"),           # sphere: basic skipped
            _run("ddboat", 82666, "bvh-box", "sah")]          # the paper has no basic time
    table = "\n".join(_report(runs, ["sah"])._table2())
    sphere = next(line for line in table.splitlines() if line.startswith("| sphere |"))
    assert sphere.split(" | ")[2] == "-" and sphere.split(" | ")[5] == "-", sphere   # basic, reduction
    ddboat = next(line for line in table.splitlines() if line.startswith("| ddboat |"))
    cells = [c.strip() for c in ddboat.split("|")[1:-1]]
    assert cells[6] == "6,796,711" and cells[7] == "-", cells      # paper BVH; no paper reduction
    diamond = next(line for line in table.splitlines() if line.startswith("| diamond |"))
    assert [c.strip() for c in diamond.split("|")[1:-1]][5] == "40.00%"   # 10 ms -> 6 ms


def test_clrt_bench_explains_itself(capsys):
    """``clrt bench --help``: the command's usage and a line of help for every option."""
    from clrt import cli
    assert cli.main(["bench", "--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: clrt bench [-h]")
    sub = next(a for a in cli._parser(bench=True)._actions if isinstance(a, argparse._SubParsersAction))
    bare = [a.option_strings[0] for a in sub.choices["bench"]._actions if a.option_strings and not a.help]
    assert not bare, f"options without help: {bare}"

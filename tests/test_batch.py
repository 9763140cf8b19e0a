"""Batch jobs on Dask distributed (clrt.batch, ``clrt batch render``): the same
images as ``clrt render`` with 1 or 2 workers, nothing lost when a worker dies,
resume, bad sources, ray queries on dask arrays, and a loopback-only cluster.

Clusters are LocalClusters of at most 2 worker processes on PoCL; images are
tiny and meshes generated."""

import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("distributed")

import dask  # noqa: E402
import dask.array as da  # noqa: E402
from distributed import Client  # noqa: E402
from distributed.diagnostics.plugin import WorkerPlugin  # noqa: E402

import clrt  # noqa: E402
import clrt.batch  # noqa: E402
from clrt.batch.cluster import start_local_cluster  # noqa: E402
from clrt.batch.jobs import Source, expand_sources, plan_tasks  # noqa: E402
from clrt.cli import main  # noqa: E402
from clrt.config import BATCH_MANIFEST  # noqa: E402
from clrt.errors import InputError, OutputError  # noqa: E402
from clrt.output import write_file  # noqa: E402
from clrt.scene import primitives  # noqa: E402
from clrt.scene.render_setup import turntable  # noqa: E402
from clrt.scene.scene import Camera  # noqa: E402

SIZE = {"width": 20, "height": 14}
SIZE_ARGS = ["--width", "20", "--height", "14"]


def _write_obj(path, mesh):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshes")
    return [_write_obj(folder / "ball.obj", primitives.icosphere(1)),
            _write_obj(folder / "block.obj", primitives.box((1.0, 0.6, 1.4)))]


@pytest.fixture(scope="module")
def client(device):
    """One cluster of 2 worker processes for the module's Python-API tests."""
    with start_local_cluster(2, device) as cluster, Client(cluster) as c:
        yield c


def _manifest(folder):
    return [json.loads(line) for line in (folder / BATCH_MANIFEST).read_text().splitlines()]


def _images(folder):
    return {p.relative_to(folder).as_posix(): np.asarray(Image.open(p)) for p in sorted(folder.rglob("*.png"))}


# --------------------------------------------------------------------------- without a cluster

def test_turntable_keeps_distance_elevation_and_framing():
    camera = Camera((1.0, 2.0, 5.0), (0.5, 0.25, -1.0), fov=40.0, width=30, height=20)
    target = np.array(camera.target)
    for i in range(8):
        view = turntable(camera, i, 8)
        offset, base = np.array(view.eye) - target, np.array(camera.eye) - target
        assert np.isclose(np.linalg.norm(offset), np.linalg.norm(base))
        assert np.isclose(offset[1], base[1])                     # same height above the target
        azimuth = math.degrees(math.atan2(offset[0], offset[2]) - math.atan2(base[0], base[2])) % 360
        assert np.isclose(azimuth, 45.0 * i) or np.isclose(azimuth - 360.0, 45.0 * i)
        assert (view.target, view.up, view.fov, view.width, view.height) == \
               (camera.target, camera.up, camera.fov, camera.width, camera.height)
    assert turntable(camera, 0, 8) is camera


def test_sources_names_and_tasks(tmp_path, meshes):
    other = tmp_path / "other"
    other.mkdir()
    twin = _write_obj(other / "ball.obj", primitives.icosphere(1))
    (other / "notes.txt").write_text("not a mesh")
    found = expand_sources([str(meshes[0]), str(other), str(meshes[0].parent / "*.obj"), "nope.obj",
                            str(tmp_path / "*.stl")])
    paths = [s.path for s in found if not s.error]
    assert paths == [str(meshes[0]), str(twin), str(meshes[1])], "each file once, in argument order"
    names = [s.name for s in found if not s.error]
    assert len(set(names)) == 3 and names[2] == "block"
    assert names[0].startswith("ball-") and names[1].startswith("ball-"), "colliding stems get a path hash"
    assert [s.error.split(":")[-1].strip() for s in found if s.error] == ["no such file",
                                                                          "no file matches this pattern"]
    source = Source("x", "x")
    assert [t.views for t in plan_tasks(source, list(range(4)), set(), 2, 1)] == [[0, 1], [2, 3]]
    assert [len(t.views) for t in plan_tasks(source, list(range(20)), {3}, 2, 5)] == [7, 7, 6]
    assert plan_tasks(source, list(range(20)), {3}, 2, 5)[0].replace == [3]


def test_batch_takes_every_render_option():
    from clrt.batch.cli import NOT_TAKEN, parser
    from clrt.cli import _parser

    def options(p, command):
        sub = next(a for a in p._actions if a.dest == "command").choices[command]
        return {s for a in sub._actions for s in a.option_strings if s.startswith("--")}

    missing = options(_parser(), "render") - options(parser(), "render") - set(NOT_TAKEN) - {"--help"}
    assert not missing, f"clrt batch render lacks {missing}"


@pytest.mark.parametrize("args, fragment", [
    (["--views", "0"], "--views must be an integer in 1..100000, got 0"),
    (["--workers", "0"], "--workers must be an integer in 1..4096, got 0"),
    (["--width", "0"], "--width must be"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not allowed with"),
    (["--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler"),
    (["--scheduler", "tls://127.0.0.1:1"], "needs certificates"),
    (["--format", "psd"], "--format must be one of png, jpg, jpeg, tif, tiff, webp, gif, bmp, ppm, exr, got 'psd'"),
    (["--format", "jpg", "--bit-depth", "16"], "JPEG holds 8-bit sRGB gray or RGB images, not 16-bit sRGB RGB images; "
                                               "formats that can: .png"),
    (["--format", "exr", "--bit-depth", "8"], "OpenEXR holds linear float32"),
    (["--bit-depth", "12"], "--bit-depth must be 8 or 16, got 12"),
])
def test_bad_options_are_one_line_errors(args, fragment, meshes, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("clrt.batch.cluster.BATCH_CONNECT_TIMEOUT", 1.0)   # nobody listens there
    code = main(["batch", "render", str(meshes[0]), "-o", str(tmp_path / "out"), *args])
    out, err = capsys.readouterr()
    assert code == 2
    assert fragment in err and err.startswith("clrt: ") and len(err.strip().splitlines()) == 1, err
    assert not list((tmp_path / "out").rglob("*.png"))


def test_workers_are_capped_at_the_cores_and_the_tasks(monkeypatch):
    """--workers 64 on 2 cores started 64 processes (92 s for one tiny frame):
    a local cluster gets at most one worker per core and per task, with a note."""
    from clrt.batch import engine
    monkeypatch.setattr(engine, "cpu_cores", lambda: 2)
    notes, asked_for = [], []

    def jobs(n):
        def make(count):
            asked_for.append(count)
            return list(range(n))
        return make

    assert engine._local_workers(64, "cpu", notes.append, jobs(5)) == (2, [0, 1, 2, 3, 4])
    assert asked_for == [2], "the tasks are cut for the workers that can run"
    assert engine._local_workers(64, "cpu", notes.append, jobs(1))[0] == 1
    assert engine._local_workers(2, "cpu", notes.append, jobs(3))[0] == 2
    assert engine._local_workers(None, "cpu", notes.append, jobs(1))[0] == 1
    assert notes == ["2 worker(s) instead of 64: 2 CPU core(s), 5 task(s)",
                     "1 worker(s) instead of 64: 2 CPU core(s), 1 task(s)"]


def test_workers_asked_beyond_the_tasks_are_not_started(meshes, tmp_path, device, capsys):
    dev = ["--device", device] if device else []
    assert main(["batch", "render", str(meshes[0]), "-o", str(tmp_path / "out"), *SIZE_ARGS, "--workers", "64",
                 *dev]) == 0
    printed, err = capsys.readouterr()
    from clrt.batch.cluster import cpu_cores
    assert f"1 worker(s) instead of 64: {cpu_cores()} CPU core(s), 1 task(s)" in err.splitlines(), err
    assert "1 frame(s) rendered" in printed and "1 worker(s) ->" in printed, printed


def test_each_worker_gets_its_own_device(monkeypatch):
    from clrt.batch import worker
    from clrt.device.context import DeviceInfo

    def info(p, d, kind):
        return DeviceInfo(p, d, "platform", f"dev{p}{d}", kind, 1, 1, 1, 1, "OpenCL 3.0", "1")

    devices = [info(0, 0, "CPU"), info(1, 0, "GPU"), info(1, 1, "GPU"), info(1, 2, "GPU")]
    monkeypatch.setattr("clrt.device.context.list_devices", lambda: devices)
    monkeypatch.delenv("CLRT_DEVICE", raising=False)
    assert [worker.choose_device(None, i) for i in range(4)] == ["1:0", "1:1", "1:2", "1:0"]
    assert [worker.choose_device("gpu", i) for i in (0, 2)] == ["1:0", "1:2"]
    assert worker.choose_device("cpu", 1) == "0:0"
    assert worker.choose_device("1:1", 0) == "1:1"
    monkeypatch.setenv("CLRT_DEVICE", "1:2")
    assert worker.choose_device(None, 0) == "1:2" and worker.choose_device("gpu", 0) == "1:2"
    assert worker.choose_device("0:0", 0) == "0:0", "a P:D given to the batch wins"
    assert [worker.worker_index(n) for n in (3, "gpu-2", "tcp://h:1234-1", "x")] == [3, 2, 1, None]


# --------------------------------------------------------------------------- clusters

def test_local_cluster_listens_on_loopback_only(device):
    import psutil
    with start_local_cluster(2, device) as cluster:
        info = cluster.scheduler_info
        addresses = [cluster.scheduler_address, *info["workers"],
                     *(w["nanny"] for w in info["workers"].values())]
        assert len(addresses) == 5
        assert all(a.startswith("tcp://127.0.0.1:") for a in addresses), addresses
        assert cluster.dashboard_link.startswith("http://127.0.0.1:")
        processes = [psutil.Process()] + psutil.Process().children(recursive=True)
        sockets = [getattr(p, "net_connections", None) or p.connections for p in processes]   # psutil < 6
        listening = [c.laddr for each in sockets for c in each(kind="inet") if c.status == "LISTEN"]
        assert len(listening) >= 6   # scheduler, its HTTP server, 2 workers, 2 nannies
        assert all(addr.ip == "127.0.0.1" for addr in listening), listening


def test_one_and_two_workers_make_the_images_of_clrt_render(meshes, tmp_path, device, capsys):
    dev = ["--device", device] if device else []
    args = [str(m) for m in meshes] + ["--views", "3", "--width", "20", "--height", "14", "-q", *dev]
    assert main(["batch", "render", *args, "-o", str(tmp_path / "one"), "--workers", "1"]) == 0
    assert main(["batch", "render", *args, "-o", str(tmp_path / "two"), "--workers", "2"]) == 0
    capsys.readouterr()
    one, two = _images(tmp_path / "one"), _images(tmp_path / "two")
    assert sorted(one) == [f"{s}/view-{v:04d}.png" for s in ("ball", "block") for v in range(3)]
    for name in one:
        assert np.array_equal(one[name], two[name]), name
    assert not np.array_equal(one["ball/view-0000.png"], one["block/view-0000.png"])
    assert not np.array_equal(one["block/view-0000.png"], one["block/view-0001.png"]), "views differ"
    records = {r["path"]: r for r in _manifest(tmp_path / "two")}
    assert {r["status"] for r in records.values()} == {"done"} and len(records) == 6
    assert len({r["worker"] for r in records.values()}) == 2, "both workers rendered"

    # The same cameras through clrt render: view 0 is its default camera, the others its --eye/--target.
    for name in ("block/view-0000.png", "block/view-0002.png"):
        cam = records[name]["camera"]
        out = tmp_path / f"single-{name.replace('/', '-')}"
        place = [] if name.endswith("0000.png") else \
            ["--eye", ",".join(map(repr, cam["eye"])), "--target", ",".join(map(repr, cam["target"]))]
        assert main(["render", str(meshes[1]), "-o", str(out), "--width", "20", "--height", "14", "-q",
                     *place, *dev]) == 0
        assert np.array_equal(np.asarray(Image.open(out)), one[name]), name


def test_bad_sources_are_reported_while_the_others_finish(meshes, tmp_path, device, capsys):
    (tmp_path / "corrupt.obj").write_text("v 1 2\nf 1 2 3\n")
    (tmp_path / "empty.off").write_text("")
    dev = ["--device", device] if device else []
    code = main(["batch", "render", str(meshes[0]), str(tmp_path / "missing.obj"), str(tmp_path / "corrupt.obj"),
                 str(tmp_path / "empty.off"), "-o", str(tmp_path / "out"), "--views", "2",
                 "--width", "20", "--height", "14", "--workers", "2", "-q", *dev])
    out, err = capsys.readouterr()
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 3 and all(line.startswith("clrt: ") for line in lines), err
    assert "missing.obj: no such file" in err and "corrupt.obj" in err and "empty.off" in err
    assert "Traceback" not in err
    assert sorted(_images(tmp_path / "out")) == ["ball/view-0000.png", "ball/view-0001.png"]
    statuses = {(r["source"].rsplit("/", 1)[-1], r["view"]): r["status"] for r in _manifest(tmp_path / "out")}
    assert statuses == {("ball.obj", 0): "done", ("ball.obj", 1): "done", ("missing.obj", None): "bad",
                        ("corrupt.obj", 0): "bad", ("corrupt.obj", 1): "bad",
                        ("empty.off", 0): "bad", ("empty.off", 1): "bad"}
    assert "2 frame(s) rendered" in out


def test_device_trouble_exits_3(meshes, tmp_path, capsys):
    code = main(["batch", "render", str(meshes[0]), "-o", str(tmp_path / "out"), "--width", "20",
                 "--height", "14", "--device", "9:9", "-q"])
    out, err = capsys.readouterr()
    assert code == 3
    assert err.count("\n") == 1 and "9" in err and "does not exist" in err, err
    assert not list((tmp_path / "out").rglob("*.png"))


class KillOnce(WorkerPlugin):
    """Kills its worker process when the worker starts its first render task,
    once per batch (a marker file remembers)."""

    name = "test-kill-once"

    def __init__(self, marker):
        self.marker = str(marker)

    def setup(self, worker):
        self.worker = worker

    def transition(self, key, start, finish, **kwargs):
        if finish == "executing" and str(key).startswith("clrt-render") and not os.path.exists(self.marker):
            with open(self.marker, "w") as fh:
                fh.write(str(os.getpid()))
            os._exit(1)


def test_a_killed_workers_tasks_are_done_elsewhere(client, meshes, tmp_path, device):
    marker = tmp_path / "killed"
    client.register_plugin(KillOnce(marker))
    try:
        outputs = clrt.batch.render(meshes, tmp_path / "out", views=4, client=client, device=device, **SIZE)
    finally:
        client.unregister_worker_plugin(KillOnce.name)
    assert marker.exists(), "a worker was killed"
    assert sorted(o.status for o in outputs) == ["done"] * 8
    images = _images(tmp_path / "out")
    assert len(images) == 8
    records = _manifest(tmp_path / "out")
    assert sorted(r["path"] for r in records) == sorted(images), "each output recorded once"
    assert not [p for p in (tmp_path / "out").rglob(".*.png*")
                if not (p.name.endswith(".clrt") and p.with_name(p.name[1:-5]).is_file())], "no temporary file left"
    assert int(marker.read_text()) not in [p["pid"] for p in client.run(lambda: {"pid": os.getpid()}).values()]


@pytest.mark.parametrize("folder", ["", "  "])
def test_an_empty_output_folder_is_refused(folder, meshes, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)   # '' would be this folder
    code = main(["batch", "render", str(meshes[0]), "-o", folder, "--workers", "1", "--width", "8"])
    out, err = capsys.readouterr()
    assert code == 2 and err == f"clrt: -o must name a folder, got {folder!r}\n", err
    assert not out and not list(tmp_path.iterdir()), "nothing written"
    with pytest.raises(OutputError, match="out_dir must name a folder"):
        clrt.batch.render(meshes[0], folder, workers=1)
    with pytest.raises(InputError, match=r"^views must be an integer in 1\.\.100000, got 0$"):
        clrt.batch.render(meshes[0], tmp_path / "out", views=0)   # the Python name, not --views
    assert not list(tmp_path.iterdir())


def test_a_manifest_clrt_did_not_write_is_kept_without_force(client, meshes, tmp_path, device, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / BATCH_MANIFEST).write_text("precious\n")
    code = main(["batch", "render", str(meshes[0]), "-o", str(out), "--workers", "1", "--width", "8",
                 "--height", "8"])
    _, err = capsys.readouterr()
    assert code == 2 and err.startswith("clrt: ") and len(err.strip().splitlines()) == 1, err
    assert "manifest.jsonl exists and was not written by clrt" in err and "--force" in err
    assert (out / BATCH_MANIFEST).read_text() == "precious\n" and not list(out.rglob("*.png"))
    with pytest.raises(OutputError, match="not written by clrt"):
        clrt.batch.render(meshes[0], out, client=client, device=device, **SIZE)
    assert (out / BATCH_MANIFEST).read_text() == "precious\n"

    # force=True replaces it (unread) with clrt's own manifest, which the next run reads and resumes from.
    first = clrt.batch.render(meshes[0], out, client=client, device=device, force=True, **SIZE)
    assert [o.status for o in first] == ["done"]
    assert "note" not in _manifest(out)[0]
    again = clrt.batch.render(meshes[0], out, client=client, device=device, **SIZE)
    assert [o.status for o in again] == ["skipped"]
    records = _manifest(out)
    assert [r["path"] for r in records] == ["ball/view-0000.png"]
    assert "note" not in records[0], "known from the manifest, not found afresh"

    # A manifest changed since clrt wrote it is the user's now.
    ours = (out / BATCH_MANIFEST).read_text()
    (out / BATCH_MANIFEST).write_text(ours + "{}\n")
    with pytest.raises(OutputError, match="manifest.jsonl was changed since clrt wrote it"):
        clrt.batch.render(meshes[0], out, client=client, device=device, **SIZE)

    # A folder from before manifests had records (clrt's lines, no record beside): resumed as before.
    (out / BATCH_MANIFEST).write_text(ours)
    (out / f".{BATCH_MANIFEST}.clrt").unlink()
    resumed = clrt.batch.render(meshes[0], out, client=client, device=device, **SIZE)
    assert [o.status for o in resumed] == ["skipped"] and "note" not in _manifest(out)[0]
    assert (out / f".{BATCH_MANIFEST}.clrt").exists()


def test_frames_as_linear_exr_and_16_bit_png(client, meshes, tmp_path, device, capsys):
    """format="exr" writes the linear float32 image that ``clrt render -o x.exr``
    writes, bit for bit; bit_depth=16 a 16-bit PNG that, reduced to 8 bits, is
    the 8-bit frame within one level.  The manifest names the files by their
    format; the same file name at another depth is rendered again, at the same
    depth skipped."""
    OpenEXR = pytest.importorskip("OpenEXR", reason="EXR frames need the exr extra (the test extra has it)")
    from png_reference import spec_decode
    out = tmp_path / "out"

    def batch(**kwargs):
        outputs = clrt.batch.render([meshes[1]], out, views=2, client=client, device=device, **SIZE, **kwargs)
        return sorted(o.status for o in outputs)

    assert batch(format="exr") == ["done", "done"]
    records = {r["path"]: r for r in _manifest(out)}
    assert sorted(records) == ["block/view-0000.exr", "block/view-0001.exr"]
    cam = records["block/view-0001.exr"]["camera"]
    single = tmp_path / "single.exr"
    dev = ["--device", device] if device else []
    assert main(["render", str(meshes[1]), "-o", str(single), *SIZE_ARGS, "-q", *dev, "--eye",
                 ",".join(map(repr, cam["eye"])), "--target", ",".join(map(repr, cam["target"]))]) == 0
    capsys.readouterr()

    def pixels(path):
        with OpenEXR.File(str(path), separate_channels=True) as f:
            return {name: c.pixels for name, c in f.channels().items()}

    frame, expected = pixels(out / "block" / "view-0001.exr"), pixels(single)
    assert sorted(frame) == ["B", "G", "R"] and frame["R"].dtype == np.float32
    assert all(frame[c].tobytes() == expected[c].tobytes() for c in "RGB")

    assert batch(bit_depth=16) == ["done", "done"]
    sixteen = {v: spec_decode((out / "block" / f"view-000{v}.png").read_bytes()) for v in (0, 1)}
    assert all(codes.dtype == np.uint16 and codes.shape == (14, 20, 3) for codes in sixteen.values())
    assert batch(bit_depth=16) == ["skipped", "skipped"]
    assert batch() == ["done", "done"], "8-bit frames of the same names: rendered again"
    assert batch(bit_depth=8) == ["skipped", "skipped"], "bit_depth 8 is the default"
    for v, codes in sixteen.items():
        image = np.asarray(Image.open(out / "block" / f"view-000{v}.png")).astype(int)
        assert np.abs(np.rint(codes / 257.0) - image).max() <= 1
    assert sorted(r["path"] for r in _manifest(out)) == sorted(f"block/view-000{v}.{s}" for s in ("exr", "png")
                                                                for v in (0, 1))


def test_path_traced_frames_are_those_of_clrt_render(client, meshes, tmp_path, device, capsys):
    """With the path tracer, an EXR frame holds what ``clrt render -o x.exr``
    writes -- the linear image and the denoisers' albedo and normal channels
    -- and a 16-bit PNG frame applies ``exposure`` as ``clrt render
    --bit-depth 16`` does: bit for bit, the same seed on the same device."""
    OpenEXR = pytest.importorskip("OpenEXR", reason="EXR frames need the exr extra (the test extra has it)")
    from png_reference import spec_decode

    from clrt.scene.texture import srgb_encode

    def read_exr(path):
        with OpenEXR.File(str(path), separate_channels=True) as f:
            return {name: c.pixels for name, c in f.channels().items()}
    out = tmp_path / "out"
    path = dict(integrator="path", spp=3, seed=5, exposure=1.5)
    dev = ["--device", device] if device else []
    for kwargs, name in ((dict(format="exr"), "view-0000.exr"), (dict(bit_depth=16), "view-0000.png")):
        outputs = clrt.batch.render([meshes[0]], out, client=client, device=device, **SIZE, **path, **kwargs)
        assert [o.status for o in outputs] == ["done"]
        cam = {r["path"]: r for r in _manifest(out)}[f"ball/{name}"]["camera"]
        single = tmp_path / f"single-{name}"
        assert main(["render", str(meshes[0]), "-o", str(single), *SIZE_ARGS, "-q", *dev, "--integrator", "path",
                     "--spp", "3", "--seed", "5", "--exposure", "1.5", "--eye", ",".join(map(repr, cam["eye"])),
                     "--target", ",".join(map(repr, cam["target"])),
                     *(["--bit-depth", "16"] if "bit_depth" in kwargs else [])]) == 0
        capsys.readouterr()
        if name.endswith(".exr"):
            frame, expected = read_exr(out / "ball" / name), read_exr(single)
            assert sorted(frame) == sorted(expected) and {"albedo.R", "normal.Z"} <= set(frame)
            assert all(frame[c].tobytes() == expected[c].tobytes() for c in frame)
            linear = np.stack([frame[c] for c in "RGB"], axis=-1)
        else:
            codes = spec_decode((out / "ball" / name).read_bytes())
            np.testing.assert_array_equal(codes, spec_decode(single.read_bytes()))
            # the linear EXR frame x 2^1.5, clamped, sRGB-encoded to 16 bits
            np.testing.assert_array_equal(codes, srgb_encode(linear * np.float32(2.0 ** 1.5), 16))
            assert (codes > 0).any() and (codes < 65535).any()


def test_resume_renders_only_what_is_missing(client, meshes, tmp_path, device):
    out = tmp_path / "out"
    first = clrt.batch.render(meshes, out, views=3, client=client, device=device, **SIZE)
    assert sorted(o.status for o in first) == ["done"] * 6
    before = {p: os.stat(out / p).st_mtime_ns for p in _images(out)}
    (out / "block/view-0001.png").unlink()                       # lost ...
    lines = (out / BATCH_MANIFEST).read_text().splitlines()     # ... and one never recorded (client killed):
    write_file("\n".join(line for line in lines if "ball/view-0002" not in line) + "\n",   # as clrt wrote it
               out / BATCH_MANIFEST, force=True)

    again = clrt.batch.render(meshes, out, views=3, client=client, device=device, **SIZE)
    redone = [o for o in again if o.seconds > 0]
    assert [(o.source, o.view, o.redone) for o in redone] == [(str(meshes[1]), 1, "missing")]
    assert sorted(o.status for o in again) == ["done"] + ["skipped"] * 5
    for p, stamp in before.items():
        if p != "block/view-0001.png":
            assert os.stat(out / p).st_mtime_ns == stamp, f"{p} was rendered again"
    assert len(_manifest(out)) == 6

    # Other settings make other images: all are rendered again.
    changed = clrt.batch.render(meshes, out, views=3, client=client, device=device, width=22, height=14)
    assert sorted(o.status for o in changed) == ["done"] * 6 and all(o.seconds > 0 for o in changed)
    assert all(img.shape == (14, 22, 3) for img in _images(out).values())


def test_resume_rerenders_frames_missing_cut_short_or_replaced(client, meshes, tmp_path, device, capsys):
    """A finished batch; then one frame deleted, one cut to 100 bytes, one
    replaced by another image (its record left as it was): running it again
    renders those three again -- the files, not their names, say what is done
    -- and says why; the untouched frame is kept."""
    out = tmp_path / "out"
    first = clrt.batch.render([meshes[0]], out, views=4, client=client, device=device, **SIZE)
    assert [o.status for o in first] == ["done"] * 4
    frames = {v: out / f"ball/view-000{v}.png" for v in range(4)}
    pixels = {v: np.asarray(Image.open(path)) for v, path in frames.items()}
    kept = os.stat(frames[3]).st_mtime_ns
    frames[0].unlink()
    frames[1].write_bytes(frames[1].read_bytes()[:100])
    Image.fromarray(255 - pixels[2]).save(frames[2])
    dev = ["--device", device] if device else []
    code = main(["batch", "render", str(meshes[0]), "-o", str(out), "--views", "4", *SIZE_ARGS, "--workers", "1",
                 "-q", *dev])
    printed, err = capsys.readouterr()
    assert code == 0 and not err, err
    assert printed.startswith("3 frame(s) rendered (3 re-rendered: 1 missing, 2 changed since written), "
                              "1 already done, 0 not rendered"), printed
    assert all(np.array_equal(np.asarray(Image.open(frames[v])), pixels[v]) for v in range(4))
    assert all(clrt.output.file_state(path) == clrt.output.OURS for path in frames.values())
    assert os.stat(frames[3]).st_mtime_ns == kept
    assert {r["status"] for r in _manifest(out)} == {"done"} and len(_manifest(out)) == 4


def test_a_foreign_file_where_a_frame_goes_is_refused_before_rendering(meshes, tmp_path, device, capsys):
    """A file that clrt did not write, where the batch would put a frame, stops
    the batch before anything is rendered (exit 2, one line, as clrt render
    does); -f replaces it."""
    out = tmp_path / "out"
    (out / "ball").mkdir(parents=True)
    foreign = out / "ball" / "view-0001.png"
    Image.fromarray(np.full((4, 4, 3), 9, np.uint8)).save(foreign)
    before = foreign.read_bytes()
    dev = ["--device", device] if device else []
    args = ["batch", "render", str(meshes[0]), "-o", str(out), "--views", "3", *SIZE_ARGS, "--workers", "1", "-q",
            *dev]
    assert main(args) == 2
    printed, err = capsys.readouterr()
    assert err == (f"clrt: {foreign} exists and was not written by clrt; pass --force (-f; force=True in Python) "
                   "to replace it, or choose another -o\n"), err
    assert not printed and foreign.read_bytes() == before
    assert sorted(p.name for p in out.rglob("*") if p.is_file()) == [".clrt-batch.lock", "view-0001.png"], \
        "nothing rendered, no manifest"
    with pytest.raises(OutputError, match="view-0001.png exists and was not written by clrt"):
        clrt.batch.render([meshes[0]], out, views=3, workers=1, device=device, **SIZE)
    assert main([*args, "-f"]) == 0
    assert "3 frame(s) rendered, 0 already done" in capsys.readouterr().out
    assert foreign.read_bytes() != before and clrt.output.written_by_clrt(foreign)


def test_ctrl_c_keeps_what_finished_and_exits_130(meshes, tmp_path, device, capsys, monkeypatch):
    from clrt.batch import watch
    original = watch.completed

    def interrupted(*args):   # Ctrl-C once the first task finished
        for future in original(*args):
            yield future
            raise KeyboardInterrupt

    monkeypatch.setattr(watch, "completed", interrupted)
    dev = ["--device", device] if device else []
    args = ["batch", "render", str(meshes[0]), "-o", str(tmp_path / "out"), "--views", "4", "--width", "20",
            "--height", "14", "--workers", "2", "-q", *dev]
    assert main(args) == 130
    done = _manifest(tmp_path / "out")
    assert 1 <= len(done) < 4 and {r["status"] for r in done} == {"done"}
    monkeypatch.undo()
    assert main(args) == 0
    assert len(_manifest(tmp_path / "out")) == 4 and len(_images(tmp_path / "out")) == 4


def test_trace_and_occluded_on_dask_arrays_equal_clrt(client, device):
    mesh = primitives.torus(1.0, 0.35, 16, 8)
    rng = np.random.default_rng(7)
    origins = rng.normal(size=(3000, 3)) * 3.0
    directions = -origins + rng.normal(size=(3000, 3))
    tmax = rng.uniform(0.0, 6.0, 3000)
    o = da.from_array(origins, chunks=(700, 3))
    d = da.from_array(directions, chunks=(1000, 3))
    hits = clrt.batch.trace(mesh, o, d, tmax=da.from_array(tmax, chunks=500), client=client, device=device)
    assert all(isinstance(x, da.Array) for x in hits)
    got = dask.compute(*hits)
    want = clrt.trace(mesh, origins, directions, tmax=tmax, device=device)
    assert 0 < want.hit.sum() < len(origins), "the rays hit and miss"
    for name, a, b in zip(want._fields, got, want):
        assert a.shape == b.shape and a.dtype == b.dtype, name
        assert np.array_equal(a, b), name
    some = clrt.batch.trace(mesh, o, d, tmax=3.0, client=client, device=device, fields=("prim", "t"))
    assert some.u is None and some.normal is None and some.hit is None
    t, prim = dask.compute(some.t, some.prim)
    want = clrt.trace(mesh, origins, directions, tmax=3.0, device=device)
    assert np.array_equal(t, want.t) and np.array_equal(prim, want.prim)
    blocked = clrt.batch.occluded(mesh, o, d, tmax=3.0, client=client, device=device)
    assert isinstance(blocked, da.Array)
    assert np.array_equal(blocked.compute(), clrt.occluded(mesh, origins, directions, tmax=3.0, device=device))


def test_a_chunk_of_rays_reaches_its_task_uncopied(monkeypatch, device):
    """clrt.batch.trace hands each task its chunk's ray arrays as Dask holds
    them: a copy of every chunk (blockwise's concatenate copies even a single
    block) took 7 of 16 s for a billion rays on one GPU."""
    import clrt.batch.rays as batch_rays
    seen = []
    real = batch_rays.trace_chunk

    def spy(origins, directions, *args, **kwargs):
        seen.append((origins, directions))
        return real(origins, directions, *args, **kwargs)

    monkeypatch.setattr(batch_rays, "trace_chunk", spy)
    rng = np.random.default_rng(3)
    origins = rng.random((5_000, 3)).astype(np.float32) * 4 - 2
    directions = rng.standard_normal((5_000, 3)).astype(np.float32)
    mesh = primitives.icosphere(1)

    def rows_of(array, block_info=None):      # a view of the caller's array
        start, stop = block_info[None]["array-location"][0]
        return array[start:stop]

    o, d = (da.map_blocks(rows_of, a, chunks=((2_000, 2_000, 1_000), (3,)), dtype=np.float32,
                          meta=np.empty((0, 3), np.float32)) for a in (origins, directions))
    prim = clrt.batch.trace(mesh, o, d, device=device, fields=("prim",)).prim.compute(scheduler="sync")
    assert len(seen) == 3 and all(np.shares_memory(o, origins) and np.shares_memory(d, directions) for o, d in seen)
    assert np.array_equal(prim, clrt.trace(mesh, origins, directions, device=device).prim)


def test_ray_benchmark_counts_the_hits_of_its_own_rays(client, meshes, device):
    """benchmarks.batch --rays: the hit count it prints is that of the random
    rays it makes (traced here in one process), and the generation-only time
    is measured apart."""
    from benchmarks.batch import _trace_rays
    from clrt.scene.sources import as_mesh
    n, chunk = 30_000, 7_000
    seconds, hit, generate = _trace_rays(client, meshes[0], n, chunk)
    assert seconds > 0 and generate > 0
    mesh = as_mesh(meshes[0])
    lo, hi = mesh.bounds
    rng = da.random.default_rng(0)
    origins = lo.astype(np.float32) + rng.random((n, 3), chunks=(chunk, 3), dtype=np.float32) * (hi - lo).astype(
        np.float32)
    directions = rng.standard_normal((n, 3), chunks=(chunk, 3), dtype=np.float32)
    o, d = dask.compute(origins, directions, scheduler="sync")
    expected = int(clrt.Accel(mesh, device=device).trace(o, d).hit.sum())
    assert 0 < hit == expected < n


def test_ray_benchmark_can_repeat_one_chunk_per_worker(client, meshes, device):
    """benchmarks.batch --ray-source repeat: every chunk holds the same seeded
    rays (the last one their first rows), made once per worker, and the hit
    count is theirs."""
    from benchmarks.batch import _trace_rays
    from benchmarks.batch_rays import random_rays, repeated_chunk
    from clrt.scene.sources import as_mesh
    n, chunk = 30_000, 7_000
    mesh = as_mesh(meshes[0])
    seconds, hit, generate = _trace_rays(client, meshes[0], n, chunk, "repeat")
    origins, directions = random_rays(n, chunk, *mesh.bounds, source="repeat")
    assert origins.chunks == ((7_000,) * 4 + (2_000,), (3,))
    o, d = dask.compute(origins, directions, scheduler="sync")
    assert np.array_equal(o[:chunk], o[3 * chunk:4 * chunk]) and np.array_equal(d[4 * chunk:], d[:n - 4 * chunk])
    low = mesh.bounds[0].astype(np.float32)
    first, _ = repeated_chunk(low, (mesh.bounds[1] - mesh.bounds[0]).astype(np.float32), chunk)
    assert np.array_equal(o[:chunk], first) and not first.flags.writeable
    assert (o >= low).all() and len(np.unique(o[:chunk], axis=0)) == chunk
    traced = clrt.Accel(mesh, device=device).trace(o[:chunk], d[:chunk]).hit
    assert 0 < hit == 4 * int(traced.sum()) + int(traced[:n - 4 * chunk].sum()) < n


def test_images_written_in_threads_keep_their_order_and_errors(meshes, tmp_path, device, monkeypatch):
    """A task writes its images in threads while it renders on (worker.render_task):
    the records keep the views' order, a failed write is that view's "failed"
    record, and the other views' files are written."""
    import clrt.output
    from clrt.batch import worker
    from clrt.batch.engine import _check_options
    from clrt.batch.jobs import output_path
    from clrt.errors import OutputError

    real_write = clrt.output.write_image

    def write(image, path, force=False, **kwargs):
        if path.name == output_path("ball", 2).rsplit("/", 1)[-1]:
            raise OutputError(f"cannot write {path}: refused by the test")
        time.sleep(0.05 * (int(path.stem[-1]) % 2))     # odd views finish later
        real_write(image, path, force=force, **kwargs)

    monkeypatch.setattr(clrt.output, "write_image", write)
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    settings = _check_options(6, "box", "sah", 4, None, {"width": 24, "height": 16})
    views = list(range(6))
    job = {"source": str(meshes[0]), "name": "ball", "views": views, "replace": [],
           "paths": {v: output_path("ball", v) for v in views}, "count": 6, "folder": str(tmp_path),
           "scene": settings["scene"], "camera": settings["camera"], "lights": settings["lights"],
           "accel": "box", "builder": "sah", "leaf_size": 4, "force": False, "key": "k"}
    records = worker.render_task(job)
    assert [r["view"] for r in records] == views
    assert [r["status"] for r in records] == ["done", "done", "failed", "done", "done", "done"]
    assert "refused by the test" in records[2]["error"]
    assert sorted(p.name for p in (tmp_path / "ball").iterdir() if not p.name.startswith(".")) == \
        [output_path("ball", v).rsplit("/", 1)[-1] for v in (0, 1, 3, 4, 5)]


# --------------------------------------------------------------------------- failures

def _job(source, folder, views, settings, name="ball"):
    from clrt.batch.jobs import output_path
    return {"source": str(source), "name": name, "views": list(views), "replace": [],
            "paths": {v: output_path(name, v) for v in views}, "count": len(views), "folder": str(folder),
            "scene": settings["scene"], "camera": settings["camera"], "lights": settings["lights"],
            "accel": "box", "builder": "sah", "leaf_size": 4, "force": False, "key": "k"}


class _Future:
    """A future of _InProcessClient: its task ran at submit -- again while it
    raises, up to ``tries`` times, as Dask retries it -- or came back ``status``."""

    def __init__(self, fn, job, status, tries=1):
        self.key, self.status, self._value, self._error = job["name"], status, None, None
        if status == "finished":
            for _ in range(tries):
                try:
                    self._value, self._error = fn(job), None
                    break
                except Exception as exc:  # noqa: BLE001 -- the task's error, as Dask keeps it
                    self._error = exc
            else:
                self.status = "error"

    def done(self):
        return True

    def result(self):
        return self._value

    def exception(self):
        return self._error


class _InProcessClient:
    """Runs the batch's tasks in this process; tasks after the first ``finished``
    come back cancelled, as when the scheduler goes away mid-batch."""

    cluster, status = None, "running"

    def __init__(self, finished):
        self.finished, self.cancelled = finished, []

    def register_plugin(self, plugin):
        pass

    def scheduler_info(self):
        return {"workers": {"tcp://127.0.0.1:1": {}}}

    def submit(self, fn, job, retries=0, **kwargs):
        self.finished -= 1
        return _Future(fn, job, "finished" if self.finished >= 0 else "cancelled", 1 + retries)

    def cancel(self, futures):
        self.cancelled += futures

    def close(self):
        pass


def test_losing_the_scheduler_mid_batch_is_reported_as_such(meshes, tmp_path, device, capsys, monkeypatch):
    """Cancelled tasks (the scheduler went away) are no frame's failure: the
    batch stops with "lost the Dask cluster" (exit 3), what finished is recorded
    done and nothing is recorded failed."""
    import distributed

    import clrt.batch.cluster
    monkeypatch.setattr(distributed, "as_completed", _Completed)
    monkeypatch.setattr(clrt.batch.cluster, "connect", lambda address: _InProcessClient(1))
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    with pytest.raises(clrt.batch.ClusterLost, match="cancelled"):
        clrt.batch.run(meshes, tmp_path / "api", views=2, client=_InProcessClient(1), device=device, **SIZE)
    code = main(["batch", "render", *map(str, meshes), "-o", str(tmp_path / "out"), "--views", "2",
                 "--scheduler", "tcp://127.0.0.1:1", "-q", *SIZE_ARGS])
    err = capsys.readouterr().err
    assert code == 3 and "lost the Dask cluster" in err and "run the same command again" in err, err
    assert "NoneType" not in err
    for folder in (tmp_path / "api", tmp_path / "out"):
        records = _manifest(folder)
        assert records and {r["status"] for r in records} == {"done"}
        assert sorted(r["path"] for r in records) == sorted(_images(folder))


class _Completed:
    """distributed.as_completed over futures that are done at submit, with add()."""

    def __init__(self, futures):
        self.queue = list(futures)

    def add(self, future):
        self.queue.append(future)

    def __iter__(self):
        return self

    def __next__(self):
        if not self.queue:
            raise StopIteration
        return self.queue.pop(0)

    def is_empty(self):
        return not self.queue

    def has_ready(self):   # never asks the batch's watchdog (it has no scheduler to ask)
        return bool(self.queue)


class _LosingClient(_InProcessClient):
    """Each task's first result comes back lost after the task ran (its images
    written), as when another task kills the worker that held the result."""

    def __init__(self):
        super().__init__(10 ** 6)
        self.seen = set()

    def submit(self, fn, job, retries=0, **kwargs):
        future = super().submit(fn, job, retries, **kwargs)
        task = (job["source"], job["views"][0])
        if task not in self.seen:
            self.seen.add(task)
            future.status, future._value = "lost", None
        return future


def test_results_lost_with_a_worker_are_submitted_again(meshes, tmp_path, device, monkeypatch):
    """A result lost with its worker while the cluster runs on is no reason to
    stop the batch: the task is submitted again, finds its images, and every
    frame is recorded done."""
    import distributed
    monkeypatch.setattr(distributed, "as_completed", _Completed)
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    client = _LosingClient()
    summary = clrt.batch.run(meshes, tmp_path / "out", views=2, client=client, device=device, **SIZE)
    records = _manifest(tmp_path / "out")
    assert len(client.seen) == len(meshes) and len(summary.outputs) == 2 * len(meshes)
    assert summary.count("failed") == 0
    assert records and {r["status"] for r in records} == {"done"}
    assert sorted(r["path"] for r in records) == sorted(_images(tmp_path / "out"))


class _KillingClient(_InProcessClient):
    """Every submission of ball.obj's task comes back KilledWorker: Dask's
    scheduler charged it 4 worker deaths (allowed-failures 3), ``ran`` of them
    while it was running -- noted in its run log, as the task notes its starts
    (clrt.batch.worker.render_task) -- and the rest while it waited."""

    def __init__(self, ran):
        super().__init__(10 ** 6)
        self.ran, self.submitted = ran, 0

    def submit(self, fn, job, retries=0, **kwargs):
        if job["name"] != "ball":
            return super().submit(fn, job, retries, **kwargs)
        from distributed.scheduler import KilledWorker
        self.submitted += 1
        (Path(job["folder"]) / job["run_log"]).write_text("s tcp://127.0.0.1:1\n" * self.ran)
        future = _Future(fn, job, "error")
        worker = type("Worker", (), {"address": "tcp://127.0.0.1:1"})()
        future.key, future._error = kwargs["key"], KilledWorker(kwargs["key"], worker, 3)
        return future


@pytest.mark.parametrize("ran, submissions", [(4, 1), (2, 2), (1, 4), (0, 4)])
def test_a_killed_task_is_blamed_for_the_deaths_while_it_ran_and_resubmitted_a_bounded_number_of_times(
        ran, submissions, meshes, tmp_path, device, monkeypatch):
    """A task failed by its workers' deaths (KilledWorker) is reported once it
    was running at allowed-failures + 1 of them (4), counted over its
    submissions; until then it is submitted again, BATCH_KILLED_RESUBMITS times
    at most, and then reported with how often it ran.  Either way its frames
    are "device" (exit 3), the other tasks' frames done, and no run log is left."""
    import distributed

    from clrt.config import BATCH_KILLED_RESUBMITS
    assert BATCH_KILLED_RESUBMITS == 3
    monkeypatch.setattr(distributed, "as_completed", _Completed)
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    client = _KillingClient(ran)
    out = tmp_path / "out"
    summary = clrt.batch.run(meshes, out, views=2, client=client, device=device, **SIZE)
    assert summary.exit_code() == 3 and client.submitted == submissions
    assert {(Path(o.source).stem, o.status) for o in summary.outputs} == {("ball", "device"), ("block", "done")}
    error = next(o.error for o in summary.outputs if o.status == "device")
    if ran:
        assert error.endswith("KilledWorker: the worker process running it died each time it was tried "
                              "(a crash, or out of memory?)"), error
    else:
        assert error.endswith("KilledWorker: its worker processes died 16 times in 4 submissions, 0 of them "
                              "while it ran (other tasks crashing the workers?)"), error
    assert {r["status"] for r in _manifest(out)} == {"device", "done"}
    assert not (out / ".clrt-runs").exists()


def test_unwritable_output_is_not_reported_as_a_bad_source_per_frame(meshes, tmp_path, device, capsys,
                                                                      monkeypatch):
    """Images that cannot be written (read-only folder, full disk) are "failed",
    not "bad": one line for the source, exit 1, and a task stops rendering once
    its first writes all failed."""
    import distributed

    import clrt.batch.cluster
    import clrt.output
    from clrt.errors import OutputError
    tried = []

    def write(image, path, force=False, **kwargs):
        tried.append(path)
        raise OutputError(f"cannot write {path}: Permission denied")

    monkeypatch.setattr(clrt.output, "write_image", write)
    monkeypatch.setattr(distributed, "as_completed", _Completed)
    monkeypatch.setattr(clrt.batch.cluster, "connect", lambda address: _InProcessClient(100))
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    code = main(["batch", "render", str(meshes[0]), "-o", str(tmp_path / "out"), "--views", "40",
                 "--scheduler", "tcp://127.0.0.1:1", "-q", *SIZE_ARGS])
    out, err = capsys.readouterr()
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Permission denied" in lines[0] and "40 frames failed" in lines[0], err
    assert "bad source" not in err and "0 frame(s) rendered" in out and "40 not rendered" in out
    assert {r["status"] for r in _manifest(tmp_path / "out")} == {"failed"}
    assert len(tried) <= 8, f"{len(tried)} images rendered and tried after every write failed"


def test_views_found_after_a_lost_worker_are_counted_and_recorded(meshes, tmp_path, device, monkeypatch):
    """A retried task finds the views its first attempt wrote: they count as
    already done and are recorded with their camera, as rendered views are."""
    import distributed

    from clrt.batch import worker
    from clrt.batch.engine import _check_options
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    settings = _check_options(4, "box", "sah", 4, None, dict(SIZE))
    job = _job(meshes[0], tmp_path / "first", range(4), settings)
    rendered = worker.render_task(job)
    out = tmp_path / "out"
    for v in (0, 1):   # the first attempt wrote these before its worker died
        (out / "ball").mkdir(parents=True, exist_ok=True)
        for name in (Path(job["paths"][v]), clrt.output.record_path(Path(job["paths"][v]))):
            os.replace(tmp_path / "first" / name, out / name)
    retried = worker.render_task({**job, "folder": str(out)})
    assert [r.get("note") for r in retried] == ["found", "found", None, None]
    assert [r["camera"] for r in retried] == [r["camera"] for r in rendered]

    # the same through a batch: the retried task's report of views 0 and 1
    def task(job):
        return retried
    monkeypatch.setattr(worker, "render_task", task)
    monkeypatch.setattr(distributed, "as_completed", _Completed)
    batch = tmp_path / "batch"
    summary = clrt.batch.run([meshes[0]], batch, views=4, client=_InProcessClient(100), device=device, **SIZE)
    assert (summary.rendered, summary.count("skipped")) == (2, 2)
    assert sorted(summary.per_worker().values()) == [2]
    assert all(r["camera"] for r in _manifest(batch)) and len(_manifest(batch)) == 4


def test_a_task_that_raises_after_writing_images_leaves_no_image_recorded_failed(meshes, tmp_path, device,
                                                                                 monkeypatch):
    """A task that writes some of its views and then raises, and again when
    retried, has failed: its frames are recorded failed and the images its
    attempts wrote are removed (as clrt render removes an image whose AOVs
    failed), so no frame recorded failed looks done; images that were there
    before stay.  The next run renders exactly the failed frames."""
    import distributed

    from clrt.batch import worker
    real = worker.render_task

    def raises_after_two_views(job):
        if job["name"] != "ball":
            return real(job)
        real({**job, "views": job["views"][:2]})   # views 0 and 1 written (found when retried)
        raise RuntimeError("raised after writing")

    monkeypatch.setattr(distributed, "as_completed", _Completed)
    monkeypatch.setenv("CLRT_DEVICE", device or "")
    out = tmp_path / "out"
    names = [f"{stem}/view-000{v}.png" for stem in ("ball", "block") for v in range(3)]
    # ball's view 2 from other settings, there before the batch: a task that fails leaves it as it was
    clrt.batch.run([meshes[0]], out, views=3, client=_InProcessClient(100), device=device, width=16, height=12)
    old = (out / names[2]).read_bytes()
    for name in names[:2]:
        (out / name).unlink()

    monkeypatch.setattr(worker, "render_task", raises_after_two_views)
    summary = clrt.batch.run(meshes, out, views=3, client=_InProcessClient(100), device=device, **SIZE)
    assert summary.exit_code() == 1 and summary.count("failed") == 3
    assert {r["path"]: r["status"] for r in _manifest(out)} == dict(zip(names, ["failed"] * 3 + ["done"] * 3))
    assert "raised after writing" in _manifest(out)[0]["error"]
    assert sorted(_images(out)) == names[2:], "the failed task's images are gone, the older one stays"
    assert (out / names[2]).read_bytes() == old
    assert not [p for p in out.rglob(".*") if p.name != ".clrt-batch.lock" and "manifest" not in p.name
                and not (p.name.endswith(".clrt") and p.with_name(p.name[1:-5]).is_file())], "only records of files"

    monkeypatch.setattr(worker, "render_task", real)
    again = clrt.batch.run(meshes, out, views=3, client=_InProcessClient(100), device=device, **SIZE)
    assert sorted(o.path for o in again.outputs if o.status == "done") == [str(out / n) for n in names[:3]]
    assert again.count("skipped") == 3 and again.exit_code() == 0
    assert {r["status"] for r in _manifest(out)} == {"done"} and sorted(_images(out)) == names


def test_a_coloured_light_renders_as_clrt_render_draws_it(client, meshes, tmp_path, device):
    """clrt.Light objects (with their colour) pass the batch's option check, travel
    in its settings as plain values, and light view 0 as clrt.render does."""
    light = clrt.Light((2.0, 4.0, 3.0), (1.0, 0.2, 0.1))
    outputs = clrt.batch.render([meshes[0]], tmp_path / "out", client=client, device=device, lights=[light], **SIZE)
    assert [o.status for o in outputs] == ["done"]
    expected = clrt.render(str(meshes[0]), device=device, lights=[light], **SIZE)
    assert np.array_equal(np.asarray(Image.open(outputs[0].path)), expected)
    assert not np.array_equal(expected, clrt.render(str(meshes[0]), device=device, lights=[light.position], **SIZE))

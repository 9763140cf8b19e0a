"""``clrt bench``: the paper's experiments, rerun on this machine.

The paper (Halim, Liliana, Intan: *Accelerated Ray Tracing with Bounding
Volume Hierarchy and CUDA*) times four programs on 25 meshes at 200 x 200 and
shows that all of them draw the same image.  Here the programs are:

==================  ===========  ======================================
program             device       acceleration
==================  ===========  ======================================
basic               CPU (PoCL)   none: every ray against every triangle
gpu                 GPU          none
bvh-box/-sphere/    CPU          BVH of boxes / spheres / ellipsoids
-ellipse
bvh-gpu-box/...     GPU          the same BVHs on the GPU
==================  ===========  ======================================

each BVH program with the paper's builder (longest axis, round robin for
spheres) and again with binned SAH.  The paper's "basic" and "BVH" programs
were plain C++ on one core; ours run the same OpenCL kernels on the CPU
device, so "CPU vs GPU" here compares two OpenCL devices.

Shading as in the paper: one point light, ambient + diffuse + specular +
shadow, no reflection (``max_depth = 0``), one ray per pixel.

Timing, per (mesh, program): a cold renderer is made and ``--warmup`` frames
are drawn (OpenCL context, program build and the driver's lazy kernel compile
happen here; its set-up time is kept as ``cold setup``); then a second
renderer is made and timed stage by stage, and ``--repeat`` frames are drawn
on it.  Reported: host BVH build, upload, the median kernel time (ray
generation + pixel colour, from OpenCL profiling events) and the median frame
wall time (host clock around ``Renderer.render``, read-back included).  The
**total**, which the tables compare with the paper's times, is everything a
run of the paper's program includes: reading the mesh file + flattening + BVH
build + upload + one frame.  Generated and decimated meshes are written to
``OUT/meshes/`` first, so every mesh is read from a file as in the paper.

Outputs in ``--out`` (each written atomically, rewritten after every mesh so
an interrupted run keeps what it measured): ``tables.md`` (the paper's tables
with its reduction formula (8), Mrays/s and the speed-up over the paper's
time), ``times.csv``, ``time-vs-faces.png`` and ``kernel-vs-faces.png``
(log-log), ``detail-loss.png`` and ``detail-loss.csv``.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import platform
import shlex
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from clrt.bench.common import NON_NEGATIVE, POSITIVE, int_at_least, parse_size, rate
from clrt.bench.paper_meshes import MeshSuite, write_mesh
from clrt.config import BUILDERS, MAX_LEAF_SIZE, VOLUMES
from clrt.errors import ClrtError, DeviceError, InputError, OutputError

# --------------------------------------------------------------------------- the paper's numbers

SHAPES = VOLUMES
PAPER_SIZE = (200, 200)   # pixels of every image the paper timed; speed-ups compare only at this size


@dataclass(frozen=True)
class PaperRow:
    """One mesh of the paper's experiments: render times in ms at 200 x 200 on an
    i5-3340 + GeForce GTX 550 Ti (CUDA 6.5).  None: not in the paper."""

    file: str
    faces: int
    basic: int | None
    cuda: int | None
    bvh: tuple          # (box, sphere, ellipse)
    bvh_cuda: tuple | None


# The paper's Tables 1-3 (basic vs CUDA), Table 4 (basic vs BVH; its pages are
# also captioned "Tabel 2") and Table 5 (BVH vs BVH + CUDA; also captioned
# "Tabel 3"), keyed by our suite name (the file name without extension).
# ddboat was not run without a BVH; Table 5 leaves out icosphere, jar, cemara,
# sword, key_b, sphere and ellipse.
PAPER: dict[str, PaperRow] = {r.file.rsplit(".", 1)[0].lower(): r for r in (
    PaperRow("triangle.obj", 1, 667, 632, (607, 798, 852), (620, 807, 837)),
    PaperRow("triangle2.obj", 2, 878, 728, (733, 915, 961), (688, 857, 835)),
    PaperRow("triangle3.obj", 3, 924, 747, (631, 721, 1266), (625, 703, 837)),
    PaperRow("triangle4.obj", 4, 1087, 818, (714, 798, 1500), (630, 735, 985)),
    PaperRow("box1.obj", 8, 1649, 916, (1242, 1713, 1511), (766, 863, 877)),
    PaperRow("diamond.obj", 33, 7014, 2655, (3586, 6302, 6119), (1142, 1820, 1618)),
    PaperRow("icosphere.obj", 80, 14247, 5203, (3803, 5517, 4913), None),
    PaperRow("bunny500.obj", 200, 42211, 14115, (7038, 21085, 8609), (1678, 5702, 1689)),
    PaperRow("bunny1500.obj", 200, 39592, 13414, (4914, 16257, 6778), (2095, 4677, 1440)),
    PaperRow("jar.obj", 204, 31073, 10501, (13582, 14040, 12851), None),
    PaperRow("cemara.obj", 246, 38929, 12933, (8906, 6913, 5414), None),
    PaperRow("sword.obj", 338, 55568, 18600, (6718, 2776, 1226), None),
    PaperRow("key_b.3ds", 588, 98024, 32114, (8329, 8419, 1875), None),
    PaperRow("gourd.obj", 648, 116987, 40977, (17404, 26882, 9985), (3639, 8066, 2986)),
    PaperRow("sphere.obj", 960, 159811, 54165, (19988, 8215, 2770), None),
    PaperRow("ellipse.obj", 960, 168727, 58074, (20967, 14455, 4748), None),
    PaperRow("knob.obj", 1344, 273141, 80490, (54315, 45134, 23271), (11592, 11504, 4793)),
    PaperRow("dolphin.obj", 1692, 285055, 93924, (35047, 38752, 9585), (7007, 13166, 2836)),
    PaperRow("apel.obj", 1704, 306869, 84352, (61153, 72912, 32501), (10493, 20220, 7118)),
    PaperRow("camel.obj", 4884, 775864, 242459, (140918, 109696, 15625), (33556, 34573, 5618)),
    PaperRow("beethoven.ply", 5030, 948919, 339572, (120614, 117617, 54105), (25526, 34385, 15816)),
    PaperRow("teapot.obj", 6320, 1254613, 397596, (240452, 371324, 51374), (52614, 115077, 18332)),
    PaperRow("bunny.off", 6966, 1203699, 383018, (296368, 223483, 26837), (63693, 71831, 8503)),
    PaperRow("sample1.3DS", 23578, 4089124, 902385, (502300, 1573880, 185232), (105226, 519273, 65486)),
    PaperRow("dragon.ply", 37986, 7158953, 901752, (1253351, 600198, 341669), (260460, 166891, 97871)),
    PaperRow("ddboat.obj", 82666, None, None, (6796711, 6665842, 6699465), (901114, 916287, 906206)),
)}

# The paper's detail-loss placements (Tables 6-8): eye and light on the +z axis.
PAPER_DETAIL = (("apel.obj", 250.0, 240.0), ("sample1.3DS", 20.0, 18.0))


def reduction(t1: float, t2: float) -> float:
    """The paper's formula (8): render-time reduction in % from time 1 to time 2."""
    return (t1 - t2) / t1 * 100.0


def paper_time(mesh: str, faces: int, program: str) -> float | None:
    """The paper's time (ms) for ``program`` on the mesh of that name, when the
    paper has one and our mesh has the paper's face count."""
    row = PAPER.get(mesh)
    if row is None or row.faces != faces:
        return None
    if program == "basic":
        return row.basic
    if program == "gpu":
        return row.cuda
    shape = program.rsplit("-", 1)[1]
    times = row.bvh_cuda if program.startswith("bvh-gpu-") else row.bvh
    return None if times is None else times[SHAPES.index(shape)]


# --------------------------------------------------------------------------- programs

@dataclass(frozen=True)
class Program:
    name: str
    kind: str        # 'CPU' or 'GPU': the device type it runs on
    accel: str       # 'none' or a bounding-volume shape


PROGRAMS = {p.name: p for p in (
    Program("basic", "CPU", "none"), Program("gpu", "GPU", "none"),
    *(Program(f"bvh-{s}", "CPU", s) for s in SHAPES),
    *(Program(f"bvh-gpu-{s}", "GPU", s) for s in SHAPES),
)}
LABELS = {"basic": "basic", "gpu": "GPU", **{f"bvh-{s}": f"BVH {s}" for s in SHAPES},
          **{f"bvh-gpu-{s}": f"BVH+GPU {s}" for s in SHAPES}}


@dataclass
class Run:
    """One timed (mesh, program, builder): milliseconds unless named otherwise."""

    mesh: str
    faces: int
    source: str
    program: str
    builder: str                 # '-' without a BVH
    kind: str
    device: str
    width: int
    height: int
    warmup: int
    repeat: int
    load_ms: float
    init_ms: float
    build_ms: float
    upload_ms: float
    cold_setup_ms: float
    raygen_ms: float
    colour_ms: float
    kernel_ms: float
    readback_ms: float
    frame_wall_ms: float
    total_ms: float
    mrays_wall: float
    mrays_kernel: float
    paper_ms: float | None = None
    speedup: float | None = None

    @property
    def variant(self) -> str:
        return self.program if self.builder == "-" else f"{self.program}/{self.builder}"


CSV_COLUMNS = list(Run.__dataclass_fields__)


def _variants(programs: list[str], builders: list[str]) -> list[tuple[str, str]]:
    return [(p, "-") if PROGRAMS[p].accel == "none" else (p, b)
            for p in programs for b in (["-"] if PROGRAMS[p].accel == "none" else builders)]


# --------------------------------------------------------------------------- measuring

def paper_scene(mesh, camera=None, light=None):
    """One mesh, default material, one light, no reflection, one ray per pixel."""
    from clrt.scene.scene import Light, default_light, scene_from_mesh
    scene = scene_from_mesh(mesh)
    scene.samples, scene.max_depth = 1, 0
    if camera is not None:
        scene.camera = camera
    scene.lights = [Light(tuple(light)) if light is not None else default_light(scene.bounds, scene.camera)]
    return scene


def measure(scene, camera, device: str, accel: str, builder: str, leaf_size: int,
            warmup: int, repeat: int) -> tuple[dict, np.ndarray, str]:
    """Times of one program on one scene (see the module notes), its last image
    and the device's label."""
    from clrt.renderer import Renderer
    cold = None
    if warmup > 0:
        renderer = Renderer(scene, device=device, accel=accel, builder=builder, leaf_size=leaf_size)
        cold = sum(renderer.timings.values())
        for _ in range(warmup):
            renderer.render(camera)
        del renderer
    renderer = Renderer(scene, device=device, accel=accel, builder=builder, leaf_size=leaf_size)
    setup = dict(renderer.timings)
    frames = []
    for _ in range(repeat):
        start = time.perf_counter()
        frame = renderer.render(camera)
        wall = 1e3 * (time.perf_counter() - start)
        frames.append((frame.timings["ray generation"], frame.timings["pixel colour"],
                       frame.timings["read back"], wall))
    raygen, colour, readback, wall = (statistics.median(x) for x in zip(*frames))
    kernel = statistics.median(g + c for g, c, _, _ in frames)
    times = {"init_ms": setup["initialisation"], "build_ms": setup["acceleration build"],
             "upload_ms": setup["copy to device"],
             "cold_setup_ms": cold if cold is not None else sum(setup.values()),
             "raygen_ms": raygen, "colour_ms": colour, "kernel_ms": kernel,
             "readback_ms": readback, "frame_wall_ms": wall}
    return times, frame.image, renderer.device


def _available_kinds(cpu_spec: str, gpu_spec: str) -> dict[str, bool]:
    from clrt.device.context import list_devices, select_device
    for spec in (cpu_spec, gpu_spec):
        if spec.lower() not in ("cpu", "gpu"):
            select_device(spec)   # DeviceError now, before any output, for a P:D not on this machine
    types = {d.type for d in list_devices()}
    return {"CPU": cpu_spec.lower() != "cpu" or "CPU" in types,
            "GPU": gpu_spec.lower() != "gpu" or "GPU" in types}


def _progress(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _made_mesh_file(suite: MeshSuite, name: str, mesh_out: Path) -> Path | None:
    """Where a generated or decimated suite mesh is written (None: read as it is)."""
    entry = suite[name]
    if entry.path is not None and entry.target is None:
        return None
    return mesh_out / f"{name}.{'obj' if entry.path is None else 'off'}"


def _load(suite: MeshSuite, name: str, mesh_out: Path, force: bool = False):
    """(mesh, load ms, file): generated and decimated meshes are written to
    ``mesh_out`` first; the time is that of reading the file, as in the paper."""
    from clrt.scene.load import load_mesh
    path = _made_mesh_file(suite, name, mesh_out)
    if path is None:
        path = suite[name].path
    else:
        write_mesh(suite[name].make(), path, force)
    start = time.perf_counter()
    mesh = load_mesh(path)
    load_ms = 1e3 * (time.perf_counter() - start)
    return mesh, load_ms, path


# --------------------------------------------------------------------------- the command

def add_bench_parser(subparsers, **kwargs) -> argparse.ArgumentParser:
    """Add ``bench`` to the CLI's subparsers (``kwargs`` to ``add_parser``, e.g.
    ``prog``); ``run_bench`` runs it."""
    b = subparsers.add_parser(
        "bench", **kwargs, help="rerun the paper's timing and detail-loss experiments on this machine",
        description="Rerun the paper's comparison (basic, GPU, BVH box/sphere/ellipse on the CPU "
                    "device, BVH + GPU) on its mesh suite; write its tables (Markdown, CSV), "
                    "log-log charts and the detail-loss image to --out.")
    b.add_argument("--meshes", type=_names, help="comma-separated suite meshes (default: all; "
                                                 "see --list)")
    b.add_argument("--programs", type=_names, help="comma-separated: " + ", ".join(PROGRAMS)
                   + ", or cpu / gpu / all (default all)")
    b.add_argument("--builder", choices=(*BUILDERS, "all"), default="all",
                   help="BVH builder: the paper's, binned SAH, PLOC on the device, or all (default all)")
    b.add_argument("--size", type=parse_size, default=(200, 200), help="WxH (default 200x200, the paper's)")
    b.add_argument("--repeat", type=POSITIVE, default=3, help="timed frames, median reported (default 3)")
    b.add_argument("--warmup", type=NON_NEGATIVE, default=1, help="untimed frames first (default 1)")
    b.add_argument("--leaf-size", type=int_at_least(1, MAX_LEAF_SIZE), default=4, help="most triangles per BVH leaf (default 4)")
    b.add_argument("--out", default="bench-results", help="output folder (default bench-results/)")
    b.add_argument("-f", "--force", action="store_true",
                   help="replace files in --out that clrt did not write (tables, charts, meshes)")
    b.add_argument("--mesh-dir", help="folder of scanned meshes (default ../shared/meshes beside the "
                                      "repository, when it exists)")
    b.add_argument("--cpu-device", default="cpu", help="device of the CPU programs (default cpu; or P:D)")
    b.add_argument("--gpu-device", default="gpu", help="device of the GPU programs (default gpu; or P:D)")
    b.add_argument("--max-brute-faces", type=POSITIVE,
                   help="skip basic and gpu (no BVH) above this many faces, as the paper did for ddboat")
    b.add_argument("--detail-meshes", type=_names, default=None,
                   help="two meshes for the detail-loss test (default teapot,camel)")
    b.add_argument("--no-detail", action="store_true", help="skip the detail-loss test")
    b.add_argument("--list", action="store_true", help="list the mesh suite and exit")
    return b


def _names(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected comma-separated names, got {text!r}")
    return names




def _select_programs(names: list[str] | None) -> list[str]:
    if not names:
        return list(PROGRAMS)
    chosen = []
    for n in names:
        group = {"all": list(PROGRAMS), "cpu": [p for p in PROGRAMS if PROGRAMS[p].kind == "CPU"],
                 "gpu": [p for p in PROGRAMS if PROGRAMS[p].kind == "GPU"]}.get(n.lower())
        if group is None and n not in PROGRAMS:
            raise InputError(f"unknown program {n!r}: choose from {', '.join(PROGRAMS)}, cpu, gpu, all")
        chosen += group or [n]
    return [p for p in PROGRAMS if p in chosen]       # canonical order, no repeats


def _command_line(args) -> str:
    """The command that reproduces this run (from the parsed options)."""
    parts = ["clrt", "bench"]
    if args.meshes:
        parts += ["--meshes", ",".join(args.meshes)]
    if args.programs:
        parts += ["--programs", ",".join(args.programs)]
    parts += ["--builder", args.builder, "--size", f"{args.size[0]}x{args.size[1]}",
              "--repeat", str(args.repeat), "--warmup", str(args.warmup)]
    if args.leaf_size != 4:
        parts += ["--leaf-size", str(args.leaf_size)]
    if args.mesh_dir:
        parts += ["--mesh-dir", str(args.mesh_dir)]
    for name in ("cpu_device", "gpu_device"):
        if getattr(args, name).lower() != name[:3]:
            parts += [f"--{name.replace('_', '-')}", getattr(args, name)]
    if args.max_brute_faces:
        parts += ["--max-brute-faces", str(args.max_brute_faces)]
    if args.no_detail:
        parts.append("--no-detail")
    elif args.detail_meshes:
        parts += ["--detail-meshes", ",".join(args.detail_meshes)]
    parts += ["--out", str(args.out)]
    return shlex.join(parts)   # quoted where needed: the line can be pasted back into a shell


def _check_outputs(out: Path, suite: MeshSuite, meshes: list[str], force: bool) -> None:
    """OutputError before any work for an --out that is not a folder, or a file in
    it that the run would replace and that clrt did not write (clrt.output's rule)."""
    from clrt.output import check_replace
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: it is a file, not a folder")
    files = [out / name for name in Report.FILES]
    files += [p for p in (_made_mesh_file(suite, name, out / "meshes") for name in meshes) if p is not None]
    for path in files:
        if path.parent.exists() and not path.parent.is_dir():
            raise OutputError(f"cannot write {path}: {path.parent} is not a folder")
        check_replace(path, force, "--out")


def run_bench(args) -> int:
    """Run ``clrt bench`` with parsed ``args``; 0 on success (errors raise ClrtError)."""
    from clrt import checks
    if args.mesh_dir and not Path(args.mesh_dir).is_dir():   # the default folder may be absent; a named one not
        raise InputError(f"--mesh-dir {args.mesh_dir}: no such folder")
    args.cpu_device = checks.device(args.cpu_device, "--cpu-device")
    args.gpu_device = checks.device(args.gpu_device, "--gpu-device")
    suite = MeshSuite(args.mesh_dir)
    if args.list:
        for entry in suite.entries.values():
            faces = f"{entry.faces:,}" if entry.faces is not None else "?"
            print(f"{entry.name:<14} {faces:>8} faces  {entry.source}")
        for note in suite.notes:
            print(f"note: {note}")
        return 0
    width, height = args.size
    builders = list(BUILDERS) if args.builder == "all" else [args.builder]
    programs = _select_programs(args.programs)
    meshes = args.meshes or suite.names()
    for name in meshes:
        suite[name]                                         # unknown names fail before any work
    notes = [] if args.meshes else list(suite.notes)    # which variants of the default set were skipped

    specs = {"CPU": args.cpu_device, "GPU": args.gpu_device}
    available = _available_kinds(args.cpu_device, args.gpu_device)
    for kind in ("CPU", "GPU"):
        wanted = [p for p in programs if PROGRAMS[p].kind == kind]
        if wanted and not available[kind]:
            notes.append(f"no {kind} OpenCL device on this machine: skipped {', '.join(wanted)}")
    if not any(available.values()):
        raise DeviceError("no OpenCL CPU or GPU device found (see `clrt info`)")
    programs = [p for p in programs if available[PROGRAMS[p].kind]]
    if not programs:
        raise DeviceError("none of the requested programs has a device here: " + "; ".join(notes))
    if (width, height) != PAPER_SIZE:
        notes.append(f"speed-up not given: the paper's times are for {PAPER_SIZE[0]}x{PAPER_SIZE[1]} pixels, "
                     f"this run's for {width}x{height}")
    for note in notes:
        _progress(f"note: {note}")

    out = Path(args.out)
    _check_outputs(out, suite, meshes, args.force)
    try:
        (out / "meshes").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot make the output folder {out}: {exc.strerror or exc}") from None
    report = Report(out, _command_line(args), width, height, builders, args, notes)
    variants = _variants(programs, builders)
    total_runs = len(meshes) * len(variants)
    done = 0
    _progress(f"clrt bench: {len(meshes)} meshes x {len(variants)} programs at {width}x{height}, "
              f"warm-up {args.warmup}, median of {args.repeat}; results in {out}/")
    from clrt.scene.scene import Camera
    for name in meshes:
        mesh, load_ms, path = _load(suite, name, out / "meshes", args.force)
        faces = len(mesh.faces)
        source = suite[name].source
        _progress(f"{name}: {faces:,} faces ({source}), read from {path} in {load_ms:.1f} ms")
        scene = paper_scene(mesh, Camera.framing(mesh.bounds, width, height))
        camera = scene.camera
        for program, builder in variants:
            done += 1
            p = PROGRAMS[program]
            if p.accel == "none" and args.max_brute_faces and faces > args.max_brute_faces:
                _progress(f"[{done}/{total_runs}] {name} {program}: skipped (> {args.max_brute_faces:,} faces)")
                continue
            times, _, device = measure(scene, camera, specs[p.kind], p.accel,
                                           builder if p.accel != "none" else "sah", args.leaf_size,
                                           args.warmup, args.repeat)
            total = load_ms + times["init_ms"] + times["build_ms"] + times["upload_ms"] + times["frame_wall_ms"]
            paper = paper_time(name, faces, program)
            pixels = width * height
            run = Run(name, faces, source, program, builder, p.kind, device, width, height, args.warmup,
                      args.repeat, load_ms, **times, total_ms=total,
                      mrays_wall=pixels / times["frame_wall_ms"] / 1e3,
                      mrays_kernel=pixels / times["kernel_ms"] / 1e3 if times["kernel_ms"] > 0 else math.nan,
                      paper_ms=paper, speedup=paper / total if paper and (width, height) == PAPER_SIZE else None)
            report.runs.append(run)
            _progress(f"[{done}/{total_runs}] {name} {run.variant} on {p.kind}: total {total:.1f} ms "
                      f"(build {times['build_ms']:.1f}, upload {times['upload_ms']:.1f}, "
                      f"frame {times['frame_wall_ms']:.2f}, kernel {times['kernel_ms']:.3f})"
                      + (f", paper {paper:,} ms: {_x(run.speedup)} its speed" if run.speedup else ""))
        report.write()

    if not args.no_detail:
        detail_names = args.detail_meshes or _default_detail(suite)
        for name in detail_names:
            suite[name]
        report.detail = detail_loss(suite, detail_names[:2], programs, builders, specs, args, out)
        report.write()
    _progress(f"wrote {out / 'tables.md'}, {out / 'times.csv'} and the charts")
    return 0


def _default_detail(suite: MeshSuite) -> list[str]:
    """teapot, and camel (else its full scan, else the next largest mesh)."""
    second = next((n for n in ("camel", "camel-full", "bunny", "sphere") if n in suite), "sphere")
    return ["teapot", second]


# --------------------------------------------------------------------------- detail loss

@dataclass
class DetailRow:
    mesh: str
    faces: int
    eye: tuple
    light: tuple
    placement: str                 # the paper's mesh and placement it stands for
    program: str
    builder: str
    kind: str
    device: str
    differ_from_basic: int | None    # None: basic not run
    differ_same_device: int | None   # from the no-BVH program on the same device
    max_channel_diff: int | None
    image: np.ndarray = field(repr=False, default=None)


def detail_loss(suite: MeshSuite, names: list[str], programs, builders, specs, args, out: Path) -> list[DetailRow]:
    """Render every program once on each mesh with the paper's eye/light placement
    scaled to the mesh; count pixels that differ from basic's image."""
    from clrt.renderer import Renderer
    from clrt.scene.scene import Camera
    width, height = args.size
    rows: list[DetailRow] = []
    for (paper_file, eye_z, light_z), name in zip(PAPER_DETAIL, names):
        mesh, _, _ = _load(suite, name, out / "meshes")
        # The paper looks down -z from (0, 0, eye_z) with the light at (0, 0, light_z).
        # Here the eye is on the +z axis through the mesh's centre at the
        # distance that frames it, and the light keeps the paper's ratio.
        framed = Camera.framing(mesh.bounds, width, height, direction=(0.0, 0.0, 1.0))
        centre = np.asarray(framed.target)
        offset = np.asarray(framed.eye) - centre
        light = tuple(centre + offset * (light_z / eye_z))
        scene = paper_scene(mesh, framed, light)
        placement = f"{paper_file}: eye (0, 0, {eye_z:g}), light (0, 0, {light_z:g})"
        _progress(f"detail loss: {name} ({len(mesh.faces):,} faces), as {placement}")
        images: dict[tuple, tuple] = {}
        for program, builder in _variants(programs, builders):
            p = PROGRAMS[program]
            r = Renderer(scene, device=specs[p.kind], accel=p.accel, builder=builder if p.accel != "none" else "sah",
                         leaf_size=args.leaf_size)
            images[(program, builder)] = (r.render(framed).image, r.device, p.kind)
        basic = images.get(("basic", "-"))
        brute = {"CPU": basic, "GPU": images.get(("gpu", "-"))}
        for (program, builder), (image, device, kind) in images.items():
            same = brute[kind]
            rows.append(DetailRow(
                name, len(mesh.faces), tuple(float(x) for x in framed.eye), tuple(float(x) for x in light),
                placement, program, builder, kind, device,
                _differ(image, basic[0]) if basic else None,
                _differ(image, same[0]) if same else None,
                int(np.abs(image.astype(int) - basic[0].astype(int)).max()) if basic else None,
                image))
        for row in rows[-len(images):]:
            if row.differ_same_device:
                _progress(f"WARNING: {name} {row.program}/{row.builder}: {row.differ_same_device} pixels "
                          f"differ from the no-BVH image on the same device")
    return rows


def _differ(a: np.ndarray, b: np.ndarray) -> int:
    """Pixels where any channel differs."""
    return int(np.any(a != b, axis=-1).sum())


# --------------------------------------------------------------------------- output

def _ms(v: float | None) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if v >= 100:
        return f"{v:,.0f}"
    if v >= 1:
        return f"{v:.2f}"
    return f"{v:.3f}"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}%"


def _x(v: float | None) -> str:
    if v is None:
        return "-"
    return f"{v:,.0f}x" if v >= 100 else f"{v:.3g}x"


def _md_table(headers: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


class Report:
    """Everything measured so far, and the files made from it."""

    def __init__(self, out: Path, command: str, width: int, height: int, builders: list[str], args,
                 notes: list[str]):
        self.out, self.command, self.width, self.height = out, command, width, height
        self.builders, self.args, self.notes = builders, args, notes
        self.date = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        self.runs: list[Run] = []
        self.detail: list[DetailRow] = []

    def find(self, mesh: str, program: str, builder: str = "-") -> Run | None:
        return next((r for r in self.runs if r.mesh == mesh and r.program == program
                     and r.builder == builder), None)

    def meshes(self) -> list[tuple[str, int]]:
        seen = {}
        for r in self.runs:
            seen.setdefault(r.mesh, r.faces)
        return list(seen.items())

    # -- files

    FILES = ("times.csv", "tables.md", "time-vs-faces.png", "kernel-vs-faces.png", "detail-loss.png",
             "detail-loss.csv")

    def write(self) -> None:
        from clrt.output import write_file
        force = self.args.force

        def write(name: str, data) -> None:
            write_file(data, self.out / name, force, "--out")
        write("times.csv", self.csv())
        write("tables.md", self.markdown())
        series = self.series("total_ms")
        write("time-vs-faces.png", loglog_chart(
            series, f"Total time per frame (as the paper's times), {self.width}x{self.height}",
            "total ms (read + build + upload + frame)"))
        write("kernel-vs-faces.png", loglog_chart(
            self.series("kernel_ms"), f"Kernel time per frame (ray generation + colour), "
                                      f"{self.width}x{self.height}", "kernel ms"))
        if self.detail:
            write("detail-loss.png", detail_sheet(self.detail))
            write("detail-loss.csv", self.detail_csv())

    def csv(self) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, CSV_COLUMNS, lineterminator="\n")
        w.writeheader()
        for r in self.runs:
            row = asdict(r)
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else ("" if v is None else v))
                        for k, v in row.items()})
        return buf.getvalue()

    def detail_csv(self) -> str:
        buf = io.StringIO()
        cols = ["mesh", "faces", "placement", "eye", "light", "program", "builder", "kind", "device",
                "differ_from_basic", "differ_same_device", "max_channel_diff"]
        w = csv.DictWriter(buf, cols, lineterminator="\n")
        w.writeheader()
        for d in self.detail:
            w.writerow({c: ("" if getattr(d, c) is None else
                            " ".join(f"{x:.6g}" for x in getattr(d, c)) if c in ("eye", "light")
                            else getattr(d, c)) for c in cols})
        return buf.getvalue()

    def series(self, metric: str) -> list[tuple[str, str, str, list]]:
        """(label, colour, style, points) per program and builder: the colour
        tells the program, the line style and marker (``STYLES``) the builder."""
        out = []
        for program, builder in _variants(list(PROGRAMS), BUILDERS):
            pts = [(r.faces, getattr(r, metric)) for r in self.runs
                   if r.program == program and r.builder == builder]
            if pts:
                label = LABELS[program] + ("" if builder == "-" else f" ({builder})")
                out.append((label, COLOURS[program], STYLES[builder], sorted(pts)))
        return out

    # -- Markdown

    def markdown(self) -> str:
        a = self.args
        devices = {}
        for r in self.runs:
            devices.setdefault(r.kind, r.device)
        lines = [
            "# The paper's experiments on this machine",
            "",
            f"- date: {self.date}",
            f"- command: `{self.command}`",
            f"- host: {platform.system()} {platform.machine()}, Python {platform.python_version()}",
            *(f"- {kind} programs: {devices.get(kind, 'not run')}" for kind in ("CPU", "GPU")),
            f"- {self.width}x{self.height} pixels, one ray per pixel, one point light: ambient + diffuse + "
            f"specular + shadow, no reflection (the paper's shading); default framing of each mesh",
            f"- BVH builders: {', '.join(self.builders)}; leaf size {a.leaf_size}",
            f"- timing: {a.warmup} warm-up frame(s) on a cold renderer, then a second renderer timed "
            f"stage by stage and the median of {a.repeat} frame(s)",
            "",
            "**total** = reading the mesh file + flattening + BVH build + upload + one frame (median), "
            "which is what the paper's times include; **kernel** = ray generation + pixel colour from "
            "OpenCL profiling events; **frame** = host wall clock around one `Renderer.render` "
            "(kernels, sRGB encode, read back). Reduction % is the paper's formula (8), "
            "(t1 - t2) / t1 x 100. **speed-up** = the paper's time / our total for the same mesh "
            "and program (only where the paper has the mesh at the same face count, and only at the "
            "paper's 200x200 pixels). The paper ran "
            "on an i5-3340 and a GeForce GTX 550 Ti; its basic/BVH programs were single-threaded "
            "C++, ours run the same OpenCL kernels on the CPU device.",
        ]
        if self.notes:
            lines += ["", "Notes:", *(f"- {n}" for n in self.notes)]
        lines += ["", self._table1(), "", *self._table2(), "", *self._table3(), "", self._all(), ""]
        lines += self._detail_md()
        return "\n".join(lines) + "\n"

    def _table1(self) -> str:
        rows = []
        for mesh, faces in self.meshes():
            b, g = self.find(mesh, "basic"), self.find(mesh, "gpu")
            if not (b and g):
                continue
            row = PAPER.get(mesh) if paper_time(mesh, faces, "basic") else None
            rows.append([mesh, f"{faces:,}", _ms(b.total_ms), _ms(g.total_ms), _pct(reduction(b.total_ms, g.total_ms)),
                         _ms(row.basic) if row else "-", _ms(row.cuda) if row else "-",
                         _pct(reduction(row.basic, row.cuda)) if row else "-", _x(b.speedup), _x(g.speedup)])
        head = "## Tables 1-3 of the paper: basic vs GPU (no BVH), total ms"
        if not rows:
            return head + "\n\nNot run: needs both the basic and the gpu program."
        return head + "\n\n" + _md_table(
            ["mesh", "faces", "basic", "GPU", "reduction", "paper basic", "paper CUDA", "paper reduction",
             "speed-up basic", "speed-up GPU"], rows)

    def _table2(self) -> list[str]:
        out = []
        for builder in self.builders:
            rows = []
            for mesh, faces in self.meshes():
                b = self.find(mesh, "basic")
                first = True
                for k, shape in enumerate(SHAPES):
                    r = self.find(mesh, f"bvh-{shape}", builder)
                    if not r:
                        continue
                    # basic skipped (--max-brute-faces, as the paper did for
                    # ddboat): the BVH row stays, basic and reduction blank.
                    paper_bvh = paper_time(mesh, faces, f"bvh-{shape}")
                    paper_basic = paper_time(mesh, faces, "basic")
                    rows.append([mesh if first else "", f"{faces:,}" if first else "",
                                 (_ms(b.total_ms) if b else "-") if first else "", shape,
                                 _ms(r.total_ms), _pct(reduction(b.total_ms, r.total_ms)) if b else "-",
                                 _ms(paper_bvh),
                                 _pct(reduction(paper_basic, paper_bvh)) if paper_basic and paper_bvh
                                 else "-", _x(r.speedup), rate(r.mrays_wall)])
                    first = False
            head = f"## Table 4 of the paper: basic vs BVH on the CPU device, builder {builder}, total ms"
            out += [head, "", _md_table(
                ["mesh", "faces", "basic", "BVH", "BVH ms", "reduction", "paper BVH", "paper reduction",
                 "speed-up", "Mrays/s"], rows) if rows else "Not run: needs the bvh-* programs.", ""]
        return out[:-1]

    def _table3(self) -> list[str]:
        out = []
        for builder in self.builders:
            rows = []
            for mesh, faces in self.meshes():
                first = True
                for k, shape in enumerate(SHAPES):
                    c, g = self.find(mesh, f"bvh-{shape}", builder), self.find(mesh, f"bvh-gpu-{shape}", builder)
                    if not (c and g):
                        continue
                    row = PAPER.get(mesh) if paper_time(mesh, faces, f"bvh-gpu-{shape}") else None
                    rows.append([mesh if first else "", f"{faces:,}" if first else "", shape,
                                 _ms(c.total_ms), _ms(g.total_ms), _pct(reduction(c.total_ms, g.total_ms)),
                                 _ms(row.bvh[k]) if row else "-", _ms(row.bvh_cuda[k]) if row else "-",
                                 _pct(reduction(row.bvh[k], row.bvh_cuda[k])) if row else "-",
                                 _x(g.speedup), rate(g.mrays_wall)])
                    first = False
            head = f"## Table 5 of the paper: BVH vs BVH + GPU, builder {builder}, total ms"
            out += [head, "", _md_table(
                ["mesh", "faces", "shape", "BVH", "BVH + GPU", "reduction", "paper BVH", "paper BVH+CUDA",
                 "paper reduction", "speed-up BVH+GPU", "Mrays/s"], rows)
                if rows else "Not run: needs the bvh-* and bvh-gpu-* programs.", ""]
        return out[:-1]

    def _all(self) -> str:
        rows = [[r.mesh, f"{r.faces:,}", r.program, r.builder, r.kind, _ms(r.load_ms), _ms(r.build_ms),
                 _ms(r.upload_ms), _ms(r.cold_setup_ms), _ms(r.kernel_ms), _ms(r.frame_wall_ms),
                 _ms(r.total_ms), rate(r.mrays_wall), rate(r.mrays_kernel), _ms(r.paper_ms), _x(r.speedup)]
                for r in self.runs]
        return "## All measurements (ms)\n\n" + _md_table(
            ["mesh", "faces", "program", "builder", "device", "read", "BVH build", "upload", "cold setup",
             "kernel", "frame", "total", "Mrays/s (frame)", "Mrays/s (kernel)", "paper", "speed-up"], rows)

    def _detail_md(self) -> list[str]:
        if not self.detail:
            return []
        lines = ["## Detail loss (the paper's Tables 6-8)", "",
                 "Each mesh rendered once by every program with the paper's detail-loss placement scaled "
                 "to it: the eye on the +z axis through the mesh's centre at the distance that frames it, "
                 "the light on the same axis at the paper's fraction of the eye's distance (apel.obj: "
                 "240/250; sample1.3DS: 18/20). Counts are pixels (any channel) that differ from basic's "
                 "image, and from the no-BVH image of the same device. `detail-loss.png` shows them all "
                 "side by side.", ""]
        rows = [[d.mesh, f"{d.faces:,}", d.placement.split(":")[0], d.program, d.builder, d.kind,
                 "-" if d.differ_from_basic is None else f"{d.differ_from_basic:,}",
                 "-" if d.differ_same_device is None else f"{d.differ_same_device:,}",
                 "-" if d.max_channel_diff is None else d.max_channel_diff] for d in self.detail]
        lines.append(_md_table(["mesh", "faces", "stands for", "program", "builder", "device",
                                "pixels differing from basic", "from no-BVH on same device",
                                "largest channel difference"], rows))
        same = [d for d in self.detail if d.differ_same_device]
        cross = [d for d in self.detail if d.kind == "GPU" and d.differ_from_basic]
        lines += ["", ("On each device every program draws the same image, bit for bit: the BVH changes "
                       "which triangles are tested, never the arithmetic of the test or of the shading."
                       if not same else f"**{len(same)} image(s) differ from the no-BVH image of their own "
                                         "device** (see the table): a bug.")]
        gpu_rows = [d for d in self.detail if d.kind == "GPU" and d.differ_from_basic is not None]
        if gpu_rows and not cross:
            lines += ["", "The GPU's images are identical to the CPU's as well."]
        if cross:
            lines += ["", "Between the CPU and the GPU device some pixels differ. Both run the same OpenCL "
                      "source, but OpenCL C lets each device round differently: single-precision division "
                      "and `sqrt` (in `normalize`, `length`) may be off by up to 2.5 and 3 ulp, and each "
                      "compiler decides where `a * b + c` becomes a fused multiply-add (one rounding instead "
                      "of two). The last bits of hit distances, normals and shadow-ray origins therefore "
                      "differ; a pixel changes where a colour lies on an 8-bit rounding step, where a "
                      "shadow ray grazes an edge, or where a camera ray passes within rounding of a "
                      "silhouette or a shared edge. The paper's 'exactly the same image' holds per device."]
        return lines


# --------------------------------------------------------------------------- pictures

COLOURS = {"basic": "#000000", "gpu": "#7f7f7f", "bvh-box": "#1f77b4", "bvh-sphere": "#2ca02c",
           "bvh-ellipse": "#d62728", "bvh-gpu-box": "#17becf", "bvh-gpu-sphere": "#bcbd22",
           "bvh-gpu-ellipse": "#ff7f0e"}
# Line style (and marker) per BVH builder: solid line + filled circle, dashed +
# hollow square, dotted + filled triangle.  "-": the programs without a BVH.
STYLES = {"-": "solid", "paper": "solid", "sah": "dashed", "device": "dotted"}


def _png(image) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return buf.getvalue()


def _decade_label(k: int) -> str:
    return f"{10 ** k:,}" if k >= 0 else f"{10.0 ** k:.{-k}f}"


def loglog_chart(series, title: str, ylabel: str, xlabel: str = "faces",
                 size: tuple[int, int] = (1000, 640)) -> bytes:
    """PNG bytes of a log-log line chart.  ``series``: (label, colour, style,
    [(x, y), ...]) each, style "solid", "dashed" or "dotted" (or a bool: dashed); non-positive points are left out."""
    from PIL import Image, ImageDraw, ImageFont
    font = ImageFont.load_default()
    w, h = size
    img = Image.new("RGB", size, "white")
    d = ImageDraw.Draw(img)
    left, right, top, bottom = 90, w - 250, 50, h - 70
    d.text((left, 15), title, fill="black", font=font)
    pts = [(x, y) for _, _, _, s in series for x, y in s if x > 0 and y > 0 and math.isfinite(y)]
    if not pts:
        d.text((left, h // 2), "no data", fill="black", font=font)
        return _png(img)
    xs, ys = np.log10([p[0] for p in pts]), np.log10([p[1] for p in pts])
    x0, x1 = math.floor(xs.min()), math.ceil(xs.max())
    y0, y1 = math.floor(ys.min()), math.ceil(ys.max())
    x1, y1 = max(x1, x0 + 1), max(y1, y0 + 1)

    def px(x):
        return left + (math.log10(x) - x0) / (x1 - x0) * (right - left)

    def py(y):
        return bottom - (math.log10(y) - y0) / (y1 - y0) * (bottom - top)

    for k in range(x0, x1 + 1):                       # vertical grid, x ticks
        for m in range(1, 10):
            if k == x1 and m > 1:
                break
            x = px(m * 10.0 ** k)
            d.line([(x, top), (x, bottom)], fill="#dddddd" if m == 1 else "#f2f2f2")
            d.line([(x, bottom), (x, bottom + (6 if m == 1 else 3))], fill="black")
        label = _decade_label(k)
        d.text((px(10.0 ** k) - 3 * len(label), bottom + 9), label, fill="black", font=font)
    for k in range(y0, y1 + 1):                       # horizontal grid, y ticks
        for m in range(1, 10):
            if k == y1 and m > 1:
                break
            y = py(m * 10.0 ** k)
            d.line([(left, y), (right, y)], fill="#dddddd" if m == 1 else "#f2f2f2")
            d.line([(left - (6 if m == 1 else 3), y), (left, y)], fill="black")
        label = _decade_label(k)
        d.text((left - 10 - 6 * len(label), py(10.0 ** k) - 6), label, fill="black", font=font)
    d.rectangle([left, top, right, bottom], outline="black")
    d.text(((left + right) // 2 - 3 * len(xlabel), bottom + 30), xlabel + " (log)", fill="black", font=font)
    ytext = Image.new("RGB", (8 * len(ylabel) + 40, 14), "white")
    ImageDraw.Draw(ytext).text((0, 0), ylabel + " (log)", fill="black", font=font)
    ytext = ytext.rotate(90, expand=True)
    img.paste(ytext, (8, (top + bottom) // 2 - ytext.height // 2))

    for label, colour, style, s in series:
        style = _style(style)
        s = [(px(x), py(y)) for x, y in s if x > 0 and y > 0 and math.isfinite(y)]
        for a, b in zip(s, s[1:]):
            _line(d, a, b, colour, style)
        for x, y in s:
            _marker(d, x, y, colour, style)
    ly = top
    for label, colour, style, _ in series:               # legend
        style = _style(style)
        _line(d, (right + 15, ly + 6), (right + 45, ly + 6), colour, style)
        _marker(d, right + 30, ly + 6, colour, style)
        d.text((right + 52, ly), label, fill="black", font=font)
        ly += 18
    return _png(img)


def _style(style) -> str:
    """A series' line style: "solid", "dashed" or "dotted" (a bool: dashed or not)."""
    if isinstance(style, bool):
        return "dashed" if style else "solid"
    if style not in ("solid", "dashed", "dotted"):
        raise ValueError(f"unknown line style {style!r}")
    return style


def _marker(d, x, y, colour, style: str) -> None:
    if style == "dashed":
        d.rectangle([x - 3, y - 3, x + 3, y + 3], outline=colour, width=2)
    elif style == "dotted":
        d.polygon([(x, y - 4), (x - 4, y + 3), (x + 4, y + 3)], fill=colour)
    else:
        d.ellipse([x - 3, y - 3, x + 3, y + 3], fill=colour)


def _line(d, a, b, colour, style="solid") -> None:
    style = _style(style)
    if style == "solid":
        d.line([a, b], fill=colour, width=2)
        return
    dash = 7.0 if style == "dashed" else 2.0      # dotted: short dashes, short gaps
    length = math.dist(a, b)
    steps = max(1, int(length // dash))
    for i in range(0, steps, 2):
        t0, t1 = i / steps, min(1.0, (i + 1) / steps)
        d.line([(a[0] + (b[0] - a[0]) * t0, a[1] + (b[1] - a[1]) * t0),
                (a[0] + (b[0] - a[0]) * t1, a[1] + (b[1] - a[1]) * t1)], fill=colour, width=2)


def detail_sheet(rows: list[DetailRow]) -> bytes:
    """PNG bytes: one row of images per mesh, one column per program, labelled."""
    from PIL import Image, ImageDraw, ImageFont
    font = ImageFont.load_default()
    meshes = list(dict.fromkeys(r.mesh for r in rows))
    columns = max(sum(1 for r in rows if r.mesh == m) for m in meshes)
    ih, iw = rows[0].image.shape[:2]
    scale = max(1, math.ceil(128 / max(iw, ih)))             # small renders are enlarged, pixel for pixel
    tw, th = iw * scale, ih * scale
    cell_w, label_h, margin = max(tw, 130) + 10, 48, 190
    sheet = Image.new("RGB", (margin + columns * cell_w, len(meshes) * (th + label_h + 10) + 10), "white")
    d = ImageDraw.Draw(sheet)
    for i, mesh in enumerate(meshes):
        y = 10 + i * (th + label_h + 10)
        mine = [r for r in rows if r.mesh == mesh]
        first = mine[0]
        d.multiline_text((8, y), f"{mesh}\n{first.faces:,} faces\nstands for {first.placement.split(':')[0]}\n"
                                 f"eye {_vec(first.eye)}\nlight {_vec(first.light)}", fill="black", font=font)
        for j, r in enumerate(mine):
            x = margin + j * cell_w
            tile = Image.fromarray(r.image).resize((tw, th), Image.NEAREST)
            sheet.paste(tile, (x, y))
            diff = "-" if r.differ_from_basic is None else f"{r.differ_from_basic:,}"
            name = LABELS[r.program] + ("" if r.builder == "-" else f" ({r.builder})")
            d.multiline_text((x, y + th + 3), f"{name}\n{r.kind}\ndiffer from basic: {diff}",
                             fill="black", font=font)
    return _png(sheet)


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


# --------------------------------------------------------------------------- python -m clrt.bench.paper

def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m clrt.bench.paper")
    sub = parser.add_subparsers(dest="command", required=True)
    add_bench_parser(sub, prog=parser.prog)   # its usage and errors name the module, not "... bench"
    args = parser.parse_args(["bench", *(sys.argv[1:] if argv is None else argv)])
    try:
        return run_bench(args)
    except ClrtError as exc:
        print(f"clrt: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())

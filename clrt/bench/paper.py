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
(log-log), ``detail-loss.png`` and ``detail-loss.csv`` (clrt/bench/paper_report.py
writes them).
"""

from __future__ import annotations

import argparse
import math
import shlex
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from clrt.bench.common import NON_NEGATIVE, POSITIVE, int_at_least, parse_size
from clrt.bench.paper_meshes import MeshSuite, write_mesh
from clrt.bench.paper_report import (PAPER_DETAIL, PAPER_SIZE, PROGRAMS, DetailRow, Report, Run, factor, paper_time,
                                     variants)
from clrt.config import BUILDERS, MAX_LEAF_SIZE
from clrt.errors import DeviceError, InputError, OutputError

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
    chosen = variants(programs, builders)
    total_runs = len(meshes) * len(chosen)
    done = 0
    _progress(f"clrt bench: {len(meshes)} meshes x {len(chosen)} programs at {width}x{height}, "
              f"warm-up {args.warmup}, median of {args.repeat}; results in {out}/")
    from clrt.scene.scene import Camera
    for name in meshes:
        mesh, load_ms, path = _load(suite, name, out / "meshes", args.force)
        faces = len(mesh.faces)
        source = suite[name].source
        _progress(f"{name}: {faces:,} faces ({source}), read from {path} in {load_ms:.1f} ms")
        scene = paper_scene(mesh, Camera.framing(mesh.bounds, width, height))
        camera = scene.camera
        for program, builder in chosen:
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
                      + (f", paper {paper:,} ms: {factor(run.speedup)} its speed" if run.speedup else ""))
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
        for program, builder in variants(programs, builders):
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

"""Time to the first image: ``python -m benchmarks.first_image MESH``.

    python -m benchmarks.first_image ../shared/meshes/bunny00.off --device gpu
    python -m benchmarks.first_image MESH --size 1920x1080 --runs 5 --builder device

1. Wall time of ``python -m clrt render MESH --width W --height H [--device D]
   [--builder B] -o TMP/N.png`` in ``--runs`` fresh processes, one after the
   other, from starting the process to its exit; an untimed run first fills the
   program cache and the file cache, so the timed runs start warm.  Prints the
   median, min and max.
2. One more fresh process (this module with ``--stages``) that runs the same
   stages as ``clrt render``, one after the other, and prints how long each
   took: python start (from this process starting it to the stage code's first
   line: interpreter, site, argument parsing), the imports, the platform query,
   the device list, the context and queue (and, apart, one more queue alone),
   the mesh load, the crease split, the renderer (with its own stage times:
   flatten, acceleration build, upload and program), the first frame (ray
   generation, pixel colour, read back), the PNG write, and last the printing
   and process exit (the driver's teardown), timed from here.

The stage process starts clrt.device.warmup as ``clrt render`` does (the
driver starting in a thread while numpy and pyopencl import), so its rows add
up to about one run's wall time; ``--serial`` leaves the warm-up out, and
each row is then that stage's whole cost.  The scene is made from the loaded
mesh (a glTF file's own camera is not used).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import time     # the stage process's "python start" ends at its first row: no other imports before

STAGES_MARK = "first_image stages:"


def _render_command(mesh: str, size, device, builder, out) -> list:
    command = [sys.executable, "-m", "clrt", "render", mesh, "--width", str(size[0]),
               "--height", str(size[1]), "-o", str(out)]
    if device:
        command += ["--device", device]
    if builder:
        command += ["--builder", builder]
    return command


def _run(command: list) -> float:
    """Seconds from starting ``command`` to its exit; SystemExit with its error if it fails.
    The process imports this checkout's clrt (``repo_env``), whatever the folder."""
    import subprocess

    from benchmarks.common import repo_env
    env = repo_env()
    start = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"benchmarks.first_image: {' '.join(command)} failed "
                         f"(exit {done.returncode}): {done.stderr.strip()[-2000:]}")
    return seconds


def stages(mesh: str, size, device, builder, out, started: float, serial: bool) -> list:
    """[(stage, ms, [(sub-stage, ms), ...])] of one render, each stage timed after the last
    (``started``: time.perf_counter() when the parent started this process; the clock
    is system-wide)."""
    rows = []
    last = started

    def row(name, subs=(), end=None):
        nonlocal last
        rows.append((name, 1e3 * ((end or time.perf_counter()) - last), [list(s) for s in subs]))
        last = time.perf_counter()

    row("python start")
    if not serial:
        from clrt.device import warmup
        warmup.start(device)   # as clrt render does: the driver starts while numpy and pyopencl import
    import numpy  # noqa: F401
    row("import numpy")
    import pyopencl as cl
    row("import pyopencl")
    from clrt import config
    from clrt.device.context import create_context, device_label, select_device
    from clrt.output import write_image
    from clrt.renderer import Renderer, TileLimits
    from clrt.scene.load import load_mesh
    from clrt.scene.render_setup import render_camera, render_lights, render_scene
    row("import clrt (renderer, scene, output)")
    if not serial:
        warmup.wait()
    cl.get_platforms()
    row("cl.get_platforms()" if serial else "cl.get_platforms() (after any warm-up thread)")
    select_device(device)
    row("device list (clrt select_device)")
    context, queue = create_context(device)
    made = time.perf_counter()
    cl.CommandQueue(context, properties=cl.command_queue_properties.PROFILING_ENABLE)
    one_more = 1e3 * (time.perf_counter() - made)
    row("cl.Context + CommandQueue (clrt create_context)",
        [("one more CommandQueue alone (not in the total)", one_more)], end=made)
    loaded = load_mesh(mesh)
    row("mesh load")
    scene = render_scene(loaded)
    camera = render_camera(scene, width=size[0], height=size[1])
    scene.lights = render_lights(scene.bounds, camera, scene.lights)
    row("crease split, camera, lights")
    # The first tile of clrt render's progress bar (tqdm present), so the launches are its launches.
    limits = TileLimits(first_launch_pixels=config.PROGRESS_FIRST_TILE)
    renderer = Renderer(scene, device=device, builder=builder or config.DEFAULT_BUILDER, limits=limits)
    row("renderer (flatten, build, upload, program)", renderer.timings.items())
    frame = renderer.render(camera)
    row("first frame", frame.timings.items())
    write_image(frame.image, out, force=True)
    row("PNG write")
    rows.append((f"device: {device_label(queue.device)}", None, []))
    return rows


def run(mesh: str, size, device, builder, runs: int, serial: bool) -> None:
    import json
    import os
    import statistics
    import subprocess
    import tempfile
    from pathlib import Path

    from benchmarks.common import module_command, repo_env
    mesh = os.path.abspath(mesh)
    if not os.path.isfile(mesh):
        raise SystemExit(f"benchmarks.first_image: no such mesh file: {mesh}")
    with tempfile.TemporaryDirectory(prefix="clrt-first-image-") as folder:
        folder = Path(folder)
        shown = _render_command(mesh, size, device, builder, Path("OUT.png"))[1:]
        print(f"python {' '.join(shown)}: {runs} fresh process(es) after one untimed run")
        _run(_render_command(mesh, size, device, builder, folder / "warm.png"))
        walls = [_run(_render_command(mesh, size, device, builder, folder / f"{i}.png")) for i in range(runs)]
        print(f"  wall  median {statistics.median(walls):.3f} s  min {min(walls):.3f} s  "
              f"max {max(walls):.3f} s")
        command = module_command("first_image") + [mesh, "--size", f"{size[0]}x{size[1]}",
                                                   "--stages", str(folder / "stages.png")]
        command += ["--device", device] if device else []
        command += ["--builder", builder] if builder else []
        command += ["--serial"] if serial else []
        started = time.perf_counter()
        done = subprocess.run(command + ["--started", repr(started)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=repo_env())
        ended = time.perf_counter()
        lines = [line for line in done.stdout.splitlines() if line.startswith(STAGES_MARK)]
        if done.returncode != 0 or not lines:
            raise SystemExit(f"benchmarks.first_image: the stage process failed (exit {done.returncode}): "
                             f"{done.stderr.strip()[-2000:]}")
    print("stages of one more fresh process, each timed after the last"
          + (" (serial: no driver warm-up thread)" if serial else "") + ":")
    total = 0.0
    for name, ms, subs in json.loads(lines[-1][len(STAGES_MARK):]):
        if ms is None:
            print(f"  {name}")
            continue
        total += ms
        print(f"  {name:<48} {ms:9.1f} ms")
        for sub, sub_ms in subs:
            print(f"      {sub:<44} {sub_ms:9.1f} ms")
    print(f"  {'total (python start to the PNG written)':<48} {total:9.1f} ms")
    print(f"  {'then printing and process exit':<48} {1e3 * (ended - started) - total:9.1f} ms")


def main(argv=None) -> int:
    import argparse
    import json

    from benchmarks.common import parse_size
    p = argparse.ArgumentParser(prog="python -m benchmarks.first_image", description=__doc__.split("\n")[0])
    p.add_argument("mesh", help="mesh file to render")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D, passed to clrt render (default: clrt's choice)")
    p.add_argument("--size", type=parse_size, default=(1920, 1080), help="WxH (default 1920x1080)")
    p.add_argument("--runs", type=int, default=5, help="timed fresh processes (default 5)")
    p.add_argument("--builder", help="passed to clrt render --builder (default: clrt's)")
    p.add_argument("--serial", action="store_true",
                   help="stage process without the driver warm-up thread: each stage's whole cost")
    p.add_argument("--stages", metavar="PNG", help=argparse.SUPPRESS)     # the stage process itself
    p.add_argument("--started", type=float, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.stages:
        started = args.started if args.started is not None else time.perf_counter()
        rows = stages(args.mesh, args.size, args.device, args.builder, args.stages, started, args.serial)
        print(STAGES_MARK + json.dumps(rows))
        return 0
    if args.runs < 1:
        p.error("--runs must be at least 1")
    run(args.mesh, args.size, args.device, args.builder, args.runs, args.serial)
    return 0


if __name__ == "__main__":
    sys.exit(main())

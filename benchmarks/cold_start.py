"""A first call with empty program caches against the same call warm: ``python -m benchmarks.cold_start``.

    python -m benchmarks.cold_start --mesh ../shared/meshes/bunny00.off --runs 5
    python -m benchmarks.cold_start --mesh M.off --case render-mesh --runs 3 --breakdown

Three cases, each a fresh process timed from its start to its exit:

``render``       ``python -m clrt render -o OUT.png``: the built-in scene at its size;
``render-mesh``  ``python -m clrt render MESH -o OUT.png``;
``accel``        a fresh Python that imports clrt, makes ``clrt.Accel(MESH)`` and traces
                 4096 rays (``python -m benchmarks.cold_start --child accel MESH``).

A run of a case is two processes: the first with empty caches -- the
drivers' (``POCL_CACHE_DIR``, NVIDIA's ``CUDA_CACHE_PATH``) and clrt's
(``CLRT_CACHE_DIR``) pointed at a new temporary folder -- the second at once
with the caches the first left (on PoCL after the background build a cold
call may start has ended: clrt.device.first_build).
Each case prints the median, min and max of both over ``--runs`` runs, and
the median (and range) of each run's cold / warm ratio; the runs take turns
so that the other work of a shared machine falls on both alike.

``--breakdown`` runs one more cold and warm pair of each case with the work
done in the process itself, and prints where the time went: each program
build (clBuildProgram; on PoCL the front end, source to LLVM IR), with its
own defines, source size and kernel count; each kernel's first launch for
each work-group size and grid class (timed with the queue drained before and
after; on PoCL that is where a kernel is compiled, once per local size and
per grid narrower or not than 65535 work-items); and the rest (Python,
imports, reading the mesh, the host's work, later launches).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import json
import os
import statistics
import subprocess
import tempfile
import textwrap
import time
from pathlib import Path

from benchmarks import FIRST_BUILD_GIVEN
from benchmarks.common import POSITIVE, SHARED_MESHES, module_command, repo_env

CASES = ("render", "render-mesh", "accel")
BREAKDOWN_MARK = "cold_start breakdown:"
ACCEL_RAYS = 4096
SMALL_GRID = 65535    # PoCL compiles a kernel apart for grids narrower than this (USHRT_MAX) and wider


def _case_command(case: str, mesh: str | None, device: str | None, out: Path, breakdown: bool = False) -> list:
    """The command of one process of ``case``."""
    device_args = ["--device", device] if device else []
    if case == "accel":
        return module_command("cold_start") + ["--child", "accel", mesh, *device_args] + (
            ["--breakdown"] if breakdown else [])
    render = (["render"] + ([mesh] if case == "render-mesh" else []) + ["-o", str(out), "-f", "-q"]
              + device_args)
    if breakdown:
        return module_command("cold_start") + ["--child", "render", "--breakdown", "--", *render]
    return [sys.executable, "-m", "clrt", *render]


def _run(command: list, caches: Path) -> tuple[float, str]:
    """Seconds from starting ``command`` to its exit, with the program caches in
    ``caches``, and its standard output; SystemExit with its error if it fails."""
    env = repo_env()
    # (CUDA_CACHE_PATH: NVIDIA's OpenCL keeps its compiled programs there)
    env.update(POCL_CACHE_DIR=str(caches / "pocl"), CLRT_CACHE_DIR=str(caches / "clrt"),
               CUDA_CACHE_PATH=str(caches / "nv"))
    env.pop("CLRT_NO_PROGRAM_CACHE", None)
    if FIRST_BUILD_GIVEN is None:   # a user's first call: host builds while the builder compiles
        env["CLRT_FIRST_BUILD"] = "1"   # (clrt's default; set, so that a --child keeps it)
    start = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"benchmarks.cold_start: {' '.join(command)} failed (exit {done.returncode}): "
                         f"{done.stderr.strip()[-2000:]}")
    return seconds, done.stdout


def _pair(case, mesh, device, folder: Path, breakdown: bool = False) -> tuple:
    """(cold, warm) runs of ``case`` on caches made empty in ``folder``: (seconds, stdout) each."""
    caches = Path(tempfile.mkdtemp(prefix="caches-", dir=folder))
    command = _case_command(case, mesh, device, folder / "out.png", breakdown)
    cold = _run(command, caches)
    _settle(caches / "clrt" / "first-build")
    return cold, _run(command, caches)


def _settle(ready: Path, timeout: float = 300.0) -> None:
    """Wait until the background builds a cold run started
    (clrt.device.first_build: each holds a lock file there) have ended, so
    that the warm run finds what they compiled."""
    end = time.monotonic() + timeout
    while ready.is_dir() and any(ready.glob("*.lock")) and time.monotonic() < end:
        time.sleep(0.05)


def _spread(values) -> str:
    return f"median {statistics.median(values):7.2f}  min {min(values):7.2f}  max {max(values):7.2f}"


def run(cases, mesh, device, runs: int, breakdown: bool, out=None) -> None:
    out = out or sys.stdout
    with tempfile.TemporaryDirectory(prefix="clrt-cold-start-") as folder:
        folder = Path(folder)
        times = {case: [] for case in cases}
        for _ in range(runs):
            for case in cases:
                (cold, _), (warm, _) = _pair(case, mesh, device, folder)
                times[case].append((cold, warm))
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        print(f"{runs} run(s) of each case, each cold (empty caches) then warm; load average {load:.1f} after",
              file=out)
        for case in cases:
            shown = _case_command(case, "MESH", device, Path("OUT.png"))
            shown = " ".join(["python"] + shown[1:])
            cold = [c for c, _ in times[case]]
            warm = [w for _, w in times[case]]
            ratios = [c / w for c, w in times[case]]
            print(f"\n{case}: {shown}", file=out)
            print(f"  cold s        {_spread(cold)}", file=out)
            print(f"  warm s        {_spread(warm)}", file=out)
            print(f"  cold / warm   {_spread(ratios)}", file=out)
        if breakdown:
            for case in cases:
                (cold, cold_out), (warm, warm_out) = _pair(case, mesh, device, folder, breakdown=True)
                _print_breakdown(case, _parse_breakdown(cold_out), _parse_breakdown(warm_out), out)


def _parse_breakdown(stdout: str) -> dict:
    lines = [line for line in stdout.splitlines() if line.startswith(BREAKDOWN_MARK)]
    if not lines:
        raise SystemExit(f"benchmarks.cold_start: no breakdown in the child's output:\n{stdout[-2000:]}")
    return json.loads(lines[-1][len(BREAKDOWN_MARK):])


def _print_breakdown(case: str, cold: dict, warm: dict, out=None) -> None:
    out = out or sys.stdout
    print(f"\n{case}: breakdown of one more cold and warm process, ms", file=out)
    print(f"  {'program build (its defines below it)':<74} {'KB':>5} {'kernels':>7} "
          f"{'cold':>8} {'(binary)':>8} {'warm':>8}", file=out)
    warm_builds = {(b["entry"], b["defines"]): b for b in warm["builds"]}
    spent_cold = spent_warm = 0.0
    for b in cold["builds"]:
        w = warm_builds.get((b["entry"], b["defines"]), {})
        print(f"  {b['entry']:<74} {b['source_bytes'] / 1024:5.0f} {b['kernels']:7d} {b['ms']:8.1f} "
              f"{b['binary_ms']:8.1f} {w.get('ms', float('nan')):8.1f}", file=out)
        print(textwrap.fill(b["defines"], 108, initial_indent=" " * 6, subsequent_indent=" " * 6), file=out)
        spent_cold += b["ms"]
        spent_warm += w.get("ms", 0.0)
    print(f"  {'first launch (kernel, local size, grid)':<74} {'':>5} {'':>7} {'cold':>8} {'':>8} {'warm':>8}",
          file=out)
    warm_launches = {tuple(x["key"]): x["ms"] for x in warm["launches"]}
    for x in cold["launches"]:
        w = warm_launches.get(tuple(x["key"]), float("nan"))
        kernel, local, grid = x["key"]
        name = f"{kernel} {local} {grid}"
        print(f"  {name:<74} {'':>5} {'':>7} {x['ms']:8.1f} {'':>8} {w:8.1f}", file=out)
        spent_cold += x["ms"]
        spent_warm += 0.0 if w != w else w
    print(f"  {'builds and first launches':<88} {spent_cold:8.1f} {'':>8} {spent_warm:8.1f}", file=out)
    print(f"  {'the rest (python, imports, host work, later launches)':<88} "
          f"{cold['ms'] - spent_cold:8.1f} {'':>8} {warm['ms'] - spent_warm:8.1f}", file=out)
    print(f"  {'in the process (its main() to the end of the call)':<88} {cold['ms']:8.1f} {'':>8} "
          f"{warm['ms']:8.1f}", file=out)


# ----------------------------------------------------------------------------- the child processes

def _timed_first_launches(launches: list) -> None:
    """Time each kernel's first launch of each local size and grid class: the
    queue drained before and after (pyopencl.enqueue_nd_range_kernel wrapped)."""
    import pyopencl as cl

    plain = cl.enqueue_nd_range_kernel
    seen = set()

    def enqueue(queue, kernel, global_size, local_size, *args, **kwargs):
        grid = f"grid < {SMALL_GRID}" if max(global_size) < SMALL_GRID else f"grid >= {SMALL_GRID}"
        key = (kernel.function_name, "x".join(map(str, local_size)) if local_size else "driver's", grid)
        if key in seen:
            return plain(queue, kernel, global_size, local_size, *args, **kwargs)
        seen.add(key)
        queue.finish()
        start = time.perf_counter()
        event = plain(queue, kernel, global_size, local_size, *args, **kwargs)
        queue.finish()
        launches.append({"key": key, "ms": 1e3 * (time.perf_counter() - start)})
        return event

    cl.enqueue_nd_range_kernel = enqueue


def _accel_call(mesh: str, device: str | None) -> None:
    import numpy as np

    import clrt
    accel = clrt.Accel(mesh, device=device)
    rng = np.random.default_rng(0)
    lo, hi = accel.mesh.bounds
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    origins = centre + radius * rng.normal(size=(ACCEL_RAYS, 3))
    hits = accel.trace(origins, centre - origins)
    assert (hits.prim >= 0).any(), "no ray hit the mesh"


def child(kind: str, args: list, device: str | None, breakdown: bool, started: float) -> int:
    launches: list = []
    if breakdown:
        _timed_first_launches(launches)
    if kind == "accel":
        _accel_call(args[0], device)
    else:
        from clrt.cli import main
        code = main(args)
        if code:
            return code
    if breakdown:
        from clrt.device import program
        builds = [{"entry": b.entry, "defines": " ".join(f"{k}" if v is None else f"{k}={v}"
                                                          for k, v in sorted(b.defines.items())),
                   "source_bytes": b.source_bytes, "kernels": b.kernels, "ms": 1e3 * b.seconds,
                   "binary_ms": 1e3 * b.binary_seconds} for b in program.builds]
        print(BREAKDOWN_MARK + json.dumps({"builds": builds, "launches": launches,
                                           "ms": 1e3 * (time.perf_counter() - started)}))
    return 0


def main(argv=None) -> int:
    started = time.perf_counter()
    p = argparse.ArgumentParser(prog="python -m benchmarks.cold_start", description=__doc__.split("\n")[0])
    p.add_argument("--mesh", default=str(SHARED_MESHES / "bunny00.off"),
                   help="mesh of the render-mesh and accel cases (default: ../shared/meshes/bunny00.off)")
    p.add_argument("--case", action="append", choices=CASES, help="a case to run (default: all three)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    p.add_argument("--runs", type=POSITIVE, default=3, help="cold and warm pairs of each case (default 3)")
    p.add_argument("--breakdown", action="store_true", help="then one more pair of each case, timed inside")
    p.add_argument("--child", choices=("accel", "render"), help=argparse.SUPPRESS)   # a timed process itself
    p.add_argument("rest", nargs="*", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        return child(args.child, args.rest, args.device, args.breakdown, started)
    cases = args.case or list(CASES)
    if any(case != "render" for case in cases) and not os.path.isfile(args.mesh):
        p.error(f"--mesh: no such file: {args.mesh}")
    run(cases, os.path.abspath(args.mesh), args.device, args.runs, args.breakdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())

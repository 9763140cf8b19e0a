"""The path tracer's speed: ``python -m benchmarks.path [--scene NAME ...]``.

Scenes (benchmarks/scenes.py, the same files Mitsuba 3 renders in benchmarks.mitsuba_reference):
``cornell-box`` (assets/scenes/cornell-box.gltf, 1024x1024) and ``bunny00`` (bunny00 on a diffuse
ground under an area light, 1920x1080; written by benchmarks.scenes when ../shared/meshes/bunny00.off
or ``--bunny DIR``/bunny00.off is there).  Each render is what a user waits for: ``Renderer.render`` of the
whole image at ``--spp`` samples, wall time from the call to the linear image in numpy, medians of
``--runs`` renders after one warm-up (which builds the program).  Msamples/s = pixels x spp / s, as
the issue's Mitsuba anchor counts them; its kernel time (profiling events) beside it.

``--mitsuba`` renders the same scenes with Mitsuba 3 in this process after clrt (its cuda_ad_rgb
variant on a GPU, llvm_ad_rgb elsewhere; an optional import), same size, spp and max depth, so the
two stand side by side in one table from one run.  ``--rmse N`` adds the error at equal time: the
time is Mitsuba's median wall at ``--spp``; clrt renders the spp its own wall affords in it; both
images are compared with Mitsuba's render at N spp (RMSE of the linear RGB values).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from benchmarks import scenes
from benchmarks.common import NON_NEGATIVE, POSITIVE, exit_code

SCENES = {"cornell-box": (1024, 1024), "bunny00": (1920, 1080)}


def scene_file(name: str, bunny: Path | None) -> Path:
    if name == "cornell-box":
        return scenes.CORNELL_BOX_FILE
    out = scenes.ROOT / "out" / "scenes" / scenes.BUNNY_FILE_NAME
    if not out.is_file():
        scenes.main(["--mesh-dir", str(bunny)] if bunny else [])
    return out


def clrt_row(path: Path, size, spp: int, max_depth: int, runs: int, device) -> dict:
    import clrt
    from clrt.scene.render_setup import render_frame

    scene, camera = render_frame(str(path), integrator="path", width=size[0], height=size[1])
    renderer = clrt.Renderer(scene, device=device)
    renderer.render(camera, spp=spp, max_depth=max_depth, seed=0, linear=True)   # program build, upload
    walls, kernels = [], []
    for run in range(runs):
        start = time.perf_counter()
        frame = renderer.render(camera, spp=spp, max_depth=max_depth, seed=run + 1, linear=True)
        walls.append(time.perf_counter() - start)
        kernels.append(frame.timings.get("kernels", float("nan")))
    wall = statistics.median(walls)
    return {"library": "clrt", "wall_ms": 1e3 * wall, "kernel_ms": statistics.median(kernels),
            "msamples": size[0] * size[1] * spp / wall / 1e6, "mean": float(np.mean(frame.image)),
            "timings": frame.timings,
            "render": lambda n, seed: renderer.render(camera, spp=n, max_depth=max_depth, seed=seed,
                                                      linear=True).image}


def mitsuba_row(name: str, path: Path, size, spp: int, max_depth: int, runs: int) -> dict | None:
    try:
        from benchmarks import mitsuba_reference as mr
    except ImportError:
        return None
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return None
    mi = mr.start_mitsuba("cuda_ad_rgb" if _has_cuda() else "llvm_ad_rgb")
    read = mr.read_scene(path, size)
    scene = mr.mitsuba_scene(mi, read, max_depth, spp)
    image = mr.render(mi, scene, spp, 0)   # warm-up: its JIT compiles here
    walls = []
    for run in range(runs):
        start = time.perf_counter()
        image = mr.render(mi, scene, spp, run + 1)
        walls.append(time.perf_counter() - start)
    wall, variant = statistics.median(walls), mi.variant()
    return {"library": f"Mitsuba 3 ({variant})", "wall_ms": 1e3 * wall,
            "msamples": size[0] * size[1] * spp / wall / 1e6, "mean": float(np.mean(image)), "kernel_ms": None,
            "timings": {}, "render": lambda n, seed: mr.render(mi, mr.mitsuba_scene(mi, read, max_depth, n), n, seed)}


def rmse(image, reference) -> float:
    return float(np.sqrt(np.mean((np.asarray(image, np.float64) - reference) ** 2)))


def equal_time(name: str, clrt: dict, mitsuba: dict, spp: int, reference_spp: int) -> None:
    """RMSE against a converged image at equal time: Mitsuba at ``spp`` (its
    median wall above is the time), clrt at the spp its own wall affords in
    that time; the reference is Mitsuba's render at ``reference_spp``, whose
    own noise adds (spp / reference_spp) of a render's MSE to both rows."""
    reference = np.asarray(mitsuba["render"](reference_spp, 10_000), np.float64)
    clrt_spp = max(1, int(spp * mitsuba["wall_ms"] / clrt["wall_ms"]))
    start = time.perf_counter()
    clrt_image = clrt["render"](clrt_spp, 20_000)
    clrt_ms = 1e3 * (time.perf_counter() - start)
    print(f"| {name} | {mitsuba['wall_ms']:.1f} | {clrt_spp} ({clrt_ms:.1f} ms) | {rmse(clrt_image, reference):.5f} | "
          f"{spp} | {rmse(mitsuba['render'](spp, 30_000), reference):.5f} | {reference_spp} |", flush=True)


def _has_cuda() -> bool:
    try:
        import drjit as dr
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:
        return False


def run(names, spp, max_depth, runs, device, mitsuba, bunny, reference_spp=0) -> None:
    print("| scene | size | spp | max depth | renderer | wall ms | kernel ms | Msamples/s | mean radiance |")
    print("|---|---|---|---|---|---|---|---|---|")
    pairs = []
    for name in names:
        size = SCENES[name]
        path = scene_file(name, bunny)
        rows = [clrt_row(path, size, spp, max_depth, runs, device)]
        if mitsuba:
            row = mitsuba_row(name, path, size, spp, max_depth, runs)
            if row:
                rows.append(row)
        for r in rows:
            print(f"| {name} | {size[0]}x{size[1]} | {spp} | {max_depth} | {r['library']} | {r['wall_ms']:.1f} | "
                  f"{'' if r['kernel_ms'] is None else format(r['kernel_ms'], '.1f')} | {r['msamples']:.1f} | "
                  f"{r['mean']:.5f} |", flush=True)
        print(f"{name}: clrt timings of the last render: "
              + ", ".join(f"{k} {v:.2f} ms" for k, v in rows[0]["timings"].items()), file=sys.stderr)
        if reference_spp and len(rows) == 2:
            pairs.append((name, *rows))
    if pairs:
        print("\nEqual time, RMSE of the linear image against Mitsuba's render at the reference spp:\n")
        print("| scene | time (Mitsuba's wall, ms) | clrt spp (its wall) | clrt RMSE | Mitsuba spp | Mitsuba RMSE | "
              "reference spp |")
        print("|---|---|---|---|---|---|---|")
        for name, clrt, mitsuba in pairs:
            equal_time(name, clrt, mitsuba, spp, reference_spp)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.path", description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", action="append", choices=sorted(SCENES), help="repeatable (default: both)")
    p.add_argument("--spp", type=POSITIVE, default=64, help="samples per pixel (default 64)")
    p.add_argument("--max-depth", type=int, default=8, help="Mitsuba's counting (default 8)")
    p.add_argument("--runs", type=POSITIVE, default=3, help="timed renders after a warm-up (default 3)")
    p.add_argument("--device", help="'gpu', 'cpu' or P:D (default: clrt's choice)")
    p.add_argument("--mitsuba", action="store_true", help="Mitsuba 3 on the same scenes, after clrt")
    p.add_argument("--bunny", type=Path, help="folder holding bunny00.off (default: ../shared/meshes)")
    p.add_argument("--rmse", type=POSITIVE, metavar="REFERENCE_SPP",
                   help="with --mitsuba: RMSE at equal time against Mitsuba's render at REFERENCE_SPP")
    args = p.parse_args(argv)
    if args.rmse and not args.mitsuba:
        p.error("--rmse needs --mitsuba")
    return exit_code(run, args.scene or sorted(SCENES), args.spp, args.max_depth, args.runs, args.device,
                     args.mitsuba, args.bunny, args.rmse or 0)


if __name__ == "__main__":
    sys.exit(main())

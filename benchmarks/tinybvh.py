"""clrt beside tinybvh on one ray file: ``python -m benchmarks.tinybvh fetch|run``.

``fetch [DIR]`` puts the tinybvh sources this comparison needs (tiny_bvh.h;
traverse.cl and traverse_bvh2.cl, its OpenCL Aila-Laine walks; its licence; the
Khronos OpenCL headers it carries) into DIR, by default ``benchmarks/.tinybvh/``
(git-ignored: they are never committed), at the pinned commit
``PINNED_COMMIT``: from GitHub, or with ``--from GIT_DIR`` from a local clone
or mirror.  The folder holds 0.54 MB: small enough to travel with the working
tree (as a carried path) to a machine without internet.

``run MESH`` traces one set of rays with tinybvh (a child process) and clrt
(this process) on one OpenCL device:

* tinybvh: ``benchmarks/tinybvh_driver.cpp`` (ours) is compiled against the
  fetched ``tiny_bvh.h`` into the temporary folder (``g++ -O2 -march=native``
  as tinybvh's own build; the system OpenCL loader linked by path, as CUDA's
  ``libOpenCL.so.1`` ignores ``OCL_ICD_VENDORS``), builds tinybvh's ``BVH_GPU`` (the Aila-Laine layout;
  ``--builds sah`` is tinybvh's default builder, ``hq`` its SBVH) and times
  tinybvh's own OpenCL kernels on the rays: ``batch_ailalaine`` (closest hit)
  and ``isoccluded_ailalaine`` (any hit; tinybvh has that walk as a function
  only, so the driver wraps it in a one-line kernel);
* clrt: ``clrt.Accel`` with the default builder and with ``sah``, rays and
  results on the device, ``accel.trace`` and ``accel.any_hit``.

Kernel ms come from OpenCL profiling events on both sides: medians of
``--repeat`` launches after ``--warmup``, and their range.  With ``--rounds``
the two take turns, and each round gives its own medians and ratio.  Hit counts
and the rays on which the answers differ are printed: the rays, the triangles
(in the mesh's order, as clrt loads it) and the device are the same for all.

The rays are the incoherent set of issue 39: origins uniform in the mesh's
bounding box enlarged by 10 % about its centre, directions uniform on the
sphere (z = U(-1, 1), phi = U(0, 2 pi)); numpy ``default_rng(seed)``, the
origins drawn first as an N x 3 uniform array, then z, then phi; made in
float64 and kept as float32.  ``--write-rays FILE`` saves them and ``--rays
FILE`` reads such a file (benchmarks.raysets' format: N rows of 6 float32).
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import hashlib
import os
import shutil
import statistics
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import NON_NEGATIVE, POSITIVE, ROOT, exit_code, parse_count, ray_memory
from clrt.errors import ClrtError, DeviceError, InputError

PINNED_COMMIT = "4735685f64d8b2bb0ad2c6c4643f291bf58774ad"   # tinybvh 1.6.7, 2026-02-13
GITHUB = "jbikker/tinybvh"
#: what the driver needs, by its path in tinybvh's repository -> its path in the fetched folder
FILES = {
    "tiny_bvh.h": "tiny_bvh.h",
    "traverse.cl": "traverse.cl",           # the structs, and includes one file per layout ...
    "traverse_bvh2.cl": "traverse_bvh2.cl",  # ... of which the driver takes this one: the Aila-Laine walks
    "LICENSE": "LICENSE",
    # the hosts may have no OpenCL headers: tinybvh carries Khronos's
    "tmpl8/lib/OpenCL/inc/CL/cl.h": "CL/cl.h",
    "tmpl8/lib/OpenCL/inc/CL/cl_platform.h": "CL/cl_platform.h",
    "tmpl8/lib/OpenCL/inc/CL/cl_version.h": "CL/cl_version.h",
}
SOURCES = ROOT / "benchmarks" / ".tinybvh"
STAMP = "COMMIT"                        # in the fetched folder: the commit its files come from
DRIVER = Path(__file__).with_name("tinybvh_driver.cpp")
OPENCL_LOADER = "/lib/x86_64-linux-gnu/libOpenCL.so.1"
BUILDS = ("sah", "hq")                  # tinybvh's BVH_GPU::Build and BuildHQ
QUERIES = ("closest", "any")
MARGIN = 1.1                            # the rays' box: the mesh's bounding box, 10 % larger about its centre
MISS = 1e30                             # tinybvh's t of a miss (BVH_FAR)


# --------------------------------------------------------------------------- the sources

def _from_git(git_dir: Path, path: str) -> bytes:
    result = subprocess.run(["git", "-C", str(git_dir), "cat-file", "blob", f"{PINNED_COMMIT}:{path}"],
                            capture_output=True)
    if result.returncode:
        why = (result.stderr.decode(errors="replace").strip().splitlines() or ["git failed"])[-1]
        raise InputError(f"--from {git_dir}: no {path} at tinybvh commit {PINNED_COMMIT[:12]} ({why})")
    return result.stdout


def _from_github(path: str) -> bytes:
    import urllib.request
    url = f"https://raw.githubusercontent.com/{GITHUB}/{PINNED_COMMIT}/{path}"
    try:
        with urllib.request.urlopen(url, timeout=60) as response:
            return response.read()
    except OSError as exc:
        raise InputError(f"cannot download {url} ({getattr(exc, 'reason', exc)}); without internet, "
                         f"give --from a clone of {GITHUB}") from None


def fetch(dest: Path = SOURCES, git_dir: Path | None = None, out=None) -> Path:
    """The pinned commit's FILES into ``dest``, from ``git_dir`` (a clone or
    mirror, bare or not) or from GitHub; ``dest/COMMIT`` names the commit."""
    out = out or sys.stdout
    if git_dir is not None and not Path(git_dir).exists():
        raise InputError(f"--from {git_dir}: no such folder")
    dest = Path(dest)
    if dest.exists() and not dest.is_dir():
        raise InputError(f"{dest} is a file, not a folder")
    if dest.is_dir() and any(dest.iterdir()) and not (dest / STAMP).is_file():
        raise InputError(f"{dest} holds files that are not a tinybvh fetch: give another folder")
    contents = {local: _from_git(Path(git_dir), path) if git_dir else _from_github(path)
                for path, local in FILES.items()}
    if dest.is_dir():
        shutil.rmtree(dest)   # an earlier fetch: no file of another commit stays
    for local, data in contents.items():
        (dest / local).parent.mkdir(parents=True, exist_ok=True)
        (dest / local).write_bytes(data)
    (dest / STAMP).write_text(PINNED_COMMIT + "\n")
    size = sum(len(d) for d in contents.values())
    print(f"tinybvh {PINNED_COMMIT} ({len(contents)} files, {size / 1e6:.2f} MB) from "
          f"{git_dir or 'github.com/' + GITHUB} in {dest}", file=out)
    return dest


def check_sources(folder: Path) -> None:
    """The fetched folder holds every file of the pinned commit, or a one-line error."""
    hint = f"run python -m benchmarks.tinybvh fetch{'' if folder == SOURCES else ' ' + str(folder)}"
    stamp = folder / STAMP
    if not stamp.is_file() or any(not (folder / local).is_file() for local in FILES.values()):
        raise InputError(f"no tinybvh sources in {folder}: {hint}")
    if stamp.read_text().strip() != PINNED_COMMIT:
        raise InputError(f"{folder} holds tinybvh {stamp.read_text().strip()[:12]}, not the pinned "
                         f"{PINNED_COMMIT[:12]}: {hint}")


# --------------------------------------------------------------------------- the inputs

def issue_rays(bounds, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Issue 39's incoherent rays about a bounding box (2, 3): origins uniform in
    the box enlarged by 10 % about its centre, directions uniform on the sphere;
    (count, 3) float32 each, made in float64 from default_rng(seed) in the order
    origins (count x 3), z, phi."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(bounds, np.float64)
    centre, half = (lo + hi) / 2, MARGIN * (hi - lo) / 2
    origins = rng.uniform(centre - half, centre + half, (count, 3))
    z = rng.uniform(-1.0, 1.0, count)
    phi = rng.uniform(0.0, 2 * np.pi, count)
    r = np.sqrt(1 - z * z)
    directions = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return origins.astype(np.float32), directions.astype(np.float32)


def triangle_soup(mesh) -> np.ndarray:
    """The mesh's triangles as tinybvh takes them: three x y z 0 float32 vertices
    each, in the mesh's face order (tinybvh's primitive ids are clrt's)."""
    corners = np.asarray(mesh.vertices, np.float32)[np.asarray(mesh.faces)]
    return np.concatenate([corners, np.zeros((*corners.shape[:2], 1), np.float32)], axis=2)


# --------------------------------------------------------------------------- tinybvh

def compile_driver(sources: Path, compiler: str = "g++", loader: str = OPENCL_LOADER) -> Path:
    """The driver built against ``sources`` in the temporary folder, once per
    source, header and command (kept for the next run)."""
    if not Path(loader).is_file():
        raise InputError(f"no OpenCL loader at {loader} (give --opencl-loader the system's libOpenCL.so.1)")
    if shutil.which(compiler) is None:
        raise InputError(f"no C++ compiler {compiler!r} on this machine (give --cxx one)")
    # -march=native as tinybvh's own CMake build: on x86 its default builder is then BuildAVX
    flags = ["-O2", "-march=native", "-std=c++17", "-pthread", f"-I{sources}"]
    key = hashlib.sha256(DRIVER.read_bytes() + (sources / "tiny_bvh.h").read_bytes()
                         + " ".join([compiler, *flags, loader, "rpath"]).encode()).hexdigest()[:16]
    exe = Path(tempfile.gettempdir()) / "clrt-tinybvh" / f"tinybvh_driver-{key}"
    if exe.is_file():
        return exe
    exe.parent.mkdir(parents=True, exist_ok=True)
    partial = exe.with_suffix(f".{os.getpid()}")
    # The loader by path, and its folder searched first at run time (DT_RPATH, before LD_LIBRARY_PATH and
    # ld.so's cache): a name alone found CUDA's libOpenCL.so.1 on the GPU machine, which lists no platform.
    rpath = ["-Wl,--disable-new-dtags", f"-Wl,-rpath,{os.path.dirname(loader)}"]
    result = subprocess.run([compiler, *flags, str(DRIVER), "-o", str(partial), loader, *rpath],
                            capture_output=True, text=True)
    if result.returncode:
        errors = [line for line in result.stderr.splitlines() if "error" in line] or result.stderr.splitlines()
        raise ClrtError(f"the tinybvh driver did not compile: {(errors or ['no output'])[0]}")
    partial.replace(exe)
    return exe


def run_driver(exe: Path, sources: Path, triangles: Path, rays: Path, device: str, repeat: int, warmup: int,
               builds, work: Path) -> tuple[str, dict]:
    """The driver's device and, by (build, query): build ms, hits, kernel ms of
    each launch, and the answers (closest: the triangle per ray, -1 on a miss;
    any: whether it hits)."""
    result = subprocess.run([str(exe), str(sources), str(triangles), str(rays), device, str(repeat), str(warmup),
                             ",".join(builds), str(work)], capture_output=True, text=True)
    if result.returncode:
        raise DeviceError(result.stderr.strip() or f"the tinybvh driver failed (exit code {result.returncode})")
    device_name, found = "?", {}
    for line in result.stdout.splitlines():
        if line.startswith("device: "):
            device_name = line[len("device: "):]
        elif line.startswith("result "):
            _, build, query, build_ms, hits, times = line.split()
            if query == "closest":
                t_u_v_prim = np.fromfile(work / f"{build}-closest.f32", np.float32).reshape(-1, 4)
                prim = t_u_v_prim[:, 3].view(np.uint32).astype(np.int64)   # as_float(triIdx)
                answers = np.where(t_u_v_prim[:, 0] < MISS, prim, -1)
            else:
                answers = np.fromfile(work / f"{build}-any.u32", np.uint32) != 0
            found[build, query] = {"build_ms": float(build_ms), "hits": int(hits),
                                   "ms": [float(t) for t in times.split(",")], "answers": answers}
    return device_name, found


# --------------------------------------------------------------------------- clrt

def clrt_times(accel, origins, directions, repeat: int, warmup: int) -> dict:
    """By query: kernel ms of each timed call (profiling events of its launches)
    and the answers (closest: the triangle per ray, -1 on a miss; any: whether
    it hits)."""
    import pyopencl.array as cla
    o_dev, d_dev = cla.to_device(accel.queue, origins), cla.to_device(accel.queue, directions)
    calls = {"closest": lambda: accel.trace(o_dev, d_dev, fields=("t", "prim")),
             "any": lambda: accel.any_hit(o_dev, d_dev)}
    found = {}
    for query, call in calls.items():
        ms, result = [], None
        for i in range(warmup + repeat):
            accel.kernel_ms()
            result = call()
            accel.queue.finish()
            if i >= warmup:
                ms.append(accel.kernel_ms())
        answers = _host(result.prim).astype(np.int64) if query == "closest" else _host(result).astype(bool)
        found[query] = {"ms": ms, "answers": answers}
    return found


def _host(values) -> np.ndarray:
    return np.asarray(values.get() if hasattr(values, "get") else values)


def agreement(query: str, ours, theirs) -> str:
    """How two answers to the same rays compare: the rays that differ on hit or
    miss, and for closest hits, those that hit different triangles."""
    hit_ours, hit_theirs = (a >= 0 if query == "closest" else a for a in (ours, theirs))
    differ = int((hit_ours != hit_theirs).sum())
    text = "the same rays hit" if differ == 0 else f"**{differ:,} rays differ on hit or miss**"
    if query == "closest":
        both = hit_ours & hit_theirs
        other = int((ours[both] != theirs[both]).sum())
        text += ", " + ("each on the same triangle" if other == 0 else
                        f"{other:,} of the {int(both.sum()):,} hits on another triangle (a ray through an edge "
                        f"or a shared distance may name either)")
    return text


# --------------------------------------------------------------------------- the run

BUILD_NAMES = {"sah": "Build (binned SAH)", "hq": "BuildHQ (SBVH)"}


def _span(values, digits: int) -> str:
    """'a' or 'a-b': the range of ``values`` at ``digits`` decimals."""
    low, high = (f"{v:.{digits}f}" for v in (min(values), max(values)))
    return low if low == high else f"{low}-{high}"


def measure(mesh, origins, directions, device: str, repeat: int, warmup: int, rounds: int, builds, sources: Path,
            exe: Path) -> dict:
    """tinybvh (the driver, a child process) and clrt (default builder and sah,
    this process) taking turns on the same rays, ``rounds`` times: by variant
    and query, each round's kernel ms, the hits and the last answers."""
    from clrt.query import Accel
    accels = {"default": Accel(mesh, device=device), "sah": Accel(mesh, builder="sah", device=device)}
    names = {"default": f"clrt, default builder ({accels['default'].acceleration.builder})",
             "sah": "clrt, sah builder"}
    variants = [names[a] for a in accels] + [f"tinybvh Aila-Laine, {BUILD_NAMES[b]}" for b in builds]
    found = {"variants": variants, "clrt_device": accels["default"].device, "build_ms": {},
             "times": {(v, q): [] for v in variants for q in QUERIES}, "answers": {}}
    with tempfile.TemporaryDirectory(prefix="clrt-tinybvh-") as folder:
        work = Path(folder)
        triangle_soup(mesh).tofile(work / "triangles.f32")
        np.concatenate([origins, directions], axis=1).astype("<f4").tofile(work / "rays.f32")
        for _ in range(rounds):
            found["tinybvh_device"], theirs = run_driver(exe, sources, work / "triangles.f32", work / "rays.f32",
                                                         device, repeat, warmup, builds, work)
            results = {(f"tinybvh Aila-Laine, {BUILD_NAMES[b]}", q): r for (b, q), r in theirs.items()}
            for name, accel in accels.items():
                results.update({(names[name], q): r
                                for q, r in clrt_times(accel, origins, directions, repeat, warmup).items()})
            for (variant, query), result in results.items():
                found["times"][variant, query].append(result["ms"])
                found["answers"][variant, query] = result["answers"]
                if "build_ms" in result:
                    found["build_ms"][variant] = result["build_ms"]
    return found


def report(found: dict, mesh_name: str, out) -> list[dict]:
    """The markdown table of ``measure``'s figures, then how the answers agree."""
    variants, times, answers = found["variants"], found["times"], found["answers"]
    reference = variants[2]   # the first tinybvh build
    rounds = len(times[reference, QUERIES[0]])
    print(f"\n| mesh | query | library, variant | kernel ms, median{' by round' if rounds > 1 else ''} | min-max "
          f"| hits | clrt / tinybvh {reference.split(', ')[1].split()[0]} |", file=out)
    print("|---|---|---|---|---|---|---|", file=out)
    table = []
    for query in QUERIES:
        for variant in variants:
            medians = [statistics.median(ms) for ms in times[variant, query]]
            samples = [t for ms in times[variant, query] for t in ms]
            hits = int((answers[variant, query] >= 0).sum() if query == "closest" else answers[variant, query].sum())
            ratio = "-"
            if variant.startswith("clrt"):
                ratio = _span([m / statistics.median(r) for m, r in zip(medians, times[reference, query])], 2) + "x"
            print(f"| {mesh_name} | {query} | {variant} | {' / '.join(f'{m:.3f}' for m in medians)} "
                  f"| {min(samples):.3f}-{max(samples):.3f} | {hits:,} | {ratio} |", file=out)
            table.append({"query": query, "variant": variant, "medians": medians, "hits": hits})
    print("", file=out)
    for query in QUERIES:
        for variant in variants[1:]:
            note = agreement(query, answers[variants[0], query], answers[variant, query])
            print(f"{query}: {variant} against {variants[0]}: {note}", file=out)
    return table


def run(mesh_path, rays_file=None, count: int = 1_000_000, seed: int = 0, write_rays_to=None, force: bool = False,
        device: str = "gpu", repeat: int = 50, warmup: int = 2, rounds: int = 1, builds=("sah",),
        sources: Path = SOURCES, driver=None, compiler: str = "g++", loader: str = OPENCL_LOADER, out=None) -> list:
    from benchmarks.raysets import read_rays, write_rays
    from clrt.scene.load import load_mesh

    out = out or sys.stdout
    check_sources(sources)   # the driver reads tinybvh's kernels at run time
    if write_rays_to is not None:
        from clrt.output import check_replace
        check_replace(Path(write_rays_to), force, "--write-rays")
    if rays_file is not None:
        origins, directions = read_rays(rays_file)
    else:
        ray_memory(count, 24 + 48 + 120)   # float64 while made, float32 kept, the answers
    exe = Path(driver) if driver is not None else compile_driver(sources, compiler, loader)
    mesh = load_mesh(mesh_path)
    if rays_file is None:
        origins, directions = issue_rays(mesh.bounds, count, seed)
        if write_rays_to is not None:
            write_rays(write_rays_to, origins, directions, force)
    found = measure(mesh, origins, directions, device, repeat, warmup, rounds, builds, sources, exe)
    digest = hashlib.sha256(np.concatenate([origins, directions], axis=1).astype("<f4").tobytes()).hexdigest()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"mesh: {Path(mesh_path).name}, {len(mesh.faces):,} triangles; {len(origins):,} rays "
          f"({rays_file or f'generated, seed {seed}'}; sha256 {digest[:16]}); kernel ms, median of {repeat} "
          f"after {warmup} warm-up, {rounds} round(s); load average {load:.2f}", file=out)
    print(f"clrt on {found['clrt_device']}; tinybvh {PINNED_COMMIT[:12]} on {found['tinybvh_device']}, host build "
          + ", ".join(f"{v.split(', ')[1]} {ms:.1f} ms" for v, ms in found["build_ms"].items()), file=out)
    return report(found, Path(mesh_path).stem, out)


def _parser() -> argparse.ArgumentParser:
    class Parser(argparse.ArgumentParser):
        """argparse, but a usage error is one line (exit code 2)."""

        def error(self, message):
            raise InputError(f"{message} (see {self.prog} --help)")

    p = Parser(prog="python -m benchmarks.tinybvh", description=__doc__.split("\n")[0].replace("``", ""))
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    f = sub.add_parser("fetch", help="put the tinybvh sources into a git-ignored folder",
                       description=f"Put tinybvh's sources at commit {PINNED_COMMIT[:12]} into DIR.")
    f.add_argument("dir", nargs="?", type=Path, default=SOURCES, metavar="DIR",
                   help=f"where (default: {SOURCES.relative_to(ROOT)})")
    f.add_argument("--from", dest="git_dir", type=Path, metavar="GIT_DIR",
                   help="a local clone or mirror of jbikker/tinybvh (bare or not) instead of GitHub")
    r = sub.add_parser("run", help="time tinybvh and clrt on one ray file",
                       description="Time tinybvh's and clrt's kernels on the same rays, side by side.")
    r.add_argument("mesh", help="mesh file")
    r.add_argument("--rays", type=Path, metavar="FILE", help="read the rays from FILE (N rows of 6 float32)")
    r.add_argument("--count", type=parse_count, help="rays to generate (default 1M)")
    r.add_argument("--seed", type=NON_NEGATIVE, help="of the generated rays (default 0)")
    r.add_argument("--write-rays", type=Path, metavar="FILE", help="also save the generated rays as FILE")
    r.add_argument("-f", "--force", action="store_true", help="let --write-rays replace a file clrt did not write")
    r.add_argument("--device", choices=("gpu", "cpu"), default="gpu",
                   help="the first OpenCL device of this type, for both (default gpu)")
    r.add_argument("--repeat", type=POSITIVE, default=50, help="timed launches, median reported (default 50)")
    r.add_argument("--warmup", type=NON_NEGATIVE, default=2, help="untimed launches first (default 2)")
    r.add_argument("--rounds", type=POSITIVE, default=1, help="times tinybvh and clrt take turns (default 1)")
    r.add_argument("--builds", default="sah", help=f"tinybvh's builders, comma-separated: {', '.join(BUILDS)} "
                   "(default sah, its default; the first is the ratio's reference)")
    r.add_argument("--sources", type=Path, default=SOURCES, help="the fetched tinybvh folder (default: "
                   f"{SOURCES.relative_to(ROOT)})")
    r.add_argument("--driver", type=Path, help="a driver built already (default: build it into the temporary folder)")
    r.add_argument("--cxx", default=os.environ.get("CXX", "g++"), help="C++ compiler (default $CXX or g++)")
    r.add_argument("--opencl-loader", default=OPENCL_LOADER, help=f"OpenCL ICD loader to link (default {OPENCL_LOADER})")
    return p


def _main(argv) -> None:
    args = _parser().parse_args(argv)
    if args.command == "fetch":
        fetch(args.dir, args.git_dir)
        return
    if args.rays is not None and (args.count is not None or args.seed is not None or args.write_rays is not None):
        raise InputError("--rays reads a ray file; it does not go with --count, --seed or --write-rays")
    builds = tuple(args.builds.split(","))
    if not builds or not set(builds) <= set(BUILDS) or len(set(builds)) < len(builds):
        raise InputError(f"--builds: expected {' and/or '.join(BUILDS)}, comma-separated, got {args.builds!r}")
    if args.driver is not None and not args.driver.is_file():
        raise InputError(f"--driver {args.driver}: no such file")
    run(args.mesh, args.rays, args.count or 1_000_000, args.seed or 0, args.write_rays, args.force, args.device,
        args.repeat, args.warmup, args.rounds, builds, args.sources, args.driver, args.cxx, args.opencl_loader)


def main(argv=None) -> int:
    return exit_code(_main, argv)


if __name__ == "__main__":
    sys.exit(main())

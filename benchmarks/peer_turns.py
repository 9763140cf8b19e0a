"""clrt beside the CPU ray tracers, taking turns on the same arrays in one
process: ``python -m benchmarks.raysets MESH --open3d --embree-processes 2``.

The peers (issue 39's CPU table), each an optional import:

* Open3D's ``RaycastingScene`` (Embree 4 inside; ``pip install open3d-cpu``):
  ``cast_rays`` for closest hits, ``test_occlusions`` for occlusion, on one
  float32 (N, 6) tensor of the rays made once; its own thread count (0: all
  cores).  ``cast_rays`` returns distances, ids, barycentrics and normals
  (clrt's closest-hit query here returns distances and triangles), and takes no
  far distance: a finite reach (the AO set) counts its hits up to the reach;
* Embree through embreex in N processes, one a core
  (benchmarks.raysets.embree_processes_measure).

Each repetition runs clrt's query, then Open3D's, then Embree's, closest hit
and then occlusion: a slow spell of the shared machine falls on all of them.
A peer's ratio is the median over the repetitions of its time over clrt's in
the same repetition (above 1: clrt is faster); ``clrt / best`` takes the
fastest peer of each repetition.

The build row times, in the same turns, what a user waits for from arrays to
a structure ready to trace: ``clrt.Accel((vertices, faces))`` whole (checks,
build, upload, programs); Open3D's ``TriangleMesh`` from the arrays and
``RaycastingScene.add_triangles`` -- and, as Open3D builds its BVH lazily at
the first query, a first query of one ray; Embree's scene made, the mesh
added and one ray traced (embreex commits at its first query too; one
process, Embree's own threads).
"""

from __future__ import annotations

import gc
import statistics
import time

import numpy as np

from benchmarks.common import rate

QUERIES = ("closest", "any")
OPEN3D, EMBREE = "Open3D", "Embree"
ONE_RAY = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]], np.float32)   # the build's first query


def open3d_scene(vertices, faces):
    """Open3D's RaycastingScene of one mesh from float32 vertices and int32
    faces, ready to trace: Open3D builds its Embree scene at the first query,
    so one ray is cast here."""
    import open3d as o3d
    mesh = o3d.t.geometry.TriangleMesh(o3d.core.Tensor(vertices), o3d.core.Tensor(faces))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(mesh)
    scene.cast_rays(o3d.core.Tensor(ONE_RAY))
    return scene


def open3d_queries(scene, origins, directions, tmax) -> dict:
    """Open3D's two queries of one ray set, the rays made into its tensor once:
    {"closest": call, "any": call}."""
    import open3d as o3d
    rays = o3d.core.Tensor(np.ascontiguousarray(np.concatenate([origins, directions], axis=1), np.float32))
    return {"closest": lambda: scene.cast_rays(rays),
            "any": lambda: scene.test_occlusions(rays, tfar=float(min(tmax, np.finfo(np.float32).max)))}


def open3d_hits(query: str, result, tmax) -> np.ndarray:
    """Which rays hit (bool), from an Open3D query's result."""
    if query == "closest":
        t = result["t_hit"].numpy()
        return np.isfinite(t) & (t <= tmax)
    return result.numpy().astype(bool)


def clrt_hits(query: str, result) -> np.ndarray:
    """Which rays hit (bool), from a clrt query's result (device arrays)."""
    import pyopencl.array as cla
    got = result.prim if query == "closest" else result
    got = np.asarray(got.get() if isinstance(got, cla.Array) else got)
    return got >= 0 if query == "closest" else got.astype(bool)


def embree_build(vertices, faces):
    """An embreex scene of one mesh, committed by one ray."""
    from benchmarks.raysets import _embree_scene
    scene = _embree_scene(vertices, faces)
    scene.run(ONE_RAY[:, :3], ONE_RAY[:, 3:])
    return scene


def build_in_turns(mesh, accel="box", builder="auto", device=None, open3d=True, embree=False, repeat=5,
                   warmup=2) -> dict:
    """Wall ms of each build from the mesh's arrays (the module's docstring says
    what each includes), taking turns: {name: [ms per repetition]}."""
    from clrt.query import Accel
    vertices, faces = np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32)

    def clrt_build():
        made = Accel((vertices, faces), accel=accel, builder=builder, device=device)
        made.queue.finish()
        return made

    builds = {"clrt": clrt_build}
    if open3d:
        builds[OPEN3D] = lambda: open3d_scene(vertices, faces)
    if embree:
        builds[EMBREE] = lambda: embree_build(vertices, faces)
    times = {name: [] for name in builds}
    for i in range(warmup + repeat):
        for name, build in builds.items():
            gc.collect()   # the last structure's memory goes before this one is timed
            start = time.perf_counter()
            made = build()
            if i >= warmup:
                times[name].append(1e3 * (time.perf_counter() - start))
            del made
    return times


def measure_in_turns(accel, mesh, origins, directions, tmax=np.inf, open3d=True, embree_processes=0, repeat=5,
                     warmup=2) -> dict:
    """clrt (``accel``, rays and results on the device) and the peers on one ray
    set, taking turns query by query: ``times`` {name: {query: [wall ms per
    repetition]}}, ``hits`` {name: {query: rays that hit}} and ``differ``
    {name: {query: rays whose hit or miss is not clrt's}} (Open3D's, ray by ray;
    Embree's processes report counts only)."""
    from benchmarks.raysets import _queries, embree_processes_measure
    in_process = {"clrt": _queries(accel, origins, directions, tmax)}
    if open3d:
        vertices, faces = np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.int32)
        in_process[OPEN3D] = open3d_queries(open3d_scene(vertices, faces), origins, directions, tmax)
    times = {name: {q: [] for q in QUERIES} for name in in_process}
    last = {}

    def turn(query, counted):
        for name, calls in in_process.items():
            start = time.perf_counter()
            last[name, query] = calls[query]()
            if name == "clrt":
                accel.queue.finish()
            if counted:
                times[name][query].append(1e3 * (time.perf_counter() - start))

    if embree_processes:
        embree = embree_processes_measure(mesh, origins, directions, tmax, embree_processes, repeat, warmup, turn)
        embree_name = f"{EMBREE} x{embree_processes}"
        times[embree_name] = {q: [float(ms) for ms in embree["times"][:, k]] for k, q in enumerate(QUERIES)}
    else:
        for i in range(warmup + repeat):
            for query in QUERIES:
                turn(query, i >= warmup)
    masks = {(name, q): (clrt_hits(q, result) if name == "clrt" else open3d_hits(q, result, tmax))
             for (name, q), result in last.items()}
    hits = {name: {q: int(masks[name, q].sum()) for q in QUERIES} for name in in_process}
    differ = {name: {q: int((masks[name, q] != masks["clrt", q]).sum()) for q in QUERIES} for name in in_process}
    if embree_processes:
        hits[embree_name] = dict(zip(QUERIES, embree["hits"]))
    return {"count": len(origins), "times": times, "hits": hits, "differ": differ}


def paired_ratio(ours, theirs) -> float:
    """The median over the repetitions of their time over ours (above 1: ours is faster)."""
    return statistics.median(t / o for o, t in zip(ours, theirs))


def best_ratio(ours, peers) -> float:
    """paired_ratio against the fastest peer of each repetition."""
    return statistics.median(min(times) / o for o, *times in zip(ours, *peers))


def turns_header(peers) -> str:
    """The table's header, for peer names in the order of its columns."""
    names = ["clrt", *peers]
    columns = ["case", "rays"] + [f"{n} ms (Mrays/s)" for n in names] + [f"clrt / {p}" for p in peers]
    columns += ["clrt / best", "hits"]
    return "| " + " | ".join(columns) + " |\n" + "|---" * len(columns) + "|"


def turns_row(case: str, count, times: dict, hits=None, differ=None) -> str:
    """One table row: each one's median ms (Mrays/s for ``count`` rays; "-" for
    a build), the paired ratios, and the hit counts -- clrt's, and any peer's
    that is not the same (with the rays that differ, where known)."""
    names = list(times)
    ours, peers = times["clrt"], names[1:]
    cells = [case, "-" if count is None else f"{count:,}"]
    for name in names:
        ms = statistics.median(times[name])
        cells.append(f"{ms:,.1f}" if count is None else f"{ms:,.1f} ({rate(count / ms / 1e3)})")
    cells += [f"{paired_ratio(ours, times[p]):.2f}" for p in peers]
    cells.append(f"{best_ratio(ours, [times[p] for p in peers]):.2f}" if peers else "-")
    if hits is None:
        cells.append("-")
    else:
        odd = [f"{p} {hits[p]:,}" + (f" ({_rays(differ[p])} differ{'s' if differ[p] == 1 else ''})"
                                     if differ and differ.get(p) else "")
               for p in peers if hits[p] != hits["clrt"] or (differ and differ.get(p))]
        cells.append(f"{hits['clrt']:,}" + ("; " + ", ".join(odd) if odd else (", all equal" if peers else "")))
    return "| " + " | ".join(cells) + " |"


def _rays(count: int) -> str:
    return f"{count:,} ray" + ("" if count == 1 else "s")


QUERY_NAMES = {"closest": "closest", "any": "occlusion"}


def print_turns(out, accel, label: str, mesh, ray_sets, accel_options: dict, device=None, open3d=True,
                embree_processes=0, repeat=5, warmup=2) -> list[dict]:
    """The table: the build, then each ray set's two queries, clrt (``accel``,
    made with ``accel_options``, described by ``label``) beside the peers."""
    peers = ([OPEN3D] if open3d else []) + ([f"{EMBREE} x{embree_processes}"] if embree_processes else [])
    print(f"\nclrt ({label}) beside {', '.join(peers)}, taking turns (median of {repeat} after {warmup}; wall ms; "
          "clrt / peer: the median of the peer's time over clrt's in each turn; build: Embree in one process, "
          "Open3D's and Embree's with a first query of one ray):\n", file=out)
    print(turns_header(peers), file=out)
    builds = build_in_turns(mesh, **accel_options, device=device, open3d=open3d, embree=bool(embree_processes),
                            repeat=repeat, warmup=warmup)
    builds = {(f"{EMBREE} x{embree_processes}" if name == EMBREE else name): t for name, t in builds.items()}
    print(turns_row("build from arrays", None, builds), file=out, flush=True)
    rows = [{"rays": "build", "times": builds}]
    for name, o, d, reach in ray_sets:
        m = measure_in_turns(accel, mesh, o, d, reach, open3d, embree_processes, repeat, warmup)
        for query in QUERIES:
            times = {who: t[query] for who, t in m["times"].items()}
            hits = {who: h[query] for who, h in m["hits"].items()}
            differ = {who: d_[query] for who, d_ in m["differ"].items()}
            print(turns_row(f"{name}, {QUERY_NAMES[query]}", m["count"], times, hits, differ), file=out, flush=True)
        rows.append({"rays": name, **m})
    return rows

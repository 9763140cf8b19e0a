"""Inside queries: ``python -m benchmarks.inside [MESH] [--points N]``.

Two measurements on one mesh (default: bunny00 from the shared scans, else
clrt's torus knot):

1. The far fields of the winding numbers' BVH (clrt/query/inside.py): made
   on the device (trace.cl's winding_nodes, one launch a tree level) against
   the same sums made on the host in numpy, level by level as well (here, for
   the comparison only), then uploaded.  Both from the same tree; the host
   time counts neither the tree's build nor the upload.
2. Points uniform in the mesh's box grown by 10 % on every side (a fixed
   seed): wall-clock ms and Mpoints/s of ``winding_number``, ``contains`` and
   ``signed_distance`` by each sign rule, numpy in and out, medians of
   ``--repeat`` calls after one warm-up (which makes the far fields and the
   pseudo-normals), with the share of points inside.

With ``--placed``, instead: the mesh placed once as an instance (a
two-level scene: docs/instances.md, "Point queries") by maps from a rotation
to an uneven scale of condition number 40 (summed exactly), beside the
one-level Accel of the same placed triangles (flattened) -- its wide BVH
where the device walks one (CPU devices), and its binary rows, which a GPU
walks and a two-level scene walks everywhere --, on the same points:
``winding_number``'s median ms of each, and the largest error of each
against the exact sum over the placed triangles (the two-level brute force,
float64) on the first ``--exact`` points.

Speed is not yet a goal of these queries (issue 36's GPU step is); this
records where they stand.
"""

from __future__ import annotations

import sys

if not __package__:   # run as a script, python benchmarks/NAME.py: import from the repository, not this folder
    import os.path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import argparse
import itertools

import numpy as np

from benchmarks.common import POSITIVE, SHARED_MESHES, exit_code, median_wall_ms, parse_count


def host_winding_nodes(rows: np.ndarray, corners: np.ndarray) -> dict:
    """The WindingNodes' values of ``rows`` over slot-ordered ``corners`` (F, 3, 3),
    float64, in numpy: centre, radius, dipole, area, first and second moments
    per child (2 * rows), leaves from their triangles, inner children from
    their row's two, the deepest level first (as trace.cl's winding_nodes);
    the moments made whole, then their symmetric parts taken (what a
    WindingNode keeps; here as full 3 x 3 and 3 x 3 x 3 arrays)."""
    from clrt.accel.rows import child_refs, tree_levels
    refs = child_refs(rows).astype(np.int64)
    c = corners.astype(np.float64)
    va = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]) / 2
    area = np.linalg.norm(va, axis=1)
    centroid = c.mean(axis=1)
    n = 2 * len(rows)
    out = {"centre": np.zeros((n, 3)), "radius": np.zeros(n), "dipole": np.zeros((n, 3)), "area": np.zeros(n),
           "first": np.zeros((n, 3, 3)), "second": np.zeros((n, 3, 3, 3))}
    child = np.stack([refs[:, 0], refs[:, 2]], 1).reshape(-1)
    count = np.stack([refs[:, 1], refs[:, 3]], 1).reshape(-1)
    leaf = np.nonzero(count > 0)[0]
    leaf = leaf[np.argsort(child[leaf])]            # leaves in slot order: they cover the slots in turn
    starts = child[leaf]
    a = np.add.reduceat(area, starts)
    weighted = np.add.reduceat(area[:, None] * centroid, starts)
    mean = np.add.reduceat(centroid, starts) / count[leaf][:, None]
    centre = np.where(a[:, None] > 0, weighted / np.maximum(a, 1e-300)[:, None], mean)
    d = c - np.repeat(centre, count[leaf], axis=0)[:, None]
    s = d.sum(axis=1)
    out["centre"][leaf], out["area"][leaf] = centre, a
    out["radius"][leaf] = np.maximum.reduceat(np.linalg.norm(d, axis=2).max(axis=1), starts)
    out["dipole"][leaf] = np.add.reduceat(va, starts)
    out["first"][leaf] = np.add.reduceat(np.einsum("fi,fj->fij", va, s / 3), starts)
    second = np.einsum("fcj,fck->fjk", d, d) + np.einsum("fj,fk->fjk", s, s)
    out["second"][leaf] = np.add.reduceat(np.einsum("fi,fjk->fijk", va / 12, second), starts)
    for level in reversed(tree_levels(rows)):
        for side in (0, 1):
            at = 2 * level + side
            inner = at[count[at] == 0]
            if not len(inner):
                continue
            kids = (2 * child[inner], 2 * child[inner] + 1)
            total = out["area"][kids[0]] + out["area"][kids[1]]
            joint = (out["area"][kids[0], None] * out["centre"][kids[0]]
                     + out["area"][kids[1], None] * out["centre"][kids[1]]) / np.maximum(total, 1e-300)[:, None]
            out["centre"][inner], out["area"][inner] = joint, total
            for k in kids:
                e = out["centre"][k] - joint
                out["radius"][inner] = np.maximum(out["radius"][inner], np.linalg.norm(e, axis=1) + out["radius"][k])
                out["dipole"][inner] += out["dipole"][k]
                m = out["first"][k]
                out["first"][inner] += m + np.einsum("ni,nj->nij", out["dipole"][k], e)
                out["second"][inner] += (out["second"][k] + np.einsum("nij,nk->nijk", m, e)
                                         + np.einsum("nik,nj->nijk", m, e)
                                         + np.einsum("ni,nj,nk->nijk", out["dipole"][k], e, e))
    out["first"] = (out["first"] + out["first"].transpose(0, 2, 1)) / 2
    t = out["second"]
    out["second"] = sum(t.transpose(0, *axes) for axes in itertools.permutations((1, 2, 3))) / 6
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.inside", description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", nargs="?", help="mesh file (default: bunny00.off of the shared scans)")
    parser.add_argument("--points", type=parse_count, default=200_000, help="query points (default 200K)")
    parser.add_argument("--repeat", type=POSITIVE, default=3, help="timed calls a query (default 3)")
    parser.add_argument("--device", default=None, help="OpenCL device (default: clrt's choice)")
    parser.add_argument("--placed", action="store_true", help="the mesh as an instance under several maps, "
                        "beside its flattened copy")
    parser.add_argument("--exact", type=parse_count, default=2000, help="--placed: points whose error is "
                        "measured (default 2K)")
    args = parser.parse_args(argv)
    return exit_code(placed if args.placed else run, args)


def run(args) -> None:
    import clrt
    from clrt.scene import primitives
    from clrt.scene.arrays import triangle_corners
    path = args.mesh or (SHARED_MESHES / "bunny00.off")
    mesh = clrt.load_mesh(path) if args.mesh or path.exists() else primitives.torus_knot()
    accel = clrt.Accel(mesh, device=args.device)
    print(f"{getattr(mesh, 'name', path)}: {len(mesh.faces):,} triangles, {accel}")
    accel.winding_number(mesh.vertices[:1])           # compiles the kernels
    rows = accel.acceleration.rows
    corners = triangle_corners(mesh, accel.geometry.origin)[accel.acceleration.prim_ids]
    device_ms, _ = median_wall_ms(lambda: (accel.__dict__.pop("_winding_cache", None),
                                           accel._winding_nodes()), args.repeat)
    host_ms, _ = median_wall_ms(lambda: host_winding_nodes(rows, corners), args.repeat)
    print(f"far fields of {len(rows):,} rows: device {device_ms:.1f} ms, numpy on the host {host_ms:.1f} ms "
          "(without the upload)")
    rng = np.random.default_rng(0)
    lo, hi = mesh.bounds
    grow = 0.1 * (hi - lo)
    points = (lo - grow + rng.random((args.points, 3)) * (hi - lo + 2 * grow)).astype(np.float32)
    queries = {"winding_number": accel.winding_number, "contains": accel.contains,
               **{f"signed_distance {rule}": (lambda p, rule=rule: accel.signed_distance(p, sign=rule))
                  for rule in ("winding", "parity", "normal")},
               "distance": accel.distance}
    print(f"\n{args.points:,} points uniform in the box grown by 10 %\n")
    print("| query | ms | Mpoints/s | inside |\n|---|---|---|---|")
    for name, query in queries.items():
        ms, result = median_wall_ms(lambda: query(points), args.repeat)
        share = (result.astype(bool) if name == "contains" else result >= 0.5 if name == "winding_number"
                 else result < 0)
        print(f"| {name} | {ms:.1f} | {args.points / ms / 1e3:.2f} | {100 * share.mean():.2f} % |")


def _placements() -> dict:
    """name -> 3x3 linear map: a rotation, a mirror, then uneven scales (their
    condition numbers 2, 4, 7, 30 and 40) between two rotations."""
    def turn(axis, angle):
        a = np.asarray(axis, float) / np.linalg.norm(axis)
        k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    uneven = {f"scale {int(round(max(d) / min(d)))}:1": turn((1, 2, 3), 1.1) @ np.diag(d) @ turn((3, -1, 2), 0.4)
              for d in ([1.0, 2.0, 1.0], [1.0, 4.0, 1.5], [0.5, 1.0, 3.5], [0.3, 1.0, 9.0], [0.1, 1.0, 4.0])}
    return {"rotation": turn((1, 2, 3), 1.1), "mirror": np.diag([-1.0, 1.0, 1.0]) @ turn((0, 1, 1), 0.5), **uneven}


def placed(args) -> None:
    import clrt
    from clrt.device import geometry
    from clrt.scene import primitives
    path = args.mesh or (SHARED_MESHES / "bunny00.off")
    mesh = clrt.load_mesh(path) if args.mesh or path.exists() else primitives.torus_knot()
    print(f"{getattr(mesh, 'name', path)}: {len(mesh.faces):,} triangles; {args.points:,} points uniform in the "
          f"placed mesh's box grown by 10 %, errors on the first {min(args.exact, args.points):,}\n")
    print("| placement | condition | two-level ms | flattened ms | flattened, binary rows ms | two-level error "
          "| flattened error |")
    print("|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    for name, linear in _placements().items():
        transform = np.eye(4)
        transform[:3, :3] = linear
        instances = clrt.Instances([mesh], [0], transform[None])
        two = clrt.Accel(instances, device=args.device)
        flat = clrt.Accel(instances.flattened(), device=args.device)
        kinds, geometry.WIDE_BVH_KINDS = geometry.WIDE_BVH_KINDS, ()   # (as the tests compare the walks)
        try:
            rows = clrt.Accel(instances.flattened(), device=args.device)
        finally:
            geometry.WIDE_BVH_KINDS = kinds
        lo, hi = instances.bounds
        grow = 0.1 * (hi - lo)
        points = (lo - grow + rng.random((args.points, 3)) * (hi - lo + 2 * grow)).astype(np.float32)
        two_ms, w_two = median_wall_ms(lambda: two.winding_number(points), args.repeat)
        flat_ms, w_flat = median_wall_ms(lambda: flat.winding_number(points), args.repeat)
        rows_ms, _ = median_wall_ms(lambda: rows.winding_number(points), args.repeat)
        some = points[:args.exact]
        exact = clrt.Accel(instances, accel="none", device=args.device).winding_number(some)
        singular = np.linalg.svd(linear, compute_uv=False)
        print(f"| {name} | {singular[0] / singular[2]:.1f} | {two_ms:.1f} | {flat_ms:.1f} | {rows_ms:.1f} | "
              f"{np.abs(w_two[:len(some)] - exact).max():.1e} | {np.abs(w_flat[:len(some)] - exact).max():.1e} |")


if __name__ == "__main__":
    sys.exit(main())

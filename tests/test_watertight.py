"""Watertight hits: on closed meshes, rays aimed exactly at vertices and at points on
edges, from outside, never pass through -- for every acceleration structure.

After pbrt-v4's ``Triangle.Watertight`` test.  A ray crossing the surface at a
vertex or on an edge meets the triangles around that point at (nearly) the same
distance; a test that is not watertight can miss all of them and let the ray
through to whatever lies behind.  So that a miss is a bug and never a graze,
only rays that cross the surface transversally are used: every triangle around
the point (its star) faces the ray the same way, with ``|cos| > 0.1``.  Such a
ray, coming from outside the bounding box, must hit something at a distance no
larger than that of the point (it enters there, or entered before).

Three kinds of rays, thousands per mesh:

* axis-parallel rays through vertices: the ray's other two coordinates are the
  vertex's own float32 values, so it passes *exactly* through the vertex;
* axis-parallel rays through points of edges (midpoints and random points);
* rays from random far points towards vertices and edge points.
"""

import numpy as np
import pytest

import clrt
from clrt.config import BUILDERS, VOLUMES
from clrt.scene import primitives

from conftest import SHARED_MESHES

CONFIGS = [("none", "sah")] + [(v, b) for v in VOLUMES for b in BUILDERS]   # every traversal, every builder
MIN_COS = 0.1


def _closed_meshes() -> dict:
    meshes = {
        "icosphere": lambda: primitives.icosphere(3),
        "torus": lambda: primitives.torus(1.0, 0.35, 48, 24),
        "box": lambda: primitives.box((1.0, 0.6, 1.4)),
    }
    for name in ("cow.off", "camel.off"):
        if (SHARED_MESHES / name).is_file():
            meshes[name] = lambda name=name: clrt.load_mesh(SHARED_MESHES / name)
    return meshes


MESHES = _closed_meshes()


def _edges(faces: np.ndarray):
    """(E, 2) vertex pairs of the edges with exactly two triangles, and (E, 2) those triangles."""
    pairs = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(faces)), 3)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    pairs, owner = pairs[order], owner[order]
    key = pairs[:, 0].astype(np.int64) * (faces.max() + 1) + pairs[:, 1]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    count = np.diff(np.r_[start, len(key)])
    two = start[count == 2]
    return pairs[two], np.stack([owner[two], owner[two + 1]], axis=1)


def _stars(faces: np.ndarray, num_vertices: int) -> np.ndarray:
    """(V, K) triangles around each vertex, padded with -1."""
    corner_vertex = faces.reshape(-1)
    corner_face = np.repeat(np.arange(len(faces)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    degree = np.bincount(corner_vertex, minlength=num_vertices)
    star = np.full((num_vertices, degree.max()), -1, np.int64)
    slot = np.arange(len(order)) - np.repeat(np.cumsum(degree) - degree, degree)
    star[corner_vertex[order], slot] = corner_face[order]
    return star


def _crossing(normals: np.ndarray, star: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N,) bool: does direction d[i] meet every triangle of star[i] (padded -1) from the
    same side with |cos| > MIN_COS?"""
    cos = np.einsum("nkj,nj->nk", normals[np.maximum(star, 0)], d)
    valid = star >= 0
    lo = np.where(valid, cos, np.inf).min(axis=1)
    hi = np.where(valid, cos, -np.inf).max(axis=1)
    return (lo > MIN_COS) | (hi < -MIN_COS)


def watertight_rays(mesh, rng, general=3000, per_kind=1500):
    """(origins (N, 3) float32, directions (N, 3), distance to the aimed point (N,), kind (N,))."""
    v = mesh.vertices.astype(np.float64)
    normals = mesh.face_normals()
    lo, hi = v.min(axis=0), v.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    star = _stars(mesh.faces, len(v))
    edges, edge_faces = _edges(mesh.faces)
    edge_star = np.concatenate([edge_faces, np.full((len(edges), star.shape[1] - 2), -1)], axis=1) \
        if star.shape[1] > 2 else edge_faces
    lam = np.concatenate([np.full(len(edges), 0.5), rng.uniform(0.05, 0.95, len(edges))])
    edge_points = v[edges[:, 0]][np.r_[0:len(edges), 0:len(edges)]] * (1 - lam[:, None]) \
        + v[edges[:, 1]][np.r_[0:len(edges), 0:len(edges)]] * lam[:, None]
    edge_points = edge_points.astype(np.float32).astype(np.float64)   # exactly what the ray gets
    edge_star = np.concatenate([edge_star, edge_star])

    origins, dirs, dist, kinds = [], [], [], []
    # Axis-parallel rays, from both sides, through vertices and edge points.
    for kind, points, stars in (("vertex, axis", v, star), ("edge, axis", edge_points, edge_star)):
        for k in range(3):
            for s in (1.0, -1.0):
                d = np.zeros((len(points), 3))
                d[:, k] = -s
                ok = _crossing(normals, stars, d)
                o = points[ok].copy()
                o[:, k] = hi[k] + 0.3 * diag if s > 0 else lo[k] - 0.3 * diag
                origins.append(o)
                dirs.append(d[ok])
                dist.append(np.abs(o[:, k] - points[ok][:, k]))
                kinds += [kind] * int(ok.sum())
    # Rays from far points: around each target's mean normal, from either side.
    pick_v = rng.integers(0, len(v), general // 2)
    pick_e = rng.integers(0, len(edge_points), general - general // 2)
    targets = np.concatenate([v[pick_v], edge_points[pick_e]])
    stars = np.concatenate([star[pick_v], edge_star[pick_e]])
    mean = np.where((stars >= 0)[..., None], normals[np.maximum(stars, 0)], 0).sum(axis=1)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-12)
    jitter = rng.normal(size=targets.shape)
    jitter /= np.linalg.norm(jitter, axis=1, keepdims=True)
    d = -(mean * rng.choice([-1.0, 1.0], (len(targets), 1)) + 0.7 * jitter)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ok = _crossing(normals, stars, d)
    o = (targets[ok] - 2 * diag * d[ok]).astype(np.float32).astype(np.float64)
    origins.append(o)
    dirs.append(targets[ok] - o)
    dist.append(np.linalg.norm(targets[ok] - o, axis=1))
    kinds += ["vertex, far"] * int(ok[:len(pick_v)].sum()) + ["edge, far"] * int(ok[len(pick_v):].sum())
    o, d, dist, kinds = (np.concatenate(origins).astype(np.float32), np.concatenate(dirs),
                         np.concatenate(dist), np.array(kinds))
    # At most per_kind rays of each kind, so that brute force stays quick on large meshes.
    keep = np.concatenate([rng.permutation(np.flatnonzero(kinds == k))[:per_kind] for k in np.unique(kinds)])
    keep.sort()
    return o[keep], d[keep], dist[keep], kinds[keep]


@pytest.mark.parametrize("name", sorted(MESHES))
def test_rays_at_vertices_and_edges_never_pass_through(name, device):
    mesh = MESHES[name]()
    o, d, dist, kinds = watertight_rays(mesh, np.random.default_rng(11))
    assert len(o) >= 2000, f"only {len(o)} rays"
    for kind in ("vertex, far", "edge, far"):
        assert (kinds == kind).sum() >= 500, kind
    if name != "box":   # a box's corners and edges are never crossed along an axis
        assert (kinds == "vertex, axis").sum() >= 100 and (kinds == "edge, axis").sum() >= 500
    limit = (dist * (1 + 1e-5) + 1e-6 * np.abs(o).max()).astype(np.float32)
    for accel, builder in CONFIGS:
        a = clrt.Accel(mesh, accel=accel, builder=builder, device=device)
        hits = a.trace(o, d)
        through = ~(hits.t <= limit)
        label = f"{name}, accel {accel}/{builder}"
        assert not through.any(), (f"{label}: {through.sum()} of {len(o)} rays passed through, "
                                   f"kinds {sorted(set(kinds[through]))}, first at ray {np.argmax(through)}")
        blocked = a.occluded(o, d, tmax=limit)
        assert blocked.all(), f"{label}: occluded() missed {(~blocked).sum()} rays"

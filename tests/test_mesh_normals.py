"""Mesh.vertex_normals and Mesh.split_at_creases against plain versions of the
same computations (np.add.at sums; union-find that hooks corners, not roots,
until nothing changes): the same bits, so renders stay pixel-exact.  The
pairing rule is the documented one: an edge's half-edges in index order (a
stable sort), the cosine summed x, y, then z."""

import math
from pathlib import Path

import numpy as np
import pytest

from clrt.scene.load import load_mesh
from clrt.scene.mesh import Mesh

SHARED_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"
ASSETS = Path(__file__).resolve().parents[1] / "assets" / "meshes"


def plain_area_normals(mesh):
    tri = mesh.vertices[mesh.faces].astype(np.float64)
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def plain_vertex_normals(mesh):
    area_n = plain_area_normals(mesh)
    acc = np.zeros((len(mesh.vertices), 3))
    for corner in range(3):
        np.add.at(acc, mesh.faces[:, corner], area_n)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return np.divide(acc, length, out=np.zeros_like(acc), where=length > 0).astype(np.float32)


def plain_split(mesh, crease):
    """Mesh.split_at_creases as first written: the same joins, then label propagation
    that hooks corners (not roots) until a whole pass changes nothing."""
    faces = mesh.faces
    n_faces = len(faces)
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    _, weld = np.unique(v.view(np.dtype((np.void, 12))).reshape(-1), return_inverse=True)
    welded = weld.reshape(-1)[faces].astype(np.int64)
    area_n = plain_area_normals(mesh)
    length = np.linalg.norm(area_n, axis=1, keepdims=True)
    normals = np.divide(area_n, length, out=np.zeros_like(area_n), where=length > 0)
    a, b = welded.reshape(-1), np.roll(welded, -1, axis=1).reshape(-1)
    key = np.minimum(a, b) * (int(weld.max()) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")   # an edge's half-edges in index order (the documented rule)
    sorted_key = key[order]
    same = np.flatnonzero(sorted_key[1:] == sorted_key[:-1])
    h1, h2 = order[same], order[same + 1]
    f1, f2 = h1 // 3, h2 // 3
    cos_limit = math.cos(math.radians(float(crease))) - 1e-6
    n1, n2 = normals[f1], normals[f2]
    smooth = (f1 != f2) & ((n1[:, 0] * n2[:, 0] + n1[:, 1] * n2[:, 1]) + n1[:, 2] * n2[:, 2] >= cos_limit)
    h1, h2, f1, f2 = h1[smooth], h2[smooth], f1[smooth], f2[smooth]
    n1 = 3 * f1 + (h1 + 1) % 3
    n2 = 3 * f2 + (h2 + 1) % 3
    straight = a[h1] == a[h2]
    left = np.concatenate([h1, n1])
    right = np.concatenate([np.where(straight, h2, n2), np.where(straight, n2, h2)])
    label = np.arange(3 * n_faces)
    while len(left):
        low = np.minimum(label[left], label[right])
        before = label.copy()
        np.minimum.at(label, left, low)
        np.minimum.at(label, right, low)
        while not np.array_equal(label[label], label):
            label = label[label]
        if np.array_equal(label, before):
            break
    is_root = label == np.arange(3 * n_faces)
    corner_vertex = (np.cumsum(is_root) - 1)[label]
    return mesh.vertices[faces.reshape(-1)[is_root]], corner_vertex.reshape(n_faces, 3).astype(np.int32)


def same_bits(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def meshes():
    paths = sorted(SHARED_MESHES.glob("*.off")) + sorted(ASSETS.glob("*.obj"))
    yield from ((p.name, lambda p=p: load_mesh(p)) for p in paths)
    rng = np.random.default_rng(11)
    for case in range(40):
        n_vertices, n_faces = int(rng.integers(3, 30)), int(rng.integers(1, 60))
        vertices = rng.choice(np.array([0.0, -0.0, 1.0, -1.0, 0.5], np.float32), size=(n_vertices, 3))
        faces = rng.integers(0, n_vertices, size=(n_faces, 3))
        if case % 2:   # a soup: a vertex per corner, positions repeated (STL-like), non-manifold edges
            vertices, faces = vertices[faces.reshape(-1)], np.arange(3 * n_faces).reshape(n_faces, 3)
        yield f"random {case}", lambda v=vertices, f=faces: Mesh.from_arrays(v, f)


@pytest.mark.parametrize("name, make", list(meshes()), ids=[name for name, _ in meshes()])
def test_same_bits_as_the_plain_computations(name, make):
    mesh = make()
    assert same_bits(mesh.vertex_normals(), plain_vertex_normals(mesh))
    normals = plain_area_normals(mesh)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    assert same_bits(mesh.face_normals(), np.divide(normals, length, out=np.zeros_like(normals),
                                                    where=length > 0))
    for crease in (0.0, 45.0, 180.0):
        split = mesh.split_at_creases(crease)
        vertices, faces = plain_split(mesh, crease)
        assert same_bits(split.vertices, vertices) and same_bits(split.faces, faces)
        assert same_bits(split.vertex_normals(), plain_vertex_normals(split))

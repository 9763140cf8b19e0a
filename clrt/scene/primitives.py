"""Meshes made by our own code: the built-in scene and the test assets need no files."""

from __future__ import annotations

import numpy as np

from clrt.scene.mesh import Mesh


def icosphere(subdivisions: int = 2, radius: float = 1.0, center=(0.0, 0.0, 0.0), name="icosphere") -> Mesh:
    """Geodesic sphere: an icosahedron whose faces are split in four ``subdivisions`` times
    (20 * 4**subdivisions triangles), every new vertex pushed onto the sphere."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
                  [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                  [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                  [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                  [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    for _ in range(subdivisions):
        # Midpoint of every edge, shared between the two faces that use it.
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inverse.reshape(3, -1).T          # (F, 3): midpoints of edges 01, 12, 20
        v = np.concatenate([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
        a, b, c = f.T
        ab, bc, ca = mid.T
        f = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1),
                            np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
    v = v / np.linalg.norm(v, axis=1, keepdims=True) * radius + np.asarray(center, dtype=np.float64)
    return Mesh.from_arrays(v, f, name)


def box(size=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0), name="box") -> Mesh:
    """Axis-aligned box, 12 triangles wound outwards."""
    h = 0.5 * np.asarray(size, dtype=np.float64)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return Mesh.from_arrays(corners * h + np.asarray(center, dtype=np.float64), f, name)


def checkerboard(tiles: int = 8, size: float = 8.0, height: float = 0.0) -> tuple[Mesh, Mesh]:
    """A square floor in the y = ``height`` plane, centred on the origin, as two
    meshes: the even tiles and the odd tiles (two triangles per tile, facing +y)."""
    edge = np.linspace(-size / 2, size / 2, tiles + 1)
    i, k = np.meshgrid(np.arange(tiles), np.arange(tiles), indexing="ij")
    i, k = i.ravel(), k.ravel()
    x0, x1, z0, z1 = edge[i], edge[i + 1], edge[k], edge[k + 1]
    y = np.full_like(x0, height)
    quad = np.stack([np.stack([x0, y, z0], 1), np.stack([x0, y, z1], 1),
                     np.stack([x1, y, z1], 1), np.stack([x1, y, z0], 1)], 1)   # (T, 4, 3)
    halves = []
    for parity in (0, 1):
        q = quad[(i + k) % 2 == parity]
        base = 4 * np.arange(len(q))[:, None]
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
        halves.append(Mesh.from_arrays(q.reshape(-1, 3), faces, f"floor{parity}"))
    return halves[0], halves[1]


def torus(major: float = 1.0, minor: float = 0.35, n_major: int = 32, n_minor: int = 16,
          name="torus") -> Mesh:
    """Torus around the y axis, 2 * n_major * n_minor triangles."""
    a, b = np.meshgrid(np.linspace(0, 2 * np.pi, n_major, endpoint=False),
                       np.linspace(0, 2 * np.pi, n_minor, endpoint=False), indexing="ij")
    ring = major + minor * np.cos(b)
    v = np.stack([ring * np.cos(a), minor * np.sin(b), ring * np.sin(a)], -1).reshape(-1, 3)
    return Mesh.from_arrays(v, grid_faces(n_major, n_minor, wrap=True)[:, ::-1], name)   # outward


def heightfield(n: int = 24, size: float = 2.0, seed: int = 0, name="heightfield") -> Mesh:
    """An open, bumpy sheet (not watertight): a grid of n x n quads over the xz plane."""
    rng = np.random.default_rng(seed)
    x, z = np.meshgrid(np.linspace(-size / 2, size / 2, n + 1), np.linspace(-size / 2, size / 2, n + 1),
                       indexing="ij")
    y = 0.15 * size * (np.sin(3 * x) * np.cos(2 * z)) + 0.02 * size * rng.standard_normal(x.shape)
    v = np.stack([x, y, z], -1).reshape(-1, 3)
    return Mesh.from_arrays(v, grid_faces(n + 1, n + 1, wrap=False), name)


def grid_faces(rows: int, cols: int, wrap: bool) -> np.ndarray:
    """Two triangles per cell of a rows x cols vertex grid (wrapping in both directions or not)."""
    r_end, c_end = (rows, cols) if wrap else (rows - 1, cols - 1)
    i, j = np.meshgrid(np.arange(r_end), np.arange(c_end), indexing="ij")
    i, j = i.ravel(), j.ravel()
    a = i * cols + j
    b = ((i + 1) % rows) * cols + j
    c = ((i + 1) % rows) * cols + (j + 1) % cols
    d = i * cols + (j + 1) % cols
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def torus_knot(p: int = 2, q: int = 3, radius: float = 1.0, tube: float = 0.12, segments: int = 256,
               sides: int = 24, name="torus knot") -> Mesh:
    """A tube of radius ``tube`` around the (p, q) torus knot, scaled to fit in
    ``radius``; 2 * segments * sides triangles.  The tube's frame is the curve's
    Frenet frame, which is well defined since a torus knot never straightens."""
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)

    def curve(t):
        r = 2 + np.cos(q * t)
        return np.stack([r * np.cos(p * t), -np.sin(q * t), r * np.sin(p * t)], -1) / 3.0 * radius

    h = 1e-4
    c, c_next, c_prev = curve(t), curve(t + h), curve(t - h)
    tangent = c_next - c_prev
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = c_next - 2 * c + c_prev
    normal -= np.sum(normal * tangent, axis=1, keepdims=True) * tangent
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    a = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(a)[None, :, None] * normal[:, None] + np.sin(a)[None, :, None] * binormal[:, None]
    v = (c[:, None] + tube * ring).reshape(-1, 3)
    return Mesh.from_arrays(v, grid_faces(segments, sides, wrap=True)[:, ::-1], name)

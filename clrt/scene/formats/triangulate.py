"""Polygons to triangles, in place: a fan where the fan is right, ear clipping
where it is not (OBJ, OFF and PLY faces).

A fan from the first corner is right when that corner sees every edge (every
convex polygon, and some concave ones); otherwise it folds over and covers the
outside (an L-shaped hexagon's fan from its wrong corner covers area 4 for 3).
Whether a fan folds is decided per polygon size at once (numpy over every
polygon of n corners): one of its triangles faces against the polygon's Newell
normal.  Only those polygons are ear clipped, in the plane of that normal, so
a mesh whose fans are right is triangulated exactly as before, and a mesh of
triangles never gets here.

Ear clipping (Meisters' two-ears theorem: a simple polygon of more than three
corners has two ears to cut off): a cursor starts at the first corner; the
next corner from it that turns left and whose triangle with its two neighbours
holds no remaining corner that does not (on its edges included) is cut off,
and the search goes on from the corner after it.  Small polygons are clipped in
numpy, one step for all the polygons of a size at once; large ones one by one,
each candidate tested against the corners that do not turn left; both give
the same triangles.  A polygon with no ear left (self-intersecting, or
degenerate) loses its next left-turning corner, or the cursor's, so that it
still gives n - 2 triangles.
"""

from __future__ import annotations

import numpy as np

# A fan triangle facing against the polygon's normal by less than this (the
# cosine of the angle between them) counts as flat: rounding, and corners on a
# straight edge, do not make a convex polygon's fan fold.
_FLAT = 1e-9
# Polygons of more corners than this are ear clipped one by one: the numpy step
# for all the polygons of a size at once costs n^3 per polygon, about 40 ns n^3
# (1.3 ms at n = 32, where one by one costs as much).  The numpy steps take at
# most _CHUNK corner pairs at a time.
_ONE_BY_ONE = 32
_CHUNK = 1 << 21
# Fans are checked this many corners at a time: the dozens of temporary arrays
# stay small and are reused (over a whole file of a million quads at once, the
# fresh memory they took cost a second).
_FOLD_CHUNK = 1 << 14
# Ear clipping is quadratic, so a file's ear clipping stops after about a
# second's work (of _clip_cost): the polygons past that keep their fans, and a
# hostile file (a million-corner polygon, millions of concave ones) loads in
# the time its size says, as with fans.  Sizes go smallest first.
_BUDGET_NS = 10 ** 9


def _clip_cost(n: int) -> int:
    """Rough nanoseconds to ear clip one polygon of n corners (measured on
    PoCL's 2-core CI machine: 6 us at n = 4, 1.2 ms at 32, 0.6 s at 4,000)."""
    return 40 * n ** 3 if n <= _ONE_BY_ONE else 40_000 * n + 30 * n * n


def triangulate(counts: np.ndarray, flat: np.ndarray, vertices: np.ndarray,
                names: np.ndarray | None = None) -> np.ndarray:
    """Triangulate polygons in place, keeping polygon order.

    counts: (P,) int64 corners per polygon, all >= 3.
    flat: (sum(counts),) int64 vertex indices of all polygons' corners, concatenated.
    vertices: (V, 3) float64 positions ``flat`` indexes (indices out of range are
    left for the mesh checks to report; such a polygon keeps its fan).
    names: (sum(counts),) int64 what the triangles hold for each corner; ``flat``
    when not given (OBJ passes the corners' numbers, to triangulate its
    per-corner texture coordinates and normals alike).
    Returns (sum(counts - 2), 3) int64 names: polygon ``p`` becomes ``counts[p]
    - 2`` consecutive triangles, wound as the polygon, of its own corners -- for
    a convex polygon ``c0..ck`` the fan ``(c0, c1, c2), (c0, c2, c3), ...``.
    """
    if names is None:
        names = flat
    if (counts == 3).all():
        return names.reshape(-1, 3)
    starts = np.cumsum(counts) - counts
    tris = counts - 2
    first = np.repeat(starts, tris)
    # Index of each triangle within its own polygon: 0, 1, ..., tris[p] - 1.
    local = np.arange(int(tris.sum())) - np.repeat(np.cumsum(tris) - tris, tris)
    triangles = np.stack([names[first], names[first + local + 1], names[first + local + 2]], axis=1)
    triangle_starts = np.cumsum(tris) - tris
    vertices = np.asarray(vertices, dtype=np.float64)
    budget = _BUDGET_NS
    in_range = flat.min() >= 0 and flat.max() < len(vertices)
    larger = counts[counts > 3]
    columns = np.ascontiguousarray(vertices.T)   # x, y and z each contiguous, for np.take
    for n in [int(larger[0])] if (larger == larger[0]).all() else np.unique(larger).tolist():
        every = np.flatnonzero(counts == n)
        step = max(1, _FOLD_CHUNK // n)
        for polygons in (every[i:i + step] for i in range(0, len(every), step)):
            # Corner k of the polygons in row k: numpy runs over contiguous rows.
            at = starts[polygons] + np.arange(n)[:, None]                        # (n, Pn) places in flat
            corners = flat[at]
            if not in_range:
                valid = ((corners >= 0) & (corners < len(vertices))).all(axis=0)
                polygons, at, corners = polygons[valid], at[:, valid], corners[:, valid]
            with np.errstate(all="ignore"):   # NaN or infinite positions: reported by the mesh checks
                folds = _fan_folds(*(np.take(column, corners) for column in columns))
                clip = np.flatnonzero(folds)[:budget // _clip_cost(n)]
                if len(clip):
                    budget -= len(clip) * _clip_cost(n)
                    ears = _ear_clip(vertices[corners[:, clip].T])                # (Pc, n - 2, 3) corner numbers
                    rows = polygons[clip]
                    triangles[triangle_starts[rows, None] + np.arange(n - 2)] = np.take_along_axis(
                        names[at[:, clip].T][:, None, :], ears, axis=2)
    return triangles


def _newell_normals(points: np.ndarray) -> np.ndarray:
    """(P, 3) Newell normals (twice the vector area) of (P, n, 3) polygons."""
    centred = points - points[:, :1]
    return np.cross(centred, np.roll(centred, -1, axis=1)).sum(axis=1)


def _fan_folds(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(P,) whether the fan of each polygon of n corners (``x``, ``y``, ``z``:
    (n, P) its corners' coordinates, corner k in row k) folds over: one of its
    triangles faces against the polygon's Newell normal, which is the sum of the
    fan triangles' own normals.  A fan none of whose triangles fold covers the
    polygon exactly (its triangles lie in turn around the first corner and are
    bounded by the polygon's edges): every convex polygon's, and a concave
    one's whose first corner sees all the others.  Written out per coordinate
    on contiguous rows: over a million quads this is several times faster than
    np.cross on (P, n, 3) arrays."""
    dx, dy, dz = (c[1:] - c[0] for c in (x, y, z))        # from the first corner to the others
    ax, ay, az, bx, by, bz = dx[:-1], dy[:-1], dz[:-1], dx[1:], dy[1:], dz[1:]
    fx, fy, fz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx   # (n - 2, P) fan normals
    nx, ny, nz = (f.sum(axis=0) for f in (fx, fy, fz))
    facing = fx * nx + fy * ny + fz * nz
    against = facing < 0
    if not against.any():
        return against[0]
    # Flat enough not to count: |facing| <= _FLAT |fan normal| |normal|, compared squared.
    scale = (fx * fx + fy * fy + fz * fz) * (nx * nx + ny * ny + nz * nz)
    return (against & (facing * facing > _FLAT * _FLAT * scale)).any(axis=0)


def _plane_coordinates(points: np.ndarray) -> np.ndarray:
    """(P, n, 2) coordinates of (P, n, 3) polygons in the plane of their Newell
    normal, dropping its largest axis and mirrored where needed so that every
    polygon runs anticlockwise."""
    normals = _newell_normals(points)
    axis = np.abs(normals).argmax(axis=1)
    rows = np.arange(len(points))
    u = points[rows, :, (axis + 1) % 3]
    v = points[rows, :, (axis + 2) % 3]
    # Dropping axis k keeps the polygon's winding as seen from +k: anticlockwise when normal[k] > 0.
    v = np.where(normals[rows, axis][:, None] < 0, -v, v)
    return np.stack([u, v], axis=2)


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _ear_clip(points: np.ndarray) -> np.ndarray:
    """(P, n - 2, 3) corner numbers (0..n-1) of the triangles of (P, n, 3)
    polygons of n corners, ear clipped in their planes (the module docstring)."""
    xy = _plane_coordinates(points)
    n = xy.shape[1]
    if n > _ONE_BY_ONE:
        return np.stack([_ear_clip_one(polygon) for polygon in xy]).reshape(-1, n - 2, 3)
    step = max(1, _CHUNK // (n * n))
    return np.concatenate([_ear_clip_all(xy[i:i + step]) for i in range(0, len(xy), step)])


def _ear_clip_all(xy: np.ndarray) -> np.ndarray:
    """:func:`_ear_clip` of (P, n, 2) anticlockwise polygons, a step for all of
    them at once: every remaining corner of each is tested as an ear, against
    every remaining corner of its polygon that does not turn left."""
    count, n = xy.shape[:2]
    rows = np.arange(count)
    alive = np.ones((count, n), dtype=bool)
    cursor = np.zeros(count, dtype=np.int64)
    out = np.empty((count, n - 2, 3), dtype=np.int64)
    for step in range(n - 2):
        m = n - step
        left = np.nonzero(alive)[1].reshape(count, m)    # remaining corner numbers, in order
        p = xy[rows[:, None], left]                       # (P, m, 2)
        prev, after = np.roll(p, 1, axis=1), np.roll(p, -1, axis=1)
        convex = _cross2(p - prev, after - p) > 0
        # Remaining corner j against the triangle (prev_i, p_i, after_i) of each corner i.
        a, b, c, q = prev[:, :, None], p[:, :, None], after[:, :, None], p[:, None, :]
        inside = ((_cross2(b - a, q - a) >= 0) & (_cross2(c - b, q - b) >= 0) & (_cross2(a - c, q - c) >= 0))
        offset = (np.arange(m)[None, :] - np.arange(m)[:, None]) % m
        inside &= (offset != 0) & (offset != 1) & (offset != m - 1)   # the triangle's own corners
        inside &= ~convex[:, None, :]
        # A corner at the same place as one of the triangle's does not block it.
        inside &= ~((q == a).all(axis=3) | (q == b).all(axis=3) | (q == c).all(axis=3))
        ear = convex & ~inside.any(axis=2)
        # Candidates in order from the cursor; an ear, else a left turn, else the cursor's corner.
        order = (np.arange(m) - np.argmax(left == cursor[:, None], axis=1)[:, None]) % m
        choice = np.where(ear.any(axis=1), np.argmin(np.where(ear, order, m), axis=1),
                          np.argmin(np.where(convex, order, m), axis=1))
        choice = np.where(ear.any(axis=1) | convex.any(axis=1), choice, np.argmin(order, axis=1))
        out[:, step] = np.stack([left[rows, (choice - 1) % m], left[rows, choice], left[rows, (choice + 1) % m]],
                                axis=1)
        alive[rows, left[rows, choice]] = False
        cursor = left[rows, (choice + 1) % m]
    return out


def _ear_clip_one(xy: np.ndarray) -> np.ndarray:
    """:func:`_ear_clip` of one (n, 2) anticlockwise polygon, candidate by
    candidate from the cursor, each tested against the remaining corners that do
    not turn left (the same rule, and triangles, as :func:`_ear_clip_all`)."""
    n = len(xy)
    after, before = list(range(1, n)) + [0], [n - 1] + list(range(n - 1))   # the remaining corners' links
    alive = np.ones(n, dtype=bool)
    convex = _cross2(xy - np.roll(xy, 1, axis=0), np.roll(xy, -1, axis=0) - xy) > 0
    x, y = xy[:, 0].tolist(), xy[:, 1].tolist()

    def turns_left(i: int) -> bool:
        a, c = before[i], after[i]
        return (x[i] - x[a]) * (y[c] - y[i]) - (y[i] - y[a]) * (x[c] - x[i]) > 0

    def is_ear(i: int) -> bool:
        corners = np.array([before[i], i, after[i]])
        blocking = np.flatnonzero(alive & ~convex)
        q = xy[blocking[~np.isin(blocking, corners)], None]           # (r, 1, 2)
        a, b, c = xy[corners]
        inside = (_cross2(b - a, q - a) >= 0) & (_cross2(c - b, q - b) >= 0) & (_cross2(a - c, q - c) >= 0)
        same = (q == a).all(axis=2) | (q == b).all(axis=2) | (q == c).all(axis=2)
        return not (inside & ~same).any()

    out, cursor = [], 0
    for remaining in range(n, 2, -1):
        i, first_left = cursor, None
        for _ in range(remaining):
            if convex[i]:
                first_left = i if first_left is None else first_left
                if is_ear(i):
                    break
            i = after[i]
        else:
            i = cursor if first_left is None else first_left
        a, c = before[i], after[i]
        out.append((a, i, c))
        after[a], before[c], alive[i] = c, a, False
        convex[a], convex[c] = turns_left(a), turns_left(c)
        cursor = c
    return np.array(out, dtype=np.int64)

"""The paper's 25-mesh suite, as far as it can be made honestly.

Generated here (vectorised numpy, no files needed), with the paper's names and
face counts:

==========  =====  =====================================================================
name        faces  what we build
==========  =====  =====================================================================
triangle        1  one equilateral triangle
triangle2       2  a strip of two triangles (a rhombus)
triangle3       3  a strip of three triangles
triangle4       4  a strip of four triangles
box1            8  an *open* box: the four walls of a cube, no top or bottom (the
                   paper's file has 8 faces, which a closed box cannot have: 12)
diamond        33  a seven-fold brilliant-style gem: heptagonal table (5), crown of 7
                   bezel and 14 upper-girdle facets (21), pavilion of 7 main facets (7).
                   A closed 2-manifold always has an even face count; 33 is reached with
                   T-junctions: each pavilion facet's girdle edge passes through the
                   midpoint shared by two upper-girdle facets, so the gem is closed to
                   the eye with an odd count.  Facets are flat (no shared vertices).
icosphere      80  an icosahedron split once (:func:`clrt.scene.primitives.icosphere`)
sphere        960  UV sphere, 32 segments x 16 stacks: 2 * 32 * 15 triangles
ellipse       960  the same sphere scaled to semi-axes 1.5, 1, 0.75
teapot       6320  Newell's teapot: the 32 bicubic Bezier patches (306 control points,
                   public domain; rim, body, handle, spout, lid and the later-added
                   bottom), each tessellated 10 x 10 into 200 triangles, patch seams
                   welded and the 8 x 10 zero-area triangles at the lid's and the
                   bottom's poles dropped: 32 * 200 - 80 = 6320, exactly the paper's
                   count (which is how we know its tessellation).
==========  =====  =====================================================================

Real scans come from a folder (default ``<repo>/../shared/meshes``): every mesh
file there at full size, named by its stem (``cow``, ``homer``, ...), and, for
the scans the paper names, also decimated to the paper's face count under the
paper's name: ``bunny`` (6,966, from ``bunny00.off``), ``camel`` (4,884),
``dragon`` (37,986 from ``ChineseDragon-10kv.off``, only when the source has
more faces); their full-size versions are ``bunny-full``, ``camel-full`` and
``dragon-full``.  Decimation is quadric edge collapse by the optional package
``fast-simplification``; without it the decimated variants are skipped with a
note.  The paper's other meshes (jar, knob, apel, sample1.3DS, ...) are
third-party models we do not have and do not fake.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from clrt.errors import InputError
from clrt.scene.mesh import Mesh
from clrt.scene.primitives import grid_faces, icosphere

# --------------------------------------------------------------------------- simple shapes


def triangle_strip(n: int, name: str = "") -> Mesh:
    """``n`` equilateral triangles in a strip in the z = 0 plane, all facing +z."""
    i = np.arange(n + 2)
    v = np.stack([0.5 * i, (i % 2) * (np.sqrt(3.0) / 2.0), np.zeros(len(i))], 1)
    f = np.stack([i[:n], i[1:n + 1], i[2:n + 2]], 1)
    return _facing(v, f, np.array([0.0, 0.0, 1.0]), name or (f"triangle{n}" if n > 1 else "triangle"))


def open_box(size=(1.0, 1.0, 1.0), name: str = "box1") -> Mesh:
    """The four walls of an axis-aligned box (8 triangles, no top or bottom),
    each wall with its own vertices so that it shades flat."""
    hx, hy, hz = 0.5 * np.asarray(size, dtype=np.float64)
    # Each wall: 4 corners counter-clockwise seen from outside.
    walls = np.array([
        [[hx, -hy, hz], [hx, -hy, -hz], [hx, hy, -hz], [hx, hy, hz]],        # +x
        [[-hx, -hy, -hz], [-hx, -hy, hz], [-hx, hy, hz], [-hx, hy, -hz]],    # -x
        [[-hx, -hy, hz], [hx, -hy, hz], [hx, hy, hz], [-hx, hy, hz]],        # +z
        [[hx, -hy, -hz], [-hx, -hy, -hz], [-hx, hy, -hz], [hx, hy, -hz]],    # -z
    ])
    base = 4 * np.arange(4)[:, None]
    f = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return Mesh.from_arrays(walls.reshape(-1, 3), f, name)


def gem(sides: int = 7, table: float = 0.55, crown: float = 0.35, pavilion: float = 0.85,
        name: str = "diamond") -> Mesh:
    """A brilliant-style gem with ``sides``-fold symmetry and 5 * sides - 2 facets
    (33 for 7 sides); girdle radius 1, table on top (+y).  See the module notes
    for the facet layout and its T-junctions."""
    k = np.arange(sides)
    step = 2.0 * np.pi / sides

    def ring(radius, height, angle):
        return np.stack([radius * np.cos(angle), np.full(angle.shape, height), radius * np.sin(angle)], -1)

    g = ring(1.0, 0.0, k * step)                                  # girdle corners G_k
    m = 0.5 * (g + np.roll(g, -1, axis=0))                         # girdle edge midpoints M_k
    t = ring(table, crown, (k + 0.5) * step)                       # table corners T_k, above M_k
    culet = np.array([0.0, -pavilion, 0.0])
    k1 = (k + 1) % sides
    tris = [
        np.stack([np.broadcast_to(t[0], (sides - 2, 3)), t[1:-1], t[2:]], 1),   # table fan
        np.stack([t, g, m], 1), np.stack([t, m, g[k1]], 1),                      # upper girdle
        np.stack([t, t[k1], g[k1]], 1),                                          # bezel
        np.stack([np.broadcast_to(culet, (sides, 3)), g, g[k1]], 1),             # pavilion
    ]
    corners = np.concatenate(tris)                                 # (5 * sides - 2, 3, 3)
    return _outward(corners, np.array([0.0, 0.0, 0.0]), name, weld=False)


def uv_sphere(segments: int = 32, stacks: int = 16, radii=(1.0, 1.0, 1.0), name: str = "sphere") -> Mesh:
    """Latitude-longitude sphere (ellipsoid with ``radii``) around the y axis:
    ``segments`` around, ``stacks`` from pole to pole, 2 * segments * (stacks - 1)
    triangles (one fan at each pole, two per quad between)."""
    theta = np.arange(1, stacks) * np.pi / stacks                  # polar angle of the rings
    phi = np.arange(segments) * 2.0 * np.pi / segments
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    rings = np.stack([np.sin(th) * np.cos(ph), np.cos(th), -np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    v = np.concatenate([[[0.0, 1.0, 0.0]], rings, [[0.0, -1.0, 0.0]]]) * np.asarray(radii, dtype=np.float64)
    s = np.arange(segments)
    s1 = (s + 1) % segments
    top = np.stack([np.zeros(segments, int), 1 + s, 1 + s1], 1)
    last = 1 + (stacks - 2) * segments
    bottom = np.stack([np.full(segments, len(v) - 1), last + s1, last + s], 1)
    r, c = (x.ravel() for x in np.meshgrid(np.arange(stacks - 2), s, indexing="ij"))
    a, b = r * segments + c, (r + 1) * segments + c
    a1, b1 = r * segments + (c + 1) % segments, (r + 1) * segments + (c + 1) % segments
    band = np.concatenate([np.stack([a, b, b1], 1), np.stack([a, b1, a1], 1)])
    f = np.concatenate([top, 1 + band, bottom])
    return _outward(v[f], np.zeros(3), name)


def _facing(v: np.ndarray, f: np.ndarray, normal: np.ndarray, name: str) -> Mesh:
    """Faces re-wound where needed so that every one faces ``normal``."""
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = n @ normal < 0
    f = f.copy()
    f[flip] = f[flip][:, ::-1]
    return Mesh.from_arrays(v, f, name)


def _outward(corners: np.ndarray, inside: np.ndarray, name: str, weld: bool = True) -> Mesh:
    """A mesh from (F, 3, 3) corners of a star-shaped solid around ``inside``,
    every triangle wound to face away from it.  ``weld``: corners that are
    exactly equal become one vertex (smooth shading across edges); otherwise
    every triangle keeps its own three (flat facets)."""
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flip = np.einsum("ij,ij->i", n, corners.mean(axis=1) - inside) < 0
    corners = corners.copy()
    corners[flip] = corners[flip][:, ::-1]
    if not weld:
        return Mesh.from_arrays(corners.reshape(-1, 3), np.arange(3 * len(corners)).reshape(-1, 3), name)
    v, f = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    return Mesh.from_arrays(v, f.reshape(-1, 3), name)


# --------------------------------------------------------------------------- Newell's teapot

# Control points (x, y, z; z up) of the 32 patches of Martin Newell's 1975
# teapot, in the ubiquitous 306-point, one-based form (public domain; the last
# four patches, the bottom, were added later by others).  Points 205, 206, 216
# and 223 are not used by any patch.
_TEAPOT_POINTS = """
1.4 0 2.4  1.4 -0.784 2.4  0.784 -1.4 2.4  0 -1.4 2.4
1.3375 0 2.53125  1.3375 -0.749 2.53125  0.749 -1.3375 2.53125  0 -1.3375 2.53125
1.4375 0 2.53125  1.4375 -0.805 2.53125  0.805 -1.4375 2.53125  0 -1.4375 2.53125
1.5 0 2.4  1.5 -0.84 2.4  0.84 -1.5 2.4  0 -1.5 2.4
-0.784 -1.4 2.4  -1.4 -0.784 2.4  -1.4 0 2.4
-0.749 -1.3375 2.53125  -1.3375 -0.749 2.53125  -1.3375 0 2.53125
-0.805 -1.4375 2.53125  -1.4375 -0.805 2.53125  -1.4375 0 2.53125
-0.84 -1.5 2.4  -1.5 -0.84 2.4  -1.5 0 2.4
-1.4 0.784 2.4  -0.784 1.4 2.4  0 1.4 2.4
-1.3375 0.749 2.53125  -0.749 1.3375 2.53125  0 1.3375 2.53125
-1.4375 0.805 2.53125  -0.805 1.4375 2.53125  0 1.4375 2.53125
-1.5 0.84 2.4  -0.84 1.5 2.4  0 1.5 2.4
0.784 1.4 2.4  1.4 0.784 2.4
0.749 1.3375 2.53125  1.3375 0.749 2.53125
0.805 1.4375 2.53125  1.4375 0.805 2.53125
0.84 1.5 2.4  1.5 0.84 2.4
1.75 0 1.875  1.75 -0.98 1.875  0.98 -1.75 1.875  0 -1.75 1.875
2 0 1.35  2 -1.12 1.35  1.12 -2 1.35  0 -2 1.35
2 0 0.9  2 -1.12 0.9  1.12 -2 0.9  0 -2 0.9
-0.98 -1.75 1.875  -1.75 -0.98 1.875  -1.75 0 1.875
-1.12 -2 1.35  -2 -1.12 1.35  -2 0 1.35
-1.12 -2 0.9  -2 -1.12 0.9  -2 0 0.9
-1.75 0.98 1.875  -0.98 1.75 1.875  0 1.75 1.875
-2 1.12 1.35  -1.12 2 1.35  0 2 1.35
-2 1.12 0.9  -1.12 2 0.9  0 2 0.9
0.98 1.75 1.875  1.75 0.98 1.875
1.12 2 1.35  2 1.12 1.35
1.12 2 0.9  2 1.12 0.9
2 0 0.45  2 -1.12 0.45  1.12 -2 0.45  0 -2 0.45
1.5 0 0.225  1.5 -0.84 0.225  0.84 -1.5 0.225  0 -1.5 0.225
1.5 0 0.15  1.5 -0.84 0.15  0.84 -1.5 0.15  0 -1.5 0.15
-1.12 -2 0.45  -2 -1.12 0.45  -2 0 0.45
-0.84 -1.5 0.225  -1.5 -0.84 0.225  -1.5 0 0.225
-0.84 -1.5 0.15  -1.5 -0.84 0.15  -1.5 0 0.15
-2 1.12 0.45  -1.12 2 0.45  0 2 0.45
-1.5 0.84 0.225  -0.84 1.5 0.225  0 1.5 0.225
-1.5 0.84 0.15  -0.84 1.5 0.15  0 1.5 0.15
1.12 2 0.45  2 1.12 0.45
0.84 1.5 0.225  1.5 0.84 0.225
0.84 1.5 0.15  1.5 0.84 0.15
-1.6 0 2.025  -1.6 -0.3 2.025  -1.5 -0.3 2.25  -1.5 0 2.25
-2.3 0 2.025  -2.3 -0.3 2.025  -2.5 -0.3 2.25  -2.5 0 2.25
-2.7 0 2.025  -2.7 -0.3 2.025  -3 -0.3 2.25  -3 0 2.25
-2.7 0 1.8  -2.7 -0.3 1.8  -3 -0.3 1.8  -3 0 1.8
-1.5 0.3 2.25  -1.6 0.3 2.025
-2.5 0.3 2.25  -2.3 0.3 2.025
-3 0.3 2.25  -2.7 0.3 2.025
-3 0.3 1.8  -2.7 0.3 1.8
-2.7 0 1.575  -2.7 -0.3 1.575  -3 -0.3 1.35  -3 0 1.35
-2.5 0 1.125  -2.5 -0.3 1.125  -2.65 -0.3 0.9375  -2.65 0 0.9375
-2 -0.3 0.9  -1.9 -0.3 0.6  -1.9 0 0.6
-3 0.3 1.35  -2.7 0.3 1.575
-2.65 0.3 0.9375  -2.5 0.3 1.125
-1.9 0.3 0.6  -2 0.3 0.9
1.7 0 1.425  1.7 -0.66 1.425  1.7 -0.66 0.6  1.7 0 0.6
2.6 0 1.425  2.6 -0.66 1.425  3.1 -0.66 0.825  3.1 0 0.825
2.3 0 2.1  2.3 -0.25 2.1  2.4 -0.25 2.025  2.4 0 2.025
2.7 0 2.4  2.7 -0.25 2.4  3.3 -0.25 2.4  3.3 0 2.4
1.7 0.66 0.6  1.7 0.66 1.425
3.1 0.66 0.825  2.6 0.66 1.425
2.4 0.25 2.025  2.3 0.25 2.1
3.3 0.25 2.4  2.7 0.25 2.4
2.8 0 2.475  2.8 -0.25 2.475  3.525 -0.25 2.49375  3.525 0 2.49375
2.9 0 2.475  2.9 -0.15 2.475  3.45 -0.15 2.5125  3.45 0 2.5125
2.8 0 2.4  2.8 -0.15 2.4  3.2 -0.15 2.4  3.2 0 2.4
3.525 0.25 2.49375  2.8 0.25 2.475
3.45 0.15 2.5125  2.9 0.15 2.475
3.2 0.15 2.4  2.8 0.15 2.4
0 0 3.15  0 -0.002 3.15  0.002 0 3.15  0.8 0 3.15
0.8 -0.45 3.15  0.45 -0.8 3.15  0 -0.8 3.15  0 0 2.85
0.2 0 2.7  0.2 -0.112 2.7  0.112 -0.2 2.7  0 -0.2 2.7
-0.002 0 3.15  -0.45 -0.8 3.15  -0.8 -0.45 3.15  -0.8 0 3.15
-0.112 -0.2 2.7  -0.2 -0.112 2.7  -0.2 0 2.7
0 0.002 3.15  -0.8 0.45 3.15  -0.45 0.8 3.15  0 0.8 3.15
-0.2 0.112 2.7  -0.112 0.2 2.7  0 0.2 2.7
0.45 0.8 3.15  0.8 0.45 3.15
0.112 0.2 2.7  0.2 0.112 2.7
0.4 0 2.55  0.4 -0.224 2.55  0.224 -0.4 2.55  0 -0.4 2.55
1.3 0 2.55  1.3 -0.728 2.55  0.728 -1.3 2.55  0 -1.3 2.55
1.3 0 2.4  1.3 -0.728 2.4  0.728 -1.3 2.4  0 -1.3 2.4
-0.224 -0.4 2.55  -0.4 -0.224 2.55  -0.4 0 2.55
-0.728 -1.3 2.55  -1.3 -0.728 2.55  -1.3 0 2.55
-0.728 -1.3 2.4  -1.3 -0.728 2.4  -1.3 0 2.4
-0.4 0.224 2.55  -0.224 0.4 2.55  0 0.4 2.55
-1.3 0.728 2.55  -0.728 1.3 2.55  0 1.3 2.55
-1.3 0.728 2.4  -0.728 1.3 2.4  0 1.3 2.4
0.224 0.4 2.55  0.4 0.224 2.55
0.728 1.3 2.55  1.3 0.728 2.55
0.728 1.3 2.4  1.3 0.728 2.4
0 0 0  1.5 0 0.15  1.5 0.84 0.15  0.84 1.5 0.15  0 1.5 0.15
1.5 0 0.075  1.5 0.84 0.075  0.84 1.5 0.075  0 1.5 0.075
1.425 0 0  1.425 0.798 0  0.798 1.425 0  0 1.425 0
-0.84 1.5 0.15  -1.5 0.84 0.15  -1.5 0 0.15
-0.84 1.5 0.075  -1.5 0.84 0.075  -1.5 0 0.075
-0.798 1.425 0  -1.425 0.798 0  -1.425 0 0
-1.5 -0.84 0.15  -0.84 -1.5 0.15  0 -1.5 0.15
-1.5 -0.84 0.075  -0.84 -1.5 0.075  0 -1.5 0.075
-1.425 -0.798 0  -0.798 -1.425 0  0 -1.425 0
0.84 -1.5 0.15  1.5 -0.84 0.15
0.84 -1.5 0.075  1.5 -0.84 0.075
0.798 -1.425 0  1.425 -0.798 0
"""

# Each patch: 16 one-based point indices, 4 rows of 4.
_TEAPOT_PATCHES = """
1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16
4 17 18 19 8 20 21 22 12 23 24 25 16 26 27 28
19 29 30 31 22 32 33 34 25 35 36 37 28 38 39 40
31 41 42 1 34 43 44 5 37 45 46 9 40 47 48 13
13 14 15 16 49 50 51 52 53 54 55 56 57 58 59 60
16 26 27 28 52 61 62 63 56 64 65 66 60 67 68 69
28 38 39 40 63 70 71 72 66 73 74 75 69 76 77 78
40 47 48 13 72 79 80 49 75 81 82 53 78 83 84 57
57 58 59 60 85 86 87 88 89 90 91 92 93 94 95 96
60 67 68 69 88 97 98 99 92 100 101 102 96 103 104 105
69 76 77 78 99 106 107 108 102 109 110 111 105 112 113 114
78 83 84 57 108 115 116 85 111 117 118 89 114 119 120 93
121 122 123 124 125 126 127 128 129 130 131 132 133 134 135 136
124 137 138 121 128 139 140 125 132 141 142 129 136 143 144 133
133 134 135 136 145 146 147 148 149 150 151 152 69 153 154 155
136 143 144 133 148 156 157 145 152 158 159 149 155 160 161 69
162 163 164 165 166 167 168 169 170 171 172 173 174 175 176 177
165 178 179 162 169 180 181 166 173 182 183 170 177 184 185 174
174 175 176 177 186 187 188 189 190 191 192 193 194 195 196 197
177 184 185 174 189 198 199 186 193 200 201 190 197 202 203 194
204 204 204 204 207 208 209 210 211 211 211 211 212 213 214 215
204 204 204 204 210 217 218 219 211 211 211 211 215 220 221 222
204 204 204 204 219 224 225 226 211 211 211 211 222 227 228 229
204 204 204 204 226 230 231 207 211 211 211 211 229 232 233 212
212 213 214 215 234 235 236 237 238 239 240 241 242 243 244 245
215 220 221 222 237 246 247 248 241 249 250 251 245 252 253 254
222 227 228 229 248 255 256 257 251 258 259 260 254 261 262 263
229 232 233 212 257 264 265 234 260 266 267 238 263 268 269 242
270 270 270 270 279 280 281 282 275 276 277 278 271 272 273 274
270 270 270 270 282 289 290 291 278 286 287 288 274 283 284 285
270 270 270 270 291 298 299 300 288 295 296 297 285 292 293 294
270 270 270 270 300 305 306 279 297 303 304 275 294 301 302 271
"""


def teapot_control_points() -> np.ndarray:
    """(32, 4, 4, 3) float64 control points of Newell's teapot, z up."""
    points = np.array(_TEAPOT_POINTS.split(), dtype=np.float64).reshape(306, 3)
    patches = np.array(_TEAPOT_PATCHES.split(), dtype=np.int64).reshape(32, 4, 4) - 1
    return points[patches]


def teapot(steps: int = 10, name: str = "teapot") -> Mesh:
    """Newell's teapot, y up (spout towards +x), each patch tessellated into
    ``steps`` x ``steps`` quads split in two; seams welded and zero-area pole
    triangles dropped (6,320 triangles for 10 steps).  Every triangle is wound
    to face out of the pot."""
    control = teapot_control_points()
    u = np.linspace(0.0, 1.0, steps + 1)
    bern = np.stack([(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u ** 2 * (1 - u), u ** 3], 1)   # (S, 4)
    surface = np.einsum("ui,pijc,vj->puvc", bern, control, bern)    # (32, S, S, 3)
    n = steps + 1
    grid = grid_faces(n, n, wrap=False)                           # (2 * steps**2, 3)
    faces = (np.arange(len(control))[:, None, None] * n * n + grid).reshape(-1, 3)
    points = surface.reshape(-1, 3)
    # Weld: patches share their boundary curves, and a row of equal control
    # points (lid top, bottom centre) makes a whole row of samples coincide.
    key = np.round(points * 1e6).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    v = points[first]
    # Newell's patches are wound consistently (no welded edge is walked twice
    # the same way); turn them all outwards if they face in.
    tri = v[faces]
    signed_volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
    if signed_volume < 0:
        faces = faces[:, ::-1]
    y_up = np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1)               # (x, y, z) z-up -> (x, z, -y)
    return Mesh.from_arrays(y_up, faces, name)


# --------------------------------------------------------------------------- the suite

@dataclass(frozen=True)
class Generated:
    make: Callable[[], Mesh]
    faces: int
    description: str


# The paper's generated-looking meshes, in the order of its tables.
GENERATED: dict[str, Generated] = {
    "triangle": Generated(lambda: triangle_strip(1), 1, "one triangle"),
    "triangle2": Generated(lambda: triangle_strip(2), 2, "strip of 2 triangles"),
    "triangle3": Generated(lambda: triangle_strip(3), 3, "strip of 3 triangles"),
    "triangle4": Generated(lambda: triangle_strip(4), 4, "strip of 4 triangles"),
    "box1": Generated(lambda: open_box(), 8, "open box: 4 walls of a cube, 2 triangles each"),
    "diamond": Generated(lambda: gem(), 33, "7-fold brilliant-style gem (T-junctions at the girdle)"),
    "icosphere": Generated(lambda: icosphere(1, name="icosphere"), 80, "icosahedron subdivided once"),
    "sphere": Generated(lambda: uv_sphere(32, 16), 960, "UV sphere, 32 segments x 16 stacks"),
    "ellipse": Generated(lambda: uv_sphere(32, 16, (1.5, 1.0, 0.75), name="ellipse"), 960,
                         "UV ellipsoid, semi-axes 1.5, 1, 0.75"),
    "teapot": Generated(lambda: teapot(10), 6320, "Newell teapot, 32 Bezier patches at 10x10, poles dropped"),
}

# Scans the paper names: suite name -> (source file, the paper's face count).
DECIMATED = {
    "bunny": ("bunny00.off", 6966),
    "camel": ("camel.off", 4884),
    "dragon": ("ChineseDragon-10kv.off", 37986),
}
# Suite names of scan files whose stem is not the name (full-size variant: NAME-full).
SCAN_NAMES = {"bunny00": "bunny", "chinesedragon-10kv": "dragon"}
# Where a scan is in several formats, the first here wins; any other format clrt reads
# (clrt.scene.load.SUPPORTED_EXTENSIONS) comes after these.
SCAN_PREFERENCE = (".off", ".obj", ".ply", ".stl", ".glb", ".gltf", ".3ds")


def default_mesh_dir() -> Path | None:
    """``<repo>/../shared/meshes`` when that folder exists."""
    path = Path(__file__).resolve().parents[2].parent / "shared" / "meshes"
    return path if path.is_dir() else None


def have_decimation() -> bool:
    try:
        import fast_simplification  # noqa: F401
    except ImportError:
        return False
    return True


def decimate(mesh: Mesh, faces: int, name: str = "") -> Mesh:
    """``mesh`` reduced to about ``faces`` triangles by quadric edge collapse
    (``fast-simplification``; raises ImportError without it)."""
    import fast_simplification
    v, f = fast_simplification.simplify(mesh.vertices.astype(np.float64), mesh.faces.astype(np.int32),
                                        target_count=int(faces))
    return Mesh.from_arrays(v, f, name or mesh.name)


@dataclass
class SuiteEntry:
    """One mesh of the suite: how to make it, and what it stands for."""

    name: str
    source: str                   # human-readable origin
    faces: int | None             # known before making it (generated meshes), else None
    make: Callable[[], Mesh]
    path: Path | None = None      # the file it is read from (scans)
    target: int | None = None     # decimation target


class MeshSuite:
    """The generated meshes plus the scans found in ``mesh_dir`` (None: the default
    folder when it exists; a missing folder means generated meshes only).
    ``notes`` says which variants were skipped and why."""

    def __init__(self, mesh_dir=None):
        if mesh_dir is None:
            mesh_dir = default_mesh_dir()
        self.mesh_dir = Path(mesh_dir) if mesh_dir else None
        self.notes: list[str] = []
        self.entries: dict[str, SuiteEntry] = {}
        for name, g in GENERATED.items():
            self.entries[name] = SuiteEntry(name, f"generated: {g.description}", g.faces, g.make)
        if self.mesh_dir is not None and self.mesh_dir.is_dir():
            self._add_scans()
        elif self.mesh_dir is not None:
            self.notes.append(f"mesh folder {self.mesh_dir} does not exist: generated meshes only")

    def _add_scans(self) -> None:
        from clrt.scene.load import SUPPORTED_EXTENSIONS, load_mesh

        def rank(ext: str) -> int:
            return SCAN_PREFERENCE.index(ext) if ext in SCAN_PREFERENCE else len(SCAN_PREFERENCE)
        files: dict[str, Path] = {}
        for path in sorted(self.mesh_dir.iterdir()):
            ext = path.suffix.lower()
            if not path.is_file() or ext not in SUPPORTED_EXTENSIONS:
                continue
            stem = path.stem.lower()
            name = SCAN_NAMES.get(stem, stem)
            if name in files and rank(files[name].suffix.lower()) <= rank(ext):
                continue
            files[name] = path
        can_decimate = have_decimation()
        for name, path in sorted(files.items()):
            if name in GENERATED:
                continue
            # "-full" where a decimated variant takes the plain name.
            full = f"{name}-full" if name in DECIMATED else name
            self.entries[full] = SuiteEntry(full, f"{path.name}, full size", _face_count(path),
                                            lambda p=path, n=full: _renamed(load_mesh(p), n), path)
        for name, (file, target) in DECIMATED.items():
            path = files.get(name)
            if path is None:
                self.notes.append(f"{name}: {file} not found in {self.mesh_dir}; skipped")
                continue
            # The face count first: a scan no larger than the paper's count is not
            # decimated at all (nor subdivided up to it), package or not.
            full = _face_count(path)
            if full is not None and full <= target:
                self.notes.append(f"{name}: {path.name} has {full:,} faces, not more than the paper's "
                                  f"{target:,}: not decimated (nor subdivided); it runs at full size as "
                                  f"{name}-full only")
                continue
            if not can_decimate:
                self.notes.append(f"{name}: decimating {path.name} to {target:,} faces needs the optional "
                                  "package fast-simplification (pip install fast-simplification); skipped")
                continue
            source = f"{path.name} decimated from {full:,} faces" if full else f"{path.name} decimated"
            self.entries[name] = SuiteEntry(name, source, target,
                                            lambda p=path, n=name, t=target: _decimated(p, t, n), path, target)
        # Smallest first, as in the paper's tables (stable: generated meshes keep their order).
        self.entries = dict(sorted(self.entries.items(),
                                   key=lambda item: float("inf") if item[1].faces is None else item[1].faces))

    def names(self) -> list[str]:
        return list(self.entries)

    def __contains__(self, name: str) -> bool:
        return name in self.entries

    def __getitem__(self, name: str) -> SuiteEntry:
        try:
            return self.entries[name]
        except KeyError:
            why = [n for n in self.notes if n.startswith(f"{name}:")]
            message = f"mesh {name!r} is not available: " + (why[0] if why else
                                                               f"choose from {', '.join(self.entries)}")
            if self.mesh_dir is None or not self.mesh_dir.is_dir():
                where = f"{self.mesh_dir} does not exist" if self.mesh_dir else "no mesh folder"
                message += f" ({where}; scanned meshes are read from --mesh-dir DIR)"
            raise InputError(message) from None

    def make(self, name: str) -> Mesh:
        return self[name].make()


def _decimated(path: Path, target: int, name: str) -> Mesh:
    from clrt.scene.load import load_mesh
    mesh = load_mesh(path)
    if len(mesh.faces) <= target:
        raise InputError(f"{path.name} has {len(mesh.faces):,} faces, not more than {target:,}: "
                         f"cannot decimate it to {name}")
    return decimate(mesh, target, name)


def _renamed(mesh: Mesh, name: str) -> Mesh:
    return Mesh(mesh.vertices, mesh.faces, name)


def _face_count(path: Path) -> int | None:
    """Face count from an OFF header without reading the file (None otherwise)."""
    if path.suffix.lower() != ".off":
        return None
    try:
        with open(path, "rb") as fh:
            words: list[bytes] = []
            for line in fh:
                line = line.split(b"#", 1)[0]
                words += line.split()
                if len(words) >= 3 and words[0].upper().endswith(b"OFF"):
                    if len(words) >= 4:
                        return int(words[2])
                elif len(words) >= 3:
                    return None
    except (OSError, ValueError):
        return None
    return None


# --------------------------------------------------------------------------- writing meshes

def mesh_text(mesh: Mesh, fmt: str) -> str:
    """The mesh as OBJ or OFF text; coordinates with 9 significant digits, so a
    float32 vertex reads back bit for bit."""
    buf = io.StringIO()
    v, f = mesh.vertices.astype(np.float64), mesh.faces.astype(np.int64)
    if fmt == "obj":
        buf.write(f"# {mesh.name}: {len(f)} triangles, written by clrt.bench.paper_meshes\n")
        np.savetxt(buf, v, fmt="v %.9g %.9g %.9g")
        np.savetxt(buf, f + 1, fmt="f %d %d %d")
    elif fmt == "off":
        buf.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(buf, v, fmt="%.9g %.9g %.9g")
        np.savetxt(buf, f, fmt="3 %d %d %d")
    else:
        raise InputError(f"cannot write mesh format {fmt!r}")
    return buf.getvalue()


def write_mesh(mesh: Mesh, path, force: bool = False) -> Path:
    """Write ``mesh`` as OBJ or OFF (by the suffix of ``path``), atomically and
    under clrt's overwrite rule (clrt.output.write_file)."""
    from clrt.output import write_file
    path = Path(path)
    write_file(mesh_text(mesh, path.suffix.lower().lstrip(".")), path, force, "--out")
    return path

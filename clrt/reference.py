"""A brute-force ray tracer in plain numpy: the yardstick for the OpenCL kernels.

It follows the kernels step by step -- the same camera rays, the same watertight
triangle test in float32 (Woop, Benthin and Wald 2013), the same closest-hit
rule (lower triangle index wins a tie), the same Phong shading and shadow rays
-- but shares no code with them, so agreement between the two is evidence.
Vectorised over rays x a block of triangles; meant for small images.
"""

from __future__ import annotations

import numpy as np

from clrt.render import SceneArrays, flatten_scene, ray_epsilon
from clrt.scene.scene import Camera, Scene

f32 = np.float32


def camera_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(H*W, 3) origins and unit directions, row 0 at the top, float32."""
    w, h = camera.width, camera.height
    forward, right, up = (v.astype(f32) for v in camera.basis())
    scale_x, scale_y = (f32(s) for s in camera.scales())
    px, py = np.meshgrid(np.arange(w, dtype=f32), np.arange(h, dtype=f32))
    sx = (f32(2) * (px.ravel() + f32(0.5)) / f32(w) - f32(1)) * scale_x
    sy = (f32(1) - f32(2) * (py.ravel() + f32(0.5)) / f32(h)) * scale_y
    d = forward + sx[:, None] * right + sy[:, None] * up
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(np.asarray(camera.eye, f32), d.shape)
    return np.ascontiguousarray(o), d.astype(f32)


def _shear(dirs: np.ndarray):
    """Per-ray axis permutation and shear constants of the watertight test."""
    kz = np.argmax(np.abs(dirs), axis=1)
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    dz = np.take_along_axis(dirs, kz[:, None], 1)[:, 0]
    flip = dz < 0
    kx, ky = np.where(flip, ky, kx), np.where(flip, kx, ky)
    perm = np.stack([kx, ky, kz], axis=1)
    d = np.take_along_axis(dirs, perm, 1)
    shear = np.stack([d[:, 0] / d[:, 2], d[:, 1] / d[:, 2], f32(1) / d[:, 2]], axis=1).astype(f32)
    return perm, shear


def intersect(origins, dirs, corners, tmin, tmax, block: int = 64, any_hit: bool = False):
    """Closest hit (or any hit) of every ray against every triangle.

    origins, dirs: (N, 3) float32; corners: (F, 3, 3) float32; tmin, tmax: (N,).
    Returns t (inf on a miss), prim (-1), u, v -- or, with ``any_hit``, a bool mask.
    """
    n = len(origins)
    perm, shear = _shear(dirs)
    best_t = np.full(n, np.inf, f32)
    best_prim = np.full(n, -1, np.int64)
    best_u = np.zeros(n, f32)
    best_v = np.zeros(n, f32)
    limit = np.asarray(tmax, f32).copy()
    tmin = np.asarray(tmin, f32)
    idx = perm[:, None, :]
    sx, sy, sz = (shear[:, k, None] for k in range(3))
    for start in range(0, len(corners), block):
        tri = corners[start:start + block]
        proj = []   # sheared 2D coordinates and scaled depth of the three corners
        for k in range(3):
            p = tri[None, :, k, :] - origins[:, None, :]                   # (N, K, 3)
            p = np.take_along_axis(p, np.broadcast_to(idx, p.shape), 2)
            proj.append((p[..., 0] - sx * p[..., 2], p[..., 1] - sy * p[..., 2], sz * p[..., 2]))
        (ax, ay, az), (bx, by, bz), (cx, cy, cz) = proj
        U = cx * by - cy * bx
        V = ax * cy - ay * cx
        W = bx * ay - by * ax
        zero = (U == 0) | (V == 0) | (W == 0)
        if zero.any():
            d = lambda a: a[zero].astype(np.float64)   # noqa: E731
            U[zero] = (d(cx) * d(by) - d(cy) * d(bx)).astype(f32)
            V[zero] = (d(ax) * d(cy) - d(ay) * d(cx)).astype(f32)
            W[zero] = (d(bx) * d(ay) - d(by) * d(ax)).astype(f32)
        inside = ~(((U < 0) | (V < 0) | (W < 0)) & ((U > 0) | (V > 0) | (W > 0)))
        det = U + V + W
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (U * az + V * bz + W * cz) / det
        ok = inside & (det != 0) & (t > tmin[:, None]) & (t <= limit[:, None])
        if any_hit:
            best_prim[ok.any(axis=1)] = 0
            continue
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)                 # first minimum = lowest index in the block
        tk = t[np.arange(n), k]
        closer = tk < best_t                     # earlier blocks win ties
        rows = np.nonzero(closer)[0]
        kk = k[rows]
        best_t[rows] = tk[rows]
        best_prim[rows] = start + kk
        best_u[rows] = V[rows, kk] / det[rows, kk]
        best_v[rows] = W[rows, kk] / det[rows, kk]
        limit = np.minimum(limit, best_t)
    if any_hit:
        return best_prim >= 0
    return best_t, best_prim.astype(np.int32), best_u, best_v


def shade(arrays: SceneArrays, scene: Scene, origins, dirs, t, prim, u, v, eps: float) -> np.ndarray:
    """(N, 3) linear colour: background, or Phong ambient + diffuse + specular with shadows."""
    n = len(origins)
    color = np.tile(np.asarray(scene.background, np.float64), (n, 1))
    hit = np.nonzero(prim >= 0)[0]
    if len(hit) == 0:
        return color
    p_id = prim[hit]
    tv = arrays.tri_verts[p_id]
    v0, v1, v2 = (tv[k][:, :3].astype(np.float64) for k in ("v0", "v1", "v2"))
    d = dirs[hit].astype(np.float64)
    ng = np.cross(v1 - v0, v2 - v0)
    ng /= np.linalg.norm(ng, axis=1, keepdims=True)
    ng[np.einsum("ij,ij->i", ng, d) > 0] *= -1
    info = arrays.tri_info[p_id]
    mat = arrays.materials[info["material"]]
    smooth = (mat["flags"] & 1).astype(bool)
    vn = arrays.vertex_normals[:, :3].astype(np.float64)
    w0 = 1.0 - u[hit] - v[hit]
    ns = (w0[:, None] * vn[info["vertex"][:, 0]] + u[hit, None] * vn[info["vertex"][:, 1]]
          + v[hit, None] * vn[info["vertex"][:, 2]])
    ns_len = np.linalg.norm(ns, axis=1, keepdims=True)
    use = smooth & (ns_len[:, 0] > 0)
    n_s = np.where(use[:, None], ns / np.where(ns_len > 0, ns_len, 1), ng)
    n_s[np.einsum("ij,ij->i", n_s, ng) < 0] *= -1

    albedo = mat["color"][:, :3].astype(np.float64)
    out = mat["ambient"][:, None] * albedo * np.asarray(scene.ambient_light, np.float64)
    p = origins[hit].astype(np.float64) + t[hit, None].astype(np.float64) * d
    shadow_origin = p + eps * ng
    for light in scene.lights:
        to_light = np.asarray(light.position, np.float64) - shadow_origin
        dist = np.linalg.norm(to_light, axis=1)
        l = to_light / dist[:, None]
        n_dot_l = np.einsum("ij,ij->i", n_s, l)
        lit = (np.einsum("ij,ij->i", ng, l) > 0) & (n_dot_l > 0)
        rows = np.nonzero(lit)[0]
        blocked = intersect(shadow_origin[rows].astype(f32), l[rows].astype(f32), _corners(arrays),
                            np.zeros(len(rows), f32), dist[rows].astype(f32), any_hit=True)
        lit[rows[blocked]] = False
        reflected = 2 * n_dot_l[:, None] * n_s - l
        r_dot_v = np.maximum(np.einsum("ij,ij->i", reflected, -d), 0)
        lc = np.asarray(light.color, np.float64)
        diffuse = mat["diffuse"][:, None] * n_dot_l[:, None] * albedo * lc
        spec = (mat["specular"] * np.power(r_dot_v, mat["shininess"]))[:, None] * lc
        out += np.where(lit[:, None], diffuse + spec, 0.0)
    color[hit] = out
    return color


def _corners(arrays: SceneArrays) -> np.ndarray:
    tv = arrays.tri_verts
    return np.stack([tv["v0"][:, :3], tv["v1"][:, :3], tv["v2"][:, :3]], axis=1).astype(f32)


def srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear RGB to 8-bit sRGB (IEC 61966-2-1), clamped."""
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.rint(255.0 * s).astype(np.uint8)


def render_reference(scene: Scene, camera: Camera):
    """(image float64 (H, W, 3) linear, prim (H, W) int32, t (H, W) float32)."""
    arrays = flatten_scene(scene)
    o, d = camera_rays(camera)
    n = len(o)
    t, prim, u, v = intersect(o, d, _corners(arrays), np.zeros(n, f32), np.full(n, np.inf, f32))
    color = shade(arrays, scene, o, d, t, prim, u, v, ray_epsilon(arrays.bounds, camera))
    shape = (camera.height, camera.width)
    return color.reshape(*shape, 3), prim.reshape(shape), t.reshape(shape)

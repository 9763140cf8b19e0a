"""A brute-force ray tracer in plain numpy: the yardstick for the OpenCL kernels.

It follows the kernels step by step -- the same camera rays and anti-aliasing
jitter, the same watertight triangle test in float32 (Woop, Benthin and Wald
2013), the same closest-hit rule (lower triangle index wins a tie), the same
Phong shading, shadow rays, reflection and Fresnel-weighted refraction, the
same origins of rays that leave a surface and the same rule for their hits --
but shares no code with them, so agreement between the two is evidence.
Vectorised over rays x a block of triangles; meant for small images.  Where
the kernels keep pending rays on a stack, it traces them in waves.
"""

from __future__ import annotations

import math

import numpy as np

from clrt.config import DEFAULT_MAX_DEPTH, TEXEL_LIMIT
from clrt.scene.scene import Camera, Scene

f32 = np.float32
# shading.cl's OFFSET_U and triangle.cl's T_ERROR_U: u = 2^-24 rounded up, as float32
U_BOUND = f32(6.0e-8)


class SceneData:
    """The scene as plain arrays, read here independently of the device's
    layouts: corners (F, 3, 3) float32, each triangle's global vertex indices
    and material, per-object vertex normals, the material fields, and each
    triangle's corner colours and texture coordinates (float32; NaN and 0
    where the mesh has none) with each material's texture (None where it has
    none or its mesh has no texture coordinates)."""

    FIELDS = ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency", "ior")

    def __init__(self, scene: Scene):
        if scene.instanced:   # placed meshes: the flattened twin (Scene.flattened), as the device shows them
            scene = scene.flattened()
        corners, vertex, material, normals, colors, uv = [], [], [], [], [], []
        mats, textured = [], []   # every material; its texture, where its mesh has texture coordinates
        offset = 0
        for o in scene.objects:
            m = o.mesh
            corners.append(m.vertices[m.faces].astype(f32))
            vertex.append(m.faces.astype(np.int64) + offset)
            own = np.zeros(len(m.faces), np.int64) if m.face_material is None else m.face_material + 1
            material.append(len(mats) + own)   # 0: the object's material, 1 + i: materials[i]
            for mat in (o.material, *o.materials):
                mats.append(mat)
                textured.append(mat.texture if m.uv is not None else None)
            normals.append(m.vertex_normals().astype(f32))   # per object: normals never blend across objects
            colors.append(np.full((len(m.faces), 3, 3), np.nan, f32) if m.colors is None else m.colors.astype(f32))
            uv.append(np.zeros((len(m.faces), 3, 2), f32) if m.uv is None else m.uv.astype(f32))
            offset += len(m.vertices)
        self.corners = np.concatenate(corners)
        self.vertex = np.concatenate(vertex)
        self.material = np.concatenate(material)
        self.vertex_normals = np.concatenate(normals).astype(np.float64)
        self.corner_colors = np.concatenate(colors)
        self.corner_uv = np.concatenate(uv)
        self.color = np.array([m.color for m in mats], f32)
        self.smooth = np.array([m.smooth for m in mats])
        for name in self.FIELDS:
            setattr(self, name, np.array([getattr(m, name) for m in mats], f32))
        self.textures = textured


def decode_srgb8(pixels: np.ndarray) -> np.ndarray:
    """8-bit sRGB codes to linear float32 (IEC 61966-2-1), computed in float64 and rounded once."""
    c = np.asarray(pixels, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, np.power((c + 0.055) / 1.055, 2.4)).astype(f32)


def _wrap(i: np.ndarray, n: int, mode: str) -> np.ndarray:
    """Texel indices wrapped into 0..n-1 (numpy's % is already non-negative)."""
    if mode == "clamp":
        return np.clip(i, 0, n - 1)
    if mode == "mirror":
        m = i % (2 * n)
        return np.where(m < n, m, 2 * n - 1 - m)
    return i % n


def decode_linear8(pixels: np.ndarray) -> np.ndarray:
    """8-bit codes of a data texture (metallicRoughness, normal map) to float32:
    code * float32(1/255), one rounding, as texture.cl's texel does."""
    return np.asarray(pixels, f32) * f32(1.0 / 255.0)


def sample_texture(texture, uv: np.ndarray, linear: bool = False) -> np.ndarray:
    """(N, 3) float32 linear values of ``texture`` (a clrt Texture) at (N, 2)
    float32 coordinates: bilinear over sRGB-decoded texels (``linear``: over
    linear codes, as data textures are read), texel centres at half-integers,
    (0, 0) the bottom-left corner, each axis wrapped by its mode."""
    h, w = texture.pixels.shape[:2]
    limit = f32(TEXEL_LIMIT)
    uv = np.asarray(uv, f32)
    x = np.fmin(np.fmax(uv[:, 0] * f32(w) - f32(0.5), -limit), limit)
    y = np.fmin(np.fmax((f32(1) - uv[:, 1]) * f32(h) - f32(0.5), -limit), limit)
    x_left, y_top = np.floor(x), np.floor(y)
    fx, fy = (x - x_left)[:, None], (y - y_top)[:, None]
    x0, y0 = x_left.astype(np.int64), y_top.astype(np.int64)
    xs = [_wrap(x0 + k, w, texture.wrap_s) for k in (0, 1)]
    ys = [_wrap(y0 + k, h, texture.wrap_t) for k in (0, 1)]
    # Decode only the four texels read per point: decoding works texel by texel,
    # so this equals decoding the whole image, without doing that on every call.
    decode = decode_linear8 if linear else decode_srgb8
    (a, b), (c, d) = [[decode(texture.pixels[y, x]) for x in xs] for y in ys]
    top = a + fx * (b - a)
    bottom = c + fx * (d - c)
    return top + fy * (bottom - top)


def albedo(data: SceneData, prim, u, v) -> np.ndarray:
    """(N, 3) float64: material colour x interpolated corner colour x texture, each
    step in float32 in the kernels' order (w0 * a0 + u * a1 + v * a2)."""
    u, v = np.asarray(u, f32)[:, None], np.asarray(v, f32)[:, None]
    w0 = f32(1) - u - v

    def blend(corner, rows=slice(None)):   # (N, 3, k) -> (N, k)
        return w0[rows] * corner[:, 0] + u[rows] * corner[:, 1] + v[rows] * corner[:, 2]

    k = data.material[prim]
    out = data.color[k]
    colored = ~np.isnan(data.corner_colors[prim, 0, 0])
    out[colored] *= blend(data.corner_colors[prim[colored]], colored)
    uv = blend(data.corner_uv[prim])
    for index, texture in enumerate(data.textures):
        rows = np.nonzero(k == index)[0]
        if texture is not None and len(rows):
            out[rows] *= sample_texture(texture, uv[rows])
    return out.astype(np.float64)


def camera_rays(camera: Camera, ox=0.5, oy=0.5) -> tuple[np.ndarray, np.ndarray]:
    """(H*W, 3) origins and unit directions through (px + ox, py + oy), row 0 at
    the top, float32; ox, oy scalars or per pixel."""
    w, h = camera.width, camera.height
    forward, right, up = (v.astype(f32) for v in camera.basis())
    scale_x, scale_y = (f32(s) for s in camera.scales())
    px, py = np.meshgrid(np.arange(w, dtype=f32), np.arange(h, dtype=f32))
    sx = (f32(2) * (px.ravel() + np.asarray(ox, f32)) / f32(w) - f32(1)) * scale_x
    sy = (f32(1) - f32(2) * (py.ravel() + np.asarray(oy, f32)) / f32(h)) * scale_y
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


def certain_t_error(ax, ay, az_raw, bx, by, bz_raw, cx, cy, cz_raw, za, zb, zc, shear_x, shear_y, det, t):
    """triangle.cl's certain_t_error, the same float32 operations in the same
    order: a bound of the error of a hit's t (inf where none holds)."""
    def max3(a, b, c):
        return np.maximum(a, np.maximum(b, c))
    u2 = f32(2) * U_BOUND
    max_x = max3(np.abs(ax), np.abs(bx), np.abs(cx))
    max_y = max3(np.abs(ay), np.abs(by), np.abs(cy))
    max_az = max3(np.abs(az_raw), np.abs(bz_raw), np.abs(cz_raw))
    max_z = max3(np.abs(za), np.abs(zb), np.abs(zc))
    dx = U_BOUND * (f32(2) * max_x + f32(3) * np.abs(shear_x) * max_az)
    dy = U_BOUND * (f32(2) * max_y + f32(3) * np.abs(shear_y) * max_az)
    dz = u2 * max_z
    x1, y1, z1, x2, y2, z2 = bx - ax, by - ay, zb - za, cx - ax, cy - ay, zc - za
    nx, ny = y1 * z2 - z1 * y2, z1 * x2 - x1 * z2
    sx, sy, sz = (np.maximum(np.abs(a), np.abs(b)) for a, b in ((x1, x2), (y1, y2), (z1, z2)))
    ex, ey, ez = U_BOUND * sx + f32(2) * dx, U_BOUND * sy + f32(2) * dy, U_BOUND * sz + f32(2) * dz
    err_nx = f32(4) * U_BOUND * sy * sz + f32(2) * (sy * ez + sz * ey + ey * ez)
    err_ny = f32(4) * U_BOUND * sx * sz + f32(2) * (sx * ez + sz * ex + ex * ez)
    e = f32(6) * (max_x * dy + max_y * dx + dx * dy) + f32(4) * U_BOUND * np.abs(det)
    room = np.abs(det) - e
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        bound = (f32(7) * U_BOUND * max_z + f32(10) * U_BOUND * np.abs(t)
                 + ((np.abs(nx) + err_nx) * dx + (np.abs(ny) + err_ny) * dy) / room)
    return np.where(room > 0, bound, f32(np.inf))


def _dop(a, b, c, d):
    """Kahan's difference of products a*b - c*d, as triangle.cl computes it;
    float64 stands in for fma (products of float32 values are exact in it)."""
    a, b, c, d = (x.astype(np.float64) for x in (a, b, c, d))
    w = (c * d).astype(f32).astype(np.float64)
    e = (w - c * d).astype(f32)
    f = (a * b - w).astype(f32)
    return f + e


def watertight(origins, perm, shear, tri) -> dict:
    """The watertight test's steps (triangle.cl) for every ray against every
    triangle of ``tri`` (K, 3, 3) float32, rays set up by :func:`_shear`:
    (N, K) float32 arrays of the sheared corners "ax", "ay", "az" (scaled
    depth), "az_raw" (depth before the shear) and so on for b and c, the edge
    functions "U", "V", "W", "det", "t" and "inside"."""
    idx = perm[:, None, :]
    sx, sy, sz = (shear[:, k, None] for k in range(3))
    out = {}
    for name, k in (("a", 0), ("b", 1), ("c", 2)):
        p = tri[None, :, k, :] - origins[:, None, :]                   # (N, K, 3)
        p = np.take_along_axis(p, np.broadcast_to(idx, p.shape), 2)
        out.update({name + "x": p[..., 0] - sx * p[..., 2], name + "y": p[..., 1] - sy * p[..., 2],
                    name + "z": sz * p[..., 2], name + "z_raw": p[..., 2]})
    U = _dop(out["cx"], out["by"], out["cy"], out["bx"])
    V = _dop(out["ax"], out["cy"], out["ay"], out["cx"])
    W = _dop(out["bx"], out["ay"], out["by"], out["ax"])
    det = U + V + W
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (U * out["az"] + V * out["bz"] + W * out["cz"]) / det
    inside = ~(((U < 0) | (V < 0) | (W < 0)) & ((U > 0) | (V > 0) | (W > 0)))
    out.update(U=U, V=V, W=W, det=det, t=t, inside=inside)
    return out


def certain_error_of(w: dict, shear) -> np.ndarray:
    """certain_t_error of every hit in a :func:`watertight` result."""
    return certain_t_error(w["ax"], w["ay"], w["az_raw"], w["bx"], w["by"], w["bz_raw"], w["cx"], w["cy"],
                           w["cz_raw"], w["az"], w["bz"], w["cz"], shear[:, 0, None], shear[:, 1, None], w["det"],
                           w["t"])


def intersect(origins, dirs, corners, tmin, tmax, block: int = 64, any_hit: bool = False, spawned: bool = False):
    """Closest hit (or any hit) of every ray against every triangle.

    origins, dirs: (N, 3) float32; corners: (F, 3, 3) float32; tmin, tmax: (N,).
    ``spawned``: the rays leave surfaces (from :func:`spawn_origin`) and take only
    hits certainly in (0, tmax] (triangle.cl's certain_t_error).
    Returns t (inf on a miss), prim (-1), u, v -- or, with ``any_hit``, a bool mask.
    """
    n = len(origins)
    perm, shear = _shear(dirs)
    best_t = np.full(n, np.inf, f32)
    best_prim = np.full(n, -1, np.int64)
    best_u = np.zeros(n, f32)
    best_v = np.zeros(n, f32)
    limit = np.asarray(tmax, f32).copy()
    end = limit.copy()
    tmin = np.asarray(tmin, f32)
    for start in range(0, len(corners), block):
        w = watertight(origins, perm, shear, corners[start:start + block])
        t, det = w["t"], w["det"]
        ok = w["inside"] & (det != 0) & (t > tmin[:, None]) & (t <= limit[:, None])
        if spawned and ok.any():
            error = certain_error_of(w, shear)
            with np.errstate(over="ignore", invalid="ignore"):
                ok &= (t > error) & (t + error <= end[:, None])
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
        best_u[rows] = w["V"][rows, kk] / det[rows, kk]
        best_v[rows] = w["W"][rows, kk] / det[rows, kk]
        limit = np.minimum(limit, best_t)
    if any_hit:
        return best_prim >= 0
    return best_t, best_prim.astype(np.int32), best_u, best_v


def surface(data: SceneData, origins, dirs, t, prim, u, v) -> dict:
    """What shading needs at each hit (all rays must hit): point, normals, side,
    material, and how far rays leaving the point start off it (shading.cl's
    surface_point: the point from the corners and u, v in float32, and its error
    bound; ``origins`` and ``t`` do not enter it)."""
    v0, v1, v2 = (data.corners[prim, k].astype(np.float64) for k in range(3))
    d = dirs.astype(np.float64)
    wound = np.cross(v1 - v0, v2 - v0)
    wound /= np.linalg.norm(wound, axis=1, keepdims=True)
    front = np.einsum("ij,ij->i", wound, d) < 0
    ng = np.where(front[:, None], wound, -wound)
    k = data.material[prim]
    mat = {name: getattr(data, name)[k] for name in SceneData.FIELDS + ("smooth",)}
    mat["color"] = albedo(data, prim, u, v)
    smooth = mat["smooth"]
    vn = data.vertex_normals
    corner = data.vertex[prim]
    w0 = 1.0 - u - v
    ns = w0[:, None] * vn[corner[:, 0]] + u[:, None] * vn[corner[:, 1]] + v[:, None] * vn[corner[:, 2]]
    ns_len = np.linalg.norm(ns, axis=1, keepdims=True)
    use = smooth & (ns_len[:, 0] > 0)
    n = np.where(use[:, None], ns / np.where(ns_len > 0, ns_len, 1), ng)
    n[np.einsum("ij,ij->i", n, ng) < 0] *= -1
    return {**point_and_offset(data.corners[prim], u, v, ng), "n": n, "front": front, "mat": mat, "d": d}


def point_and_offset(corners, u, v, ng) -> dict:
    """shading.cl's surface_point for hits (u, v) of triangles (N, 3, 3) float32
    seen from the side of their unit normals ng (N, 3): the point from the
    corners (float32, the kernels' operations), ``offset``, how far rays leaving
    it start off the surface (its error bound, shading.cl says why), and ng."""
    c0, c1, c2 = (corners[:, k] for k in range(3))
    uu, vv = (np.asarray(x, f32)[:, None] for x in (u, v))
    w0 = f32(1) - uu - vv
    p = w0 * c0 + uu * c1 + vv * c2
    error = (f32(3) * U_BOUND * (np.abs(w0 * c0) + np.abs(uu * c1) + np.abs(vv * c2))
             + f32(2) * U_BOUND * np.abs(c0))
    e1, e2 = (c.astype(np.float64) - c0 for c in (c1, c2))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.fmin(10 * float(U_BOUND) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                    / np.linalg.norm(np.cross(e1, e2), axis=1) + 16 * float(U_BOUND), 0.25)
    offset = ((np.abs(ng) * error).sum(axis=1) + 3 * a * error.sum(axis=1)) / (1 - 2 * a)
    return {"p": p, "offset": offset, "ng": ng}


def spawn_origin(s: dict, w: np.ndarray, rows=slice(None)) -> np.ndarray:
    """(N, 3) float32 origins of rays that leave the points s["p"][rows] in
    directions w (shading.cl's spawn_origin): s["offset"] off the surface on w's
    side, each component rounded away from it."""
    ng = s["ng"][rows]
    away = np.where((np.einsum("ij,ij->i", w, ng) < 0)[:, None], -ng, ng).astype(f32)
    o = s["p"][rows] + s["offset"][rows].astype(f32)[:, None] * away
    return np.where(away != 0, np.nextafter(o, np.copysign(f32(np.inf), away)), o).astype(f32)


def spot_falloff(light, w) -> np.ndarray:
    """(N,) share of a spot light's intensity towards the unit directions ``w``
    (N, 3) from it: smoothstep between the cone's and the beam's cosines."""
    lo, hi = math.cos(math.radians(light.cutoff)), math.cos(math.radians(light.beam))
    c = w @ np.asarray(light.direction, np.float64)
    if not hi - lo > 0:
        return (c >= lo).astype(np.float64)
    t = np.clip((c - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def local_shading(data: SceneData, scene: Scene, s: dict) -> np.ndarray:
    """(N, 3) Phong ambient + diffuse + specular, each light behind one shadow ray
    (every surface blocks light fully, transparent ones included)."""
    mat, n_s, ng, d = s["mat"], s["n"], s["ng"], s["d"]
    albedo = mat["color"]
    out = mat["ambient"][:, None] * albedo * np.asarray(scene.ambient_light, np.float64)
    for light in scene.lights:
        position = np.asarray(light.position, np.float64)
        shadow_origin = spawn_origin(s, position - s["p"])
        to_light = position - shadow_origin
        dist = np.linalg.norm(to_light, axis=1)
        l = to_light / dist[:, None]
        n_dot_l = np.einsum("ij,ij->i", n_s, l)
        lit = (np.einsum("ij,ij->i", ng, l) > 0) & (n_dot_l > 0)
        rows = np.nonzero(lit)[0]
        blocked = intersect(shadow_origin[rows], l[rows].astype(f32), data.corners,
                            np.zeros(len(rows), f32), dist[rows].astype(f32), any_hit=True, spawned=True)
        lit[rows[blocked]] = False
        reflected = 2 * n_dot_l[:, None] * n_s - l
        r_dot_v = np.maximum(np.einsum("ij,ij->i", reflected, -d), 0)
        lc = np.asarray(light.color, np.float64)
        if light.direction is not None:   # a spot light: the kernels' spot_falloff (shading.cl)
            lc = lc * spot_falloff(light, -l)[:, None]
        diffuse = mat["diffuse"][:, None] * n_dot_l[:, None] * albedo * lc
        spec = (mat["specular"] * np.power(r_dot_v, mat["shininess"]))[:, None] * lc
        out += np.where(lit[:, None], diffuse + spec, 0.0)
    return out


MIN_RAY_WEIGHT = 1e-3


def _bounce(s: dict):
    """Reflected direction, refracted direction and Fresnel reflectance F (Schlick;
    1 under total internal reflection) -- whitted.cl's reflect_dir and fresnel_refract."""
    d, n, ng, front = s["d"], s["n"], s["ng"], s["front"]
    dot = lambda a, b: np.einsum("ij,ij->i", a, b)   # noqa: E731
    r = d - 2 * dot(d, n)[:, None] * n
    r = np.where((dot(r, ng) > 0)[:, None], r, d - 2 * dot(d, ng)[:, None] * ng)
    ior = s["mat"]["ior"].astype(np.float64)
    eta = np.where(front, 1 / ior, ior)
    cos_i = -dot(d, n)
    flip = ~(cos_i > 0)
    n = np.where(flip[:, None], ng, n)
    cos_i = -dot(d, n)
    k = 1 - eta ** 2 * (1 - cos_i ** 2)
    tir = k < 0
    cos_t = np.sqrt(np.maximum(k, 0))
    refr = eta[:, None] * d + (eta * cos_i - cos_t)[:, None] * n
    refr /= np.maximum(np.linalg.norm(refr, axis=1, keepdims=True), 1e-300)
    r0 = ((ior - 1) / (ior + 1)) ** 2
    c = 1 - np.where(front, cos_i, cos_t)
    f = np.where(tir, 1.0, r0 + (1 - r0) * c ** 5)
    return r, refr, f


def trace_whitted(data: SceneData, scene: Scene, origins, dirs, max_depth: int):
    """Colour along each camera ray (whitted.cl's model), traced in waves of
    secondary rays; also the camera rays' (t, prim)."""
    corners = data.corners
    n = len(origins)
    color = np.zeros((n, 3))
    o, d = origins.astype(f32), dirs.astype(f32)
    weight = np.ones((n, 3))
    pixel = np.arange(n)
    depth = 0
    first = None
    while len(o):
        t, prim, u, v = intersect(o, d, corners, np.zeros(len(o), f32), np.full(len(o), np.inf, f32),
                                  spawned=depth > 0)
        if first is None:
            first = (t, prim)
        miss = prim < 0
        np.add.at(color, pixel[miss], weight[miss] * np.asarray(scene.background, np.float64))
        hit = np.nonzero(~miss)[0]
        if len(hit) == 0:
            break
        s = surface(data, o[hit], d[hit], t[hit], prim[hit], u[hit], v[hit])
        np.add.at(color, pixel[hit], weight[hit] * local_shading(data, scene, s))
        if depth >= max_depth:
            break
        kr, kt = s["mat"]["reflectivity"].astype(np.float64), s["mat"]["transparency"].astype(np.float64)
        refl, refr, f = _bounce(s)
        f = np.where(kt > 0, f, 0.0)
        w_refl = weight[hit] * (kr + kt * f)[:, None]
        w_refr = weight[hit] * (kt * (1 - f))[:, None] * s["mat"]["color"]
        go_refl = (w_refl.max(axis=1) >= MIN_RAY_WEIGHT) & ((kr > 0) | (kt > 0))
        go_refr = (kt > 0) & (f < 1) & (w_refr.max(axis=1) >= MIN_RAY_WEIGHT)
        o = np.concatenate([spawn_origin(s, refl[go_refl], go_refl), spawn_origin(s, refr[go_refr], go_refr)])
        d = np.concatenate([refl[go_refl], refr[go_refr]]).astype(f32)
        weight = np.concatenate([w_refl[go_refl], w_refr[go_refr]])
        pixel = np.concatenate([pixel[hit][go_refl], pixel[hit][go_refr]])
        depth += 1
    return color, first


def srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear RGB to 8-bit sRGB (IEC 61966-2-1), clamped."""
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.rint(255.0 * s).astype(np.uint8)


def hash_u32(x: np.ndarray) -> np.ndarray:
    """camera.cl's lowbias32 integer hash, in uint32 arithmetic."""
    x = np.asarray(x, np.uint32)
    x = x ^ (x >> np.uint32(16))
    x = x * np.uint32(0x7FEB352D)
    x = x ^ (x >> np.uint32(15))
    x = x * np.uint32(0x846CA68B)
    return x ^ (x >> np.uint32(16))


def sample_offsets(pixels: int, sample: int, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """camera.cl's sample_offset for every pixel: the centre, or a jittered point
    in cell (sample % n, sample // n) of an n x n grid."""
    if n <= 1:
        half = np.full(pixels, 0.5, f32)
        return half, half
    with np.errstate(over="ignore"):
        key = hash_u32(np.uint32(seed)) ^ ((np.arange(pixels, dtype=np.uint32) * np.uint32(n * n)
                                            + np.uint32(sample)) * np.uint32(2))
        jx = (hash_u32(key) >> np.uint32(8)).astype(f32) * f32(1 / 16777216)
        jy = (hash_u32(key + np.uint32(1)) >> np.uint32(8)).astype(f32) * f32(1 / 16777216)
    return (f32(sample % n) + jx) / f32(n), (f32(sample // n) + jy) / f32(n)


def render_reference(scene: Scene, camera: Camera, samples: int | None = None,
                     max_depth: int | None = None, seed: int = 0):
    """(image float64 (H, W, 3) linear, prim (H, W) int32, t (H, W) float32) --
    prim and t of the first sample's camera rays."""
    samples = scene.samples if samples is None else samples
    max_depth = (scene.max_depth if scene.max_depth is not None else DEFAULT_MAX_DEPTH) if max_depth is None \
        else max_depth
    data = SceneData(scene)
    shape = (camera.height, camera.width)
    image = np.zeros((camera.width * camera.height, 3))
    first = None
    for sample in range(samples * samples):
        o, d = camera_rays(camera, *sample_offsets(image.shape[0], sample, samples, seed))
        color, hits = trace_whitted(data, scene, o, d, max_depth)
        image += color / (samples * samples)
        first = first or hits
    t, prim = first
    return image.reshape(*shape, 3), prim.reshape(shape), t.reshape(shape)

"""An independent numpy Whitted tracer (flat-shaded triangles only), the
reference of tests/test_optics_numpy.py and tests/test_camera_numpy.py.

Written from the documentation (README, docs/scene-files.md) and the kernels'
formula comments, not from clrt/reference.py.
"""
import math
import numpy as np

# How far this float64 tracer starts rays that leave a surface.  clrt's rays
# start off the surface by the float32 error of the hit point (about 1e-7 of
# its coordinates, docs/limits.md "Precision"); in float64 a far smaller step clears
# the surface, and moves the light's direction by nothing the tests can see.
SPAWN_EPS = 1e-9


def cam_basis(eye, target, up):
    eye, target, up = (np.asarray(a, float) for a in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    return f, r, u


def camera_dir(eye, target, up, fov, W, H, px, py, ox=0.5, oy=0.5):
    """Pinhole ray through image point (px+ox, py+oy); vertical fov; row 0 at top."""
    f, r, u = cam_basis(eye, target, up)
    t = math.tan(math.radians(fov) / 2)
    sx = (2 * (px + ox) / W - 1) * t * W / H
    sy = (1 - 2 * (py + oy) / H) * t
    d = f + sx * r + sy * u
    return d / np.linalg.norm(d)


def project(eye, target, up, fov, W, H, point):
    """Continuous image coordinates (x, y) of a 3D point (pixel px covers [px, px+1))."""
    f, r, u = cam_basis(eye, target, up)
    q = np.asarray(point, float) - np.asarray(eye, float)
    z = q @ f
    t = math.tan(math.radians(fov) / 2)
    x_ndc = (q @ r) / z / (t * W / H)
    y_ndc = (q @ u) / z / t
    return (x_ndc + 1) * W / 2, (1 - y_ndc) * H / 2


class Tracer:
    def __init__(self, tris, mats, lights, ambient_light=(1, 1, 1), background=(0, 0, 0), eps=1e-4, max_depth=5):
        """tris: (T,3,3); mats: list of dicts per triangle; lights: list of (pos, colour)."""
        self.tris = np.asarray(tris, float)
        self.mats = mats
        self.lights = [(np.asarray(p, float), np.asarray(c, float)) for p, c in lights]
        self.amb = np.asarray(ambient_light, float)
        self.bg = np.asarray(background, float)
        self.eps = eps
        self.max_depth = max_depth
        v0, v1, v2 = self.tris[:, 0], self.tris[:, 1], self.tris[:, 2]
        n = np.cross(v1 - v0, v2 - v0)
        self.wound = n / np.linalg.norm(n, axis=1, keepdims=True)

    def intersect(self, o, d, tmin=0.0, tmax=np.inf):
        v0, v1, v2 = self.tris[:, 0], self.tris[:, 1], self.tris[:, 2]
        e1, e2 = v1 - v0, v2 - v0
        p = np.cross(d, e2)
        det = (e1 * p).sum(1)
        with np.errstate(all="ignore"):
            inv = 1.0 / det
            s = o - v0
            u = (s * p).sum(1) * inv
            q = np.cross(s, e1)
            v = (q * d).sum(1) * inv
            t = (e2 * q).sum(1) * inv
        ok = (np.abs(det) > 1e-15) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > tmin) & (t < tmax)
        if not ok.any():
            return np.inf, -1
        t = np.where(ok, t, np.inf)
        i = int(np.argmin(t))
        self.last_uv = (float(u[i]), float(v[i]))
        return float(t[i]), i

    vnormals = None   # optional (T, 3, 3) corner normals for smooth shading

    def shading_normal(self, i, ng, uv):
        if self.vnormals is None or not self.mats[i].get("smooth", True):
            return ng
        u, v = uv
        n = (1 - u - v) * self.vnormals[i, 0] + u * self.vnormals[i, 1] + v * self.vnormals[i, 2]
        n = n / np.linalg.norm(n)
        return -n if n @ ng < 0 else n

    def local(self, p, d, i, ng, n=None):
        n = ng if n is None else n
        m = self.mats[i]
        col = np.asarray(m["color"], float)
        c = m["ambient"] * col * self.amb
        for L, lc in self.lights:
            so = p + self.eps * ng
            tl = L - so
            dist = np.linalg.norm(tl)
            l = tl / dist
            if ng @ l <= 0 or n @ l <= 0:
                continue
            if self.intersect(so, l, 0.0, dist)[1] >= 0:
                continue
            ndl = n @ l
            R = 2 * ndl * n - l
            rv = max(R @ -d, 0.0)
            c = c + m["diffuse"] * ndl * col * lc
            if m["specular"] > 0 and rv > 0:
                c = c + m["specular"] * rv ** m["shininess"] * lc
        return c

    def trace(self, o, d, depth=0, info=None, weight=None, cutoff=0.0):
        weight = np.ones(3) if weight is None else weight
        t, i = self.intersect(o, d)
        if info is not None:
            info.append((depth, t, i))
        if i < 0:
            return self.bg.copy()
        m = self.mats[i]
        p = o + t * d
        front = self.wound[i] @ d < 0
        ng = self.wound[i] if front else -self.wound[i]
        n = self.shading_normal(i, ng, self.last_uv)
        c = self.local(p, d, i, ng, n)
        kr, kt = m.get("reflectivity", 0.0), m.get("transparency", 0.0)
        if depth >= self.max_depth or (kr <= 0 and kt <= 0):
            return c
        refl = d - 2 * (d @ n) * n
        if refl @ ng <= 0:
            refl = d - 2 * (d @ ng) * ng
        rw = kr
        if kt > 0:
            ior = m.get("ior", 1.5)
            eta = 1 / ior if front else ior
            nn = n
            cos_i = -(d @ n)
            if not cos_i > 0:
                nn, cos_i = ng, -(d @ ng)
            k = 1 - eta * eta * (1 - cos_i ** 2)
            if k < 0:
                F = 1.0
            else:
                cos_t = math.sqrt(k)
                tdir = eta * d + (eta * cos_i - cos_t) * nn
                tdir /= np.linalg.norm(tdir)
                r0 = ((ior - 1) / (ior + 1)) ** 2
                cc = 1 - (cos_i if front else cos_t)
                F = r0 + (1 - r0) * cc ** 5
                wt = weight * kt * (1 - F) * np.asarray(m["color"], float)
                if wt.max() >= cutoff:
                    c = c + kt * (1 - F) * np.asarray(m["color"], float) * self.trace(self.spawn(p, ng, tdir), tdir,
                                                                                      depth + 1, info, wt, cutoff)
            rw += kt * F
        if rw > 0 and (weight * rw).max() >= max(cutoff, 1e-300):
            c = c + rw * self.trace(self.spawn(p, ng, refl), refl, depth + 1, info, weight * rw, cutoff)
        return c

    def spawn(self, p, ng, d):
        """Origin of a ray that leaves point p in direction d: eps off the surface,
        on the side d leaves to (a refracted ray bent by an interpolated normal
        may leave to the side the light came from)."""
        return p + self.eps * ng if d @ ng >= 0 else p - self.eps * ng


def srgb8(x):
    x = np.clip(np.asarray(x, float), 0, 1)
    e = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.floor(255 * e + 0.5).astype(np.uint8)


def quad(center, size, normal="y"):
    """Quad in a plane through center; normal '+y' etc. Wound to face the given axis."""
    cx, cy, cz = center
    a, b = size[0] / 2, size[1] / 2
    if normal == "+y":
        v = [(cx - a, cy, cz - b), (cx - a, cy, cz + b), (cx + a, cy, cz + b), (cx + a, cy, cz - b)]
    elif normal == "+z":
        v = [(cx - a, cy - b, cz), (cx + a, cy - b, cz), (cx + a, cy + b, cz), (cx - a, cy + b, cz)]
    elif normal == "-z":
        v = [(cx - a, cy - b, cz), (cx - a, cy + b, cz), (cx + a, cy + b, cz), (cx + a, cy - b, cz)]
    elif normal == "+x":
        v = [(cx, cy - a, cz - b), (cx, cy + a, cz - b), (cx, cy + a, cz + b), (cx, cy - a, cz + b)]
    else:
        raise ValueError(normal)
    v = np.array(v, float)
    return v, np.array([[0, 1, 2], [0, 2, 3]])

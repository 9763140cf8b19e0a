"""How far from a scene its rays may start: the float32 range of the triangle test.

Woop's watertight test (triangle.cl) measures a triangle from the ray's
origin and ends with ``T = U*(Sz*Az) + V*(Sz*Bz) + W*(Sz*Cz)``, ``t = T / det``.
For a ray that meets the triangle, U, V and W share a sign and add up to
``det``, twice the area of the triangle sheared along the ray, and each
``Sz*z`` is a corner's depth along the ray, so ``|T| <= det * sqrt(3) * rho``
(rho: the distance from the origin to the triangle's farthest corner;
``|Sz| <= sqrt(3)`` for a unit direction).  The sheared triangle is the
triangle seen along the ray, stretched by at most sqrt(3), and its corners
carry up to ``6 u rho`` of rounding each (u = 2^-24: the origin subtracted,
the shear applied), so

    det <= 2 sqrt(3) A + 90 u L rho + 470 u^2 rho^2
    |T| <= 6 A rho + 9.3e-6 L rho^2 + 2.9e-12 rho^3          (A: area, L: longest edge)

When that stays below FLT_MAX nothing in the test overflows (its other
products are smaller).  Past it, T becomes infinite or NaN and the hit is
lost: silently, a triangle 1e12 across seen from 1e15 away is missed (the
first term), and so is every oblique ray from past ~5e16 (the last one, where
rounding alone outgrows any triangle).  The bound is conservative by a factor
of about three against the overflows measured on PoCL (docs/limits.md,
"Precision"), so it refuses only scenes within that factor of losing hits.

:class:`Reach` holds a scene's side of the bound; the queries check a
camera's eye against it (``Accel.camera_images``, ``trace_camera``) and the
renderer its eye and the scene's own secondary rays, raising one InputError
instead of missing hits.  A batch's own origins are checked on the device,
where the kernels check every ray anyway (rays.cl, ``BAD_REACH``): the host
hands them the box and :meth:`Reach.batch_limit` and makes no pass over the
rays; :meth:`Reach.message` words the error for the first ray refused.
"""

from __future__ import annotations

import math

import numpy as np

from clrt import checks
from clrt.errors import InputError

FLT_MAX = float(np.finfo(np.float32).max)
# The bound's terms (module docstring), rounded up; the last factor covers
# the relative rounding of the products and sums that form T (a few u).
_AREA, _EDGE, _ROUNDING = 6.0, 9.3e-6, 2.9e-12
_SLACK = 1.0 + 1e-5
# Scenes up to this diagonal bound their triangles by it (no pass over them):
# the first term then passes FLT_MAX only where the last one has already
# (rho > 5e16), so measuring would refuse nothing less.  Larger scenes are
# measured once, when made (an O(F) pass; 0.15 s per million triangles on
# the 2-core development machine).
MEASURE_DIAGONAL = 1e9
_BLOCK = 1 << 18                    # triangles measured at a time (bounded temporaries)
# How far from a surface, relative to the scene's largest coordinate M, rays
# leaving it may start (shading.cl): the hit point's error is at most
# 5 x 6e-8 M per component, the offset at most (sqrt(3) + 2.25) / 0.5 times
# that, plus an ulp (1.2e-7 M): 2.5e-6 M, rounded up.
SPAWN_REACH = 3e-6


def _farthest(lo_a, hi_a, lo_b, hi_b) -> float:
    """The largest distance between a point of box a and a point of box b."""
    span = np.maximum(np.asarray(hi_b, np.float64) - lo_a, np.asarray(hi_a, np.float64) - lo_b)
    with np.errstate(over="ignore"):
        return float(np.linalg.norm(span))


def _largest_triangle(corners: np.ndarray) -> tuple[float, float]:
    """(largest area, longest edge) of (F, 3, 3) float32 corners, in float64."""
    area2 = edge2 = 0.0
    for start in range(0, len(corners), _BLOCK):
        c = corners[start:start + _BLOCK].astype(np.float64)
        e1, e2, e3 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], c[:, 2] - c[:, 1]
        cross = np.cross(e1, e2)
        area2 = max(area2, float(np.einsum("ij,ij->i", cross, cross).max(initial=0.0)))
        edge2 = max(edge2, *(float(np.einsum("ij,ij->i", e, e).max(initial=0.0)) for e in (e1, e2, e3)))
    return 0.5 * math.sqrt(area2), math.sqrt(edge2)


class Reach:
    """A scene's side of the float32 range of the triangle test (module docstring).

    ``corners``: (F, 3, 3) float32 triangle corners (not kept); ``bounds``:
    (2, 3) their min and max corner (computed from ``corners`` when None).
    Without ``corners`` (a two-level scene, whose triangles lie in their
    meshes' frames) a large scene's triangles are bounded by its diagonal too,
    as a small one's are: a larger bound, so a limit that refuses sooner.
    """

    def __init__(self, corners: np.ndarray, bounds=None):
        if bounds is None:
            flat = corners.reshape(-1, 3)
            bounds = [[flat[:, k].min() for k in range(3)], [flat[:, k].max() for k in range(3)]]
        self.lo, self.hi = (np.asarray(b, np.float64) for b in bounds)
        self._limit = None   # limit(), found once
        self._render_checked = None   # the last eye check_render passed
        self.diagonal = float(np.linalg.norm(self.hi - self.lo))
        if self.diagonal > MEASURE_DIAGONAL and corners is not None:
            self.area, self.edge = _largest_triangle(corners)
        else:
            # Every triangle lies in the bounds: no edge is longer than the diagonal,
            # no area larger than an equilateral triangle's of that side.
            self.area, self.edge = math.sqrt(3.0) / 4.0 * self.diagonal ** 2, self.diagonal

    def largest_t(self, rho: float) -> float:
        """An upper bound of |T| for rays whose origins lie within ``rho`` of
        every corner of the scene (module docstring)."""
        with np.errstate(over="ignore"):
            return float(_SLACK * (_AREA * self.area * rho + _EDGE * self.edge * rho ** 2 + _ROUNDING * rho ** 3))

    def limit(self) -> float:
        """The largest distance from the scene's far side at which a ray may start."""
        if self._limit is None:
            lo, hi = 1e-30, 1e39
            for _ in range(100):   # bisection, in ratios, of a bound that grows with rho
                mid = math.sqrt(lo * hi)
                lo, hi = (mid, hi) if self.largest_t(mid) < FLT_MAX else (lo, mid)
            self._limit = lo
        return self._limit

    def batch_limit(self) -> float:
        """The distance the query kernels hold each batch origin to (rays.cl's
        ``reach2`` is its square): :meth:`limit`.  (Tests make it infinite to
        see what the device does past the limit.)"""
        return self.limit()

    def farthest(self, lo, hi=None) -> float:
        """The largest distance from a point of the box ``lo``..``hi`` (a point
        when ``hi`` is None) to the scene's far side (inf past float64)."""
        return _farthest(lo, lo if hi is None else hi, self.lo, self.hi)

    def message(self, what: str, rho: float) -> str:
        """The error for rays that start ``rho`` from the scene's far side, past
        the limit; ``what`` names them and says where they lie (see :meth:`check`)."""
        show = lambda x: checks.show(float(f"{x:.2g}"))   # noqa: E731
        return (f"{what} {show(rho)} from the scene's far side, but the device's float32 triangle "
                f"test overflows and misses hits on this scene's triangles from about "
                f"{show(self.limit())}: start the rays nearer, or scale the scene down")

    def check(self, lo, hi, what: str) -> None:
        """InputError when rays whose origins lie in the box ``lo``..``hi`` (3
        numbers each; equal for one point) could overflow the triangle test on
        this scene.  ``what`` names the origins and says where they lie, e.g.
        "the camera's eye lies".  Origins that are not finite are left to the
        kernels' own check (rays.cl), which names the first bad ray."""
        rho = self.farthest(lo, hi)
        if not math.isfinite(rho) or self.largest_t(rho) < FLT_MAX:
            return
        raise InputError(self.message(what, rho))

    def check_render(self, eye, where=None) -> None:
        """:meth:`check` for a frame: the shadow, reflection and refraction rays
        that start on the surfaces, off them by their hit points' float32 error
        (shading.cl's spawn_origin): under 3e-6 of the largest coordinate
        (``SPAWN_REACH``), and the rays from the camera's ``eye``.  The first
        fail whatever the camera: then the scene is too large, and the error
        begins with ``where()`` (the geometry that makes it so:
        clrt.scene.scene.far_triangle), else with the camera's rays."""
        key = tuple(float(x) for x in eye)
        if key == self._render_checked:   # every frame of one view asks again: answered once
            return
        eye = np.asarray(key, np.float64)
        off = SPAWN_REACH * float(np.max(np.abs([self.lo, self.hi])))
        lo, hi = self.lo - off, self.hi + off
        rho = self.farthest(lo, hi)
        if math.isfinite(rho) and self.largest_t(rho) >= FLT_MAX:
            show = lambda x: checks.show(float(f"{x:.2g}"))   # noqa: E731
            raise InputError(f"{where() if where else 'the scene'}: the scene is too large: the device's float32 "
                             f"triangle test overflows and misses hits on its triangles from about "
                             f"{show(self.limit())} away, and rays between its surfaces start up to {show(rho)} "
                             "from its far side: fix that geometry, or scale the scene down")
        self.check(np.minimum(eye, lo), np.maximum(eye, hi), "the camera's rays start up to")
        self._render_checked = key

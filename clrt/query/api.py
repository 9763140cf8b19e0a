"""The one-call forms of the ray and point queries: build an Accel, ask once.

All share one keyword-only signature after the rays: the query's own range
(``tmin``, ``tmax``) and ``cull``, then the acceleration options of
:class:`~clrt.query.accel.Accel` (``accel``, ``builder``, ``leaf_size``,
``device``, ``chunk_rays``).  To query a mesh many times, build an Accel once.
"""

from __future__ import annotations

import numpy as np

from clrt.config import DEFAULT_ACCEL, DEFAULT_BUILDER, DEFAULT_LEAF_SIZE
from clrt.query.accel import Accel
from clrt.query.inside import sign_kernel
from clrt.query.rays import cull_code
from clrt.query.results import (ALL_HITS_FIELDS, CAMERA_FIELDS, CLOSEST_FIELDS, POINT_FIELDS, AllHits, CameraImages,
                                ClosestPoints, Hits, with_fields)


def _accel(mesh, accel, builder, leaf_size, device, chunk_rays, cull) -> Accel:
    """The Accel of a one-call form; ``cull`` is checked before the (long) build."""
    cull_code(cull)
    return Accel(mesh, accel=accel, builder=builder, leaf_size=leaf_size, device=device, chunk_rays=chunk_rays)


@with_fields(CLOSEST_FIELDS, heading="Returns", lead="Hits, a named tuple of these arrays:")
def trace(mesh, origins, directions, *, tmin=0.0, tmax=np.inf, cull: str = "none",
          accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
          device: str | None = None, chunk_rays: int | None = None) -> Hits:
    """Closest hits of a batch of rays (:meth:`Accel.trace`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, cull).trace(
        origins, directions, tmin=tmin, tmax=tmax, cull=cull)


def any_hit(mesh, origins, directions, *, tmin=0.0, tmax=np.inf, cull: str = "none",
            accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
            device: str | None = None, chunk_rays: int | None = None) -> np.ndarray:
    """(N,) bool: is each ray blocked in (tmin, tmax]? (:meth:`Accel.any_hit`)"""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, cull).any_hit(
        origins, directions, tmin=tmin, tmax=tmax, cull=cull)


occluded = any_hit


def count_hits(mesh, origins, directions, *, tmin=0.0, tmax=np.inf, cull: str = "none",
               accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
               device: str | None = None, chunk_rays: int | None = None) -> np.ndarray:
    """(N,) int32 hits along each ray (:meth:`Accel.count`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, cull).count(
        origins, directions, tmin=tmin, tmax=tmax, cull=cull)


@with_fields(ALL_HITS_FIELDS, ("K",), heading="Returns", lead="AllHits, a named tuple of these arrays:")
def all_hits(mesh, origins, directions, *, tmin=0.0, tmax=np.inf, cull: str = "none",
             accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
             device: str | None = None, chunk_rays: int | None = None) -> AllHits:
    """Every hit of every ray (:meth:`Accel.all_hits`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, cull).all_hits(
        origins, directions, tmin=tmin, tmax=tmax, cull=cull)


@with_fields(CAMERA_FIELDS, ("H", "W"), heading="Returns",
             lead="CameraImages, a named tuple of these images:")
def camera_images(mesh, camera=None, *, K=None, pose=None, width=None, height=None,
                  pixel_center: float = 0.0, cull: str = "none",
                  accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
                  device: str | None = None, chunk_rays: int | None = None) -> CameraImages:
    """Depth, normal, triangle and hit images (:meth:`Accel.camera_images`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, cull).camera_images(
        camera, K=K, pose=pose, width=width, height=height, pixel_center=pixel_center, cull=cull)


# Point queries: the same acceleration options; no rays, so no range and no culling.

@with_fields(POINT_FIELDS, heading="Returns", lead="ClosestPoints, a named tuple of these arrays:")
def closest_points(mesh, points, *, max_distance=np.inf,
                   accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
                   device: str | None = None, chunk_rays: int | None = None) -> ClosestPoints:
    """The mesh's nearest point to each query point (:meth:`Accel.closest_points`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, "none").closest_points(
        points, max_distance=max_distance)


def distance(mesh, points, *, max_distance=np.inf,
             accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
             device: str | None = None, chunk_rays: int | None = None) -> np.ndarray:
    """(N,) float32 distance of each point to the mesh (:meth:`Accel.distance`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, "none").distance(
        points, max_distance=max_distance)


def signed_distance(mesh, points, *, sign: str = "winding",
                    accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
                    device: str | None = None, chunk_rays: int | None = None):
    """(N,) float32 distance of each point to the mesh, negative inside by rule
    ``sign``: "winding", "parity" or "normal" (:meth:`Accel.signed_distance`)."""
    sign_kernel(sign)   # before the build
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, "none").signed_distance(points, sign=sign)


def winding_number(mesh, points, *,
                   accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
                   device: str | None = None, chunk_rays: int | None = None):
    """(N,) float32 generalised winding number of the mesh at each point (:meth:`Accel.winding_number`)."""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, "none").winding_number(points)


def contains(mesh, points, *,
             accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
             device: str | None = None, chunk_rays: int | None = None):
    """(N,) bool: is each point inside the mesh (winding number >= 1/2; :meth:`Accel.contains`)?"""
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, "none").contains(points)


def sdf_grid(mesh, resolution, bounds=None, *, sign: str = "winding",
             accel: str = DEFAULT_ACCEL, builder: str = DEFAULT_BUILDER, leaf_size: int = DEFAULT_LEAF_SIZE,
             device: str | None = None, chunk_rays: int | None = None) -> np.ndarray:
    """(X, Y, Z) float32 signed distances at the samples of a grid over
    ``bounds`` (default: the mesh's box and a margin; :meth:`Accel.sdf_grid`)."""
    sign_kernel(sign)
    return _accel(mesh, accel, builder, leaf_size, device, chunk_rays, "none").sdf_grid(resolution, bounds,
                                                                                         sign=sign)

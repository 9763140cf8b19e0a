"""What ray queries return: closest hits, all hits, camera images (array shapes
and sentinels as documented in docs/ray-queries.md)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Hits(NamedTuple):
    """Closest hits, one entry per ray (or per pixel, as (H, W) arrays)."""

    t: np.ndarray        # (N,) float32 distance along the unit direction, inf on a miss
    prim: np.ndarray     # (N,) int32 triangle index (row of the mesh's faces), -1 on a miss
    u: np.ndarray        # (N,) float32 barycentric weight of the triangle's vertex 1, 0 on a miss
    v: np.ndarray        # (N,) float32 barycentric weight of the triangle's vertex 2, 0 on a miss
    normal: np.ndarray   # (N, 3) float32 unit geometric normal (v1-v0) x (v2-v0), zeros on a miss
    front: np.ndarray    # (N,) bool: the ray met the triangle against its normal; False on a miss
    hit: np.ndarray      # (N,) bool: prim >= 0


class AllHits(NamedTuple):
    """Every hit of every ray, as flat arrays sorted by ray, then distance, then triangle."""

    ray_id: np.ndarray   # (K,) int64 index of the ray
    prim: np.ndarray     # (K,) int32 triangle index
    t: np.ndarray        # (K,) float32 distance along the unit direction


class CameraImages(NamedTuple):
    """Per-pixel results of a camera's rays, (H, W) arrays, row 0 at the top."""

    depth: np.ndarray    # float32 distance along the optical axis (z in the camera frame), inf on a miss
    t: np.ndarray        # float32 distance along the pixel's ray from the eye, inf on a miss
    normal: np.ndarray   # (H, W, 3) float32 world-space unit geometric normal, zeros on a miss
    prim: np.ndarray     # int32 triangle index, -1 on a miss
    hit: np.ndarray      # bool
    front: np.ndarray    # bool: the front face was seen
    u: np.ndarray        # float32 barycentrics, 0 on a miss
    v: np.ndarray

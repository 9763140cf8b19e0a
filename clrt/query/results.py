"""What ray queries return: closest hits, all hits, camera images (array shapes
and sentinels as documented in docs/ray-queries.md)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


# The closest hit's outputs (query_closest in trace.cl), in kernel order.
CLOSEST_FIELDS = ("t", "prim", "u", "v", "normal", "front", "hit")
# Bytes a ray and dtype of every per-ray result (count: query_count's).
RESULT_BYTES = {"t": 4, "prim": 4, "u": 4, "v": 4, "normal": 12, "count": 4, "front": 1, "hit": 1}
RESULT_DTYPES = {"t": np.float32, "prim": np.int32, "u": np.float32, "v": np.float32, "normal": np.float32,
                 "count": np.int32, "front": np.uint8, "hit": np.uint8}


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

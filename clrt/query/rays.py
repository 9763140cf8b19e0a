"""Rays as the queries take them: validated batches from numpy, pinhole
cameras given by intrinsics and pose, and clrt's own cameras (made on the device).

Every query goes through one input path (:class:`RayBatch`, or a camera), so a
ray gives the same answer alone or in a batch, in any chunk.
"""

from __future__ import annotations

import numpy as np

from clrt.config import CULL_MODES, MAX_IMAGE_SIDE
from clrt.device.args import camera_args
from clrt.errors import InputError
from clrt.layouts import RAY
from clrt.scene.scene import check_int


def cull_code(cull: str) -> np.int32:
    """The kernels' code of a culling mode name (clrt.config.CULL_MODES)."""
    if not isinstance(cull, str) or cull not in CULL_MODES:
        raise InputError(f"cull must be one of {', '.join(map(repr, CULL_MODES))}, got {cull!r}")
    return np.int32(CULL_MODES[cull])


def _real_array(value, what: str) -> np.ndarray:
    try:
        a = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be numbers ({exc})") from None
    if a.dtype.kind not in "fiub":
        raise InputError(f"{what} must be real numbers, got dtype {a.dtype}")
    return a


def _ray_rows(value, what: str) -> np.ndarray:
    a = _real_array(value, what)
    if a.shape == (3,):
        a = a.reshape(1, 3)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{what} must have shape (3,) or (N, 3), got {a.shape}")
    return a


def _per_ray(value, n: int, what: str) -> np.ndarray:
    a = _real_array(value, what)
    if a.ndim > 1 or (a.ndim == 1 and len(a) not in (1, n)):
        raise InputError(f"{what} must be a number or have shape ({n},), got {a.shape}")
    a = a.astype(np.float64, copy=False)
    if np.isnan(a).any():
        raise InputError(f"{what} must not be NaN")
    return np.broadcast_to(a.reshape(-1) if a.ndim else a, (n,))


class RayBatch:
    """Validated rays, turned into device RAY records one chunk at a time.

    The single input path of every query: shapes and dtypes are checked here
    once; values (finite, non-zero directions) chunk by chunk, so no copy of
    the whole batch is made beyond the caller's arrays.
    """

    def __init__(self, origins, directions, tmin=0.0, tmax=np.inf):
        o = _ray_rows(origins, "origins")
        d = _ray_rows(directions, "directions")
        if len(o) != len(d) and 1 not in (len(o), len(d)):
            raise InputError(f"{len(o)} origins but {len(d)} directions")
        n = max(len(o), len(d)) if min(len(o), len(d)) > 0 else 0
        self.origins = np.broadcast_to(o, (n, 3))
        self.directions = np.broadcast_to(d, (n, 3))
        self.tmin = _per_ray(tmin, n, "tmin")
        self.tmax = _per_ray(tmax, n, "tmax")

    def __len__(self) -> int:
        return len(self.origins)

    def unit_directions(self, start: int, stop: int) -> np.ndarray:
        """(M, 3) float64 unit directions of rays start..stop-1."""
        d = self.directions[start:stop].astype(np.float64)
        length = np.linalg.norm(d, axis=1)
        bad = ~np.isfinite(length) | (length == 0)
        if bad.any():
            i = start + int(np.argmax(bad))
            raise InputError(f"direction {i} is {self.directions[i].tolist()}: "
                             "directions must be finite and non-zero")
        return d / length[:, None]

    def records(self, start: int, stop: int) -> np.ndarray:
        """RAY records (layouts.py) of rays start..stop-1."""
        o = self.origins[start:stop].astype(np.float64)
        bad = ~np.isfinite(o).all(axis=1)
        if bad.any():
            i = start + int(np.argmax(bad))
            raise InputError(f"origin {i} is {self.origins[i].tolist()}: origins must be finite")
        rays = np.empty(stop - start, RAY)
        rays["origin"][:, :3] = o
        rays["origin"][:, 3] = self.tmin[start:stop]
        rays["dir"][:, :3] = self.unit_directions(start, stop)
        rays["dir"][:, 3] = self.tmax[start:stop]
        return rays


class PinholeRays:
    """The rays of a pinhole camera given by intrinsics ``K`` (3x3) and a
    camera-to-world ``pose`` (4x4), OpenCV axes: x right, y down, z forward.

    Pixel (col, row) is traced through image point (col + c, row + c), c =
    ``pixel_center``: 0 (default) is OpenCV's convention, the top-left pixel's
    centre at (0, 0); 0.5 puts it at (0.5, 0.5).  Made one chunk at a time.
    """

    def __init__(self, K, pose, width: int, height: int, pixel_center: float = 0.0):
        check_int("width", width, 1, MAX_IMAGE_SIDE)
        check_int("height", height, 1, MAX_IMAGE_SIDE)
        K = _real_array(K, "K").astype(np.float64)
        if K.shape != (3, 3) or not np.isfinite(K).all():
            raise InputError(f"K must be a finite 3x3 matrix, got shape {K.shape}")
        if abs(np.linalg.det(K)) < 1e-300:
            raise InputError("K must be invertible")
        pose = np.eye(4) if pose is None else _real_array(pose, "pose").astype(np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise InputError(f"pose must be a finite 4x4 camera-to-world matrix, got shape {pose.shape}")
        R = pose[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-4) or np.linalg.det(R) <= 0:
            raise InputError("pose[:3, :3] must be a rotation (orthonormal, determinant +1)")
        if not np.isfinite(pixel_center):
            raise InputError("pixel_center must be finite")
        self.K_inv = np.linalg.inv(K)
        self.R, self.eye = R, pose[:3, 3].copy()
        self.width, self.height = int(width), int(height)
        self.pixel_center = float(pixel_center)

    def __len__(self) -> int:
        return self.width * self.height

    def camera_directions(self, start: int, stop: int) -> np.ndarray:
        """(M, 3) float64 unit directions in the camera frame of pixels start..stop-1."""
        pixel = np.arange(start, stop, dtype=np.int64)
        p = np.stack([pixel % self.width + self.pixel_center, pixel // self.width + self.pixel_center,
                      np.ones(len(pixel))], axis=1)
        d = p @ self.K_inv.T
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def records(self, start: int, stop: int) -> np.ndarray:
        rays = np.empty(stop - start, RAY)
        rays["origin"][:, :3] = self.eye
        rays["origin"][:, 3] = 0.0
        rays["dir"][:, :3] = self.camera_directions(start, stop) @ self.R.T
        rays["dir"][:, 3] = np.inf
        return rays


class CameraRays:
    """Our Camera's pixel-centre rays, made on the device (``camera_rays`` in
    trace.cl): exactly the rays the renderer traces."""

    def __init__(self, camera):
        self.camera = camera
        self.args = camera_args(camera)
        self.forward = camera.basis()[0]

    def __len__(self) -> int:
        return self.camera.width * self.camera.height

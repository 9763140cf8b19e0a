"""Rays as the queries take them: batches from numpy or device arrays,
pinhole cameras given by intrinsics and pose, and clrt's own cameras (made on
the device).

Every query goes through one input path (rays.cl reads and checks every ray on
the device), so a ray gives the same answer alone or in a batch, in any chunk,
and the host makes no pass over the caller's rays beyond one conversion to
float32 where they are not float32 already.
"""

from __future__ import annotations

import math

import numpy as np

from clrt import checks, config
from clrt.config import CULL_MODES
from clrt.device.args import camera_value
from clrt.errors import InputError
from clrt.query.results import CLOSEST_FIELDS, RESULT_BYTES


def cull_code(cull: str) -> np.int32:
    """The kernels' code of a culling mode name (clrt.config.CULL_MODES)."""
    return np.int32(CULL_MODES[checks.choice("cull", cull, CULL_MODES)])


def _real_array(value, what: str) -> np.ndarray:
    try:
        a = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be numbers ({exc})") from None
    if a.dtype.kind not in "fiub":
        raise InputError(f"{what} must be real numbers, got dtype {a.dtype}")
    return a


def is_device_array(value) -> bool:
    """A pyopencl.array.Array (checked without importing pyopencl.array)."""
    return type(value).__module__.startswith("pyopencl") and hasattr(value, "base_data")


def _device_rows(a, what: str, width: int):
    """A device array of float32 rows of ``width`` (3: points, 1: numbers), C-contiguous."""
    shape = tuple(a.shape)
    if width == 3 and shape == (3,):
        shape = (1, 3)
    ok = shape[1:] == (3,) if width == 3 else len(shape) == 1
    if not ok or len(shape) != (2 if width == 3 else 1):
        expected = "(3,) or (N, 3)" if width == 3 else "(N,)"
        raise InputError(f"{what} must have shape {expected}, got {tuple(a.shape)}")
    if a.dtype != np.float32 or not a.flags.c_contiguous:
        raise InputError(f"{what} on the device must be C-contiguous float32, got {a.dtype}")
    return a, shape[0]


def host_rows(value, what: str) -> np.ndarray:
    """A host array of points or vectors as (N, 3) (a single (3,) row as (1, 3));
    InputError for anything else."""
    a = _real_array(value, what)
    if a.shape == (3,):
        a = a.reshape(1, 3)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{what} must have shape (3,) or (N, 3), got {a.shape}")
    return a


# Bytes a ray's closest-hit results take on the host, every field asked for.
RESULT_BYTES_PER_RAY = sum(RESULT_BYTES[name] for name in CLOSEST_FIELDS)


def host_memory_for_rays(n: int, copies: int = 0) -> None:
    """TooLargeError when ``n`` rays' results (and ``copies`` bytes of converted
    inputs) would not fit in the host memory available now."""
    nbytes = n * RESULT_BYTES_PER_RAY + copies
    if nbytes > 1 << 28:   # small batches skip reading /proc/meminfo
        checks.host_memory(nbytes, f"a batch of {n:,} rays", "trace them in smaller batches")


class RayBatch:
    """Rays as the caller gave them, checked for shape and type only.

    The single input path of every query.  ``origins`` and ``directions`` are
    (N, 3) or (3,) arrays -- numpy arrays of any real dtype, converted once to
    float32 (as they are if already float32 and contiguous), or
    ``pyopencl.array.Array`` float32 arrays already on the device.  One of them
    may be a single row for all rays.  ``tmin``/``tmax`` are numbers or (N,)
    arrays.  Values are checked by the kernels (rays.cl), which report the
    first bad ray of each kind; :meth:`bad_ray_message` turns that into the
    error the caller sees.  ``inputs`` holds (array, floats per ray: 3, 1 or 0
    for one value shared by every ray) for origins, directions, tmin, tmax.
    """

    normalise = True   # directions from callers need not be unit length

    def __init__(self, origins, directions, tmin=0.0, tmax=np.inf):
        self.given = {"origin": origins, "direction": directions, "tmin": tmin, "tmax": tmax}
        self.on_device = any(is_device_array(v) for v in self.given.values())
        rows = []
        for what, value in (("origins", origins), ("directions", directions)):
            if is_device_array(value):
                rows.append(_device_rows(value, what, 3))
            else:
                a = host_rows(value, what)
                rows.append((a, len(a)))
        (o, no), (d, nd) = rows
        if no != nd and 1 not in (no, nd):
            raise InputError(f"{no} origins but {nd} directions")
        n = max(no, nd) if min(no, nd) > 0 else 0
        self.n = n
        if not self.on_device:   # the float32 copies and the results, before numpy's MemoryError
            copies = sum(12 * rows for a, rows in ((o, no), (d, nd))
                         if not (a.dtype == np.float32 and a.flags.c_contiguous) or rows != n)
            host_memory_for_rays(n, copies)
        self.inputs = [self._points(o, no, n), self._points(d, nd, n),
                       self._numbers(tmin, n, "tmin"), self._numbers(tmax, n, "tmax")]

    def __len__(self) -> int:
        return self.n

    @staticmethod
    def _points(a, rows: int, n: int):
        stride = 0 if rows == 1 and n != 1 else 3
        if is_device_array(a):
            return a, stride
        with np.errstate(over="ignore"):   # beyond float32: inf, reported by the kernel as not finite
            return np.ascontiguousarray(a, dtype=np.float32).reshape(-1), stride

    @staticmethod
    def _numbers(value, n: int, what: str):
        if is_device_array(value):
            a, rows = _device_rows(value, what, 1)
            if rows != n:
                raise InputError(f"{what} must be a number or have shape ({n},), got {tuple(value.shape)}")
            return a, 1
        a = _real_array(value, what)
        if a.ndim > 1 or (a.ndim == 1 and len(a) not in (1, n)):
            raise InputError(f"{what} must be a number or have shape ({n},), got {a.shape}")
        if a.size == 1:
            if np.isnan(a).any():
                raise InputError(f"{what} must not be NaN")
            with np.errstate(over="ignore"):
                return a.reshape(1).astype(np.float32), 0
        with np.errstate(over="ignore"):
            return np.ascontiguousarray(a, dtype=np.float32), 1

    @property
    def origins(self) -> np.ndarray:
        """(N, 3) the caller's origins as given (broadcast; host arrays only)."""
        return np.broadcast_to(host_rows(self.given["origin"], "origins"), (self.n, 3))

    @property
    def directions(self) -> np.ndarray:
        """(N, 3) the caller's directions as given (broadcast; host arrays only)."""
        return np.broadcast_to(host_rows(self.given["direction"], "directions"), (self.n, 3))

    def host_chunk(self, k: int, start: int, stop: int):
        """Input ``k`` of rays start..stop-1 as a host array to upload (the whole
        single row when shared)."""
        a, stride = self.inputs[k]
        return a if stride == 0 else a[start * stride:stop * stride]

    def _origin(self, i: int) -> np.ndarray:
        """(3,) the origin of ray ``i`` as given (one row read back from a device array)."""
        given = self.given["origin"]
        if is_device_array(given):
            rows = given.reshape(-1, 3)
            return rows[i:i + 1].get()[0] if len(rows) > 1 else rows.get()[0]
        rows = host_rows(given, "origins")
        return np.asarray(rows[i if len(rows) > 1 else 0])

    def bad_ray_message(self, kind: str, i: int, reach=None) -> str:
        """The error for ray ``i`` failing check ``kind`` (clrt.config.RAY_CHECKS);
        ``reach``: the scene's :class:`clrt.device.reach.Reach` (for "reach")."""
        if kind == "reach":
            row = self._origin(i)
            shown = [float(str(x)) for x in row] if row.dtype == np.float32 else row.tolist()   # float32: shortest
            return reach.message(f"origin {i} is {shown}: it lies", reach.farthest(row.astype(np.float64)))
        given = self.given[kind]
        if is_device_array(given):
            value = "not finite" if kind == "origin" else "invalid"
        else:
            a = np.asarray(given)
            row = a if a.ndim <= (0 if kind in ("tmin", "tmax") else 1) else a[i]
            value = np.asarray(row).tolist()
        overflow = ""
        if kind in ("origin", "direction") and isinstance(value, list) and all(
                isinstance(x, float) and math.isfinite(x) for x in value):
            largest = max(abs(x) for x in value)
            if largest > config.FLOAT32_MAX:   # finite as given, infinite on the device
                overflow = f": {checks.show(largest)} overflows float32 (the largest float32 is about 3.4e38);"
        if kind == "origin":
            return f"origin {i} is {value}{overflow or ':'} origins must be finite" + (" in float32" if overflow else "")
        if kind == "direction":
            return (f"direction {i} is {value}{overflow or ':'} directions must be finite"
                    + (" in float32" if overflow else "") + " and non-zero")
        return f"{kind} of ray {i} is {value}: {kind} must not be NaN"


class PinholeRays:
    """The rays of a pinhole camera given by intrinsics ``K`` (3x3) and a
    camera-to-world ``pose`` (4x4), OpenCV axes: x right, y down, z forward.

    Pixel (col, row) is traced through image point (col + c, row + c), c =
    ``pixel_center``: 0 (default) is OpenCV's convention, the top-left pixel's
    centre at (0, 0); 0.5 puts it at (0.5, 0.5).  Made one chunk at a time,
    on the host (float64, then float32), from one shared origin.
    """

    normalise = False   # made unit length here

    def __init__(self, K, pose, width: int, height: int, pixel_center: float = 0.0):
        checks.image_size(width, height)
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
        pixel_center = checks.number("pixel_center", pixel_center)
        checks.vector("pose[:3, 3]", pose[:3, 3])   # the eye: within +-1e30, as every position
        host_memory_for_rays(int(width) * int(height))
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

    def directions(self, start: int, stop: int) -> np.ndarray:
        """(M, 3) float32 unit world directions of pixels start..stop-1."""
        return (self.camera_directions(start, stop) @ self.R.T).astype(np.float32)


class CameraRays:
    """Our Camera's pixel-centre rays, made on the device (``camera_rays`` in
    trace.cl): exactly the rays the renderer traces, from the eye."""

    normalise = False   # camera.cl makes them unit length

    def __init__(self, camera):
        self.camera = camera
        self.camera_value = camera_value(camera)   # the Camera struct of camera_rays
        self.forward = camera.basis()[0]

    def __len__(self) -> int:
        return self.camera.width * self.camera.height


class PointBatch:
    """Query points as the caller gave them, checked for shape and type only,
    in the form of a RayBatch's inputs (rays.cl's load_point): ``points`` in
    the origins, ``max_distance`` (one number for all) in tmax; directions
    and tmin unused.  ``points``: (3,) or (N, 3), a numpy array of any real
    dtype or a float32 ``pyopencl.array.Array``; the kernels report the first
    point that is not finite.  A C-contiguous numpy array is converted to
    float32 only on its way to the device, a chunk at a time (on a GPU by the
    threads that fill the page-locked staging: clrt.device.pinned.upload), so
    the host makes one pass over it."""

    normalise = False

    def __init__(self, points, max_distance=np.inf):
        self.given = points
        self.on_device = is_device_array(points)
        if self.on_device:
            a, self.n = _device_rows(points, "points", 3)
            flat = a
        else:
            a = host_rows(points, "points")
            self.n = len(a)
            host_memory_for_rays(self.n, 0 if a.flags.c_contiguous else 12 * self.n)
            if a.flags.c_contiguous:   # as given: a chunk at a time to float32 on its way (Accel._upload)
                flat = a.reshape(-1)
            else:
                with np.errstate(over="ignore"):   # beyond float32: inf, reported by the kernel as not finite
                    flat = np.ascontiguousarray(a, dtype=np.float32).reshape(-1)
        if not checks.is_number(max_distance) or not float(max_distance) > 0:   # NaN fails too
            raise checks.fail("max_distance", "a number > 0 (inf: no limit)", max_distance)
        limit = float(max_distance)
        with np.errstate(over="ignore"):
            limit = np.full(1, limit, np.float32)
        self.inputs = [(flat, 3), (np.zeros(3, np.float32), 0), (np.zeros(1, np.float32), 0), (limit, 0)]

    def __len__(self) -> int:
        return self.n

    def host_chunk(self, k: int, start: int, stop: int):
        a, stride = self.inputs[k]
        return a if stride == 0 else a[start * stride:stop * stride]

    def bad_ray_message(self, kind: str, i: int, reach=None) -> str:
        """The error for point ``i`` (the kernels report it as a bad origin)."""
        if self.on_device:
            return f"point {i} is not finite: points must be finite"
        row = np.asarray(host_rows(self.given, "points")[i]).tolist()
        overflow = all(isinstance(x, float) and math.isfinite(x) for x in row)
        if overflow:
            return (f"point {i} is {row}: {checks.show(max(abs(x) for x in row))} overflows float32 "
                    "(the largest float32 is about 3.4e38); points must be finite in float32")
        return f"point {i} is {row}: points must be finite"

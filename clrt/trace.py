"""Ray queries against a triangle mesh on the OpenCL device.

    >>> accel = clrt.Accel(mesh)                          # BVH + upload, once
    >>> hits = accel.trace(origins, directions)           # closest hit: Hits
    >>> blocked = accel.any_hit(origins, directions, tmax=dist)
    >>> n = accel.count(origins, directions)              # hits along each ray
    >>> every = accel.all_hits(origins, directions)       # AllHits(ray_id, prim, t)
    >>> images = accel.camera_images(K=K, pose=pose, width=640, height=480)

Conventions shared by every query (docs/ray-queries.md has the full guide):

* Rays: ``origins`` and ``directions`` of shape ``(3,)`` (one ray) or ``(N, 3)``
  (one of them may be a single row, broadcast to the other), any real dtype.
  Directions need not be unit length: they are normalised, and ``t`` is the
  distance along the normalised direction.  ``tmin`` and ``tmax`` are scalars or
  ``(N,)`` arrays; a hit counts when ``tmin < t <= tmax``.
* Misses: ``t = inf``, ``prim = -1``, ``u = v = 0``, ``normal = (0, 0, 0)``,
  ``front = False``.  ``prim`` is the row of the mesh's faces.
* ``cull``: ``"none"`` (double-sided, the default), ``"back"`` (a ray passes
  through triangles it sees from behind) or ``"front"``.  The front face is the
  one the winding faces: the ray meets it against the normal
  ``(v1 - v0) x (v2 - v0)``.
* Arithmetic is float32 on the device (watertight test of Woop et al.).

Every query goes through one input path (:class:`RayBatch`) and the same
kernels, so a ray gives the same answer alone or in a batch, in any chunk.
Large batches are cut into chunks (``Accel.chunk_rays``); device memory is
bounded by the chunk, not the batch -- see :meth:`Accel.memory`.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import pyopencl as cl

from clrt import checks
from clrt.device import layouts
from clrt.device.context import create_context, device_label
from clrt.device.geometry import DeviceGeometry, order_triangles
from clrt.device.program import build_program
from clrt.errors import InputError
from clrt.scene.mesh import Mesh

CULL = {"none": 0, "back": 1, "front": 2}    # CULL_* in triangle.cl

DEFAULT_CHUNK_RAYS = 1 << 20        # rays per launch: ~50 MB of device buffers
BRUTE_FORCE_TESTS = 1 << 30         # ray-triangle tests per launch without a BVH
MIN_CHUNK_RAYS = 4096
ALL_HITS_PER_RAY = 4                # first guess of room for all_hits, grown as hits show up
ALL_HITS_CAPACITY = 1 << 24         # most hits of one launch kept on the device (192 MiB)


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


def as_mesh(source) -> Mesh:
    """A Mesh from a Mesh, a Scene (all objects, in order), a path, a trimesh.Trimesh
    or (vertices, faces)."""
    from clrt.scene.scene import Scene
    if isinstance(source, Mesh):
        return source
    if isinstance(source, Scene):
        return Mesh.concatenate([o.mesh for o in source.objects])
    if isinstance(source, (str, Path)):
        from clrt.scene.load import load_mesh
        return load_mesh(source)
    if hasattr(source, "vertices") and hasattr(source, "faces"):
        return Mesh.from_arrays(source.vertices, source.faces)
    if isinstance(source, tuple) and len(source) == 2:
        return Mesh.from_arrays(*source)
    raise InputError(f"expected a mesh, a path or (vertices, faces), got {type(source).__name__}")


def cull_code(cull: str) -> np.int32:
    if not isinstance(cull, str) or cull not in CULL:
        raise InputError(f"cull must be one of {', '.join(map(repr, CULL))}, got {cull!r}")
    return np.int32(CULL[cull])


# --------------------------------------------------------------------------- input normalisation

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
        rays = np.empty(stop - start, layouts.RAY)
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
        from clrt.scene.scene import check_int
        check_int("width", width, 1, 65536)
        check_int("height", height, 1, 65536)
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
        rays = np.empty(stop - start, layouts.RAY)
        rays["origin"][:, :3] = self.eye
        rays["origin"][:, 3] = 0.0
        rays["dir"][:, :3] = self.camera_directions(start, stop) @ self.R.T
        rays["dir"][:, 3] = np.inf
        return rays


class _CameraRays:
    """Our Camera's pixel-centre rays, made on the device (``camera_rays`` in
    trace.cl): exactly the rays the renderer traces."""

    def __init__(self, camera):
        from clrt.render import camera_args
        self.camera = camera
        self.args = camera_args(camera)
        self.forward = camera.basis()[0]

    def __len__(self) -> int:
        return self.camera.width * self.camera.height


# --------------------------------------------------------------------------- the accelerated mesh

def _check_chunk_rays(chunk_rays) -> None:
    if chunk_rays is not None and (isinstance(chunk_rays, bool) or not isinstance(chunk_rays, (int, np.integer))
                                   or chunk_rays < 1):
        raise InputError(f"chunk_rays must be a positive integer, got {chunk_rays!r}")


class Accel:
    """A mesh and its acceleration structure, uploaded once to one device.

    ``accel``: "box" (default), "sphere", "ellipse" or "none"; ``builder``:
    "sah" (default) or "paper"; ``leaf_size``: most triangles per leaf.
    ``chunk_rays``: most rays per kernel launch (default: see :meth:`chunk_size`).
    Not thread-safe: give each thread its own Accel.
    """

    def __init__(self, mesh, accel: str = "box", builder: str = "sah", leaf_size: int = 4,
                 device: str | None = None, chunk_rays: int | None = None):
        from clrt.render import flatten_scene
        from clrt.scene.scene import Scene, SceneObject
        _check_chunk_rays(chunk_rays)
        self.mesh = as_mesh(mesh)
        tri_verts = flatten_scene(Scene([SceneObject(self.mesh)], [])).tri_verts
        order = order_triangles(tri_verts, accel, builder, leaf_size)
        context, queue = create_context(device)
        from clrt.render import _check_fits   # a clear DeviceMemoryError before any upload
        _check_fits(queue.device, device_label(queue.device),
                    {"triangles": order.tri_verts, "BVH nodes": order.nodes, "triangle ids": order.prim_ids})
        self._setup(self.mesh, order, context, queue, DeviceGeometry(context, order), chunk_rays)

    @classmethod
    def from_renderer(cls, renderer, chunk_rays: int | None = None) -> "Accel":
        """Ray queries on a Renderer's scene, sharing its device, BVH and buffers;
        ``prim`` is then the triangle index in the scene's objects, in order
        (as ``Frame.prim``)."""
        self = cls.__new__(cls)
        self.mesh = as_mesh(renderer.scene)
        self._setup(self.mesh, renderer.order, renderer.context, renderer.queue, renderer.geometry,
                    chunk_rays)
        return self

    def _setup(self, mesh, order, context, queue, geometry, chunk_rays):
        _check_chunk_rays(chunk_rays)
        self.order, self.context, self.queue, self.geometry = order, context, queue, geometry
        self.device = device_label(queue.device)
        self.chunk_rays = chunk_rays
        self.max_alloc = int(queue.device.max_mem_alloc_size)   # bytes of the largest buffer
        self.all_hits_capacity = ALL_HITS_CAPACITY
        program = build_program(context, "trace.cl", {**order.defines, **geometry.defines})
        self.kernels = {name: cl.Kernel(program, name) for name in
                        ("query_closest", "query_any", "query_count", "query_all", "camera_rays",
                         "trace_camera", "occlude_camera")}
        self.face_normals = mesh.face_normals().astype(np.float32)
        self._buffers: dict[str, cl.Buffer] = {}
        self._hits_per_ray = float(ALL_HITS_PER_RAY)

    @property
    def bvh(self):
        """The host BVH (clrt.accel.bvh.Bvh), or None for accel="none"."""
        return self.order.bvh

    # ----------------------------------------------------------------------- chunks and memory

    def chunk_size(self) -> int:
        """Rays per launch: ``chunk_rays`` if given, else 2**20 -- and without a
        BVH at most 2**30 / triangles (so that one launch stays short), but no
        fewer than 4096; never more than fit in one allocation."""
        if self.chunk_rays is not None:
            size = int(self.chunk_rays)
        else:
            size = DEFAULT_CHUNK_RAYS
            if self.order.bvh is None:
                size = min(size, max(MIN_CHUNK_RAYS, BRUTE_FORCE_TESTS // max(len(self.order.tri_verts), 1)))
        return max(1, min(size, self.max_alloc // layouts.RAY.itemsize, 2**31 - 1))

    def memory(self) -> dict:
        """Upper bounds, in bytes, of what queries keep on the device: ``scene``
        (triangles, BVH, triangle ids), ``chunk`` (rays and results of one chunk:
        49 bytes a ray for the closest hit, the largest query) and ``all_hits``
        (12 bytes a hit for at most ``all_hits_capacity`` hits; a chunk with
        more hits is split in halves).  Host memory beyond the caller's arrays
        and the results is one chunk's temporaries (about 200 bytes a ray)."""
        chunk = self.chunk_size()
        per_ray = layouts.RAY.itemsize + layouts.HIT.itemsize + 1
        return {"scene": int(self.geometry.nbytes), "chunk_rays": chunk, "chunk": chunk * per_ray,
                "all_hits": 12 * self._all_hits_limit()}

    def _all_hits_limit(self) -> int:
        return max(1, min(self.all_hits_capacity, self.max_alloc // 4))

    def _buffer(self, name: str, nbytes: int) -> cl.Buffer:
        """A device buffer of at least ``nbytes``, kept for the next chunk and query."""
        buf = self._buffers.get(name)
        if buf is None or buf.size < nbytes:
            self._buffers.pop(name, None)
            buf = cl.Buffer(self.context, cl.mem_flags.READ_WRITE, max(int(nbytes), 1))
            self._buffers[name] = buf
        return buf

    def _chunks(self, n: int):
        step = self.chunk_size()
        for start in range(0, n, step):
            yield start, min(n, start + step)

    def _load_rays(self, source, start: int, stop: int) -> tuple[cl.Buffer, np.ndarray | None]:
        """Rays start..stop-1 of ``source`` in the device's ray buffer; their RAY
        records when they were made on the host."""
        m = stop - start
        buf = self._buffer("rays", m * layouts.RAY.itemsize)
        if isinstance(source, _CameraRays):
            kernel = self.kernels["camera_rays"]
            kernel.set_args(buf, *source.args, np.uint64(start), np.uint32(m))
            cl.enqueue_nd_range_kernel(self.queue, kernel, (m,), None)
            return buf, None
        records = source.records(start, stop)
        cl.enqueue_copy(self.queue, buf, records)
        return buf, records

    def _run(self, name: str, m: int, *args) -> None:
        kernel = self.kernels[name]
        kernel.set_args(*args, *self.geometry.args)
        cl.enqueue_nd_range_kernel(self.queue, kernel, (m,), None)

    # ----------------------------------------------------------------------- the queries

    def _closest(self, source, cull: str, depth_axis=None) -> tuple[Hits, np.ndarray | None]:
        """Closest hits of every ray of ``source``; with ``depth_axis`` also the
        cosine between each ray and that unit vector (for depth images)."""
        code = cull_code(cull)
        n = len(source)
        t, prim = np.empty(n, np.float32), np.empty(n, np.int32)
        u, v = np.empty(n, np.float32), np.empty(n, np.float32)
        front = np.empty(n, np.uint8)
        cosine = np.empty(n, np.float64) if depth_axis is not None else None
        chunk = np.empty(min(n, self.chunk_size()), layouts.HIT)
        for start, stop in self._chunks(n):
            m = stop - start
            rays, records = self._load_rays(source, start, stop)
            hit_buf = self._buffer("hits", m * layouts.HIT.itemsize)
            front_buf = self._buffer("front", m)
            self._run("query_closest", m, rays, hit_buf, front_buf, np.uint32(m), code)
            cl.enqueue_copy(self.queue, chunk[:m], hit_buf)
            cl.enqueue_copy(self.queue, front[start:stop], front_buf)
            for name, out in (("t", t), ("prim", prim), ("u", u), ("v", v)):
                out[start:stop] = chunk[name][:m]
            if cosine is not None:
                if records is None:
                    records = np.empty(m, layouts.RAY)
                    cl.enqueue_copy(self.queue, records, rays)
                cosine[start:stop] = records["dir"][:, :3].astype(np.float64) @ depth_axis
        return self._hits(t, prim, u, v, front.astype(bool)), cosine

    def _hits(self, t, prim, u, v, front) -> Hits:
        hit = prim >= 0
        normal = np.zeros(prim.shape + (3,), np.float32)
        normal[hit] = self.face_normals[prim[hit]]
        return Hits(t, prim, u, v, normal, front & hit, hit)

    def trace(self, origins, directions, tmin=0.0, tmax=np.inf, *, cull: str = "none") -> Hits:
        """Closest hit of each ray with tmin < t <= tmax (scalars or per-ray arrays)."""
        return self._closest(RayBatch(origins, directions, tmin, tmax), cull)[0]

    closest = trace

    def _flags(self, kernel: str, batch: RayBatch, cull: str, dtype) -> np.ndarray:
        code = cull_code(cull)
        out = np.empty(len(batch), dtype)
        for start, stop in self._chunks(len(batch)):
            m = stop - start
            rays, _ = self._load_rays(batch, start, stop)
            buf = self._buffer(kernel, m * out.itemsize)
            self._run(kernel, m, rays, buf, np.uint32(m), code)
            cl.enqueue_copy(self.queue, out[start:stop], buf)
        return out

    def any_hit(self, origins, directions, tmin=0.0, tmax=np.inf, *, cull: str = "none") -> np.ndarray:
        """(N,) bool: does anything lie on each ray with tmin < t <= tmax?  Stops at
        the first hit found (occlusion, shadow rays)."""
        return self._flags("query_any", RayBatch(origins, directions, tmin, tmax), cull, np.uint8).astype(bool)

    def occluded(self, origins, directions, t_max=np.inf, tmin=0.0, *, cull: str = "none") -> np.ndarray:
        """(N,) bool: is each ray blocked in (tmin, t_max]?  (:meth:`any_hit`, with
        the distance first.)"""
        return self.any_hit(origins, directions, tmin, t_max, cull=cull)

    def count(self, origins, directions, tmin=0.0, tmax=np.inf, *, cull: str = "none") -> np.ndarray:
        """(N,) int32: how many triangles each ray meets in (tmin, tmax] (a ray
        through a shared edge or vertex meets each triangle there)."""
        return self._flags("query_count", RayBatch(origins, directions, tmin, tmax), cull,
                           np.uint32).astype(np.int32)

    def all_hits(self, origins, directions, tmin=0.0, tmax=np.inf, *, cull: str = "none") -> AllHits:
        """Every hit in (tmin, tmax] of every ray, found in one traversal per ray,
        as flat arrays sorted by ray, then t, then triangle."""
        batch = RayBatch(origins, directions, tmin, tmax)
        code = cull_code(cull)
        parts = []
        for start, stop in self._chunks(len(batch)):
            self._all_hits_chunk(batch, start, stop, code, parts)
        if not parts:
            return AllHits(np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, np.float32))
        return AllHits(*(np.concatenate(p) for p in zip(*parts)))

    def _all_hits_chunk(self, batch, start, stop, code, parts) -> None:
        """Hits of rays start..stop-1 appended to ``parts``.  The output is sized
        from the hits per ray seen so far; when a launch finds more hits than
        there was room for, it tells how many, and the chunk runs once more
        with room for all (or in halves, when they would not fit one allocation)."""
        m = stop - start
        limit = self._all_hits_limit()
        capacity = int(min(limit, max(1024, np.ceil(self._hits_per_ray * m))))
        rays, _ = self._load_rays(batch, start, stop)
        counter = self._buffer("all_next", 4)
        total = np.zeros(1, np.uint32)
        for _attempt in range(2):
            outs = [self._buffer(f"all_{k}", capacity * 4) for k in ("ray", "prim", "t")]
            cl.enqueue_copy(self.queue, counter, np.zeros(1, np.uint32))
            self._run("query_all", m, rays, *outs, counter, np.uint32(capacity), np.uint32(m), code)
            cl.enqueue_copy(self.queue, total, counter)
            found = int(total[0])
            self._hits_per_ray = max(self._hits_per_ray, found / m)
            if found <= capacity:
                break
            if found > limit:
                if m == 1:
                    raise InputError(f"ray {start} meets {found:,} triangles, more than all_hits "
                                     f"keeps on the device ({limit:,})")
                mid = start + m // 2
                self._all_hits_chunk(batch, start, mid, code, parts)
                self._all_hits_chunk(batch, mid, stop, code, parts)
                return
            capacity = found
        else:
            raise RuntimeError(f"all_hits: {found} hits found for room of {capacity} twice")
        ray, prim = np.empty(found, np.int32), np.empty(found, np.int32)
        t = np.empty(found, np.float32)
        for host, buf in zip((ray, prim, t), outs):
            if found:
                cl.enqueue_copy(self.queue, host, buf)
        order = np.lexsort((prim, t, ray))
        parts.append((ray[order].astype(np.int64) + start, prim[order], t[order]))

    # ----------------------------------------------------------------------- cameras

    def camera_images(self, camera=None, *, K=None, pose=None, width: int | None = None,
                      height: int | None = None, pixel_center: float = 0.0,
                      cull: str = "none") -> CameraImages:
        """Depth, distance, normal, triangle and hit images of a camera.

        Either ``camera``, a :class:`clrt.Camera` (its pixel-centre rays, exactly
        those the renderer traces), or ``K`` (3x3 pinhole intrinsics) with
        ``width``, ``height`` and ``pose`` (4x4 camera-to-world, OpenCV axes: x
        right, y down, z forward; default identity) -- see :class:`PinholeRays`.
        ``depth`` is the distance along the optical axis (the camera's forward
        direction), ``t`` the distance along each pixel's ray.
        """
        if camera is not None:
            if K is not None or pose is not None:
                raise InputError("give either a camera or K and pose, not both")
            source = _CameraRays(camera)
            axis, shape = source.forward, (camera.height, camera.width)
        else:
            if K is None or width is None or height is None:
                raise InputError("camera_images needs a camera, or K with width and height")
            source = PinholeRays(K, pose, width, height, pixel_center)
            axis, shape = source.R[:, 2], (source.height, source.width)
        hits, cosine = self._closest(source, cull, depth_axis=np.asarray(axis, np.float64))
        with np.errstate(invalid="ignore", over="ignore"):
            depth = np.where(hits.hit, hits.t * cosine, np.inf).astype(np.float32)
        h, w = shape
        return CameraImages(depth.reshape(h, w), hits.t.reshape(h, w), hits.normal.reshape(h, w, 3),
                            hits.prim.reshape(h, w), hits.hit.reshape(h, w), hits.front.reshape(h, w),
                            hits.u.reshape(h, w), hits.v.reshape(h, w))

    def trace_camera(self, camera) -> Hits:
        """Closest hits of the camera's pixel-centre rays, as (H, W) arrays."""
        hits, _ = self._closest(_CameraRays(camera), "none")
        shape = (camera.height, camera.width)
        return Hits(*(a.reshape(shape + a.shape[1:]) for a in hits))

    def launch_camera(self, camera, out: cl.Buffer, occlusion: bool = False, tile=(8, 8)) -> cl.Event:
        """Enqueue one launch that makes and traces one ray per pixel of ``camera``
        (closest hits as HIT records, or occlusion bytes, into ``out``): the
        primary-ray benchmark's kernel, without chunks.  ``tile`` (w, h): the
        work-group as a block of pixels, or None for the driver's choice.  Rays
        of a block run together and, being neighbours, walk much the same nodes:
        8 x 8 blocks made the H200 15 % faster than the driver's choice."""
        from clrt.render import camera_args
        kernel = self.kernels["occlude_camera" if occlusion else "trace_camera"]
        kernel.set_args(out, *camera_args(camera), *self.geometry.args)
        size = (camera.width, camera.height)
        if tile is not None:   # round up: the kernel skips pixels outside the image
            size = tuple(-(-n // t) * t for n, t in zip(size, tile))
        return cl.enqueue_nd_range_kernel(self.queue, kernel, size, tile)


# --------------------------------------------------------------------------- one-call forms

def _accel_for(mesh, device, accel="box", builder="sah", leaf_size=4, **unknown) -> Accel:
    """The Accel of a one-call form, with its arguments checked as the CLI checks them."""
    if unknown:
        raise InputError(f"unexpected argument {next(iter(unknown))!r} (accel options: accel, builder, leaf_size)")
    device = checks.device(device)
    accel, builder, leaf_size = checks.accel_options(accel, builder, leaf_size)
    return Accel(mesh, accel, builder, leaf_size, device)


def trace(mesh, origins, directions, accel: str = "box", builder: str = "sah", leaf_size: int = 4,
          device: str | None = None, tmin=0.0, tmax=np.inf, cull: str = "none") -> Hits:
    """Closest hits of a batch of rays (:meth:`Accel.trace`); build an :class:`Accel`
    once to query a mesh many times."""
    cull_code(cull)
    return _accel_for(mesh, device, accel, builder, leaf_size).trace(origins, directions, tmin, tmax, cull=cull)


def occluded(mesh, origins, directions, t_max=np.inf, accel: str = "box", builder: str = "sah",
             leaf_size: int = 4, device: str | None = None, cull: str = "none", tmin=0.0) -> np.ndarray:
    """(N,) bool: is each ray blocked in (tmin, t_max]?"""
    cull_code(cull)
    return _accel_for(mesh, device, accel, builder, leaf_size).occluded(origins, directions, t_max, tmin,
                                                                        cull=cull)


def count_hits(mesh, origins, directions, tmin=0.0, tmax=np.inf, cull: str = "none",
               device: str | None = None, **accel_options) -> np.ndarray:
    """(N,) int32 hits along each ray (:meth:`Accel.count`)."""
    cull_code(cull)
    return _accel_for(mesh, device, **accel_options).count(origins, directions, tmin, tmax, cull=cull)


def all_hits(mesh, origins, directions, tmin=0.0, tmax=np.inf, cull: str = "none",
             device: str | None = None, **accel_options) -> AllHits:
    """Every hit of every ray (:meth:`Accel.all_hits`)."""
    cull_code(cull)
    return _accel_for(mesh, device, **accel_options).all_hits(origins, directions, tmin, tmax, cull=cull)


def camera_images(mesh, camera=None, *, K=None, pose=None, width=None, height=None,
                  pixel_center: float = 0.0, cull: str = "none", device: str | None = None,
                  **accel_options) -> CameraImages:
    """Depth, normal, triangle and hit images (:meth:`Accel.camera_images`)."""
    cull_code(cull)
    return _accel_for(mesh, device, **accel_options).camera_images(
        camera, K=K, pose=pose, width=width, height=height, pixel_center=pixel_center, cull=cull)


# --------------------------------------------------------------------------- AOV files (clrt render --aov)

AOVS = ("depth", "distance", "normal", "prim", "hit", "front")


def parse_aovs(text) -> tuple[str, ...]:
    """'depth,normal' -> ('depth', 'normal'); InputError naming an unknown one."""
    names = tuple(dict.fromkeys(n.strip().lower() for n in str(text).split(",") if n.strip()))
    if not names:
        raise InputError(f"--aov needs one or more of {','.join(AOVS)}")
    unknown = [n for n in names if n not in AOVS]
    if unknown:
        raise InputError(f"unknown AOV {unknown[0]!r}: choose from {','.join(AOVS)}")
    return names


def aov_arrays(images: CameraImages, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(values for the .npy, 8-bit picture for the .png) of one AOV."""
    hit = images.hit
    if name in ("depth", "distance"):
        values = images.depth if name == "depth" else images.t
        picture = np.zeros(hit.shape, np.uint8)
        if hit.any():
            near, far = float(values[hit].min()), float(values[hit].max())
            scale = (values[hit] - near) / (far - near) if far > near else np.zeros(int(hit.sum()))
            picture[hit] = np.round(255 - 215 * scale).astype(np.uint8)   # near bright, misses black
        return values, picture
    if name == "normal":
        picture = np.where(hit[..., None], np.round((images.normal + 1) * 127.5), 0).astype(np.uint8)
        return images.normal, picture
    if name == "prim":
        key = images.prim.astype(np.uint32) * np.uint32(2654435761)
        rgb = np.stack([(key >> s) & 0xFF for s in (8, 16, 24)], axis=-1).astype(np.uint8) | 0x30
        return images.prim, np.where(hit[..., None], rgb, 0).astype(np.uint8)
    flag = images.hit if name == "hit" else images.front
    return flag, flag.astype(np.uint8) * 255


def aov_paths(image_path, names) -> list[Path]:
    """IMAGE.NAME.npy and IMAGE.NAME.png for each AOV name, beside ``image_path``."""
    image_path = Path(image_path)
    paths = []
    for name in names:
        base = f"{image_path.stem}.{name}"
        paths += [image_path.with_name(base + ".npy"), image_path.with_name(base + ".png")]
    return paths


def write_aovs(source, camera, names, image_path, force: bool = False) -> list[Path]:
    """Write each AOV of ``camera`` as IMAGE.NAME.npy (the values) and
    IMAGE.NAME.png (a picture of them), next to ``image_path``.  ``source``: a
    Renderer (its uploaded scene is reused) or an Accel.  Existing files are
    replaced only if clrt wrote them, or with ``force`` (clrt.output).
    Returns the paths."""
    from clrt.output import write_array, write_image
    if isinstance(names, str):
        names = parse_aovs(names)
    accel = source if isinstance(source, Accel) else Accel.from_renderer(source)
    images = accel.camera_images(camera)
    image_path = Path(image_path)
    written = []
    for name in names:
        values, picture = aov_arrays(images, name)
        npy, png = aov_paths(image_path, [name])
        write_array(values, npy, marked_by=png, force=force)
        write_image(picture, png, force=force)
        written += [npy, png]
    return written

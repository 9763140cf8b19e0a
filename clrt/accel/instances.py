"""The two-level acceleration structure of a scene of instances
(docs/instances.md): bottom-level BVHs, one per distinct mesh, concatenated;
the instance table; a top-level BVH over the instances' world boxes.

    >>> table, condition = instance_table(transforms, mesh_of, mesh_bounds, mesh_origins, origin)
    >>> first, counts = mesh_places(bottoms, table, "box")      # root, first, count of each row
    >>> two = assemble(bottoms, table, top_level(table, "box"), "box", depth)
    >>> two.rows, two.prim_ids, two.instances      # ready for upload (DeviceGeometry)

The bottom levels are built elsewhere (any builder: clrt.device.acceleration
builds them, one mesh at a time); here they are only joined: every child
reference is made global (a row index counts from the first row of the whole
buffer, a leaf's first slot from the first slot), the top level's rows first.
The instance table comes in closed forms (no SVD, no LU) that the device's
top-level build (clrt.device.top_level, build_instances.cl) computes
operation for operation: both give the same rows, bit for bit.  The top
level is built on the device (a linear BVH) when the meshes' builder is the
device's; here, on the host, otherwise: binned SAH (sah.py) over the
instances' boxes, one instance a leaf, whose reference is then rewritten to
the instance's own index.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from clrt.accel import build
from clrt.accel.bvh import Acceleration
from clrt.accel.rows import child_refs
from clrt.accel.volumes import round_down32, round_up32
from clrt.config import INSTANCE_MIRROR, MAX_COORDINATE, MAX_TRANSFORM_CONDITION
from clrt.errors import InputError
from clrt.layouts import BVH_PAIR_NODE, INSTANCE
from clrt.scene.instances import dot3, mapped_columns

# The world box of an instance is padded by this times the transform's
# condition number times the box's size and distance from the device origin
# (its largest coordinate): the move of a ray into object space rounds its
# origin and direction by a few float32 ulps of their size (mapped back into
# the world, times the condition number), so an object-space hit may lie that
# far outside the exact world box -- this keeps such a ray in the box (2^-20 =
# 16 ulps, for rays that start within the scene's box; docs/instances.md).
INSTANCE_BOX_PAD = 2.0 ** -20
# The table's numbers of a linear part A come in closed form, the same on the
# host (here) and on the device (build_instances.cl), with +, -, *, / and
# sqrt only: the inverse is the adjugate over the determinant, and the
# singular values are bounded through eigenvalue_bound (at most 3^(1/16) =
# 7 % off), never computed.  Instance.min_scale is 1 / that bound of
# |A^-1|, less MIN_SCALE_SLACK for the float64 rounding of the bound (a few
# ulps, through eight powers) and INVERSE_SLACK * condition^2 for the
# determinant's: where A's two smaller singular values are both small its
# terms cancel, which leaves an error of up to about 30 u cond^2 of it (u =
# 2^-53; 2^-46 = 128 u) -- at the largest condition allowed, 1e6, 2 % of the
# scale, and the condition's bound below MAX_TRANSFORM_CONDITION by as much.
MIN_SCALE_SLACK = 2.0 ** -20
INVERSE_SLACK = 2.0 ** -46
# A transform whose condition bound, less those slacks, exceeds this is
# checked again on the host (clrt.scene.instances.checked_transforms: its
# singular values), which decides: the bound alone would refuse a transform
# up to 13 % below MAX_TRANSFORM_CONDITION.
RECHECK_CONDITION = MAX_TRANSFORM_CONDITION


def instance_defines() -> dict:
    """The constants above as the device's top-level build (build_instances.cl)
    takes them: ``-D`` defines of the device builder's program (repr() of a
    float is a C double literal of the same value)."""
    return {"INSTANCE_BOX_PAD": repr(INSTANCE_BOX_PAD), "MIN_SCALE_SLACK": repr(MIN_SCALE_SLACK),
            "INVERSE_SLACK": repr(INVERSE_SLACK), "RECHECK_CONDITION": repr(float(RECHECK_CONDITION)),
            "MAX_COORDINATE": repr(float(MAX_COORDINATE))}


@dataclass
class TwoLevel(Acceleration):
    """An Acceleration of a scene of instances: ``rows`` the top level's then
    each mesh's (every reference global), ``prim_ids`` each slot's row in its
    own mesh's faces, and beside them:

    instances: (I,) ``INSTANCE`` (clrt/layouts.py), in the caller's order.
    top:       the top level's Acceleration (its rows are the first of ``rows``;
               None without a BVH).
    bottoms:   each distinct mesh's Acceleration, as built (own references).
    order:     (S,) int64, the row of the meshes' concatenated corners (input
               order, mesh after mesh) that each slot holds.
    move_ms:   wall milliseconds of the last move of the instances
               (clrt.device.instances.move_instances), 0 before;
               ``move_times`` its parts (ms, by name).
    device_top: the device's top-level build (clrt.device.top_level), when
               the device built the top level: the moves build it there again.
    pending:   after such a move, what reads its rows and table back: the
               host copies of ``rows``, ``instances`` and ``top`` are read
               when first asked for (reading back 2 MB a move of 10,000
               instances would cost more than the move).
    """

    instances: np.ndarray = field(repr=False, default=None)
    top: Acceleration | None = field(repr=False, default=None)
    bottoms: list = field(repr=False, default_factory=list)
    order: np.ndarray = field(repr=False, default=None)
    move_ms: float = 0.0
    move_times: dict = field(repr=False, default_factory=dict)
    device_top: object = field(repr=False, default=None, compare=False)
    pending: object = field(repr=False, default=None, compare=False)

    def slot_order(self) -> np.ndarray:
        return self.order

    def device_bytes(self) -> int:
        return super().device_bytes() + int(self.instances.nbytes)

    def stats(self) -> dict:
        """The top level's numbers (None without a BVH), the instances and meshes
        counted, each mesh's numbers, build time and device bytes."""
        return {"instances": int(len(self.instances)), "meshes": len(self.bottoms),
                "top": self.top.stats() if self.top is not None else None,
                "bottoms": [b.stats() for b in self.bottoms], "depth": int(self.depth),
                "build_ms": float(self.build_ms), "device_bytes": self.device_bytes()}

    def read_back(self) -> None:
        """Bring the host copies up to date with a move on the device (``pending``)."""
        pending, self.pending = self.pending, None
        if pending is not None:
            table, top = pending()
            self.__dict__["instances"], self.__dict__["top"] = table, top
            self.__dict__["rows"][:len(top.rows)] = top.rows

    def __getstate__(self):
        self.read_back()
        state = super().__getstate__()
        state["device_top"] = None            # device memory does not travel
        return state


class _ReadBack:
    """A TwoLevel array that a move on the device leaves on the device until
    it is asked for (TwoLevel.pending)."""

    def __init__(self, name: str):
        self.name = name

    def __get__(self, two, owner=None):
        if two is None:
            return self
        if two.__dict__.get("pending") is not None:
            two.read_back()
        return two.__dict__[self.name]

    def __set__(self, two, value):
        two.__dict__[self.name] = value


# (After the dataclass is made: its __init__ then sets them through __set__.)
TwoLevel.rows = _ReadBack("rows")
TwoLevel.instances = _ReadBack("instances")
TwoLevel.top = _ReadBack("top")


def _cross(p, q):
    return np.stack([p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]])


def _square(d, o):
    """The square of the symmetric 3x3 matrices of diagonal ``d`` and off-diagonal
    (01, 02, 12) ``o`` (build_instances.cl's square_symmetric)."""
    return ([(d[0] * d[0] + o[0] * o[0]) + o[1] * o[1], (o[0] * o[0] + d[1] * d[1]) + o[2] * o[2],
             (o[1] * o[1] + o[2] * o[2]) + d[2] * d[2]],
            [(d[0] * o[0] + o[0] * d[1]) + o[1] * o[2], (d[0] * o[1] + o[0] * o[2]) + o[1] * d[2],
             (o[0] * o[1] + d[1] * o[2]) + o[2] * d[2]])


def eigenvalue_bound(r: np.ndarray) -> np.ndarray:
    """(I,) an upper bound of the largest eigenvalue of R R^T, R of rows ``r``
    ((3, 3, I): row, column, instance): its trace times tr(S^8)^(1/8), S = R
    R^T over its trace -- the eigenvalues' 8th powers summed, so at most
    3^(1/8) above the largest (two squarings and a sum; no eigen solver)."""
    d = [dot3(r[0], r[0]), dot3(r[1], r[1]), dot3(r[2], r[2])]
    o = [dot3(r[0], r[1]), dot3(r[0], r[2]), dot3(r[1], r[2])]
    trace = (d[0] + d[1]) + d[2]
    d, o = [x / trace for x in d], [x / trace for x in o]
    for _ in range(2):
        d, o = _square(d, o)
    f = ((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]) + 2.0 * ((o[0] * o[0] + o[1] * o[1]) + o[2] * o[2])
    return trace * np.sqrt(np.sqrt(np.sqrt(f)))


def linear_part(a: np.ndarray):
    """What the table needs of linear parts ``a`` ((3, 3, I): row, column,
    instance), in float64: the inverses' rows (3, 3, I), the determinants, a
    bound of the condition numbers (at least the true one, at most 15 % above
    it, but for INVERSE_SLACK) and a lower bound of the smallest singular values
    (build_instances.cl's linear_part, bit for bit)."""
    u, v, x = _cross(a[1], a[2]), _cross(a[2], a[0]), _cross(a[0], a[1])
    det = dot3(a[0], u)
    inverse = np.stack([np.stack([u[r], v[r], x[r]]) / det for r in range(3)])
    largest, bound = np.sqrt(eigenvalue_bound(a)), np.sqrt(eigenvalue_bound(inverse))
    condition = largest * bound
    min_scale = np.fmax((1.0 / bound) * (1.0 - (MIN_SCALE_SLACK + INVERSE_SLACK * condition * condition)), 0.0)
    return inverse, det, condition, min_scale


def to_recheck(transforms: np.ndarray, condition: np.ndarray) -> np.ndarray:
    """(I,) bool: the instances whose transform the host checks exactly
    (clrt.scene.instances.checked_transforms): not finite, not affine, or of a
    condition bound (:func:`linear_part`) that may lie above the limit."""
    with np.errstate(invalid="ignore"):
        limit = RECHECK_CONDITION * (1.0 - (MIN_SCALE_SLACK + INVERSE_SLACK * condition * condition))
        return (~np.isfinite(transforms).all(axis=(1, 2)) | (transforms[:, 3] != (0.0, 0.0, 0.0, 1.0)).any(axis=1)
                | ~(condition <= limit))


def instance_table(transforms: np.ndarray, mesh_of: np.ndarray, mesh_bounds: np.ndarray,
                   mesh_origins: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The INSTANCE rows of instances placed by ``transforms`` ((I, 4, 4)
    float64, object -> world; their meshes ``mesh_of``, boxes ``mesh_bounds``
    (M, 2, 3) and device origins ``mesh_origins`` (M, 3)) but their mesh's
    place (root, first, count: :func:`assemble`), and each one's condition
    bound.  The transforms between each mesh's device frame (its vertices
    moved by ``-mesh_origins[m]``) and the world's (moved by ``-origin``), in
    float64, each rounded to float32 once; the world boxes, padded
    (INSTANCE_BOX_PAD) and rounded outwards; the mirror flag; a lower bound of
    the smallest scale.  In closed forms, each operation as the device's
    instance_rows does it (build_instances.cl): the same rows, bit for bit."""
    rows = np.moveaxis(transforms[:, :3], 0, -1)            # (3, 4, I): row, column, instance
    c = mesh_origins[mesh_of].T                               # (3, I)
    bounds = np.moveaxis(mesh_bounds[mesh_of], 0, -1)       # (2, 3, I)
    with np.errstate(all="ignore"):   # (a bad transform is refused after: to_recheck)
        # p_world - origin = A (p_dev + c) + t - origin
        to_world = rows.copy()
        for r in range(3):
            to_world[r, 3] = rows[r, 3] + (dot3(rows[r, :3], c) - origin[r])
        inverse, det, condition, min_scale = linear_part(rows[:, :3])
        shift = -np.stack([dot3(inverse[r], to_world[:, 3]) for r in range(3)])
        lo, hi = mapped_columns(to_world, bounds[0] - c, bounds[1] - c)
        d = hi - lo
        size = np.sqrt((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]) + np.maximum(np.abs(lo), np.abs(hi)).max(axis=0)
        pad = (INSTANCE_BOX_PAD * condition) * size
        table = np.zeros(len(mesh_of), INSTANCE)
        table["to_world"] = np.moveaxis(to_world, -1, 0)
        table["to_object"] = np.moveaxis(np.concatenate([inverse, shift[:, None]], axis=1), -1, 0)
        table["lo"][:, :3] = round_down32(lo - pad).T
        table["hi"][:, :3] = round_up32(hi + pad).T
        table["min_scale"] = round_down32(min_scale)
    table["mesh"] = mesh_of
    table["flags"] = np.where(det < 0.0, INSTANCE_MIRROR, 0)
    return table, condition


def top_rows(count: int) -> int:
    """Rows of a binary top level over ``count`` instances, one a leaf, whatever
    its builder: count - 1, one for a single instance (its leaf on the left)."""
    return max(count - 1, 1)


def lbvh_depth_bound(count: int) -> int:
    """The most levels of the device's top level over ``count`` instances (a
    linear BVH: every inner node's keys share a longer prefix than its
    parent's, of at most 30 Morton bits and the bits of the instances'
    places), whatever their boxes: the programs' stack needs no other size
    when they move."""
    return min(count, 31 + (count - 1).bit_length())


def top_level(table: np.ndarray, accel: str) -> Acceleration:
    """The host's top-level BVH over the instances' boxes (binned SAH, one
    instance a leaf), each leaf's reference rewritten to its instance's row of
    ``table``."""
    lo, hi = table["lo"][:, :3], table["hi"][:, :3]
    # A "triangle" (lo, hi, lo) has exactly the box as its bounds and its centre as
    # SAH's key: the builders see boxes and centres only.
    top = build(np.stack([lo, hi, lo], axis=1), accel, "sah", leaf_size=1)
    refs = child_refs(top.rows)
    for k in (0, 2):
        leaf = refs[:, k + 1] > 0
        if (refs[leaf, k + 1] != 1).any():   # the SAH builder splits every node above leaf_size
            raise RuntimeError("the top level must hold one instance a leaf")
        refs[leaf, k] = top.prim_ids[refs[leaf, k]]
    return top


def mesh_places(bottoms: list, table: np.ndarray, accel: str) -> tuple[np.ndarray, np.ndarray]:
    """Fill in each instance's mesh's place (``table``'s root, first, count:
    its mesh's rows follow the top level's and the meshes before it, its slots
    the meshes' before it); returns each mesh's first slot and triangle count."""
    counts = np.array([len(b.prim_ids) for b in bottoms], np.int64)
    if counts.sum() >= 2**31 - 1:
        raise InputError(f"the distinct meshes of a scene hold at most {2**31 - 2:,} triangles (slots are "
                         f"int32), got {int(counts.sum()):,}")
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    sizes = [len(b.rows) if accel != "none" else 0 for b in bottoms]
    root = top_rows(len(table)) + np.concatenate([[0], np.cumsum(sizes)[:-1]]) if accel != "none" else first * 0
    mesh_of = table["mesh"]
    table["root"], table["first"], table["count"] = root[mesh_of], first[mesh_of], counts[mesh_of]
    return first, counts


def assemble(bottoms: list, table: np.ndarray, top: Acceleration | None, accel: str, depth: int = 0,
             start: float | None = None) -> TwoLevel:
    """The TwoLevel of the distinct meshes' Accelerations ``bottoms`` (built over
    each mesh's corners in its device frame, in mesh order), the instance rows
    ``table`` (:func:`instance_table`, their places filled by
    :func:`mesh_places`) and the top level ``top`` over them (None without a
    BVH); ``depth``: the top level's levels as the walk's stack must hold them
    (its depth, or the device's bound); ``start``: when the build began
    (perf_counter), for build_ms."""
    start = time.perf_counter() if start is None else start
    counts = np.array([len(b.prim_ids) for b in bottoms], np.int64)
    slots = np.concatenate([[0], np.cumsum(counts)[:-1]])
    rows = [top.rows if top is not None else np.zeros(1, BVH_PAIR_NODE)]
    base = len(rows[0])
    for b, slot in zip(bottoms, slots):
        if top is None:
            continue
        r = b.rows.copy()
        refs = child_refs(r)
        for k in (0, 2):
            refs[refs[:, k + 1] == 0, k] += base
            refs[refs[:, k + 1] > 0, k] += slot
        rows.append(r)
        base += len(r)
    depth = depth + 1 + max(b.depth for b in bottoms) if top is not None else 0
    prim_ids = np.concatenate([b.prim_ids for b in bottoms]).astype(np.int32)
    order = np.concatenate([b.prim_ids.astype(np.int64) + f for b, f in zip(bottoms, slots)])
    return TwoLevel(accel, bottoms[0].builder, np.concatenate(rows), prim_ids, depth=int(depth),
                    build_ms=1e3 * (time.perf_counter() - start), leaf_size=bottoms[0].leaf_size,
                    instances=table, top=top, bottoms=list(bottoms), order=order)


def move(two: TwoLevel, table: np.ndarray) -> int:
    """Place ``two``'s instances anew on the host: ``table`` their INSTANCE
    rows for the new transforms (:func:`instance_table`; their meshes' places
    are copied here), the top level built again over its boxes, as the
    host's build makes it -- the meshes' levels stay, rows and all
    (:func:`top_rows`).  Returns how many rows from the first changed (the
    top level's; 0 without a BVH)."""
    for name in ("mesh", "root", "first", "count", "material"):
        table[name] = two.instances[name]
    two.instances = table
    if two.top is None:
        return 0
    top = top_level(table, two.accel)
    base = len(two.top.rows)
    if len(top.rows) != base:   # (cannot happen: top_rows)
        raise RuntimeError(f"a top level of {len(table)} instances has {len(top.rows)} rows, not {base}")
    two.rows[:base] = top.rows
    two.top = top
    two.depth = int(top.depth + 1 + max(b.depth for b in two.bottoms))
    return base

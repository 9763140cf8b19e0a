"""The render programs -- Whitted's (entry render.cl) and the path tracer's
(entry path.cl) -- with every kernel's parameters, declared once
(clrt.device.signature; tests/test_kernel_args.py checks them against the
compiler's view of each program), and the buffers only they read: a tile's
frame buffer and the scene's small tables.
"""

from __future__ import annotations

import numpy as np

from clrt.device.signature import GEOMETRY, buffer, value
from clrt.layouts import CAMERA, HIT, MATERIAL, PATH_LAUNCH, RAY, TILE

#: SHADING_PARAMS (shading.cl, texture.cl).
SHADING = (buffer("tri_info", split=True), buffer("vertex_normals", split=True), buffer("tables"),
           buffer("tri_detail", when="SURFACE_DETAIL", split=True), buffer("texels", when="SURFACE_DETAIL", split=True))

RENDER_KERNELS = {
    "generate_rays": (buffer("frame"), value("cam", CAMERA), value("tile", TILE)),
    "shade_pixels": (buffer("frame"), value("tile", TILE), *GEOMETRY, *SHADING),
}

#: The path tracer's program (path.cl): a megakernel that traces whole paths,
#: its image's sums in `frame` (PATH_ARRAYS), its light tables in `tables`
#: beside the materials (pack_tables); and the kernel that turns the sums into
#: the means read back, the first `arrays` of PATH_ARRAYS packed in `out`.
PATH_KERNELS = {
    "path_trace": (buffer("frame"), value("launch", PATH_LAUNCH), *GEOMETRY, *SHADING),
    "path_resolve": (buffer("frame"), value("launch", PATH_LAUNCH), value("arrays", np.uint32), buffer("out")),
}

#: The path tracer's per-pixel sums in its frame buffer, float4 each (w: the
#: samples summed), after FRAME_HEADER bytes whose first uint says whether a
#: camera ray hit anything: radiance, the first hit's albedo and shading normal.
PATH_ARRAYS = ("image", "albedo", "normal")

#: Bytes of a tile's per-pixel arrays in its frame buffer: its ray, its hit
#: record, its linear colour (float4) and its packed 8-bit sRGB colour (the
#: last sample's), in that order (Tile in layouts.h),
#: after FRAME_HEADER bytes whose first uint says whether a camera ray of the
#: tile hit anything (render.cl's TILE_SEEN).
FRAME_ARRAYS = {"rays": RAY.itemsize, "hits": HIT.itemsize, "image": 16, "srgb": 3}
FRAME_HEADER = 16
TABLE_ALIGN = 16   # every table of the `tables` buffer starts at a multiple (float4 rows)


def frame_offsets(pixels: int) -> dict[str, int]:
    """Byte offset of each per-pixel array in a frame buffer of ``pixels`` pixels
    (and of the "seen" word, 0); "end": the buffer's size."""
    offsets, at = {"seen": 0}, FRAME_HEADER
    for name, size in FRAME_ARRAYS.items():
        offsets[name] = at
        at += pixels * size
    offsets["end"] = at
    return offsets


def pack_tables(materials: np.ndarray, lights: np.ndarray, textures: np.ndarray | None = None,
                srgb_table: np.ndarray | None = None, **more: np.ndarray) -> tuple[np.ndarray, dict]:
    """The scene's small tables in one byte array (the `tables` buffer,
    shading.cl), and the offsets of each: SceneInfo's (materials_at, lights_at,
    textures_at, srgb_at; 0 for a table not there), then NAME_at of each of
    ``more`` (the path tracer's light tables, PathLaunch's offsets)."""
    assert materials.dtype == MATERIAL
    parts, offsets, at = [], {}, 0
    for name, table in (("materials_at", materials), ("lights_at", lights), ("textures_at", textures),
                        ("srgb_at", srgb_table), *((f"{k}_at", v) for k, v in more.items())):
        offsets[name] = at if table is not None else 0
        if table is None:
            continue
        raw = np.ascontiguousarray(table).view(np.uint8).ravel()
        pad = -len(raw) % TABLE_ALIGN
        parts += [raw, np.zeros(pad, np.uint8)]
        at += len(raw) + pad
    packed = np.concatenate(parts) if at else np.zeros(TABLE_ALIGN, np.uint8)
    return packed, offsets

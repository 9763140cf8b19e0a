"""Per-pixel images of a camera written as files (``clrt render --aov``): beside
the image as IMAGE.NAME.npy + IMAGE.NAME.png (:data:`VALUES` and
:data:`PICTURES`), or, when the image's format holds named channels (OpenEXR),
as extra channels of that file (:data:`EXR_CHANNELS`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clrt import checks, config
from clrt.output import WRITERS, write_array, write_image
from clrt.query.accel import Accel
from clrt.query.results import CameraImages


AOVS = config.AOVS
#: The formats of the files beside the image: each AOV's values as they are, and
#: a picture of them (8-bit gray or RGB).
VALUES, PICTURES = WRITERS["npy"], WRITERS["png"]

#: The channels each AOV becomes in an .exr output, with the values of its .npy
#: (misses included): depth as ``Z`` (FLOAT, inf on a miss: OpenEXR's usual
#: depth channel), distance as ``distance`` (FLOAT, inf), normal as ``N.X N.Y
#: N.Z`` (FLOAT, world space, 0 on a miss: layer ``N``, as compositors name
#: normals), prim as ``prim`` (UINT: the int32 index as its two's complement,
#: so a miss, -1, is 0xFFFFFFFF and ``.view(np.int32)`` gives the .npy back;
#: float would lose indices above 2**24), instance as ``instance`` (UINT
#: likewise: the placement seen in a scene of placed meshes, 0 for a single
#: mesh), hit and front as ``hit`` and ``front`` (HALF 1.0 / 0.0, mattes for
#: compositing).
EXR_CHANNELS = {"depth": ("Z",), "distance": ("distance",), "normal": ("N.X", "N.Y", "N.Z"),
                "prim": ("prim",), "instance": ("instance",), "hit": ("hit",), "front": ("front",)}


def parse_aovs(text) -> tuple[str, ...]:
    """'depth,normal' -> ('depth', 'normal'); InputError naming an unknown one
    (clrt.checks.aov_names, which the --aov option checks with)."""
    return checks.aov_names("--aov", text)


def aov_arrays(images: CameraImages, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(values, 8-bit picture of them) of one AOV."""
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
    if name in ("prim", "instance"):   # indices: each its own arbitrary colour
        values = getattr(images, name)
        key = values.astype(np.uint32) * np.uint32(2654435761)
        rgb = np.stack([(key >> s) & 0xFF for s in (8, 16, 24)], axis=-1).astype(np.uint8) | 0x30
        return values, np.where(hit[..., None], rgb, 0).astype(np.uint8)
    flag = images.hit if name == "hit" else images.front
    return flag, flag.astype(np.uint8) * 255


def exr_channels(images: CameraImages, names) -> dict:
    """The EXR channels (:data:`EXR_CHANNELS`) of the AOVs ``names``: channel name ->
    (H, W) array, float32, float16 or uint32 as the file stores it."""
    channels = {}
    for name in names:
        values, _ = aov_arrays(images, name)
        if name == "normal":
            parts = [np.ascontiguousarray(values[..., k], np.float32) for k in range(3)]
        elif name in ("prim", "instance"):
            parts = [np.ascontiguousarray(values, np.int32).view(np.uint32)]
        elif name in ("hit", "front"):
            parts = [values.astype(np.float16)]
        else:
            parts = [np.ascontiguousarray(values, np.float32)]
        channels.update(zip(EXR_CHANNELS[name], parts))
    return channels


def camera_images_of(source, camera) -> CameraImages:
    """The AOVs' source: ``camera``'s images from a Renderer (its uploaded scene
    is reused) or an Accel."""
    accel = source if isinstance(source, Accel) else Accel.from_renderer(source)
    return accel.camera_images(camera)


def aov_paths(image_path, names) -> list[Path]:
    """IMAGE.NAME.npy and IMAGE.NAME.png (the suffixes of VALUES and PICTURES) for
    each AOV name, beside ``image_path``."""
    image_path = Path(image_path)
    paths = []
    for name in names:
        base = f"{image_path.stem}.{name}"
        paths += [image_path.with_name(base + VALUES.suffix), image_path.with_name(base + PICTURES.suffix)]
    return paths


def write_aovs(source, camera, names, image_path, force: bool = False, images=None,
               written: list | None = None) -> list[Path]:
    """Write each AOV of ``camera`` as IMAGE.NAME.npy (the values) and
    IMAGE.NAME.png (a picture of them), next to ``image_path``.  ``source``: a
    Renderer (its uploaded scene is reused) or an Accel; ``images``: its
    camera_images_of(source, camera) if already traced.  Existing files are
    replaced only if clrt wrote them, or with ``force`` (clrt.output).
    Returns the paths, appended to ``written`` as each is written (so that a
    caller can remove them when a later write fails)."""
    if isinstance(names, str):
        names = parse_aovs(names)
    if images is None:
        images = camera_images_of(source, camera)
    image_path = Path(image_path)
    written = [] if written is None else written
    paths = []
    for name in names:
        values, picture = aov_arrays(images, name)
        values_path, picture_path = aov_paths(image_path, [name])
        write_array(values, values_path, force=force)
        written.append(values_path)
        write_image(picture, picture_path, force=force)
        written.append(picture_path)
        paths += [values_path, picture_path]
    return paths

"""Why a frame shows nothing but the background.

The kernels say whether any camera ray of a frame hit a triangle (render.cl's
TILE_SEEN, read back with the image: no pass over the hits).  Only when none
did does the host look for the reason, for the one-line warning
(:class:`clrt.errors.NothingVisibleWarning`): a pass over the triangles then,
never on a frame that shows something.
"""

from __future__ import annotations

import numpy as np

from clrt import checks

_BLOCK = 1 << 18   # triangles measured at a time (bounded temporaries)
# A triangle counts as of zero area when twice its area is below this share of
# its longest edge squared: degenerate in float32, where the kernels test it.
_FLAT = 1e-7


def zero_area_count(corners: np.ndarray) -> int:
    """How many of the (F, 3, 3) triangles have (float32) zero area."""
    flat = 0
    for start in range(0, len(corners), _BLOCK):
        c = corners[start:start + _BLOCK].astype(np.float64)
        e1, e2, e3 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], c[:, 2] - c[:, 1]
        cross = np.linalg.norm(np.cross(e1, e2), axis=1)
        longest = np.max([np.einsum("ij,ij->i", e, e) for e in (e1, e2, e3)], axis=0)
        flat += int((cross <= _FLAT * longest).sum())
    return flat


def nothing_visible(corners: np.ndarray, bounds, camera) -> str:
    """The warning for a frame of ``camera`` in which no camera ray hit any of
    the triangles ``corners`` ((F, 3, 3), the scene's box ``bounds`` (2, 3))."""
    n = len(corners)
    image = f"nothing visible in the {camera.width}x{camera.height} image, only the background: "
    if zero_area_count(corners) == n:
        return image + ("the scene's only triangle has zero area" if n == 1 else
                        f"all {n:,} triangles of the scene have zero area") + " (a corrupt or flattened mesh?)"
    forward, _, _ = camera.basis()
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    box = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    where = f"the camera at {checks.show(camera.eye)} looks at {checks.show(camera.target)}"
    if ((box - np.asarray(camera.eye, np.float64)) @ forward <= 0.0).all():
        return image + f"the scene lies behind the camera ({where})"
    return image + (f"no camera ray hits the scene's {n:,} triangle(s): it lies out of the camera's view or "
                    f"is too small in it ({where}; the scene's box is {checks.show(tuple(lo))} .. "
                    f"{checks.show(tuple(hi))})")

"""Scene buffers larger than one allocation are split into parts (split.cl):
the same hits and the same image as whole buffers, forced here on small scenes
by lowering the allocation limit."""

from pathlib import Path

import numpy as np
import pytest

from clrt.renderer import Renderer
from clrt.scene.load import load_mesh
from clrt.scene.scene import Camera, scene_from_mesh
from clrt.query import Accel

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def knot():
    return load_mesh(REPO / "assets" / "meshes" / "knot.obj")


def _limit_for_parts(triangles: int, parts: int = 4) -> int:
    """An allocation limit that cuts the triangles and BVH rows into ``parts``."""
    step = 1 << int(np.ceil(np.log2(triangles / parts)))
    return 80 * step      # 80 B BVH rows; 48 B triangles get the same power of two


@pytest.mark.parametrize("accel", ["none", "box", "sphere"])
def test_split_buffers_render_the_same_frame(knot, accel, device):
    scene = scene_from_mesh(knot)
    camera = Camera.framing(scene.bounds, 64, 48)
    whole = Renderer(scene, device=device, accel=accel)
    assert whole.geometry.parts() == 1 and "SPLIT_BUFFERS" not in whole.geometry.defines
    expected = whole.render(camera, hits=True)
    split = Renderer(scene, device=device, accel=accel, max_buffer_bytes=_limit_for_parts(len(knot.faces)))
    assert split.geometry.parts() >= 3 and "SPLIT_BUFFERS" in split.geometry.defines
    frame = split.render(camera, hits=True)
    # The image shows triangles of every part.
    prim_ids = split.acceleration.prim_ids
    slot_of = np.empty_like(prim_ids)
    slot_of[prim_ids] = np.arange(len(prim_ids))
    seen = np.unique(expected.prim[expected.prim >= 0])
    assert len(np.unique(slot_of[seen] >> split.geometry.shifts["tris"])) == split.geometry.parts()
    for name in ("image", "prim", "t"):
        assert np.array_equal(getattr(frame, name), getattr(expected, name)), name


def test_split_buffers_answer_every_query_alike(knot, device):
    rng = np.random.default_rng(7)
    centre = knot.vertices.mean(axis=0)
    origins = centre + rng.normal(size=(3000, 3)) * 3.0
    directions = centre + rng.normal(size=(3000, 3)) * 0.5 - origins
    whole = Accel(knot, device=device)
    split = Accel(knot, device=device, max_buffer_bytes=_limit_for_parts(len(knot.faces), 3))
    assert split.geometry.parts() >= 2
    a, b = whole.trace(origins, directions), split.trace(origins, directions)
    assert a.hit.mean() > 0.2
    for name in ("t", "prim", "u", "v", "front"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(whole.occluded(origins, directions), split.occluded(origins, directions))
    assert np.array_equal(whole.count(origins, directions), split.count(origins, directions))
    all_a, all_b = whole.all_hits(origins, directions), split.all_hits(origins, directions)
    for name in ("ray_id", "prim", "t"):   # both sorted by ray, distance, triangle
        assert np.array_equal(getattr(all_a, name), getattr(all_b, name)), name

"""The GPU against PoCL, where a machine has both (the lent H200 does; the CI
machine has PoCL alone and skips this file): the path tracer's images agree
within noise for the same scene and seeds, and point queries agree exactly."""

import numpy as np
import pyopencl as cl
import pytest

import clrt
import path_reference
from benchmarks.scenes import CORNELL_BOX_FILE
from clrt.scene import primitives

GALLERY_GOLD = CORNELL_BOX_FILE.parent / "gallery" / "gold-knot.toml"


def _has(kind) -> bool:
    try:
        return any(p.get_devices(device_type=kind) for p in cl.get_platforms())
    except cl.Error:
        return False


pytestmark = pytest.mark.skipif(not (_has(cl.device_type.GPU) and _has(cl.device_type.CPU)),
                                reason="needs a GPU and a CPU OpenCL device")


def _stack(source, device, **options):
    return np.stack([clrt.render(str(source), integrator="path", linear=True, device=device, seed=seed, **options)
                     for seed in range(4)])


# The Cornell box takes the diffuse-only BSDF, the gold knot (metal, rough
# plastic) the general one.
@pytest.mark.parametrize("source, options", [
    (CORNELL_BOX_FILE, dict(spp=64, max_depth=8, width=64, height=64)),
    (GALLERY_GOLD, dict(spp=64, max_depth=8, width=64, height=40))])
def test_the_path_tracer_agrees_on_gpu_and_pocl(source, options):
    gpu, cpu = (path_reference.mean_and_variance(_stack(source, d, **options)) for d in ("gpu", "cpu"))
    z = path_reference.block_z(*gpu, *cpu)
    assert np.abs(z).max() <= path_reference.Z_LIMIT and (z ** 2).mean() <= path_reference.MEAN_Z2_LIMIT, (
        f"max |z| {np.abs(z).max():.2f}, mean z^2 {(z ** 2).mean():.2f}")


def test_point_queries_agree_on_gpu_and_pocl():
    """Within the documented bounds (the devices round double and float32
    arithmetic alike but not always identically: contraction into FMAs is the
    compiler's choice): distances within POINT_DISTANCE_BOUND of each other,
    the same triangle where no other is as near, the same sign and inside
    answer away from the surface and from w = 0.5."""
    from clrt.query.results import POINT_DISTANCE_BOUND, WINDING_NUMBER_ERROR

    mesh = primitives.torus(1.0, 0.35, 48, 24)
    points = np.random.default_rng(2).uniform(-1.6, 1.6, (20000, 3))
    answers = {}
    for device in ("gpu", "cpu"):
        accel = clrt.Accel(mesh, device=device)
        answers[device] = (accel.closest_points(points), accel.signed_distance(points, sign="normal"),
                           accel.contains(points), accel.winding_number(points))
    (g_closest, g_signed, g_inside, g_winding), (c_closest, c_signed, c_inside, c_winding) = answers.values()
    bound = 4 * POINT_DISTANCE_BOUND * 1.6
    assert np.abs(g_closest.distance - c_closest.distance).max() <= bound
    differ = g_closest.prim != c_closest.prim
    assert differ.mean() < 0.01   # ties and near-ties only
    assert np.abs(np.abs(g_signed) - np.abs(c_signed)).max() <= bound
    away = np.abs(c_signed) > 4 * bound
    np.testing.assert_array_equal(np.sign(g_signed[away]), np.sign(c_signed[away]))
    assert np.abs(g_winding - c_winding).max() <= 2 * WINDING_NUMBER_ERROR
    clear = np.abs(c_winding - 0.5) > 4 * WINDING_NUMBER_ERROR
    np.testing.assert_array_equal(g_inside[clear], c_inside[clear])

"""The path tracer against Mitsuba 3: the Cornell box (assets/scenes/cornell-box.gltf, built from
the numbers of Mitsuba's mi.cornell_box()) converges to Mitsuba's own converged render within
noise (tests/path_reference.py: block z-scores; docs/path-tracing.md, "Reference images")."""

import numpy as np
import pytest

import clrt
import clrt.renderer.path
import path_reference
from benchmarks.scenes import CORNELL_BOX_FILE

SEEDS = 4      # independent renders, whose spread gives the image's own variance
SPP = 64


@pytest.mark.parametrize("max_depth, diffuse_only", [(2, True), (8, True), (8, False)])
def test_cornell_box_matches_mitsuba(max_depth, diffuse_only, device, monkeypatch):
    """Both path programs: the box's materials are all Lambertian, so it gets
    the diffuse-only BSDF (bsdf.cl, BSDF_DIFFUSE_ONLY) unless that is turned
    off, when the general BSDF must give the same image."""
    monkeypatch.setattr(clrt.renderer.path, "DIFFUSE_ONLY_PROGRAMS", diffuse_only)
    reference = path_reference.load_reference(max_depth)
    h, w = reference.image.shape[:2]
    renders = np.stack([clrt.render(str(CORNELL_BOX_FILE), integrator="path", spp=SPP, max_depth=max_depth,
                                    seed=seed, width=w, height=h, linear=True, device=device)
                        for seed in range(SEEDS)])
    path_reference.assert_matches(renders, reference)
    # and a wrong answer fails: the same images 3 % too bright
    with pytest.raises(AssertionError):
        path_reference.assert_matches(renders * 1.03, reference)


def test_only_all_lambertian_scenes_get_the_diffuse_only_bsdf():
    from clrt.layouts import MATERIAL
    from clrt.renderer.path import bsdf_defines

    rows = np.zeros(3, MATERIAL)
    assert bsdf_defines(rows) == {"BSDF_DIFFUSE_ONLY": None}
    for field in ("metallic", "specular_weight", "transmission"):
        changed = rows.copy()
        changed[field][1] = 0.25
        assert bsdf_defines(changed) == {}, field
        assert bsdf_defines(changed, used=np.array([0, 2, 2])) == {"BSDF_DIFFUSE_ONLY": None}, field

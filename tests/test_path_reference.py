"""The path tracer against Mitsuba 3: the Cornell box (assets/scenes/cornell-box.gltf, built from
the numbers of Mitsuba's mi.cornell_box()) converges to Mitsuba's own converged render within
noise (tests/path_reference.py: block z-scores; docs/path-tracing.md, "Reference images")."""

import numpy as np
import pytest

import clrt
import path_reference
from benchmarks.scenes import CORNELL_BOX_FILE

SEEDS = 4      # independent renders, whose spread gives the image's own variance
SPP = 64


@pytest.mark.parametrize("max_depth", [2, 8])
def test_cornell_box_matches_mitsuba(max_depth, device):
    reference = path_reference.load_reference(max_depth)
    h, w = reference.image.shape[:2]
    renders = np.stack([clrt.render(str(CORNELL_BOX_FILE), integrator="path", spp=SPP, max_depth=max_depth,
                                    seed=seed, width=w, height=h, linear=True, device=device)
                        for seed in range(SEEDS)])
    path_reference.assert_matches(renders, reference)
    # and a wrong answer fails: the same images 3 % too bright
    with pytest.raises(AssertionError):
        path_reference.assert_matches(renders * 1.03, reference)

"""Scale: a 2M-triangle mesh builds and renders on PoCL (about 15 s on 2 cores).

The mesh is a finely tessellated torus, so every hit can be checked against
the analytic surface.  The paper builder is used: binned SAH takes about 25 s
for this mesh on 2 cores (docs/limits.md has the figures); both give the same
image (tests/test_accel.py).  ``python -m benchmarks.scale`` measures larger
meshes, on the GPU too.
"""

import numpy as np

from clrt.reference import camera_rays
from clrt.renderer import Renderer
from clrt.scene import primitives
from clrt.scene.scene import Camera, scene_from_mesh

MAJOR, MINOR = 1.0, 0.35


def test_two_million_triangles_build_and_render(device):
    mesh = primitives.torus(MAJOR, MINOR, 1000, 1000)
    assert len(mesh.faces) == 2_000_000
    renderer = Renderer(scene_from_mesh(mesh), device=device, accel="box", builder="paper")
    camera = Camera((0.0, 2.2, 2.6), (0.0, 0.0, 0.0), width=64, height=48)
    frame = renderer.render(camera, hits=True)
    assert frame.triangles == 2_000_000
    hit = frame.prim >= 0
    assert 0.2 < hit.mean() < 0.9
    assert frame.prim.max() < 2_000_000
    # Every hit lies on the torus (the tessellation is within 1e-5 of it).
    origins, dirs = camera_rays(camera)
    p = origins + frame.t.reshape(-1, 1) * dirs
    p = p[hit.ravel()]
    tube = np.hypot(np.hypot(p[:, 0], p[:, 2]) - MAJOR, p[:, 1])
    np.testing.assert_allclose(tube, MINOR, atol=1e-4)
    # Lit: the image is not just the ambient term.
    assert frame.image[hit].max() > 100
    stats = renderer.acceleration.stats()
    assert renderer.device_bytes < 300 * 2**20, "about 130 bytes per triangle on the device"
    assert stats["device_bytes"] <= renderer.device_bytes

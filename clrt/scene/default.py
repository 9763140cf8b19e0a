"""The built-in scene: glass and mirror over a checkerboard, all made of triangles."""

from __future__ import annotations

from clrt.scene.mesh import Mesh
from clrt.scene.primitives import checkerboard, icosphere, torus_knot
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject


def default_scene(width: int = 640, height: int = 480, coarse: bool = False) -> Scene:
    """A glass sphere, a mirror sphere, a torus knot and two small spheres on a
    checkerboard, lit by two lights; every Whitted effect appears: Phong
    highlights, shadows, reflection, refraction.  2 x 2 anti-aliasing.
    ``coarse`` uses a few thousand triangles instead of ~68,000 (for tests
    against the brute-force references)."""
    fine, small = (2, 1) if coarse else (5, 3)
    light_tiles, dark_tiles = checkerboard(tiles=10, size=10.0)
    floor = dict(ambient=0.1, diffuse=0.8, specular=0.1, shininess=16.0, smooth=False, reflectivity=0.1)
    knot = torus_knot(2, 3, radius=0.9, tube=0.16, segments=64 if coarse else 384, sides=8 if coarse else 32)
    knot = Mesh(knot.vertices + [[1.9, 1.15, -1.2]], knot.faces, knot.name)
    objects = [
        SceneObject(light_tiles, Material(color=(0.85, 0.85, 0.8), **floor)),
        SceneObject(dark_tiles, Material(color=(0.05, 0.05, 0.08), **floor)),
        SceneObject(icosphere(fine, 1.0, (-0.2, 1.0, 0.6), "glass sphere"),
                    Material(color=(0.97, 0.99, 1.0), ambient=0.0, diffuse=0.02, specular=0.8,
                             shininess=200.0, transparency=0.92, ior=1.5)),
        SceneObject(icosphere(fine, 1.1, (-2.2, 1.1, -1.6), "mirror sphere"),
                    Material(color=(0.9, 0.9, 0.9), ambient=0.02, diffuse=0.05, specular=0.6,
                             shininess=150.0, reflectivity=0.88)),
        SceneObject(knot, Material(color=(0.8, 0.25, 0.05), specular=0.5, shininess=60.0)),
        SceneObject(icosphere(small, 0.45, (1.6, 0.45, 1.3), "blue sphere"),
                    Material(color=(0.1, 0.3, 0.85), specular=0.5, shininess=40.0)),
        SceneObject(icosphere(small, 0.3, (0.9, 0.3, 2.3), "green sphere"),
                    Material(color=(0.15, 0.65, 0.25), specular=0.4, shininess=30.0)),
    ]
    lights = [Light((-4.0, 7.0, 5.0), (0.8, 0.78, 0.72)), Light((5.0, 4.0, 3.0), (0.35, 0.38, 0.5))]
    camera = Camera(eye=(0.3, 2.4, 7.2), target=(0.0, 0.9, 0.0), fov=45.0, width=width, height=height)
    return Scene(objects, lights, background=(0.03, 0.04, 0.07), camera=camera, max_depth=6, samples=2)

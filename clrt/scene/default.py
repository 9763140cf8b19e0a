"""The built-in scene: spheres over a checkerboard floor, all made of triangles."""

from __future__ import annotations

from clrt.scene.primitives import checkerboard, icosphere
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject


def default_scene(width: int = 640, height: int = 480) -> Scene:
    """Four spheres of different sizes and finishes on an 8 x 8 checkerboard, two lights."""
    light_tiles, dark_tiles = checkerboard(tiles=8, size=8.0)
    floor = dict(ambient=0.12, diffuse=0.8, specular=0.1, shininess=16.0, smooth=False)
    objects = [
        SceneObject(light_tiles, Material(color=(0.85, 0.85, 0.8), **floor)),
        SceneObject(dark_tiles, Material(color=(0.08, 0.08, 0.1), **floor)),
        SceneObject(icosphere(3, 1.0, (0.0, 1.0, 0.0), "centre sphere"),
                    Material(color=(0.75, 0.1, 0.08), specular=0.6, shininess=80.0)),
        SceneObject(icosphere(2, 0.6, (-1.9, 0.6, 0.7), "left sphere"),
                    Material(color=(0.1, 0.35, 0.8), specular=0.5, shininess=40.0)),
        SceneObject(icosphere(2, 0.5, (1.7, 0.5, 1.0), "right sphere"),
                    Material(color=(0.9, 0.7, 0.15), specular=0.8, shininess=120.0)),
        SceneObject(icosphere(2, 0.3, (0.6, 0.3, 2.0), "small sphere"),
                    Material(color=(0.2, 0.7, 0.3), specular=0.4, shininess=30.0)),
    ]
    lights = [Light((-4.0, 6.0, 5.0), (0.75, 0.75, 0.7)), Light((5.0, 4.0, 2.0), (0.35, 0.35, 0.45))]
    camera = Camera(eye=(0.0, 2.6, 6.8), target=(0.0, 0.7, 0.0), fov=45.0, width=width, height=height)
    return Scene(objects, lights, background=(0.02, 0.02, 0.03), camera=camera)

"""Materials, lights, camera and the scene that groups them (the paper's configuration)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clrt.config import DEFAULT_FOV, DEFAULT_HEIGHT, DEFAULT_MAX_DEPTH, DEFAULT_WIDTH, MAX_IMAGE_SIDE
from clrt.errors import InputError
from clrt.scene.mesh import Mesh


def _vec3(value, what: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be three numbers, got {value!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what} must be three finite numbers, got {value!r}")
    if np.abs(v).max() > 1e30:   # the device computes in float32 (largest 3.4e38)
        raise InputError(f"{what} must lie within +-1e30 (the device computes in float32), got {value!r}")
    return v


@dataclass(frozen=True)
class Material:
    """Phong material with Whitted optics.

    ``color`` is linear RGB in [0, 1]; ``smooth`` interpolates vertex normals.
    ``reflectivity`` (0..1) is the weight of the mirror reflection;
    ``transparency`` (0..1) the weight of the refracted ray, with index of
    refraction ``ior`` (Fresnel-weighted, total internal reflection included).
    """

    color: tuple = (0.8, 0.8, 0.8)
    ambient: float = 0.1
    diffuse: float = 0.7
    specular: float = 0.3
    shininess: float = 32.0
    smooth: bool = True
    reflectivity: float = 0.0
    transparency: float = 0.0
    ior: float = 1.5

    def __post_init__(self):
        color = _vec3(self.color, "material colour")
        if not ((color >= 0) & (color <= 1)).all():
            raise InputError(f"material colour must be three numbers in 0..1, got {self.color!r}")
        for name in ("ambient", "diffuse", "specular", "shininess", "reflectivity", "transparency"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InputError(f"material {name} must be a finite number >= 0, got {value!r}")
        for name in ("reflectivity", "transparency"):
            if getattr(self, name) > 1:
                raise InputError(f"material {name} must be between 0 and 1, got {getattr(self, name)!r}")
        if not (isinstance(self.ior, (int, float)) and math.isfinite(self.ior) and self.ior >= 1.0):
            raise InputError(f"material ior must be a finite number >= 1, got {self.ior!r}")


@dataclass(frozen=True)
class Light:
    """Point light at ``position`` with linear RGB ``color`` (intensity)."""

    position: tuple
    color: tuple = (1.0, 1.0, 1.0)

    def __post_init__(self):
        _vec3(self.position, "light position")
        _vec3(self.color, "light colour")


def check_int(name: str, value, lo: int, hi: int) -> None:
    """InputError unless ``value`` is an integer (not a bool) in lo..hi."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise InputError(f"{name} must be an integer in {lo}..{hi}, got {value!r}")


def _check_image(width, height, fov) -> None:
    check_int("width", width, 1, MAX_IMAGE_SIDE)
    check_int("height", height, 1, MAX_IMAGE_SIDE)
    if not (isinstance(fov, (int, float)) and 0.0 < fov < 180.0):
        raise InputError(f"fov must be between 0 and 180 degrees (exclusive), got {fov!r}")


@dataclass(frozen=True)
class Camera:
    """Pinhole camera: ``fov`` is the vertical field of view in degrees."""

    eye: tuple
    target: tuple
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = DEFAULT_FOV
    width: int = DEFAULT_WIDTH
    height: int = DEFAULT_HEIGHT

    def __post_init__(self):
        eye, target, up = (_vec3(self.eye, "eye"), _vec3(self.target, "target"), _vec3(self.up, "up"))
        _check_image(self.width, self.height, self.fov)
        forward = target - eye
        if not np.linalg.norm(forward) > 0:
            raise InputError("eye and target must differ")
        if not np.linalg.norm(np.cross(forward, up)) > 1e-9 * np.linalg.norm(forward) * np.linalg.norm(up):
            raise InputError("up must not be zero or parallel to the viewing direction")

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(forward, right, up) unit vectors, float64: r = f x up, u = r x f."""
        f = _vec3(self.target, "target") - _vec3(self.eye, "eye")
        f /= np.linalg.norm(f)
        r = np.cross(f, _vec3(self.up, "up"))
        r /= np.linalg.norm(r)
        return f, r, np.cross(r, f)

    def scales(self) -> tuple[float, float]:
        """(scale_x, scale_y): half-extent of the image plane at distance 1."""
        sy = math.tan(math.radians(self.fov) / 2.0)
        return sy * self.width / self.height, sy

    @classmethod
    def framing(cls, bounds, width: int = DEFAULT_WIDTH, height: int = DEFAULT_HEIGHT, fov: float = DEFAULT_FOV,
                direction=(0.35, 0.3, 1.0), up=(0.0, 1.0, 0.0)) -> "Camera":
        """A camera looking at the centre of ``bounds`` (2x3) from ``direction``,
        far enough that the bounding sphere fits in the narrower field of view."""
        _check_image(width, height, fov)
        bounds = np.asarray(bounds, dtype=np.float64)
        centre = bounds.mean(axis=0)
        radius = max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-6 * (1 + np.abs(centre).max()))
        half = math.radians(fov) / 2.0
        half = min(half, math.atan(math.tan(half) * width / height))
        d = np.asarray(direction, dtype=np.float64)
        eye = centre + d / np.linalg.norm(d) * radius / math.sin(half) * 1.05
        return cls(tuple(eye), tuple(centre), tuple(up), fov, width, height)


@dataclass(frozen=True)
class SceneObject:
    mesh: Mesh
    material: Material = field(default_factory=Material)


@dataclass
class Scene:
    """Objects (mesh + material), point lights and the colours of empty space."""

    objects: list
    lights: list
    background: tuple = (0.0, 0.0, 0.0)
    ambient_light: tuple = (1.0, 1.0, 1.0)
    camera: Camera | None = None   # suggested view; renderers may override
    camera_framed: bool = False    # the camera was framed from the bounds, not placed by the user
    max_depth: int = DEFAULT_MAX_DEPTH  # reflection / refraction bounces after the camera ray
    samples: int = 1               # anti-aliasing: samples x samples rays per pixel

    @property
    def bounds(self) -> np.ndarray:
        b = np.stack([o.mesh.bounds for o in self.objects])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    @property
    def num_triangles(self) -> int:
        return sum(len(o.mesh.faces) for o in self.objects)


def default_light(bounds, camera: Camera) -> Light:
    """A white light above and to the left of the eye, so shapes read clearly."""
    f, r, u = camera.basis()
    bounds = np.asarray(bounds, dtype=np.float64)
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    pos = np.asarray(camera.eye, dtype=np.float64) + (0.8 * u - 0.5 * r) * diag
    return Light(tuple(pos))


def scene_from_mesh(mesh: Mesh, material: Material | None = None, lights=None,
                    background=(0.0, 0.0, 0.0)) -> Scene:
    """The paper's scene: one mesh, one material, point lights (default: one above the eye)."""
    scene = Scene([SceneObject(mesh, material or Material())], list(lights or []), background)
    scene.camera, scene.camera_framed = Camera.framing(scene.bounds), True
    if not scene.lights:
        scene.lights = [default_light(scene.bounds, scene.camera)]
    return scene


def ray_epsilon(bounds, eye) -> float:
    """How far secondary rays start off the surface: well above float32 rounding of
    hit points (relative to the coordinates' magnitude) yet small against the scene."""
    bounds = np.asarray(bounds, dtype=np.float64)
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    magnitude = max(float(np.abs(bounds).max()), float(np.abs(np.asarray(eye, dtype=np.float64)).max()))
    return 1e-4 * diag + 1e-6 * magnitude


def as_mesh(source) -> Mesh:
    """A Mesh from a Mesh, a Scene (all objects, in order), a path, a trimesh.Trimesh
    or (vertices, faces)."""
    if isinstance(source, Mesh):
        return source
    if isinstance(source, Scene):
        return Mesh.concatenate([o.mesh for o in source.objects])
    if isinstance(source, (str, Path)):
        from clrt.scene.load import load_mesh   # trimesh is imported only when a file is read
        return load_mesh(source)
    if hasattr(source, "vertices") and hasattr(source, "faces"):
        return Mesh.from_arrays(source.vertices, source.faces)
    if isinstance(source, tuple) and len(source) == 2:
        return Mesh.from_arrays(*source)
    raise InputError(f"expected a mesh, a path or (vertices, faces), got {type(source).__name__}")


def as_scene(source) -> Scene:
    """A Scene from a Scene, or from anything :func:`as_mesh` takes (a Mesh, a file
    path, a trimesh object, (vertices, faces)) with the default framing and light."""
    if isinstance(source, Scene):
        return source
    return scene_from_mesh(as_mesh(source))

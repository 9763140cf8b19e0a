"""Materials, lights, camera and the scene that groups them (the paper's configuration)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np

from clrt import checks, config
from clrt.errors import InputError
from clrt.scene.mesh import Mesh
from clrt.scene.environment import Environment
from clrt.scene.texture import Texture



#: The textures a Material may hold, each read by its own decoding (True:
#: linear): base colour and emission are sRGB colours, metallicRoughness and
#: normal maps linear data (glTF 2.0 says which is which).
MATERIAL_TEXTURES = {"texture": False, "emission_texture": False, "metallic_roughness_texture": True,
                     "normal_texture": True}


@dataclass(frozen=True)
class PbrValues:
    """The path tracer's scalars of a material: its own, or mapped from Phong
    (:meth:`Material.pbr_values`)."""

    metallic: float
    roughness: float
    specular_weight: float
    transmission: float


@dataclass(frozen=True)
class Material:
    """Phong material with Whitted optics, and the metallic-roughness model
    (glTF 2.0 appendix B) of the path tracer.

    Whitted: ``color`` is linear RGB in [0, 1]; ``smooth`` interpolates vertex
    normals, blending them over edges where faces meet at up to ``crease``
    degrees (box edges stay sharp, curved surfaces look round; 180 blends over
    every edge).  ``reflectivity`` (0..1) is the weight of the mirror
    reflection; ``transparency`` (0..1) the weight of the refracted ray, with
    index of refraction ``ior`` (Fresnel-weighted, total internal reflection
    included).  ``texture`` (a :class:`~clrt.scene.texture.Texture`, or None)
    multiplies ``color`` where the mesh has texture coordinates (``Mesh.uv``),
    as a file's base-colour texture does.  The Whitted renderer reads only
    these fields.

    Path tracer: the base colour is ``color`` x ``texture`` (x the mesh's
    colours), as above.  ``emission``: linear emitted radiance (RGB >= 0; glTF's
    emissiveFactor x KHR_materials_emissive_strength), times
    ``emission_texture`` (sRGB) where there is one; it leaves the front face
    (counter-clockwise, glTF's) only, both when ``double_sided``.
    ``metallic`` and ``roughness`` (perceptual, GGX alpha = roughness^2), each
    0..1, times the G (roughness) and B (metallic) channels of
    ``metallic_roughness_texture`` (linear); ``specular_weight`` (0..1, 0: pure
    Lambert) and ``specular_color`` (linear RGB >= 0) as KHR_materials_specular
    says; ``transmission`` (0..1): the weight of a dielectric of index ``ior``
    (KHR_materials_transmission), smooth or rough by ``roughness``;
    ``normal_texture``: a tangent-space normal map (linear), its x and y scaled
    by ``normal_scale``.

    The paper's materials in the path tracer: ``metallic``, ``roughness``,
    ``specular_weight`` and ``transmission`` left None (as every Phong
    material -- the built-in scene, TOML and OBJ/MTL files without PBR keys --
    leaves them) come from the Phong fields through one mapping,
    :meth:`pbr_values`: a diffuse + glossy approximation of the Whitted look.

    ====================  ==================================================
    path tracer           from the Phong fields
    ====================  ==================================================
    base colour           ``color`` as it is (``diffuse`` and ``ambient`` are
                          not applied: the path tracer's light is bounded by
                          the light arriving, and its indirect light takes
                          the place of the ambient term)
    ``metallic``          ``reflectivity`` (Whitted's mirror becomes a metal)
    ``roughness``         ``(2 shininess + 1) ** -0.25``, the roughness whose
                          GGX highlight is as wide as the Phong one (the
                          inverse of the glTF reader's mapping), times ``1 -
                          max(reflectivity, transparency)``: Whitted's mirror
                          and refraction are sharp
    ``specular_weight``   ``min(specular, 1)`` (0: no highlight, pure Lambert)
    ``transmission``      ``transparency``
    ====================  ==================================================
    """

    color: tuple = config.DEFAULT_COLOR
    ambient: float = config.DEFAULT_AMBIENT
    diffuse: float = config.DEFAULT_DIFFUSE
    specular: float = config.DEFAULT_SPECULAR
    shininess: float = config.DEFAULT_SHININESS
    smooth: bool = True
    reflectivity: float = 0.0
    transparency: float = 0.0
    ior: float = config.DEFAULT_IOR
    crease: float = config.DEFAULT_CREASE_ANGLE
    texture: Texture | None = None
    emission: tuple = config.DEFAULT_EMISSION
    emission_texture: Texture | None = None
    double_sided: bool = False
    metallic: float | None = None
    roughness: float | None = None
    metallic_roughness_texture: Texture | None = None
    specular_weight: float | None = None
    specular_color: tuple = config.DEFAULT_SPECULAR_COLOR
    transmission: float | None = None
    normal_texture: Texture | None = None
    normal_scale: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "color", checks.color("material color", self.color))
        object.__setattr__(self, "emission", checks.intensity("material emission", self.emission))
        object.__setattr__(self, "specular_color", checks.vector("material specular_color", self.specular_color,
                                                                 ge=0, le=config.MAX_SPECULAR_COLOR))
        for name in MATERIAL_TEXTURES:
            value = getattr(self, name)
            if value is not None and not isinstance(value, Texture):
                raise checks.fail(f"material {name}", "a clrt Texture or None", value)
        for name in config.MATERIAL_RANGES:
            value = getattr(self, name)
            if value is not None or name not in _PBR_MAPPED:
                object.__setattr__(self, name, checks.material_number(f"material {name}", value, name))
        checks.boolean("material smooth", self.smooth)
        checks.boolean("material double_sided", self.double_sided)
        object.__setattr__(self, "crease", checks.crease(self.crease, "material crease"))

    def pbr_values(self) -> PbrValues:
        """The path tracer's metallic, roughness, specular_weight and
        transmission: each one given, else mapped from the Phong fields as the
        class docstring's table says."""
        sharp = 1.0 - max(self.reflectivity, self.transparency)
        mapped = PbrValues(metallic=self.reflectivity,
                           roughness=(2.0 * self.shininess + 1.0) ** -0.25 * sharp,
                           specular_weight=min(self.specular, 1.0),
                           transmission=self.transparency)
        return replace(mapped, **{name: getattr(self, name) for name in _PBR_MAPPED
                                  if getattr(self, name) is not None})

    @classmethod
    def of(cls, value) -> "Material":
        """A Material from a Material, None (the defaults) or a dict of its fields
        (as a scene file's material table): ``Material.of({"color": (1, 0, 0)})``."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            known = [f.name for f in fields(cls)]
            for key in value:
                if key not in known:
                    raise InputError(unknown_name("material field", key, known))
            return cls(**value)
        raise InputError(f"material must be a clrt.Material or a dict of its fields, got {type(value).__name__}")

    def with_overrides(self, **overrides) -> "Material":
        """A copy with the fields given replaced (None leaves a field as it is,
        except a texture field, which None removes)."""
        return replace(self, **{k: v for k, v in overrides.items() if v is not None or k in MATERIAL_TEXTURES})


#: The path tracer's fields that None leaves to the Phong mapping (Material.pbr_values).
_PBR_MAPPED = tuple(f.name for f in fields(PbrValues))


def unknown_name(what: str, name, known) -> str:
    """'unknown <what> 'x' (did you mean 'y'?)', or the list of valid names when nothing is close."""
    import difflib
    known = list(known)
    close = difflib.get_close_matches(str(name), known, n=1)
    if close:
        return f"unknown {what} {name!r} (did you mean {close[0]!r}?)"
    if not known:
        return f"unknown {what} {name!r} (no {what}s are defined)"
    return f"unknown {what} {name!r} (expected one of: {', '.join(sorted(known))})"


@dataclass(frozen=True)
class Light:
    """Point light at ``position`` with linear RGB ``color`` (an intensity: >= 0, may exceed 1).

    With a ``direction`` it is a spot light: it shines into the cone of half
    angle ``cutoff`` degrees about that direction (0 < cutoff <= 90), at full
    intensity within ``beam`` degrees of the axis (default three quarters of
    ``cutoff``), falling off smoothly between (smoothstep of the cosines; both
    integrators).  The path tracer takes ``color`` as the radiant intensity
    (W/sr, lighting falls off with the squared distance); Whitted's Phong model
    uses it without falloff, as the paper does.
    """

    position: tuple
    color: tuple = config.DEFAULT_LIGHT_COLOR
    direction: tuple | None = None
    cutoff: float = config.DEFAULT_SPOT_CUTOFF
    beam: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", checks.position("light position", self.position))
        object.__setattr__(self, "color", checks.intensity("light color", self.color))
        if self.direction is not None:
            d = checks.position("light direction", self.direction)
            norm = math.sqrt(sum(x * x for x in d))
            if not norm > 0:
                raise checks.fail("light direction", "3 numbers, not all 0", self.direction)
            object.__setattr__(self, "direction", tuple(x / norm for x in d))
        object.__setattr__(self, "cutoff", checks.number("light cutoff", self.cutoff, gt=0, le=90))
        beam = 0.75 * self.cutoff if self.beam is None else checks.number("light beam", self.beam, ge=0,
                                                                          le=self.cutoff)
        object.__setattr__(self, "beam", beam)

    @classmethod
    def of(cls, value) -> "Light":
        """A Light from a Light, a position (x, y, z) (a white light there), or a
        dict of its fields (as a batch's settings carry it: plain JSON)."""
        if isinstance(value, dict):
            return cls(**value)
        return value if isinstance(value, cls) else cls(value)


def _check_image(width, height, fov) -> None:
    checks.image_size(width, height)
    checks.fov(fov)


@dataclass(frozen=True)
class Camera:
    """Pinhole camera: ``fov`` is the vertical field of view in degrees."""

    eye: tuple
    target: tuple
    up: tuple = config.DEFAULT_UP
    fov: float = config.DEFAULT_FOV
    width: int = config.DEFAULT_WIDTH
    height: int = config.DEFAULT_HEIGHT

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            object.__setattr__(self, name, checks.position(name, getattr(self, name)))
        eye, target, up = (np.asarray(v) for v in (self.eye, self.target, self.up))
        object.__setattr__(self, "width", checks.integer("width", self.width, 1, config.MAX_IMAGE_SIDE))
        object.__setattr__(self, "height", checks.integer("height", self.height, 1, config.MAX_IMAGE_SIDE))
        object.__setattr__(self, "fov", checks.fov(self.fov))
        forward = target - eye
        if not np.linalg.norm(forward) > 0:
            raise InputError("eye and target must differ")
        if not np.linalg.norm(np.cross(forward, up)) > 1e-9 * np.linalg.norm(forward) * np.linalg.norm(up):
            raise InputError("up must not be zero or parallel to the viewing direction")

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(forward, right, up) unit vectors, float64: r = f x up, u = r x f.
        (The vectors were checked when the camera was made.)"""
        f = np.asarray(self.target, dtype=np.float64) - np.asarray(self.eye, dtype=np.float64)
        f /= np.linalg.norm(f)
        r = np.cross(f, np.asarray(self.up, dtype=np.float64))
        r /= np.linalg.norm(r)
        return f, r, np.cross(r, f)

    def scales(self) -> tuple[float, float]:
        """(scale_x, scale_y): half-extent of the image plane at distance 1."""
        sy = math.tan(math.radians(self.fov) / 2.0)
        return sy * self.width / self.height, sy

    @classmethod
    def framing(cls, bounds, width: int = config.DEFAULT_WIDTH, height: int = config.DEFAULT_HEIGHT,
                fov: float = config.DEFAULT_FOV, direction=(0.35, 0.3, 1.0), up=config.DEFAULT_UP) -> "Camera":
        """A camera looking at the centre of ``bounds`` (2x3) from ``direction``,
        far enough that the bounding sphere fits in the narrower field of view."""
        _check_image(width, height, fov)
        bounds = np.asarray(bounds, dtype=np.float64)
        centre = bounds.mean(axis=0)
        # At least a float32 step or so of the centre, so that the eye stands apart
        # from it on the device; relative only, so that a mesh a micron or a
        # nanometre across fills the frame as a metre one does (a point at the
        # origin, with no size at all, gets 1e-6).
        radius = max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-6 * float(np.abs(centre).max())) or 1e-6
        half = math.radians(fov) / 2.0
        half = min(half, math.atan(math.tan(half) * width / height))
        d = np.asarray(direction, dtype=np.float64)
        with np.errstate(all="ignore"):
            eye = centre + d / np.linalg.norm(d) * radius / math.sin(half) * 1.05
        _within_limit(eye, "cannot frame the scene: the camera would stand at {}", "place the camera "
                      "(eye and target)")
        return cls(tuple(eye), tuple(centre), tuple(up), fov, width, height)


@dataclass(frozen=True)
class SceneObject:
    """A mesh and its materials, and where the mesh is placed.

    ``mesh`` may be anything :func:`clrt.scene.load.as_mesh` takes (a Mesh, a
    file path, a trimesh object, ``(vertices, faces)``), ``material`` a
    Material or a dict of its fields.  ``materials``: the materials a file
    gives its faces -- face ``f`` has ``materials[mesh.face_material[f]]``;
    faces without one (id -1, or a mesh without ``face_material``) have
    ``material``.  For a smooth material ``mesh`` becomes the mesh prepared for
    smooth shading (:meth:`Mesh.split_at_creases` with ``material``'s crease
    angle): the same triangles in the same order at the same positions, with
    vertices shared where normals blend.

    ``transforms``: None -- the mesh stands where its vertices are -- or
    ``(K, 4, 4)`` affine maps (a single 4x4 is one) from the mesh's own space
    to the world: the mesh placed K times, each placement an instance of one
    mesh on the device, never a copy (docs/instances.md).  Objects that give
    one Mesh object, with the same crease angle, share one bottom-level mesh
    whatever their materials: a material per placement is an object per
    placement.  Checked here: finite, affine, invertible, the placed mesh
    within the device's range.
    """

    mesh: Mesh
    material: Material = field(default_factory=Material)
    materials: tuple = ()
    transforms: np.ndarray | None = field(default=None, compare=False)

    def __post_init__(self):
        from clrt.scene.load import as_mesh
        material = Material.of(self.material)
        if isinstance(self.materials, (str, bytes, dict)) or not hasattr(self.materials, "__iter__"):
            raise checks.fail("materials", "a list of clrt.Material", self.materials)
        materials = tuple(Material.of(m) for m in self.materials)
        mesh = as_mesh(self.mesh)
        ids = mesh.face_material
        if ids is not None and not materials:   # the file's materials were not wanted
            mesh, ids = _without(mesh, "face_material"), None
        if ids is not None and len(ids) and ids.max() >= len(materials):
            raise InputError(f"{mesh.name or 'mesh'}: face material id {int(ids.max())} but only "
                             f"{len(materials)} materials")
        if any(m.smooth for m in (material, *materials)):
            mesh = mesh.split_at_creases(material.crease)
        object.__setattr__(self, "material", material)
        object.__setattr__(self, "materials", materials)
        object.__setattr__(self, "mesh", mesh)
        if self.transforms is not None:
            object.__setattr__(self, "transforms", _placements(self.transforms, mesh))

    @property
    def placements(self) -> int:
        """How many times the mesh is placed (1 without transforms)."""
        return 1 if self.transforms is None else len(self.transforms)

    def with_overrides(self, **fields) -> "SceneObject":
        """The object with the material fields given (not None) replaced in all its
        materials.  A new ``color`` also drops textures and the mesh's vertex
        colours: ``--color 1,0,0`` makes an object red, whatever its file says."""
        fields = {k: v for k, v in fields.items() if v is not None}
        mesh = self.mesh
        if "color" in fields and mesh.colors is not None:
            mesh = _without(mesh, "colors")
        if "color" in fields:
            fields["texture"] = None
        material = self.material.with_overrides(**fields)
        materials = tuple(m.with_overrides(**fields) for m in self.materials)
        if "smooth" in fields or "crease" in fields:   # the mesh may need splitting anew
            return SceneObject(mesh, material, materials, self.transforms)
        # Same shading, so the mesh is already split for it: do not split it again
        # (a second crease split of a large mesh costs as much as the first).
        obj = object.__new__(SceneObject)
        for name, value in (("mesh", mesh), ("material", material), ("materials", materials),
                            ("transforms", self.transforms)):
            object.__setattr__(obj, name, value)
        return obj


def _without(mesh: Mesh, detail: str) -> Mesh:
    """``mesh`` without its ``detail`` (colours, face materials): one Mesh for
    every object that asks (Mesh.variant), so that placements stay shared."""
    return mesh.variant(("without", detail), lambda: replace(mesh, **{detail: None}))


def _placements(value, mesh: Mesh) -> np.ndarray:
    """(K, 4, 4) float64 read-only transforms of a SceneObject, checked (as
    instances' are: clrt.scene.instances) and the placed mesh within +-MAX_COORDINATE."""
    from clrt.scene.instances import checked_transforms, mapped_boxes
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise checks.fail("transforms", "(K, 4, 4) affine matrices", value) from None
    if m.shape == (4, 4):
        m = m[None]
    if m.ndim != 3 or m.shape[1:] != (4, 4) or not len(m):
        raise InputError(f"transforms must have shape (K, 4, 4) with K >= 1, or (4, 4), got {m.shape}")
    m = checked_transforms(m, len(m))
    boxes = mapped_boxes(m, np.broadcast_to(mesh.bounds, (len(m), 2, 3)))
    reach = np.abs(boxes).max(axis=(1, 2))
    if not (reach <= config.MAX_COORDINATE).all():
        k = int(np.argmax(~(reach <= config.MAX_COORDINATE)))
        raise InputError(f"{mesh.name or 'mesh'}: placement {k} takes it to {float(reach[k]):.3g}, past "
                         f"+-{checks.show(config.MAX_COORDINATE)} (the device computes in float32)")
    m.flags.writeable = False
    return m


def _objects(value) -> list:
    if not isinstance(value, (list, tuple)) or not value:
        raise checks.fail("objects", "a non-empty list of SceneObject", value)
    return [o if isinstance(o, SceneObject) else SceneObject(o) for o in value]


def _lights(value) -> list:
    if isinstance(value, Light):
        return [value]
    if isinstance(value, (tuple, list)) and len(value) == 3 and all(checks.is_number(v) for v in value):
        # one position where a list of them is meant: say how to write it
        raise InputError(f"lights must be a list of Light or of positions (x, y, z), got {checks.show(value)}: "
                         f"for one light there, write [{checks.show(value)}]")
    if value is None or isinstance(value, (str, bytes, dict)) or not hasattr(value, "__iter__"):
        raise checks.fail("lights", "a list of Light or of positions (x, y, z)", value)
    return [Light.of(light) for light in value]


def _camera(value):
    if value is not None and not isinstance(value, Camera):
        raise checks.fail("camera", "a clrt.Camera or None", value)
    return value


# Scene attribute -> its check; run on every assignment, so a value set after
# construction (as the CLI's options do) is checked like one given to Scene().
_SCENE_CHECKS = {
    "objects": _objects,
    "lights": _lights,
    "background": lambda v: checks.intensity("background", v),
    "ambient_light": lambda v: checks.intensity("ambient_light", v),
    "camera": _camera,
    "camera_framed": lambda v: checks.boolean("camera_framed", v),
    "default_lights": lambda v: checks.boolean("default_lights", v),
    "samples": checks.samples,
    "integrator": lambda v: checks.choice("integrator", v, config.INTEGRATORS),
    "spp": lambda v: None if v is None else checks.spp(v),
    "seed": checks.seed,
    "exposure": checks.exposure,
    "environment": lambda v: None if v is None else Environment.of(v),
    "source": lambda v: checks.text("source", v),
}


@dataclass
class Scene:
    """Objects (mesh + material), point lights and the colours of empty space.

    Every attribute is checked when it is set (``InputError``); ``lights`` may
    be given as positions, ``objects`` as meshes (default material).
    """

    objects: list
    lights: list
    background: tuple = config.DEFAULT_BACKGROUND
    ambient_light: tuple = config.DEFAULT_AMBIENT_LIGHT
    camera: Camera | None = None   # suggested view; renderers may override
    camera_framed: bool = False    # the camera was framed from the bounds, not placed by the user
    default_lights: bool = False   # the lights are clrt's default one, placed from ``camera``, not the user's
    max_depth: int | None = None   # None: the integrator's default (Whitted: 5 bounces; path: -1, unbounded)
    samples: int = config.DEFAULT_SAMPLES       # Whitted's anti-aliasing: samples x samples rays per pixel
    source: str = ""               # the file it came from (a mesh or scene file), named by errors
    integrator: str = config.DEFAULT_INTEGRATOR   # "whitted" (the paper's) or "path"
    spp: int | None = None         # the path tracer's samples per pixel (None: config.DEFAULT_SPP)
    seed: int = 0                  # of the sample jitter and the path tracer's random numbers
    exposure: float = 0.0          # stops: 8- and 16-bit images show the linear one x 2**exposure
    environment: Environment | None = None   # the path tracer's sky (an equirectangular HDR map)

    def __setattr__(self, name, value):
        if name == "max_depth":   # the integrator's rule, where it is known already (not within __init__)
            value = None if value is None else checks.max_depth(value, "max_depth", self.__dict__.get("integrator"))
        check = _SCENE_CHECKS.get(name)
        super().__setattr__(name, value if check is None else check(value))

    def __post_init__(self):
        self.max_depth = self.max_depth   # checked again, now for its integrator

    @property
    def depth(self) -> int:
        """max_depth, or the integrator's default where it is None."""
        if self.max_depth is not None:
            return self.max_depth
        return config.DEFAULT_PATH_MAX_DEPTH if self.integrator == "path" else config.DEFAULT_MAX_DEPTH

    def __repr__(self) -> str:
        camera = "no camera" if self.camera is None else f"camera {self.camera.width}x{self.camera.height}"
        placed = sum(o.placements for o in self.objects if o.transforms is not None)
        return (f"<clrt.Scene: {len(self.objects)} object(s), {self.num_triangles:,} triangles, "
                + (f"{placed:,} placements, " if placed else "")
                + f"{len(self.lights)} light(s), {camera}, {self.integrator}, "
                + (f"samples {self.samples}" if self.integrator == "whitted" else f"spp {self.spp or config.DEFAULT_SPP}")
                + f", max_depth {self.depth}>")

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: the box of every object as placed (a placed mesh's:
        the box of its own box's corners, mapped)."""
        from clrt.scene.instances import mapped_boxes
        b = np.concatenate([o.mesh.bounds[None] if o.transforms is None else
                            mapped_boxes(o.transforms, np.broadcast_to(o.mesh.bounds, (o.placements, 2, 3)))
                            for o in self.objects])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    @property
    def num_triangles(self) -> int:
        """Triangles as placed (a mesh placed K times counts K times)."""
        return sum(o.mesh.num_triangles * o.placements for o in self.objects)

    @property
    def instanced(self) -> bool:
        """Does an object place its mesh by transforms (a two-level scene on the
        device: docs/instances.md)?"""
        return any(o.transforms is not None for o in self.objects)

    def flattened(self) -> "Scene":
        """A copy whose objects are every placement moved into the world (in
        float64, then rounded to float32), in order: the scene an instanced
        one shows.  A placed mesh's vertex normals go with it, transformed by
        the inverse transpose (normalised again), so that it shades as its
        instances do; triangles keep their winding (a mirror turns it over)."""
        objects = []
        for o in self.objects:
            if o.transforms is None:
                objects.append(o)
                continue
            shaded = o.mesh if o.mesh.normals is not None else replace(o.mesh, normals=o.mesh.vertex_normals())
            for m in o.transforms:
                obj = object.__new__(SceneObject)   # its mesh keeps its split: normals given, none is needed
                for name, value in (("mesh", shaded.transformed(m)), ("material", o.material),
                                    ("materials", o.materials), ("transforms", None)):
                    object.__setattr__(obj, name, value)
                objects.append(obj)
        return replace(self, objects=objects, lights=list(self.lights))

    def override_materials(self, **fields) -> None:
        """Replace the fields given (not None) of every object's material, e.g.
        ``scene.override_materials(color=(1, 0, 0), smooth=False)`` -- what the
        CLI's material options (``--color``, ``--flat``, ...) do to a scene file
        or the built-in scene."""
        fields = {k: v for k, v in fields.items() if v is not None}
        if fields:
            self.objects = [o.with_overrides(**fields) for o in self.objects]


_SAMPLE = 1 << 20   # points of the median that finds a scene's middle (far_triangle)


def far_triangle(scene: "Scene") -> str:
    """Where ``scene`` reaches farthest out, for an error saying that it is too
    large: "corrupt.obj: object 0 ('corrupt'), triangle 1 has a vertex at (0,
    -4.4e28, 0), 4.4e28 from the middle of the scene (1 triangle that far out)".

    The middle is the median of the vertices; "far out" is at least half the
    farthest distance from it, or a thousand times the median distance where
    that is less (so one stray vertex among thousands is found, and a scene
    that is simply large names its farthest part).  The first such triangle is
    named, by its index in the object (the file's triangle order: vertex
    indices are renumbered by the crease split).  A pass over the vertices,
    made only on the way to an error.  (A scene of placed meshes names the
    placement that reaches farthest: far_placement.)"""
    if scene.instanced:
        from clrt.scene.instances import far_placement
        return far_placement(scene)
    meshes = [o.mesh for o in scene.objects]
    total = sum(len(m.vertices) for m in meshes)
    step = max(1, total // _SAMPLE)
    sample = np.concatenate([m.vertices[::step] for m in meshes]).astype(np.float64)
    middle = np.median(sample, axis=0)
    typical = float(np.median(np.linalg.norm(sample - middle, axis=1)))
    reach = [np.linalg.norm(m.vertices.astype(np.float64) - middle, axis=1) for m in meshes]
    farthest = max(float(r.max(initial=0.0)) for r in reach)
    far = farthest / 2 if typical == 0.0 else min(1000.0 * typical, farthest / 2)
    first, count = None, 0
    for k, (mesh, r) in enumerate(zip(meshes, reach)):
        out = (r[mesh.faces] >= far).any(axis=1) if farthest > 0.0 else np.zeros(len(mesh.faces), bool)
        count += int(out.sum())
        if first is None and out.any():
            f = int(np.argmax(out))
            corner = mesh.faces[f][int(np.argmax(r[mesh.faces[f]]))]
            first = k, f, mesh.vertices[corner].astype(np.float64), float(r[corner])
    if first is None:
        return scene.source or "the scene"
    k, f, point, distance = first
    name = meshes[k].name
    where = f"{scene.source}: " if scene.source else ""
    text = lambda x: f"{x:.3g}".replace("e+", "e")   # noqa: E731
    return (f"{where}object {name!r}" if name else f"{where}object {k}") + (
            f", triangle {f} has a vertex at "
            f"({', '.join(map(text, point))}), {text(distance)} from the middle of the scene "
            f"({count:,} triangle{'s' if count != 1 else ''} that far out)")


def default_light(bounds, camera: Camera) -> Light:
    """A white light above and to the left of the eye, so shapes read clearly:
    one scene diagonal away, or nearer (down to the eye itself) where that would
    pass +-MAX_COORDINATE -- the camera is valid, so its default light is too."""
    f, r, u = camera.basis()
    bounds = np.asarray(bounds, dtype=np.float64)
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    eye = np.asarray(camera.eye, dtype=np.float64)
    offset = (0.8 * u - 0.5 * r) * diag
    # The largest share of the offset that keeps every coordinate in range; the eye
    # is in range, so a share in [0, 1] always exists.  (Refusing here would make a
    # scene too large to frame unrenderable even from a camera the user placed.)
    room = np.where(offset > 0, config.MAX_COORDINATE - eye, -config.MAX_COORDINATE - eye)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(offset != 0, room / offset, np.inf)
    pos = eye + offset * min(1.0, max(0.0, float(share.min())))
    return Light(tuple(float(x) for x in np.clip(pos, -config.MAX_COORDINATE, config.MAX_COORDINATE)))


def _within_limit(point: np.ndarray, what: str, remedy: str) -> None:
    """InputError ``'<what>, past +-1e30 (...); <remedy>'`` for a point that the
    scene's size put out of the device's range (a camera clrt frames)."""
    if not (np.isfinite(point).all() and np.abs(point).max() <= config.MAX_COORDINATE):
        raise InputError(f"{what.format(checks.show(tuple(float(x) for x in point)))}, past "
                         f"+-{checks.show(config.MAX_COORDINATE)} (the device computes in float32; the "
                         f"scene is too large); {remedy}")


def scene_from_mesh(mesh, material=None, lights=None, background=config.DEFAULT_BACKGROUND) -> Scene:
    """The paper's scene: one mesh, one material, point lights (default: one above the eye).

    ``mesh``: a Mesh, a mesh file path, a trimesh object (Trimesh or Scene) or
    ``(vertices, faces)``; ``material``: a :class:`Material` or a dict of its
    fields -- given, it is every face's material; else a file's own materials
    apply, or a trimesh object's, mapped as the file readers map them
    (faces without one get the defaults).  ``lights``: a list of :class:`Light` or of
    positions ``(x, y, z)``.  Bad values raise InputError here.
    The camera is the file's own where a glTF/GLB file has a camera node,
    else framed from the bounds (``scene.camera_framed``).
    """
    import os
    from clrt.scene.load import as_asset, file_camera
    view, source, path = None, mesh, None
    mesh, file_materials = as_asset(source)   # first: a broken file's error is the mesh reader's
    if isinstance(source, (str, os.PathLike)):
        path = source
        view = file_camera(source)
    scene = Scene([SceneObject(mesh, Material.of(material), file_materials if material is None else ())],
                  [] if lights is None else lights, background)
    if view is not None:
        scene.camera, scene.camera_framed = file_view(view, scene.bounds, mesh.name), False
    else:
        try:
            scene.camera, scene.camera_framed = Camera.framing(scene.bounds), True
        except InputError:   # too large to frame: no camera, so that a camera the caller places still works
            scene.camera, scene.camera_framed = None, True
    scene.default_lights = not scene.lights
    if path is not None:
        scene.source = os.fsdecode(path)
    if scene.default_lights and scene.camera is not None:
        scene.lights = [default_light(scene.bounds, scene.camera)]
    return scene


def file_view(view: dict, bounds, label: str = "") -> Camera:
    """A Camera from :func:`clrt.scene.load.file_camera`'s description: the target
    on the view axis as far away as the scene's centre, 480 pixels high and as
    wide as the file's aspect ratio (else 640)."""
    eye = np.asarray(view["eye"], dtype=np.float64)
    centre = np.asarray(bounds, dtype=np.float64).mean(axis=0)
    distance = max(float(np.linalg.norm(centre - eye)), 1e-6 * (1.0 + float(np.abs(eye).max())))
    height = config.DEFAULT_HEIGHT
    width = config.DEFAULT_WIDTH if not view["aspect"] else int(min(max(round(height * view["aspect"]), 1),
                                                                    config.MAX_IMAGE_SIDE))
    try:
        return Camera(tuple(eye), tuple(eye + distance * np.asarray(view["forward"])), tuple(view["up"]),
                      view["fov"], width, height)
    except InputError as exc:
        raise InputError(f"{label}: the file's camera: {exc}" if label else f"the file's camera: {exc}") from None

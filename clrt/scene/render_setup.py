"""From a source and the render options to a scene, a camera and its lights.

``clrt render`` and ``clrt batch render`` both call these, so a frame of the
batch engine is the frame ``clrt render`` makes for the same camera:

    >>> scene = render_scene("bunny.off", color=(0.9, 0.2, 0.1))
    >>> camera = render_camera(scene, width=320, height=240)
    >>> scene.lights = render_lights(scene.bounds, camera, own=scene.lights)

Options left at ``None`` fall back to the scene file's values, then to the
defaults of clrt.config; the camera is framed from the bounds unless the
options (or the scene file) place it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from clrt import checks, config
from clrt.errors import InputError
from clrt.scene.scene import Camera, Light, Scene, default_light, far_triangle

#: The keyword options of render_scene and render_camera (the CLI's option names).
MATERIAL_OPTIONS = ("color", "ambient", "diffuse", "specular", "shininess", "crease")
SCENE_OPTIONS = MATERIAL_OPTIONS + ("flat", "background", "samples", "max_depth", "integrator", "spp", "seed",
                                    "exposure", "environment")
CAMERA_OPTIONS = ("width", "height", "eye", "target", "up", "fov")


def render_scene(source, *, color=None, ambient=None, diffuse=None, specular=None, shininess=None,
                 crease=None, flat: bool = False, background=None, samples=None, max_depth=None, integrator=None,
                 spp=None, seed=None, exposure=None, environment=None, labels: dict | None = None) -> Scene:
    """The scene of ``source``: None (the built-in scene), a ``.toml`` scene file,
    a mesh file or anything else clrt.scene.sources.as_scene takes.  The material
    options replace that field of every object's material; a mesh's scene, and a
    scene file's without lights, has no lights yet (:func:`render_lights` places
    the default one from the final camera).  A Scene given is copied, with its
    lights.  The render options are checked against the integrator they end
    with (``max_depth``'s range; ``spp`` and ``environment`` are the path
    tracer's), each named as ``labels`` names it (the command line's flags)."""
    from clrt.scene.sources import as_scene
    if isinstance(source, Scene):
        # The caller's Scene is left as it is; it keeps its lights (a default one too).
        scene = dataclasses.replace(source, objects=list(source.objects), lights=list(source.lights))
    elif source is not None and not (isinstance(source, str) and not source):
        scene = as_scene(source)
        if scene.default_lights:
            scene.lights = []   # the default light is placed from the final camera
    else:
        from clrt.scene.default import default_scene
        scene = default_scene()
    scene.override_materials(smooth=False if flat else None, color=color, ambient=ambient, diffuse=diffuse,
                             specular=specular, shininess=shininess, crease=crease)
    if background is not None:
        scene.background = background
    if samples is not None:
        scene.samples = samples
    label = (labels or {}).get
    if integrator is not None:
        scene.integrator = integrator
    named = scene.integrator
    if max_depth is not None:
        max_depth = checks.max_depth(max_depth, label("max_depth", "max_depth"), named)
    elif scene.max_depth is not None:
        checks.max_depth(scene.max_depth, "max_depth", named)
    for name, value in (("spp", spp), ("environment", environment)):
        if value is not None and named != "path":
            raise InputError(f"{label(name, name)} is the path tracer's: add {label('integrator', 'integrator')} "
                             "path (the Whitted integrator takes samples N for N x N rays a pixel and draws the "
                             "background colour)")
    for name, value in (("max_depth", max_depth), ("spp", spp), ("seed", seed), ("exposure", exposure),
                        ("environment", environment)):
        if value is not None:
            setattr(scene, name, value)
    return scene


def render_camera(scene: Scene, *, width=None, height=None, eye=None, target=None, up=None,
                  fov=None) -> Camera:
    """The camera: options override the scene's camera (a scene file's or a glTF
    file's); what neither gives is framed from the bounds (for the final size,
    fov and up)."""
    bounds, base = scene.bounds, scene.camera
    width = width if width is not None else (base.width if base else config.DEFAULT_WIDTH)
    height = height if height is not None else (base.height if base else config.DEFAULT_HEIGHT)
    fov = fov if fov is not None else (base.fov if base else config.DEFAULT_FOV)
    up = up or (base.up if base else config.DEFAULT_UP)
    placed = base if base is not None and not scene.camera_framed else None   # by the user or the file
    if eye is None and target is None and placed is not None:
        eye, target = placed.eye, placed.target
    elif eye is None or target is None:   # frame for the final size, fov and up
        # (Only then: a scene too large to frame renders from a camera the options place.)
        try:
            framed = None if placed else Camera.framing(bounds, width, height, fov, up=up)
        except InputError as exc:   # too large to frame: say where it reaches farthest
            raise InputError(f"{far_triangle(scene)}: {exc}") from None
        target = target or (placed.target if placed else framed.target)
        eye = eye or (placed.eye if placed else tuple(t + e - f for t, e, f in zip(target, framed.eye,
                                                                                   framed.target)))
    return Camera(eye, target, up, fov, width, height)


def render_lights(bounds, camera: Camera, own=(), positions=None, integrator: str = "whitted") -> list:
    """The lights of a frame: ``positions`` (the --light options), else the scene's
    ``own`` lights, else one default light placed from ``camera`` -- for the
    path tracer, whose point lights fall off with the squared distance, with
    the intensity pi d^2 (d: its distance to the middle of ``bounds``), so that
    it lights the middle of the scene as Whitted's unit light does (a white
    diffuse surface facing it: radiance 1)."""
    if positions:
        return [Light.of(p) for p in positions]
    if own:
        return list(own)
    light = default_light(bounds, camera)
    if integrator == "path":
        d = np.linalg.norm(np.asarray(light.position) - np.asarray(bounds, np.float64).mean(axis=0))
        light = Light(light.position, (math.pi * d * d,) * 3)
    return [light]


def lit_otherwise(scene: Scene) -> bool:
    """Does the path tracer find light in ``scene`` without point lights: an
    emissive material or an environment map?"""
    return scene.environment is not None or any(
        max(m.emission) > 0 for o in scene.objects for m in (o.material, *o.materials))


def render_frame(source, camera: Camera | None = None, *, lights=None, labels: dict | None = None,
                 **options) -> tuple[Scene, Camera]:
    """The scene (lights placed) and camera of one frame of ``source`` with the
    render options -- what ``clrt render`` and ``clrt.render`` both draw:
    :func:`render_scene` with the SCENE_OPTIONS, ``camera`` (if given) as the
    scene's placed camera, :func:`render_camera` with the CAMERA_OPTIONS on top,
    and :func:`render_lights` (``lights``: positions or Lights; a Scene given
    keeps its own lights, even none, unless ``lights`` are given; for the path
    tracer, a scene with emissive materials or an environment map gets no
    default light)."""
    scene = render_scene(source, labels=labels, **{k: options.pop(k) for k in SCENE_OPTIONS if k in options})
    if camera is not None:
        scene.camera, scene.camera_framed = camera, False
    camera = render_camera(scene, **{k: options.pop(k) for k in CAMERA_OPTIONS if k in options})
    if options:
        raise TypeError(f"render_frame got unknown options {sorted(options)}")
    if lights or not isinstance(source, Scene):   # a Scene keeps its own lights, none included
        if scene.integrator == "path" and not lights and not scene.lights and lit_otherwise(scene):
            scene.lights = []   # its emitters or its sky light it: no default light added
        else:
            scene.lights = render_lights(scene.bounds, camera, scene.lights, lights, scene.integrator)
    return scene, camera


def turntable(camera: Camera, view: int, views: int) -> Camera:
    """View ``view`` of ``views`` around the camera's target: the eye turned by
    360 * view / views degrees about the up axis through the target, so distance,
    elevation and framing stay those of ``camera`` (view 0 is ``camera`` itself)."""
    if not (isinstance(views, int) and views >= 1 and isinstance(view, int) and 0 <= view < views):
        raise InputError(f"view must be in 0..{views - 1}, got {view!r}")
    if view == 0:
        return camera
    angle = 2.0 * math.pi * view / views
    k = np.asarray(camera.up, dtype=np.float64)
    k = k / np.linalg.norm(k)
    target = np.asarray(camera.target, dtype=np.float64)
    v = np.asarray(camera.eye, dtype=np.float64) - target
    # Rodrigues' rotation of the eye's offset about the unit up axis k.
    rotated = (v * math.cos(angle) + np.cross(k, v) * math.sin(angle)
               + k * float(np.dot(k, v)) * (1.0 - math.cos(angle)))
    eye = tuple(float(x) for x in target + rotated)
    return Camera(eye, camera.target, camera.up, camera.fov, camera.width, camera.height)

"""The path tracer (integrator="path") against answers known without it: a
white furnace, a diffuse plane under a uniform emitter, a spot light's cone,
the same expected image from every sampling strategy, and the same image for
the same seed.  Small images and few samples on PoCL; the tolerances are
several standard errors of the estimate (measured from the renders
themselves where the noise is not known beforehand)."""

import importlib
import math

import numpy as np
import pytest

from clrt.errors import InputError
from clrt.reference import render_reference
from clrt.renderer import Renderer, TileLimits
from clrt.renderer.path import pass_sizes, tone_map
from clrt.scene import primitives
from clrt.scene.emitters import alias_table, environment_cdfs
from clrt.scene.environment import Environment, read_hdr
from clrt.scene.mesh import Mesh
from clrt.scene.scene import Camera, Light, Material, Scene, SceneObject

frame_module = importlib.import_module("clrt.renderer.frame")

# Pure Lambert of albedo 1: no specular lobe, no metal, no transmission.
WHITE = Material(color=(1.0, 1.0, 1.0), specular=0.0, metallic=0.0, specular_weight=0.0, roughness=1.0)
BLACK_EMITTER = dict(color=(0.0, 0.0, 0.0), specular=0.0, metallic=0.0, specular_weight=0.0)


def _quad(y: float, half: float, down: bool) -> Mesh:
    """A square at height y, its front face (counter-clockwise side) up or down."""
    v = np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]], float)
    faces = [[0, 1, 2], [0, 2, 3]] if down else [[0, 2, 1], [0, 3, 2]]
    return Mesh.from_arrays(v, np.array(faces))


def _sphere_camera(size=16):
    return Camera((0.0, 0.0, 2.6), (0.0, 0.0, 0.0), width=size, height=size, fov=50)


@pytest.fixture(scope="module")
def furnace(device):
    scene = Scene([SceneObject(primitives.icosphere(2), WHITE)], [], background=(1.0, 1.0, 1.0), integrator="path")
    return Renderer(scene, device=device)


def test_a_white_sphere_in_a_white_furnace_vanishes(furnace, device):
    """Albedo 1 inside uniform radiance 1: every path returns exactly 1, so
    every pixel converges to 1 (sphere and background alike)."""
    frame = furnace.render(_sphere_camera(), linear=True, spp=64, seed=3)
    assert frame.spp == 64 and frame.visible and frame.albedo.max() == pytest.approx(1.0)
    image = frame.image
    assert abs(image.mean() - 1.0) < 0.005, image.mean()
    # Per pixel: 64 samples of a bounded estimate (MIS of the background and the
    # BSDF, each weight <= 1): its spread is small; nothing is biased away.
    assert np.abs(image - 1.0).max() < 0.12, np.abs(image - 1.0).max()
    # A uniform environment map of radiance 1 is the same furnace, importance-sampled.
    env = Environment(np.ones((16, 32, 3), np.float32))
    scene = Scene([SceneObject(primitives.icosphere(2), WHITE)], [], integrator="path", environment=env)
    mapped = Renderer(scene, device=device).render(
        _sphere_camera(), linear=True, spp=64, seed=3).image
    assert abs(mapped.mean() - 1.0) < 0.005 and np.abs(mapped - 1.0).max() < 0.12


def test_russian_roulette_looks_past_the_eta_scale_of_glass(device):
    """A white Lambert ball inside a shell of smooth glass (ior 2) in a white
    furnace: a path that enters the glass carries 1 / eta^2 of radiance and
    gets eta^2 back on the way out, so every path that leaves returns exactly
    1 (the image is 1), and only the roulette adds noise.  Paths trapped by
    total internal reflection reach the roulette inside the glass; judged by
    their throughput alone (0.25) three in four would die there and the
    survivors leave with weight 4.  With the eta scale undone (pbrt's
    etaScale, Mitsuba's eta^2) they continue with probability 0.95.  One
    path's standard deviation, from the spread of pixels that all converge to
    1: 0.69 and 0.77 here (seeds 1 and 2), 1.65 and 1.80 with the roulette
    on the throughput alone -- a variance 5.5 times higher."""
    glass = Material(color=(1.0, 1.0, 1.0), metallic=0.0, specular_weight=1.0, roughness=0.0, transmission=1.0,
                     ior=2.0, smooth=False)
    white = Material(color=(1.0, 1.0, 1.0), specular=0.0, metallic=0.0, specular_weight=0.0, roughness=1.0,
                     smooth=False)
    scene = Scene([SceneObject(primitives.icosphere(2), glass), SceneObject(primitives.icosphere(2, radius=0.8), white)],
                  [], background=(1.0, 1.0, 1.0), integrator="path")
    camera = Camera((0.0, 0.0, 2.6), (0.0, 0.0, 0.0), width=16, height=16, fov=40)
    spp = 256
    for seed in (1, 2):
        centre = Renderer(scene, device=device).render(camera, linear=True, spp=spp, seed=seed).image[4:12, 4:12]
        path_std = centre.std() * math.sqrt(spp)
        assert path_std < 1.2, (seed, path_std)
        assert abs(centre.mean() - 1.0) < 4.0 * max(path_std, 0.5) / math.sqrt(centre.size / 3 * spp), centre.mean()


def test_max_depth_counts_as_mitsuba_does(device):
    """A diffuse floor (albedo 0.5) under an emitting ceiling (radiance 2,
    facing down, black) that covers the view: the floor's radiance is exactly
    0.5 x 2 -- all of it direct light (the ceiling reflects nothing) -- so
    max_depth 1 shows the emitter only, 2 and -1 the floor's 1.0."""
    floor = SceneObject(_quad(0.0, 200.0, down=False), Material(color=(0.5, 0.5, 0.5), specular=0.0,
                                                                 specular_weight=0.0, metallic=0.0))
    ceiling = SceneObject(_quad(1.0, 200.0, down=True), Material(emission=(2.0, 2.0, 2.0), **BLACK_EMITTER))
    renderer = Renderer(Scene([floor, ceiling], [], integrator="path"), device=device)
    down = Camera((0.0, 0.5, 0.0), (0.0, 0.0, 1e-3), width=12, height=12, fov=40)
    up = Camera((0.0, 0.5, 0.0), (0.0, 1.0, 1e-3), width=12, height=12, fov=40)
    assert renderer.render(up, linear=True, spp=2, max_depth=1).image == pytest.approx(2.0)
    assert renderer.render(down, linear=True, spp=2, max_depth=1).image.max() == 0.0
    for depth in (2, -1):
        image = renderer.render(down, linear=True, spp=32, max_depth=depth, seed=1).image
        assert abs(image.mean() - 1.0) < 0.01, (depth, image.mean())
    # Light sampling alone finds the same light, with more noise (a plane 400 wide).
    alone = renderer.render(down, linear=True, spp=256, max_depth=2, seed=1, strategy="bsdf").image
    assert abs(alone.mean() - 1.0) < 0.01
    # The back of the ceiling emits nothing (a single-sided emitter), the front of it all.
    above = Camera((0.0, 2.0, 0.0), (0.0, 1.0, 1e-3), width=8, height=8, fov=40)
    assert renderer.render(above, linear=True, spp=2, max_depth=1).image.max() == 0.0


def _block_means(image, k=4):
    h, w = image.shape[:2]
    return image[:h - h % k, :w - w % k].reshape(h // k, k, w // k, k, 3).mean(axis=(1, 3))


@pytest.fixture(scope="module")
def cornerless_room(device):
    """A sphere on a floor, an emissive quad above and a dim sky: every light
    can be both hit and sampled (no point lights)."""
    objects = [SceneObject(_quad(-1.0, 4.0, down=False), Material(color=(0.7, 0.6, 0.5), specular=0.0,
                                                                   specular_weight=0.0)),
               SceneObject(primitives.icosphere(2), Material(color=(0.3, 0.5, 0.8), specular=0.0,
                                                               specular_weight=0.0)),
               SceneObject(_quad(2.0, 0.7, down=True), Material(emission=(6.0, 6.0, 5.0), **BLACK_EMITTER))]
    scene = Scene(objects, [], background=(0.2, 0.25, 0.3), integrator="path", max_depth=4)
    return Renderer(scene, device=device)


@pytest.fixture(scope="module")
def glossy_room_under_a_sky(device):
    """Rough gold on rough white plastic under an emissive quad and an
    environment map with a bright patch: an area light and a sampled map
    beside glossy lobes (metal, the dielectric layer), not only Lambert."""
    sky = np.full((16, 32, 3), 0.3, np.float32)
    sky[:8] *= np.linspace(0.5, 1.5, 8, dtype=np.float32)[:, None, None]   # brighter towards the zenith
    sky[2:6, 18:24] = (6.0, 5.0, 4.0)
    objects = [SceneObject(_quad(-1.0, 4.0, down=False), Material(color=(0.8, 0.8, 0.8), metallic=0.0,
                                                                   roughness=0.6, specular_weight=1.0)),
               SceneObject(primitives.icosphere(2), Material(color=(1.0, 0.78, 0.34), metallic=1.0,
                                                               roughness=0.45)),
               SceneObject(_quad(2.0, 0.7, down=True), Material(emission=(6.0, 6.0, 5.0), **BLACK_EMITTER))]
    scene = Scene(objects, [], integrator="path", max_depth=3, environment=Environment(sky, rotation=40.0))
    return Renderer(scene, device=device)


@pytest.mark.parametrize("room, spps", [("cornerless_room", (12, 12, 24)),
                                        ("glossy_room_under_a_sky", (32, 32, 64))])
def test_light_bsdf_and_mis_sampling_agree(room, spps, request):
    """Light sampling alone, BSDF sampling alone and both by MIS estimate one
    image: 4x4 block means agree within six standard errors, each block's
    measured from the spread of eight seeds of each strategy (their noise
    differs from block to block: a glossy highlight of a small light is
    noisy for light sampling alone; estimated from eight runs, the errors
    are uncertain themselves -- Student's t of 7 degrees of freedom, whence
    six), and the image means within four.  Once with Lambert surfaces, an
    area light and a constant sky; once with rough metal and plastic, an
    area light and an importance-sampled environment map (where the map's
    pdf made 10 % too large puts the image means 4-7 standard errors apart,
    seeds 1-8, 11-18 and 21-28)."""
    renderer = request.getfixturevalue(room)
    camera = Camera((0.0, 0.6, 4.0), (0.0, 0.0, 0.0), width=24, height=16, fov=50)
    means, errors, image_errors = {}, {}, {}
    for strategy, spp in zip(("mis", "light", "bsdf"), spps):
        runs = np.stack([_block_means(renderer.render(camera, linear=True, spp=spp, seed=seed,
                                                      strategy=strategy).image) for seed in range(1, 9)])
        means[strategy] = runs.mean(axis=0)
        errors[strategy] = runs.std(axis=0, ddof=1) / math.sqrt(len(runs))   # each block's standard error
        image_errors[strategy] = runs.mean(axis=(1, 2, 3)).std(ddof=1) / math.sqrt(len(runs))
    for strategy in ("light", "bsdf"):
        sigma = np.hypot(errors["mis"], errors[strategy])
        z = np.abs(means[strategy] - means["mis"]) / np.maximum(sigma, 1e-4)
        assert z.max() < 6.0, (strategy, z.max())
        image_sigma = math.hypot(image_errors["mis"], image_errors[strategy])
        assert abs(means[strategy].mean() - means["mis"].mean()) < 4.0 * image_sigma, strategy
    # And MIS is the least noisy of the three (what it is for).
    rms = {strategy: np.sqrt(np.mean(e**2)) for strategy, e in errors.items()}
    assert rms["mis"] <= min(rms["light"], rms["bsdf"]) * 1.1, rms


def test_a_seed_gives_the_same_image_whatever_the_launches(cornerless_room, device):
    camera = Camera((0.0, 0.6, 4.0), (0.0, 0.0, 0.0), width=20, height=14, fov=50)
    first = cornerless_room.render(camera, linear=True, spp=5, seed=7).image
    again = cornerless_room.render(camera, linear=True, spp=5, seed=7).image
    np.testing.assert_array_equal(first, again)
    other = cornerless_room.render(camera, linear=True, spp=5, seed=8).image
    assert np.abs(other - first).max() > 0.01
    # One row a launch: the same sums in the same order, bit for bit.
    narrow = Renderer(cornerless_room.scene, device=device,
                      limits=TileLimits(first_launch_pixels=20, launch_ms=1e-6))
    rows = narrow.render(camera, linear=True, spp=5, seed=7)
    assert rows.tiles >= 14 * len(pass_sizes(5))
    np.testing.assert_array_equal(rows.image, first)


def test_previews_and_ctrl_c_hold_the_samples_done(cornerless_room, device, monkeypatch):
    """A preview after each pass but the last shows the image of the samples
    done, bit for bit; Ctrl-C keeps every queued launch's samples, each pixel
    averaging its own (rows a launch of the next pass reached have more), and
    is a plain interruption while the first pass is not yet queued whole."""
    camera = Camera((0.0, 0.6, 4.0), (0.0, 0.0, 0.0), width=20, height=14, fov=50)
    shown = []
    cornerless_room.render(camera, linear=True, spp=8, seed=7, preview=lambda f: shown.append((f.spp, f.image)))
    assert [samples for samples, _ in shown] == [1, 2, 4]
    alone = {n: cornerless_room.render(camera, linear=True, spp=n, seed=7).image for n in (1, 2, 4)}
    for samples, image in shown:
        np.testing.assert_array_equal(image, alone[samples])
    # One row a launch: the first pass takes 14 launches; the host waits for
    # each with one more queued behind it.
    narrow = Renderer(cornerless_room.scene, device=device,
                      limits=TileLimits(first_launch_pixels=20, launch_ms=1e-6))
    real_wait, waits = frame_module.wait_for, []

    def ctrl_c_at(k):
        def wait(event):
            real_wait(event)
            waits.append(1)
            if len(waits) == k:
                raise KeyboardInterrupt
        return wait
    monkeypatch.setattr(frame_module, "wait_for", ctrl_c_at(1))
    with pytest.raises(KeyboardInterrupt):
        narrow.render(camera, linear=True, spp=8, seed=7)
    waits.clear()
    monkeypatch.setattr(frame_module, "wait_for", ctrl_c_at(15))   # launches 1..16 queued: rows 0 and 1 twice
    cut = narrow.render(camera, linear=True, spp=8, seed=7)
    assert cut.interrupted and cut.spp == 1 and cut.tiles == 16
    np.testing.assert_array_equal(cut.image[:2], alone[2][:2])
    np.testing.assert_array_equal(cut.image[2:], alone[1][2:])


def test_a_spot_light_lights_its_cone_only(device):
    """A spot light 2 above a floor of albedo 0.5, pointing down: within the
    beam the floor's radiance is 0.5 / pi x I cos(theta)^3 / h^2 (direct light
    only); beyond the cutoff nothing.  Whitted draws the same cone."""
    floor = SceneObject(_quad(0.0, 10.0, down=False), Material(color=(0.5, 0.5, 0.5), specular=0.0,
                                                                specular_weight=0.0, ambient=0.0))
    spot = Light((0.0, 2.0, 0.0), (8.0, 8.0, 8.0), direction=(0.0, -1.0, 0.0), cutoff=30.0, beam=20.0)
    scene = Scene([floor], [spot], integrator="path", max_depth=2)
    renderer = Renderer(scene, device=device)
    camera = Camera((0.0, 6.0, 1e-3), (0.0, 0.0, 0.0), width=33, height=33, fov=60)
    image = renderer.render(camera, linear=True, spp=16, seed=2).image[..., 0]
    # Where each pixel's camera ray meets the floor (its centre; the jitter averages around it).
    f, r, u = camera.basis()
    sx, sy = camera.scales()
    px = (2.0 * (np.arange(33) + 0.5) / 33 - 1.0) * sx
    py = (1.0 - 2.0 * (np.arange(33) + 0.5) / 33) * sy
    d = f[None, None] + px[None, :, None] * r[None, None] + py[:, None, None] * u[None, None]
    t = -camera.eye[1] / d[..., 1]
    hit = np.asarray(camera.eye) + t[..., None] * d
    radius = np.hypot(hit[..., 0], hit[..., 2])
    cos = 2.0 / np.hypot(radius, 2.0)
    angle = np.degrees(np.arccos(cos))
    inside, outside = angle < 18.0, angle > 32.0
    expected = 0.5 / math.pi * 8.0 * cos ** 3 / 4.0
    np.testing.assert_allclose(image[inside], expected[inside], rtol=0.03)
    assert image[outside].max() == 0.0 and inside.sum() > 20 and outside.sum() > 100
    whitted_scene = Scene([floor], [spot], background=(0, 0, 0))
    whitted = Renderer(whitted_scene, device=device).render(camera, linear=True)
    assert whitted.image[..., 0][outside].max() == 0.0 and whitted.image[..., 0][inside].min() > 0.0
    # ... and as the numpy reference tracer draws it (the falloff between beam and cutoff too).
    reference, _, _ = render_reference(whitted_scene, camera)
    np.testing.assert_allclose(whitted.image, reference, atol=3e-3)
    falling = (angle > 21.0) & (angle < 28.0)   # between beam and cutoff: dimmer than the beam, not dark
    assert falling.sum() > 20 and 0.0 < whitted.image[..., 0][falling].max() < whitted.image[..., 0][inside].min()
    assert whitted.image[..., 0][falling].min() > 0.0


def test_environment_importance_sampling_has_the_mean_of_uniform_sampling(device):
    """A bright sun-like patch in a dim sky over a diffuse floor: the map
    sampled by its CDFs (light sampling alone) and found by cosine-weighted
    BSDF rays alone give the same mean radiance."""
    sky = np.full((32, 64, 3), 0.2, np.float32)
    sky[6:9, 40:44] = (400.0, 380.0, 300.0)
    env = Environment(sky, rotation=30.0, strength=0.5)
    floor = SceneObject(_quad(0.0, 50.0, down=False), Material(color=(0.8, 0.8, 0.8), specular=0.0,
                                                                specular_weight=0.0))
    renderer = Renderer(Scene([floor], [], integrator="path", environment=env, max_depth=2), device=device)
    camera = Camera((0.0, 1.0, 0.0), (0.0, 0.0, 1e-3), width=8, height=8, fov=30)
    sampled = renderer.render(camera, linear=True, spp=64, seed=4, strategy="light").image
    found = renderer.render(camera, linear=True, spp=2048, seed=4, strategy="bsdf").image
    # The floor's radiance is uniform (an infinite plane, a distant sky): albedo / pi x irradiance.
    h, w = sky.shape[:2]
    theta = math.pi * (np.arange(h) + 0.5) / h
    irradiance = (0.5 * sky[..., 0] * (np.cos(theta) * np.sin(theta))[:, None] * (theta < math.pi / 2)[:, None]).sum() \
        * (math.pi / h) * (2.0 * math.pi / w)
    expected = 0.8 / math.pi * irradiance
    assert sampled[..., 0].std() < 0.05 * expected   # importance sampling: little noise (64 samples)
    assert abs(sampled[..., 0].mean() - expected) < 0.02 * expected, (sampled[..., 0].mean(), expected)
    assert abs(found[..., 0].mean() - expected) < 0.1 * expected, (found[..., 0].mean(), expected)


def test_the_host_tables():
    weights = np.array([0.0, 1.0, 3.0, 0.5, 0.5])
    threshold, alias = alias_table(weights)
    chosen = np.zeros(len(weights))
    for i in range(len(weights)):   # the kernel's choice, integrated over u exactly
        chosen[i] += threshold[i]
        chosen[alias[i]] += 1.0 - threshold[i]
    np.testing.assert_allclose(chosen / len(weights), weights / weights.sum(), atol=1e-12)
    image = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32)
    image[2] = 0.0   # an empty row is never chosen
    marginal, conditional, mean = environment_cdfs(image)
    assert marginal[0] == 0.0 and marginal[-1] == 1.0 and marginal[3] == marginal[2]
    assert (np.diff(marginal) >= 0).all() and (np.diff(conditional.reshape(8, 17), axis=1) >= 0).all()
    lum = image @ np.array([0.2126, 0.7152, 0.0722])
    theta = math.pi * (np.arange(8) + 0.5) / 8
    assert mean == pytest.approx((lum * np.sin(theta)[:, None]).sum() * (math.pi / 8) * (math.pi / 8) / (4 * math.pi))
    assert pass_sizes(1) == [1] and pass_sizes(10) == [1, 1, 2, 4, 2] and sum(pass_sizes(1000)) == 1000
    assert max(pass_sizes(10**6)) == 64
    assert tone_map(np.array([[[0.25, 0.5, 2.0]]], np.float32), 1.0).tolist() == [[[188, 255, 255]]]


def test_radiance_hdr_files_are_read(tmp_path):
    # A flat scanline and a run-length encoded one: RGBE (128, 64, 32, 129) is (1, 0.5, 0.25).
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 8\n"
    flat = bytes([128, 64, 32, 129]) * 8
    rle = bytes([2, 2, 0, 8]) + b"".join(bytes([128 + 8, v]) for v in (128, 64, 32, 129))
    image = read_hdr(header + flat + rle)
    np.testing.assert_array_equal(image, np.broadcast_to([1.0, 0.5, 0.25], (2, 8, 3)))
    (tmp_path / "sky.hdr").write_bytes(header + flat + rle)
    assert Environment(str(tmp_path / "sky.hdr")).image.shape == (2, 8, 3)
    (tmp_path / "bad.hdr").write_bytes(b"not a picture")
    with pytest.raises(InputError, match="not a Radiance .hdr image"):
        Environment(str(tmp_path / "bad.hdr"))
    with pytest.raises(InputError, match="finite and >= 0"):
        Environment(np.full((2, 4, 3), -1.0))


def test_path_settings_are_checked(furnace):
    camera = _sphere_camera(4)
    for bad in ({"spp": 0}, {"spp": 2**31}, {"max_depth": 0}, {"max_depth": -2}, {"strategy": "both"},
                {"exposure": math.nan}, {"hits": True}):
        with pytest.raises(InputError):
            furnace.render(camera, **bad)
    with pytest.raises(InputError, match=r"max_depth must be an integer in 0\.\.16, got -1"):
        furnace.render(camera, integrator="whitted", max_depth=-1)


def test_scene_files_carry_the_path_tracer(tmp_path):
    from clrt.scene.scene_file import load_scene
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n"
    (tmp_path / "sky.hdr").write_bytes(header + bytes([128, 128, 128, 129]) * 8)
    path = tmp_path / "scene.toml"
    path.write_text('[render]\nintegrator = "path"\nspp = 32\nseed = 9\nexposure = -1\nmax_depth = -1\n'
                    'environment = { image = "sky.hdr", rotation = 90, strength = 2 }\n'
                    '[[objects]]\ntype = "sphere"\n'
                    '[[lights]]\nposition = [0, 3, 0]\ndirection = [0, -2, 0]\ncutoff = 40\nbeam = 10\n')
    scene = load_scene(path)
    assert (scene.integrator, scene.spp, scene.seed, scene.exposure, scene.depth) == ("path", 32, 9, -1.0, -1)
    env = scene.environment
    assert env.image.shape == (2, 4, 3) and env.image.max() == 1.0 and (env.rotation, env.strength) == (90, 2)
    light = scene.lights[0]
    assert (light.direction, light.cutoff, light.beam) == ((0.0, -1.0, 0.0), 40.0, 10.0)
    for text, says in (('[render]\nspp = 4\n', 'render.spp: is the path tracer\'s: add integrator = "path"'),
                       ('[render]\nintegrator = "path"\nmax_depth = 0\n', "render.max_depth must be -1 (unbounded)"),
                       ('[render]\nintegrator = "path"\nenvironment = "none.exr"\n', "render.environment: "),
                       ('[[lights]]\nposition = [0, 3, 0]\ndirection = [0, -1, 0]\ncutoff = 10\nbeam = 20\n',
                        "lights[0].beam: must be at most cutoff (10)")):
        path.write_text(text + '[[objects]]\ntype = "sphere"\n')
        with pytest.raises(InputError) as info:
            load_scene(path)
        assert says in str(info.value) and "\n" not in str(info.value), str(info.value)

"""One set of rules: the same bad value through the CLI, the Python API and a
scene file gets the same rule in its message and the same exit code (2).

Each case gives the value in each entry point's own syntax; only the name in
front of "must be" differs (``--width``, ``width``, ``camera.width``).  All the
checks run before any OpenCL work, so these tests are fast.
"""

import math
from pathlib import Path

import numpy as np
import pytest

import clrt
from clrt import checks, cli
from clrt.errors import InputError
from clrt.scene import primitives
from clrt.scene.scene_file import load_scene

SPHERE = '[[objects]]\ntype = "sphere"\nsubdivisions = 1\n'
MESH = primitives.icosphere(1)


def _scene():
    return clrt.scene_from_mesh(MESH)


def _set(name, value):
    def run():
        setattr(_scene(), name, value)
    return run


# (label, rule, CLI arguments or None, Python call or None, TOML text or None)
CASES = [
    ("width 0", "must be an integer in 1..65536, got 0",
     ["--width", "0"], lambda: clrt.render(MESH, width=0, height=60), "[camera]\nwidth = 0\n" + SPHERE),
    ("camera width 0", "must be an integer in 1..65536, got 0",
     None, lambda: clrt.Camera((0, 0, 5), (0, 0, 0), width=0), None),
    ("height too large", "must be an integer in 1..65536, got 70000",
     ["--height", "70000"], lambda: clrt.render(MESH, height=70000), "[camera]\nheight = 70000\n" + SPHERE),
    ("width not whole", "must be an integer in 1..65536, got 2.5",
     ["--width", "2.5"], lambda: clrt.render(MESH, width=2.5), "[camera]\nwidth = 2.5\n" + SPHERE),
    ("fov 180", "must be a number > 0 and < 180, got 180",
     ["--fov", "180"], lambda: clrt.Camera((0, 0, 5), (0, 0, 0), fov=180), "[camera]\nfov = 180\n" + SPHERE),
    ("samples 17", "must be an integer in 1..16, got 17",
     ["--samples", "17"], _set("samples", 17), "[render]\nsamples = 17\n" + SPHERE),
    ("max depth 17", "must be an integer in 0..16, got 17",
     ["--max-depth", "17"], _set("max_depth", 17), "[render]\nmax_depth = 17\n" + SPHERE),
    ("negative background", "must be 3 numbers >= 0, got (-1, 0.5, 0)",
     ["--background", "-1,0.5,0"], lambda: clrt.scene_from_mesh(MESH, background=(-1, 0.5, 0)),
     "[render]\nbackground = [-1, 0.5, 0]\n" + SPHERE),
    ("NaN background", "must be 3 finite numbers >= 0, got (nan, 0.5, 0)",
     ["--background", "nan,0.5,0"], lambda: clrt.scene_from_mesh(MESH, background=(math.nan, 0.5, 0)),
     "[render]\nbackground = [nan, 0.5, 0]\n" + SPHERE),
    ("background set later", "must be 3 numbers >= 0, got (-1, 0, 0)",
     None, _set("background", (-1, 0, 0)), None),
    ("two-number background", "must be 3 numbers >= 0, got (1, 1)",
     ["--background", "1,1"], lambda: clrt.scene_from_mesh(MESH, background=(1, 1)),
     "[render]\nbackground = [1, 1]\n" + SPHERE),
    ("negative light colour", "must be 3 numbers >= 0, got (-1, -1, -1)",
     None, lambda: clrt.Light((0, 5, 0), color=(-1, -1, -1)),
     SPHERE + "[[lights]]\nposition = [0, 5, 0]\ncolor = [-1, -1, -1]\n"),
    ("light far away", "must be 3 numbers within +-1e30 (the device computes in float32), got (1e35, 0, 0)",
     ["--light", "1e35,0,0"], lambda: clrt.scene_from_mesh(MESH, lights=[(1e35, 0, 0)]),
     SPHERE + "[[lights]]\nposition = [1e35, 0, 0]\n"),
    ("eye NaN", "must be 3 finite numbers, got (nan, 0, 0)",
     ["--eye", "nan,0,0"], lambda: clrt.Camera((math.nan, 0, 0), (0, 0, 0)),
     "[camera]\neye = [nan, 0, 0]\ntarget = [0, 0, 0]\n" + SPHERE),
    ("eye past float32", "must be 3 numbers within +-1e30 (the device computes in float32), got (1e39, 0, 0): "
                         "1e39 overflows float32 (the largest float32 is about 3.4e38)",
     ["--eye", "1e39,0,0"], lambda: clrt.Camera((1e39, 0, 0), (0, 0, 0)),
     "[camera]\neye = [1e39, 0, 0]\ntarget = [0, 0, 0]\n" + SPHERE),
    ("eye not three numbers", "must be 3 numbers, got (1, 2)",
     ["--eye", "1,2"], lambda: clrt.Camera((1, 2), (0, 0, 0)), "[camera]\neye = [1, 2]\ntarget = [0, 0, 0]\n" + SPHERE),
    ("material colour 2", "must be 3 numbers in 0..1, got (2, 0, 0)",
     ["--color", "2,0,0"], lambda: clrt.Material(color=(2, 0, 0)),
     SPHERE + "material = { color = [2, 0, 0] }\n"),
    ("material colour in a dict", "must be 3 numbers in 0..1, got (2, 0, 0)",
     None, lambda: clrt.scene_from_mesh(MESH, {"color": (2, 0, 0)}), None),
    ("negative ambient", "must be a number in 0..1000, got -1",
     ["--ambient", "-1"], lambda: clrt.Material(ambient=-1), SPHERE + "material = { ambient = -1 }\n"),
    ("infinite shininess", "must be a number in 0..10000, got inf",
     ["--shininess", "inf"], lambda: clrt.Material(shininess=math.inf), SPHERE + "material = { shininess = inf }\n"),
    ("huge ambient", "must be a number in 0..1000, got 1e300",
     ["--ambient", "1e300"], lambda: clrt.Material(ambient=1e300), SPHERE + "material = { ambient = 1e300 }\n"),
    ("huge shininess", "must be a number in 0..10000, got 1e308",
     ["--shininess", "1e308"], lambda: clrt.Material(shininess=1e308), SPHERE + "material = { shininess = 1e308 }\n"),
    ("huge ior", "must be a number in 1..100, got 1e300",
     None, lambda: clrt.Material(ior=1e300), SPHERE + "material = { ior = 1e300 }\n"),
    ("width a whole float", "must be an integer in 1..65536, got 2.0",
     ["--width", "2.0"], lambda: clrt.render(MESH, width=2.0, height=60), "[camera]\nwidth = 2.0\n" + SPHERE),
    ("width in exponent form", "must be an integer in 1..65536, got 1000.0",
     ["--width", "1e3"], lambda: clrt.render(MESH, width=1e3, height=60), "[camera]\nwidth = 1e3\n" + SPHERE),
    ("samples a whole float", "must be an integer in 1..16, got 2.0",
     ["--samples", "2.0"], _set("samples", 2.0), "[render]\nsamples = 2.0\n" + SPHERE),
    ("crease 200", "must be a number in 0..180, got 200",
     ["--crease", "200"], lambda: clrt.Material(crease=200), SPHERE + "material = { crease = 200 }\n"),
    ("device foo", "must be 'gpu', 'cpu', 'P' or 'P:D' (platform:device indices, see clrt info), got 'foo'",
     ["--device", "foo"], lambda: clrt.render(MESH, device="foo"), None),
    ("device foo, Renderer", "must be 'gpu', 'cpu', 'P' or 'P:D' (platform:device indices, see clrt info), got 'foo'",
     None, lambda: clrt.Renderer(MESH, device="foo"), None),
    ("device foo, trace", "must be 'gpu', 'cpu', 'P' or 'P:D' (platform:device indices, see clrt info), got 'foo'",
     None, lambda: clrt.trace(MESH, [0, 0, 5], [0, 0, -1], device="foo"), None),
    ("accel boxx", "must be one of none, box, sphere, ellipse, got 'boxx'",
     ["--accel", "boxx"], lambda: clrt.render(MESH, accel="boxx"), None),
    ("accel boxx, count_hits", "must be one of none, box, sphere, ellipse, got 'boxx'",
     None, lambda: clrt.count_hits(MESH, [0, 0, 5], [0, 0, -1], accel="boxx"), None),
    ("leaf size 0", "must be an integer in 1..255, got 0",
     ["--leaf-size", "0"], lambda: clrt.Renderer(MESH, leaf_size=0), None),
]


def _cases(entry: int):
    """The cases that have entry point ``entry`` (2: CLI, 3: Python, 4: scene file):
    a value without that entry point is simply not a case of its test."""
    chosen = [c for c in CASES if c[entry] is not None]
    return pytest.mark.parametrize("label, rule, args, call, toml", chosen, ids=[c[0] for c in chosen])


@_cases(2)
def test_cli_says_the_rule_and_exits_2(label, rule, args, call, toml, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in MESH.vertices)
                                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in MESH.faces))
    code = cli.main(["render", "m.obj", *args])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith(f"clrt: {args[0]} {rule}"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.obj"], "nothing written"


@_cases(3)
def test_python_raises_input_error_with_the_rule(label, rule, args, call, toml):
    with pytest.raises(InputError) as info:
        call()
    assert info.value.exit_code == 2
    message = str(info.value)
    assert message.endswith(rule) and f" {rule}" in message, message
    assert "\n" not in message


@_cases(4)
def test_scene_file_says_the_rule(label, rule, args, call, toml, tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(toml)
    with pytest.raises(InputError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and message.endswith(f" {rule}"), message
    # and through the CLI: the same line, exit 2
    assert cli.main(["render", str(path), "-o", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err == f"clrt: {message}\n"


def test_every_entry_point_has_a_case():
    """The table exercises each entry point many times (a guard against an empty table)."""
    assert sum(c[2] is not None for c in CASES) >= 15
    assert sum(c[3] is not None for c in CASES) >= 20
    assert sum(c[4] is not None for c in CASES) >= 12


def test_a_missing_device_is_opencl_trouble_not_bad_input(capsys):
    # Syntax is bad input (2); a well-formed spec naming no device here is exit 3.
    assert cli.main(["render", "--device", "7:7", "--width", "8", "--height", "8"]) == 3
    assert cli.main(["info", "--device", "foo"]) == 2
    capsys.readouterr()


@pytest.mark.parametrize("value, shown", [(0, "0"), (2.5, "2.5"), (1e40, "1e40"), ((1, 2.0), "(1, 2)"),
                                          ("x", "'x'"), (True, "True"), (np.float32(0.5), "0.5")])
def test_values_show_the_same_from_every_entry_point(value, shown):
    assert checks.show(value) == shown


def test_python_api_takes_what_the_cli_takes(tmp_path):
    """Paths, positions, dicts of material fields: accepted, or InputError at the call."""
    obj = tmp_path / "m.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in MESH.vertices)
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in MESH.faces))
    scene = clrt.scene_from_mesh(str(obj), {"color": (1, 0, 0), "shininess": 8}, lights=[(2, 4, 3)])
    assert scene.objects[0].material == clrt.Material(color=(1, 0, 0), shininess=8)
    assert scene.lights == [clrt.Light((2, 4, 3))]
    with pytest.raises(clrt.MeshLoadError, match="no such file: cow.off"):
        clrt.scene_from_mesh("cow.off")
    with pytest.raises(InputError, match=r"unknown material field 'colour' \(did you mean 'color'\?\)"):
        clrt.scene_from_mesh(MESH, {"colour": (1, 0, 0)})
    with pytest.raises(InputError, match=r"lights must be a list .*got \(2, 4, 3\): for one light there, "
                                         r"write \[\(2, 4, 3\)\]"):
        clrt.scene_from_mesh(MESH, lights=(2, 4, 3))   # a position, not a list of them
    with pytest.raises(InputError, match="expected a mesh"):
        clrt.Renderer(42)
    with pytest.raises(InputError, match="camera must be a clrt.Camera or None"):
        clrt.render(MESH, camera=(0, 0, 5))
    with pytest.raises(clrt.MeshLoadError, match="is a scene file, not a mesh"):
        clrt.load_mesh(Path("assets/scenes/showcase.toml"))


def test_python_api_renders_and_queries_like_the_cli(tmp_path, device):
    """Renderer takes a mesh; occluded takes the documented tmin; the float32 limit is named right."""
    frame = clrt.Renderer(MESH, device=device).render(clrt.Camera((0, 0, 5), (0, 0, 0), width=8, height=6))
    assert frame.image.shape == (6, 8, 3)
    origins, directions = [[0, 0, 5], [0, 0, 5]], [0, 0, -1]
    blocked = clrt.occluded(MESH, origins, directions, tmax=10.0, tmin=[0.5, 6.5], device=device)
    assert blocked.tolist() == [True, False]   # the sphere spans t = 4 .. 6 along these rays
    (tmp_path / "far.obj").write_text("v 0 0 0\nv 1e38 1 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(clrt.MeshLoadError, match=r"within \+-1e30 \(the device computes in float32\)"):
        clrt.load_mesh(tmp_path / "far.obj")

"""One table of render options (clrt/options.py): the command line and the
Python API take the same options, with the same checks and messages.

The tests walk the table: every option of ``clrt render`` is in it, every
option that is not output-only is a keyword of ``clrt.render``, and each one
given both ways draws the same image (and an image other than without it, or
reaches the Renderer) and refuses the same bad value with the same rule.
Tiny images of a tiny scene, so the walk stays fast.
"""

import importlib
import inspect
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import clrt
from clrt import cli, options

frame_module = importlib.import_module("clrt.renderer.frame")

SCENE = ('[camera]\neye = [0, 0.8, 3.2]\ntarget = [0, -0.2, 0]\n'
         '[[objects]]\ntype = "sphere"\nsubdivisions = 1\nmaterial = { reflectivity = 0.5 }\n'
         '[[objects]]\ntype = "plane"\nsize = [8, 8]\ntranslate = [0, -1, 0]\n')
BASE = {"width": ("16", 16), "height": ("12", 12)}

# A small equirectangular sky (Radiance .hdr, flat scanlines: a bright band over a dim one) for --environment.
SKY = str(Path(tempfile.mkdtemp(prefix="clrt-options-")) / "sky.hdr")
Path(SKY).write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n"
                      + bytes([128, 128, 128, 130]) * 4 + bytes([128, 64, 32, 127]) * 4)
# Options that only the path tracer takes: their good value is drawn with these too (with and without it).
NEEDS = {name: ((["--integrator", "path"]), {"integrator": "path"}) for name in ("spp", "seed", "environment")}

# name -> ((CLI words, Python value) of a good value, (CLI words, Python value) of a bad one or None
# where the command line cannot say it: a switch takes no value)
CASES = {
    "width": ((["--width", "10"], 10), (["--width", "0"], 0)),
    "height": ((["--height", "7"], 7), (["--height", "70000"], 70000)),
    "eye": ((["--eye", "0.5,1,4"], (0.5, 1, 4)), (["--eye", "nan,0,0"], (math.nan, 0, 0))),
    "target": ((["--target", "0.3,0,0"], (0.3, 0, 0)), (["--target", "1,2"], (1, 2))),
    "up": ((["--up", "0.4,1,0"], (0.4, 1, 0)), (["--up", "1e39,0,0"], (1e39, 0, 0))),
    "fov": ((["--fov", "30"], 30), (["--fov", "180"], 180)),
    "lights": ((["--light", "2,4,3", "--light", "-2,1,3"], [(2, 4, 3), (-2, 1, 3)]),
               (["--light", "0,inf,0"], [(0, math.inf, 0)])),
    "color": ((["--color", "1,0,0"], (1, 0, 0)), (["--color", "2,0,0"], (2, 0, 0))),
    "ambient": ((["--ambient", "0.5"], 0.5), (["--ambient", "-1"], -1)),
    "diffuse": ((["--diffuse", "0.2"], 0.2), (["--diffuse", "nan"], math.nan)),
    "specular": ((["--specular", "3"], 3), (["--specular", "inf"], math.inf)),
    "shininess": ((["--shininess", "4"], 4), (["--shininess", "1e308"], 1e308)),
    "flat": ((["--flat"], True), None),
    "crease": ((["--crease", "5"], 5), (["--crease", "200"], 200)),
    "background": ((["--background", "0.2,0.3,0.4"], (0.2, 0.3, 0.4)), (["--background", "-1,0,0"], (-1, 0, 0))),
    "samples": ((["--samples", "2"], 2), (["--samples", "17"], 17)),
    "max_depth": ((["--max-depth", "0"], 0), (["--max-depth", "-2"], -2)),
    "integrator": ((["--integrator", "path"], "path"), (["--integrator", "mitsuba"], "mitsuba")),
    "spp": ((["--spp", "4"], 4), (["--spp", "0"], 0)),
    "seed": ((["--seed", "5"], 5), (["--seed", "-1"], -1)),
    "exposure": ((["--exposure", "1.5"], 1.5), (["--exposure", "nan"], math.nan)),
    "environment": ((["--environment", SKY], SKY), (["--environment", "sky.png"], "sky.png")),
    "device": (None, (["--device", "foo"], "foo")),   # good value: the suite's device, below
    "accel": ((["--accel", "sphere"], "sphere"), (["--accel", "octree"], "octree")),
    "builder": ((["--builder", "paper"], "paper"), (["--builder", "fast"], "fast")),
    "leaf_size": ((["--leaf-size", "2"], 2), (["--leaf-size", "0"], 0)),
}


def test_the_table_is_the_command_line_and_the_api():
    """Every option of clrt render comes from the table; clrt.render takes every
    one that is not output-only (by signature too), and every case above is one."""
    parser = cli._parser()
    render = parser._subparsers._group_actions[0].choices["render"]
    flags = {a.option_strings[-1] for a in render._actions if a.option_strings and a.dest != "help"}
    assert flags == {o.flag for o in options.OPTIONS.values() if options.RENDER in o.commands}
    api = {name for name, o in options.OPTIONS.items() if o.api is None}
    assert api == set(options.API_OPTIONS) == set(CASES)
    assert {o.name for o in options.OPTIONS.values() if o.api is not None} == {
        "output", "force", "bit_depth", "aov", "quiet"}
    params = inspect.signature(clrt.render).parameters
    assert list(params) == ["source", "camera", "linear", *options.API_OPTIONS]
    assert all(params[name].default == o.default for name, o in options.API_OPTIONS.items())
    for name in options.API_OPTIONS:   # and help() says what each is
        assert f"``{name}``" in clrt.render.__doc__
    # render_setup's keyword lists (which the batch engine takes too) are the table's stages
    from clrt.scene import render_setup
    for stage, names in ((options.SCENE, render_setup.SCENE_OPTIONS), (options.CAMERA, render_setup.CAMERA_OPTIONS)):
        assert {o.name for o in options.OPTIONS.values() if o.stage == stage} == set(names)


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("options") / "scene.toml"
    path.write_text(SCENE)
    return path


class _Spy:
    """Renderer, recording the options it is made with (CLI and API alike)."""

    def __init__(self, monkeypatch):
        self.made = []
        spy = self

        class Recording(frame_module.Renderer):
            def __init__(self, scene, **kwargs):
                spy.made.append(kwargs)
                super().__init__(scene, **kwargs)

        monkeypatch.setattr(frame_module, "Renderer", Recording)
        monkeypatch.setattr(importlib.import_module("clrt.renderer"), "Renderer", Recording)


def _both_ways(scene_file, tmp_path, capsys, words, values):
    out = tmp_path / f"cli-{len(list(tmp_path.iterdir()))}.png"
    code = cli.main(["render", str(scene_file), "-o", str(out), "-q", *words])
    err = capsys.readouterr().err
    assert code == 0, err
    return np.asarray(Image.open(out)), clrt.render(str(scene_file), **values)


@pytest.mark.parametrize("name", list(CASES))
def test_each_option_draws_the_same_image_both_ways(name, scene_file, tmp_path, capsys, monkeypatch, device):
    good = CASES[name][0] or (["--device", device or "0:0"], device or "0:0")
    words, value = good
    needs_words, needs_values = NEEDS.get(name, ([], {}))
    base_words = [w for key, (text, _) in BASE.items() if key != name for w in (f"--{key}", text)] + needs_words
    base_values = {**{key: v for key, (_, v) in BASE.items() if key != name}, **needs_values}
    dev = [] if name == "device" or not device else ["--device", device]
    dev_values = {} if name == "device" or not device else {"device": device}
    spy = _Spy(monkeypatch)
    on_cli, on_api = _both_ways(scene_file, tmp_path, capsys, [*base_words, *dev, *words],
                                {**base_values, **dev_values, name: value})
    np.testing.assert_array_equal(on_cli, on_api, err_msg=name)
    option = options.OPTIONS[name]
    if option.stage == options.RENDERER:
        # The same image whatever the device or structure: the value must reach the Renderer instead.
        expected = options.check(name, value)
        assert [made[name] for made in spy.made] == [expected, expected], spy.made
    else:
        plain_cli, plain_api = _both_ways(scene_file, tmp_path, capsys,
                                          [*dev, "--width", "16", "--height", "12", *needs_words],
                                          {**dev_values, "width": 16, "height": 12, **needs_values})
        np.testing.assert_array_equal(plain_cli, plain_api)
        if plain_cli.shape == on_cli.shape:
            changed = (np.abs(plain_cli.astype(int) - on_cli).max(axis=2) > 2).sum()
            assert changed > 3, f"{name} changed {changed} pixels"
        np.testing.assert_array_equal(plain_cli, plain_api)


@pytest.mark.parametrize("name", [name for name, case in CASES.items() if case[1] is not None])
def test_each_option_refuses_a_bad_value_with_the_same_rule(name, scene_file, tmp_path, capsys, monkeypatch):
    """The same rule, the name as each side writes it: --max-depth / max_depth,
    --light / lights[0]; exit 2 and nothing written from the command line."""
    monkeypatch.chdir(tmp_path)
    words, value = CASES[name][1]
    assert cli.main(["render", str(scene_file), *words]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("clrt: "), err
    with pytest.raises(clrt.InputError) as info:
        clrt.render(str(scene_file), **{"width": 8, "height": 6, name: value})
    option = options.OPTIONS[name]
    label = f"{name}[0]" if option.many else name
    assert str(info.value) == err[len("clrt: "):-1].replace(option.flag, label, 1), (str(info.value), err)
    assert f"{label} must be " in str(info.value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("call, says", [
    (lambda: clrt.render(None, sample=2), "unknown option 'sample' of render (did you mean 'samples'?)"),
    (lambda: clrt.render(None, light=[(1, 2, 3)]), "unknown option 'light' of render (did you mean 'lights'?)"),
    (lambda: clrt.render(None, output="x.png"),
     "render does not take output (--output): it returns the image: write it with clrt.output.write_image"),
    (lambda: clrt.render(None, bit_depth=16), "render does not take bit_depth (--bit-depth): it returns uint8"),
    (lambda: clrt.render(None, lights=(1, 2, 3)), "lights must be a list of positions (x, y, z) or clrt.Light, "
                                                  "got (1, 2, 3): for one light there, write [(1, 2, 3)]"),
    (lambda: clrt.render(None, flat="yes"), "flat must be true or false, got 'yes'"),
])
def test_what_render_does_not_take_is_said_at_the_call(call, says):
    with pytest.raises(clrt.InputError) as info:
        call()
    assert str(info.value).startswith(says), str(info.value)


def test_render_takes_every_option_at_once_and_a_light_with_its_colour(tmp_path, device):
    """The call of the issue: clrt.render(mesh, samples=2, eye=..., max_depth=...,
    lights=..., color=...) was a TypeError."""
    from clrt.scene import primitives
    mesh = primitives.icosphere(1)
    kwargs = dict(samples=2, eye=(0, 1, 4), max_depth=2, color=(1, 0, 0), width=16, height=12, device=device)
    white = clrt.render(mesh, lights=[(2, 4, 3)], **kwargs)
    dim = clrt.render(mesh, lights=[clrt.Light((2, 4, 3), color=(0.3, 0.3, 0.3))], **kwargs)
    assert white.shape == (12, 16, 3) and white[..., 0].astype(int).sum() > dim[..., 0].astype(int).sum()
    assert (white[..., 1] <= white[..., 0]).all(), "red"


@pytest.mark.parametrize("name", [name for name, case in CASES.items() if case[1] is not None and name != "device"])
def test_the_batch_api_refuses_a_bad_value_as_render_does(name, tmp_path):
    """clrt.batch.render checks its options by the same table, before any
    worker starts: the same message as clrt.render for the same bad value,
    nothing written."""
    import clrt.batch as batch
    value = CASES[name][1][1]
    with pytest.raises(clrt.InputError) as rendered:
        clrt.render(None, **{"width": 8, "height": 6, name: value})
    with pytest.raises(clrt.InputError) as batched:
        batch.render([str(tmp_path / "none.obj")], tmp_path / "out", **{name: value})
    assert str(batched.value) == str(rendered.value)
    assert not (tmp_path / "out").exists()

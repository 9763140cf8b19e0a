"""benchmarks.host_stages prints the host's stages of an Accel and a Renderer
beside the whole calls on the test device."""

from benchmarks import host_stages


def test_host_stages_print_every_stage_and_the_whole_calls(device, capsys):
    assert host_stages.main(["--device", device or "cpu", "--triangles", "3K,6K", "--repeat", "1",
                             "--no-split"]) == 0
    out = capsys.readouterr().out
    rows = {r[1].strip(): [float(x.replace(",", "")) for x in r[2:-1]]
            for r in (line.split("|") for line in out.splitlines())
            if len(r) == 5 and r[1].strip()[:1].isalpha() and r[1].strip() != "stage"}
    for stage in ("Mesh(V, F): the checks", "Mesh.bounds (used vertices)", "triangle_corners (gather, frame)",
                  "scene_from_mesh (flat: no split)", "flatten_scene", "Accel(V, F): whole call",
                  "Renderer(scene): copy to device"):
        assert len(rows[stage]) == 2 and all(ms >= 0.0 for ms in rows[stage]), stage
    for call in ("Accel(V, F)", "Renderer(scene)"):   # a whole call holds its build
        assert all(whole >= build for whole, build in zip(rows[f"{call}: whole call"],
                                                          rows[f"{call}: of it the build"]))
    assert "| stage | 3,0" in out or "| stage | 2,9" in out      # about 3K triangles in the first column

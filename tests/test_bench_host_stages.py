"""benchmarks.host_stages prints the host's stages of an Accel and a Renderer
(and their device twins) beside the whole calls on the test device, and each
call over the device build and upload of the corners."""

from benchmarks import host_stages


def test_host_stages_print_every_stage_and_the_whole_calls(device, capsys):
    assert host_stages.main(["--device", device or "cpu", "--triangles", "3K,6K", "--repeat", "1",
                             "--no-split"]) == 0
    out = capsys.readouterr().out
    rows = {r[1].strip(): [float(x.replace(",", "")) for x in r[2:-1]]
            for r in (line.split("|") for line in out.splitlines())
            if len(r) == 5 and r[1].strip()[:1].isalpha() and r[1].strip() != "stage"}
    for stage in ("Mesh(V, F): the checks", "Mesh.bounds (used vertices)", "triangle_corners (gather, frame)",
                  "scene_from_mesh (flat: no split)", "vertex normals on the host", "flatten_scene",
                  "upload_mesh (vertices, faces)", "shade_on_device (split, normals)", "Accel(V, F): whole call",
                  "Renderer(scene): copy to device", "Renderer(V, F): whole call", "device build from corners (warm)",
                  "upload of the corners", "Renderer(V, F) / (build + upload) (ratio)"):
        assert len(rows[stage]) == 2 and all(ms >= 0.0 for ms in rows[stage]), stage
    for call in ("Accel(V, F)", "Renderer(scene)", "Renderer(V, F)"):   # a whole call holds its build
        assert all(whole >= build for whole, build in zip(rows[f"{call}: whole call"],
                                                          rows[f"{call}: of it the build"]))
        # the ratio of the unrounded times: within what the printed ones
        # (to 0.1 ms; a GPU's are a few tenths) and its own two places allow
        whole = rows[f"{call}: whole call"][0]
        parts = rows["device build from corners (warm)"][0] + rows["upload of the corners"][0]
        ratio = rows[f"{call} / (build + upload) (ratio)"][0]
        assert (whole - 0.05) / (parts + 0.1) - 0.005 <= ratio <= (whole + 0.05) / max(parts - 0.1, 1e-9) + 0.005, call
    assert "| stage | 3,0" in out or "| stage | 2,9" in out      # about 3K triangles in the first column


def test_host_stages_leave_the_host_shading_out_when_asked(device, capsys):
    assert host_stages.main(["--device", device or "cpu", "--triangles", "3K", "--repeat", "1", "--no-calls",
                             "--no-host-shading"]) == 0
    out = capsys.readouterr().out
    assert "| Mesh.bounds (used vertices) |" in out and "| scene_from_mesh (the split left for later) |" in out
    for stage in ("crease split on the host", "vertex normals on the host", "flatten_scene"):
        assert f"| {stage}" not in out, stage

"""benchmarks.cold_start times a first call with empty program caches against
the same call warm, and says where the cold one's time goes."""

import json
import subprocess

from benchmarks import cold_start
from benchmarks.common import module_command, repo_env
from conftest import write_icosphere_obj


def test_cold_and_warm_accel_calls_are_timed(tmp_path, device, capsys):
    mesh = write_icosphere_obj(tmp_path / "ball.obj")
    args = ["--case", "accel", "--mesh", str(mesh), "--runs", "1"] + (["--device", device] if device else [])
    assert cold_start.main(args) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0] + " " + line.split()[1]: line for line in out.splitlines() if line.startswith("  ")}
    for row in ("cold s", "warm s", "cold /"):
        assert row in rows, out
    cold, warm = (float(rows[row].split()[3]) for row in ("cold s", "warm s"))
    assert cold > warm > 0, out      # the empty caches cost their compiles


def test_the_breakdown_lists_every_program_build_and_first_launch(tmp_path, device, capsys):
    mesh = write_icosphere_obj(tmp_path / "ball.obj")
    command = module_command("cold_start") + ["--child", "accel", str(mesh), "--breakdown"]
    command += ["--device", device] if device else []
    done = subprocess.run(command, capture_output=True, text=True, env=repo_env(), timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    found = cold_start._parse_breakdown(done.stdout)
    assert {b["entry"] for b in found["builds"]} == {"build_bvh.cl", "trace.cl"}
    assert all(b["kernels"] > 0 and b["source_bytes"] > 0 and b["ms"] > 0 for b in found["builds"])
    launched = [x["key"][0] for x in found["launches"]]
    assert "ploc_top" in launched and "query_closest" in launched and len(launched) == len(set(map(tuple, (
        x["key"] for x in found["launches"]))))
    cold_start._print_breakdown("accel", found, json.loads(json.dumps(found)), None)
    out = capsys.readouterr().out
    assert "build_bvh.cl" in out and "trace.cl" in out and "query_closest" in out and "the rest" in out

"""tools/gpu_suite.py, run here on the CPU device: one pytest process a test
file, the table of what passed, and the --from that resumes past the budget."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(tmp_path, *args):
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "gpu_suite.py"), "--device", "cpu",
                           "--out", str(tmp_path), *args], capture_output=True, text=True, cwd=ROOT, timeout=300)
    return done.returncode, done.stdout


def test_runs_the_files_asked_for_and_tabulates_them(tmp_path):
    rc, out = _run(tmp_path, "--only", "tests/test_layouts.py")
    assert rc == 0, out
    assert "| test_layouts.py | passed |" in out and "passed" in (tmp_path / "test_layouts.txt").read_text()
    assert "resume" not in out


def test_stops_within_its_budget_and_says_where_to_resume(tmp_path):
    rc, out = _run(tmp_path, "--from", "tests/test_layouts.py", "--budget", "1", "--file-timeout", "60")
    assert "out of budget: resume with python tools/gpu_suite.py --from tests/test_layouts.py" in out, out

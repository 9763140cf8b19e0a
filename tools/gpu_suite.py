"""Run the test suite on a lent GPU file by file, within a time budget.

    python tools/gpu_suite.py [--device gpu] [--from tests/test_x.py | --only A,B] [--budget 540] [--file-timeout 150] [--out DIR]

The whole suite on an H200 takes longer than one device call (the NVIDIA
compiler builds each program variant anew on a fresh machine), and one hung
kernel would eat the call.  So each file runs in a pytest process of its own
(``CLRT_TEST_DEVICE``, ``-p no:cacheprovider``, docs excluded), killed after
--file-timeout seconds, with pytest's faulthandler dumping every thread's
stack after 40 s in one test, so a hang names its test and the line it waits
at.  Files run in name order from --from until the budget would be passed;
the table printed at the end says, per file, passed / failed / hung / not run,
the seconds and the failed tests, and the command that resumes where it
stopped.  Each file's output goes to DIR/NAME.txt (under $OUT on the device).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="gpu", help="CLRT_TEST_DEVICE for the tests (default gpu)")
    p.add_argument("--from", dest="start", default="", help="the first test file to run (default: the first)")
    p.add_argument("--only", default="", help="comma-separated test files to run instead of all")
    p.add_argument("--budget", type=float, default=540.0, help="seconds for all files (default 540)")
    p.add_argument("--file-timeout", type=float, default=150.0, help="seconds one file may take (default 150)")
    p.add_argument("--out", default=os.environ.get("OUT", "."), help="folder of each file's output")
    args = p.parse_args(argv)
    files = sorted(f for f in (REPO / "tests").glob("test_*.py") if f.name != "test_docs.py")
    names = [f"tests/{f.name}" for f in files]
    if args.start:
        if args.start not in names:
            p.error(f"--from {args.start}: no such test file")
        files = files[names.index(args.start):]
    if args.only:
        wanted = [f.strip() for f in args.only.split(",") if f.strip()]
        if set(wanted) - set(names):
            p.error(f"--only: no such test file: {', '.join(sorted(set(wanted) - set(names)))}")
        files = [f for f in files if f"tests/{f.name}" in wanted]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, CLRT_TEST_DEVICE=args.device, PYTHONPATH=os.pathsep.join(
        filter(None, [str(REPO), os.environ.get("PYTHONPATH", "")])))
    rows, end, resume = [], time.monotonic() + args.budget, None
    for f in files:
        left = end - time.monotonic()
        if left < min(30.0, args.file_timeout):
            resume = f"tests/{f.name}"
            break
        command = [sys.executable, "-m", "pytest", f"tests/{f.name}", "-q", "-p", "no:cacheprovider", "-rf",
                   "-o", "faulthandler_timeout=40"]
        start = time.monotonic()
        log = out / f"{f.stem}.txt"
        with open(log, "w") as fh:
            try:
                rc = subprocess.run(command, cwd=REPO, env=env, stdout=fh, stderr=subprocess.STDOUT,
                                    timeout=min(args.file_timeout, left)).returncode
                status = {0: "passed", 1: "failed", 5: "no tests"}.get(rc, f"exit {rc}")
            except subprocess.TimeoutExpired:
                status = "hung (killed)"
        seconds = time.monotonic() - start
        text = log.read_text(errors="replace")
        failed = re.findall(r"^FAILED (\S+)", text, re.M)
        hung = re.findall(r"^(tests/\S+) Timeout", text, re.M) or re.findall(r"(tests/\S+::\S+) Timeout", text)
        summary = (re.findall(r"^=*\s*(\d+ (?:passed|failed).*?) in ", text, re.M) or [""])[-1]
        rows.append((f.name, status, seconds, summary, failed + [f"{h} (slow or hung)" for h in hung]))
        print(f"{f.name}: {status} in {seconds:.0f} s {summary}", flush=True)
    print("\n| file | status | s | summary | failed or slow |\n|---|---|---|---|---|")
    for name, status, seconds, summary, failed in rows:
        print(f"| {name} | {status} | {seconds:.0f} | {summary} | {'; '.join(failed)} |")
    if resume:
        print(f"\nout of budget: resume with python tools/gpu_suite.py --from {resume}")
    return 0 if all(r[1] in ("passed", "no tests") for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

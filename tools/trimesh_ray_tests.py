"""Run trimesh's own ray and proximity tests with clrt.RayMeshIntersector behind
every ``mesh.ray`` and clrt.ProximityQuery behind every ``mesh.nearest``.

    python tools/trimesh_ray_tests.py                      # the installed trimesh's tests
    python tools/trimesh_ray_tests.py --source ~/src/trimesh
    python tools/trimesh_ray_tests.py --source ~/src/trimesh --source-tests
    python tools/trimesh_ray_tests.py --also-trimesh       # and once with trimesh's own engines

trimesh's wheels ship no tests, so its source distribution of the installed
version is fetched (``pip download --no-deps --no-binary :all: trimesh==V``)
into a temporary folder.  That archive has the test files but not their helper
module ``tests/generic.py`` nor the ``models/`` they load; ``--source`` names a
trimesh checkout (``git clone https://github.com/mikedh/trimesh``) that
supplies them (its own test files are used where the archive cannot be had, or
with ``--source-tests``: a helper module of another version may lack what the
archive's tests use).  Without both, the run is skipped with a message saying
what is missing.

The test files that use ``mesh.ray`` or ``mesh.nearest`` are found by a search
of their text, run with pytest and the plugin ``tools/trimesh_ray_plugin.py``
(``Trimesh.ray`` and ``Trimesh.nearest`` made properties that hand out clrt's
intersector and proximity query), and the counts printed.
Tests of the Embree engine need ``embreex`` (``pip install -e '.[raybench]'``):
without it pytest skips them.  Nothing of trimesh is copied into this repository.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
USES_RAY = re.compile(r"\.(ray|nearest)\b")


def installed_version() -> str:
    import trimesh
    return trimesh.__version__


def fetch_sdist(version: str, into: Path) -> Path | None:
    """The unpacked source distribution of trimesh ``version``, or None (with
    the reason printed) when it cannot be downloaded."""
    command = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:",
               "--quiet", f"trimesh=={version}", "-d", str(into)]
    try:
        subprocess.run(command, check=True, capture_output=True, text=True, timeout=600)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        print(f"could not download trimesh {version}'s source: {detail.strip().splitlines()[-1:]}")
        return None
    archives = sorted(into.glob("trimesh-*.tar.gz"))
    if not archives:
        print(f"pip download gave no trimesh-{version}.tar.gz")
        return None
    with tarfile.open(archives[0]) as tar:
        tar.extractall(into, filter="data")
    return into / f"trimesh-{version}"


def prepare(work: Path, sdist: Path | None, source: Path | None) -> str | None:
    """Lay out work/tests and work/models; return None, or why the run cannot go on."""
    tests = work / "tests"
    if source is not None:
        if not (source / "tests").is_dir():
            return f"{source} has no tests/ folder: is it a trimesh checkout?"
        shutil.copytree(source / "tests", tests)
        if (source / "models").is_dir():
            shutil.copytree(source / "models", work / "models")
    if sdist is not None and (sdist / "tests").is_dir():
        tests.mkdir(exist_ok=True)
        for path in (sdist / "tests").rglob("*"):          # the installed version's own tests
            if path.is_file():
                target = tests / path.relative_to(sdist / "tests")
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target)
        if (sdist / "models").is_dir():
            shutil.copytree(sdist / "models", work / "models", dirs_exist_ok=True)
    missing = [name for name, path in (("tests/generic.py", tests / "generic.py"),
                                       ("models/", work / "models")) if not path.exists()]
    if missing:
        return (f"trimesh's test helpers are missing ({', '.join(missing)}): its source "
                "distribution does not ship them; pass --source with a trimesh checkout")
    return None


def ray_test_files(tests: Path) -> list[Path]:
    return sorted(p for p in tests.glob("test_*.py") if USES_RAY.search(p.read_text(encoding="utf-8")))


def run_pytest(work: Path, files, plugin: bool, extra) -> dict:
    """Outcome counts and failing test ids of one pytest run in ``work``."""
    report = work / ("clrt.xml" if plugin else "trimesh.xml")
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rfE",
               f"--junitxml={report}", *map(str, files), *extra]
    if plugin:
        command[3:3] = ["-p", "trimesh_ray_plugin"]
    env = dict(__import__("os").environ)
    env["PYTHONPATH"] = str(TOOLS) + (":" + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    done = subprocess.run(command, cwd=work / "tests", env=env, capture_output=True, text=True)
    tail = [line for line in (done.stdout + done.stderr).splitlines()
            if line.startswith("trimesh_ray_plugin:")]
    counts = {"passed": 0, "failed": 0, "error": 0, "skipped": 0}
    failures = []
    if report.exists():
        for case in ET.parse(report).getroot().iter("testcase"):
            name = f"{Path(case.get('file') or case.get('classname', '')).name}::{case.get('name')}"
            outcome = "passed"
            for child in case:
                if child.tag in ("failure", "error", "skipped"):
                    outcome = {"failure": "failed"}.get(child.tag, child.tag)
                    message = (child.get("message") or "").splitlines()[0][:200] if child.get("message") else ""
                    if outcome != "skipped":
                        failures.append(f"{name}: {message}")
            counts[outcome] += 1
    else:
        failures.append((done.stdout + done.stderr)[-3000:])
    return {"counts": counts, "failures": failures, "plugin": tail, "exit": done.returncode}


def show(label: str, result: dict) -> None:
    c = result["counts"]
    ran = c["passed"] + c["failed"] + c["error"]
    print(f"{label}: {c['passed']}/{ran} passed, {c['failed']} failed, {c['error']} errors, "
          f"{c['skipped']} skipped")
    for line in result["plugin"]:
        print(f"  {line}")
    for failure in result["failures"]:
        print(f"  FAILED {failure}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", type=Path, help="a trimesh checkout (for tests/generic.py and models/)")
    parser.add_argument("--source-tests", action="store_true",
                        help="take the test files from --source too (they then match its helpers), "
                             "not from the installed version's source distribution")
    parser.add_argument("--also-trimesh", action="store_true",
                        help="also run the tests with trimesh's own engines, for comparison")
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder")
    parser.add_argument("pytest_args", nargs="*", help="passed on to pytest (after --)")
    args = parser.parse_args(argv)

    version = installed_version()
    work = Path(tempfile.mkdtemp(prefix="clrt-trimesh-tests-"))
    try:
        if args.source_tests and args.source is None:
            parser.error("--source-tests needs --source")
        sdist = None if args.source_tests else fetch_sdist(version, work / "sdist")
        if sdist is None and args.source is None:
            print("skipped: trimesh's tests are not reachable (no download, no --source)")
            return 0
        why = prepare(work, sdist, args.source.resolve() if args.source else None)
        if why:
            print(f"skipped: {why}")
            return 0
        files = ray_test_files(work / "tests")
        origin = f"trimesh {version} source distribution" if sdist else f"{args.source}"
        print(f"trimesh {version}: {len(files)} test files use mesh.ray or mesh.nearest "
              f"({', '.join(p.name for p in files)}), from the {origin}"
              + (f", helpers and models from {args.source}" if args.source and sdist else ""))
        import trimesh.ray
        if not trimesh.ray.has_embree:
            print("note: embreex is not installed, so pytest skips the tests of the Embree engine")
        results = {"clrt": run_pytest(work, files, True, args.pytest_args)}
        if args.also_trimesh:
            results["trimesh"] = run_pytest(work, files, False, args.pytest_args)
        show("clrt.RayMeshIntersector behind mesh.ray, clrt.ProximityQuery behind mesh.nearest", results["clrt"])
        if "trimesh" in results:
            show("trimesh's own engines", results["trimesh"])
        c = results["clrt"]["counts"]
        return 1 if c["failed"] or c["error"] or not c["passed"] else 0
    finally:
        if args.keep:
            print(f"kept {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())

# Run here (not on the GPU machine, which has no package index): the wheels
# scripts/gpu-env.sh installs there, for its CPython 3.12, into the git-ignored
# .whl/ (name it in the device call's carry list).  rtree: trimesh's own ray
# intersector, which tests/test_intersector.py compares against.
set -e
cd "$(dirname "$0")/.."
grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo '/.whl/' >> .git/info/exclude
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
    -d .whl pyopencl==2026.1.4 pytools platformdirs siphash24 trimesh rtree pytest pluggy iniconfig packaging
ls .whl

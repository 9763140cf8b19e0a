# Source this on the lent GPU machine (see ../shared/device/README.md): installs
# the carried wheels (scripts/gpu-wheels.sh makes them) and registers NVIDIA's OpenCL driver, which the image has
# but no ICD file names.  Keeps PoCL available beside it.
python3 -m pip install -q --no-index --no-deps --no-compile --upgrade --target /tmp/site .whl/*.whl || return 1
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
lib=$(find / -name libnvidia-opencl.so.1 -not -path '/proc/*' 2>/dev/null | head -1)
mkdir -p /tmp/icd && echo "$lib" > /tmp/icd/nvidia.icd
cp /etc/OpenCL/vendors/*.icd /tmp/icd/ 2>/dev/null || true
export OCL_ICD_VENDORS=/tmp/icd
unset OCL_ICD_FILENAMES
# The image sets PYTHONDONTWRITEBYTECODE and ships numpy without compiled
# bytecode, so every fresh process would compile numpy's, pyopencl's and
# clrt's modules again -- what a user's install (pip compiles on install)
# never does.  Timings of fresh processes (first image) read a compiled
# cache of their own instead.
export PYTHONPYCACHEPREFIX=/tmp/pycache
if [ ! -d /tmp/pycache ]; then
    python3 -m compileall -q -j 8 "$(python3 -c 'import sysconfig; print(sysconfig.get_paths()["stdlib"])')" \
        "$(python3 -c 'import numpy, os; print(os.path.dirname(numpy.__file__))')" /tmp/site clrt > /dev/null 2>&1 || true
fi

"""Developer benchmarks: commands that print tables, run from the repository root as
``python -m benchmarks.NAME`` (or ``python benchmarks/NAME.py``); never shipped in the clrt wheel,
never imported by clrt.  docs/benchmarks.md gives today's figures and the command of each."""

import os

# Benchmarks time the device builder as it runs with its kernels compiled: a
# machine's first builds would run on the host while a background process
# compiles them (clrt.device.first_build).  benchmarks.cold_start,
# which times that first call, gives its processes the setting found here.
FIRST_BUILD_GIVEN = os.environ.get("CLRT_FIRST_BUILD")
os.environ.setdefault("CLRT_FIRST_BUILD", "0")

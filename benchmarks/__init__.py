"""Developer benchmarks: commands that print tables, run from the repository root as
``python -m benchmarks.NAME`` (or ``python benchmarks/NAME.py``); never shipped in the clrt wheel,
never imported by clrt.  docs/benchmarks.md gives today's figures and the command of each."""

"""tools/mutate.py's mutants still fit the code they mutate (no kernel runs).

Each mutant is a search and replace that must match exactly once; when a kernel
is rewritten, a mutant whose text is gone makes every run of the tool stop at
start-up.  This catches that in the fast suite, where the change is made.
"""

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load_tool():
    spec = importlib.util.spec_from_file_location("clrt_mutate_tool", ROOT / "tools" / "mutate.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look the module up while it loads
    spec.loader.exec_module(module)
    return module


mutate = _load_tool()


@pytest.mark.parametrize("mutant", mutate.MUTANTS, ids=[m.name for m in mutate.MUTANTS])
def test_each_mutant_matches_its_file_exactly_once(mutant):
    text = (ROOT / mutant.path).read_text(encoding="utf-8")
    assert text.count(mutant.old) == 1, f"{mutant.old!r} occurs {text.count(mutant.old)} times in {mutant.path}"
    assert mutant.new != mutant.old
    # the table shows the first changed line: there must be one
    assert any(a != b for a, b in zip(mutant.old.splitlines(), mutant.new.splitlines()))


def test_mutants_have_unique_names_and_existing_tests():
    names = [m.name for m in mutate.MUTANTS]
    assert len(names) == len(set(names))
    for m in mutate.MUTANTS:
        assert m.tests and all((ROOT / t).is_file() for t in m.tests), (m.name, m.tests)


def test_the_tool_checks_every_mutant_at_start_up(capsys):
    """--list runs the same table of mutants; a stale one is refused with exit 2."""
    assert mutate.main(["--list"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == len(mutate.MUTANTS)
    stale = mutate.Mutant("stale", mutate.MUTANTS[0].path, "no such text anywhere", "x", ("tests/test_ties.py",))
    saved = mutate.MUTANTS[:]
    mutate.MUTANTS[:] = [stale]
    try:
        with pytest.raises(SystemExit) as stop:
            mutate.main(["--no-baseline"])
        assert stop.value.code == 2
    finally:
        mutate.MUTANTS[:] = saved
    assert "occurs 0 times" in capsys.readouterr().err

"""docs/architecture.md's recipes ("Where to add ...") name every file to touch:
for each recipe, the code of an existing instance (the ellipsoid volume, the
count query, the PLY reader, the WebP writer) is found by its names and
string constants -- comments and docstrings aside -- and every file holding
it must be one the recipe lists; and every file a recipe lists exists."""

import io
import re
import tokenize
from fnmatch import fnmatch
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ARCHITECTURE = REPO / "docs" / "architecture.md"


class Probe:
    """Where an existing instance of a recipe's concept lives: Python names
    matching ``names``, Python strings equal to one of ``strings``, OpenCL
    identifiers matching ``names`` (comments stripped), and in ``docs`` the
    plain words ``doc_words``.  ``elsewhere``: files holding one of these
    for another reason, with the reason."""

    def __init__(self, names: str, strings=(), doc_words=(), elsewhere=None):
        self.names, self.strings, self.doc_words = re.compile(names), set(strings), tuple(doc_words)
        self.elsewhere = elsewhere or {}

    def holds(self, path: Path) -> bool:
        text = path.read_text(encoding="utf-8")
        if path.suffix == ".py":
            for tok in tokenize.generate_tokens(io.StringIO(text).readline):
                if tok.type == tokenize.NAME and self.names.search(tok.string):
                    return True
                if tok.type == tokenize.STRING and tok.string.strip("\"'rbf") in self.strings:
                    return True
            return False
        if path.suffix in (".cl", ".h"):
            code = re.sub(r"//[^\n]*|/\*.*?\*/", "", text, flags=re.S)
            return any(self.names.search(word) for word in re.findall(r"\b\w+\b", code))
        return any(word in text for word in self.doc_words)


PROBES = {
    "volume": Probe(r"ELLIPSE", strings={"ellipse"},
                    elsewhere={"clrt/bench/paper_meshes.py": "the paper's test mesh named 'ellipse'"}),
    "query": Probe(r"^(count_hits|query_count)$", strings={"count_hits", "query_count"},
                   doc_words=("count_hits",)),
    "input": Probe(r"^(ply|PLY\w*|_?ply_\w+)$", strings={".ply", "PLY"},
                   elsewhere={"clrt/bench/paper_meshes.py": "clrt bench's preference among a scan's formats; "
                                                            "a new format is scanned without it"}),
    "output": Probe(r"WEBP", strings={".webp", "WEBP", "WebP"}),
}


def _recipes() -> dict[str, list[str]]:
    """recipe name -> the paths its numbered list names, in order."""
    recipes, name = {}, None
    for line in ARCHITECTURE.read_text(encoding="utf-8").splitlines():
        marker = re.match(r"<!-- recipe: (\w+) -->", line.strip())
        if marker:
            name = marker.group(1)
            recipes[name] = []
        elif name and re.match(r"\d+\. `", line):
            recipes[name].append(re.match(r"\d+\. `([^`]+)`", line).group(1))
        elif name and not line.strip():
            name = None
    return recipes


def _searched() -> list[Path]:
    files = [p for p in (REPO / "clrt").rglob("*") if p.suffix in (".py", ".cl", ".h")]
    return files + list((REPO / "docs").glob("*.md")) + [REPO / "README.md"]


def test_every_recipe_is_probed():
    assert sorted(_recipes()) == sorted(PROBES)


@pytest.mark.parametrize("recipe", sorted(PROBES))
def test_a_recipe_names_every_file_of_its_concept(recipe):
    listed = _recipes()[recipe]
    assert listed, f"the {recipe} recipe lists no files"
    patterns = [p.replace("<format>", "*") for p in listed]
    for path in listed:
        if "<" not in path:
            assert (REPO / path).is_file(), f"{recipe} recipe names {path}, which does not exist"
    probe = PROBES[recipe]
    found = {str(p.relative_to(REPO)) for p in _searched() if probe.holds(p)}
    for path, reason in probe.elsewhere.items():
        assert path in found, f"{path} no longer holds it ({reason}): drop it from the probe"
    missing = sorted(f for f in found - set(probe.elsewhere) if not any(fnmatch(f, p) for p in patterns))
    assert not missing, f"the {recipe} recipe in docs/architecture.md misses {missing}"


def test_the_format_lists_name_every_reader():
    """The lists of input formats a user reads (the render command's
    description, README's MESH line, the scene-file path row) name every
    extension of READERS: the parser may not import the readers to ask."""
    from clrt import cli
    from clrt.scene.load import SUPPORTED_EXTENSIONS
    render = next(a for a in cli._parser()._subparsers._group_actions[0].choices.items() if a[0] == "render")[1]
    readme = next(line for line in (REPO / "README.md").read_text().splitlines() if line.startswith("- `MESH`:"))
    path_row = next(line for line in (REPO / "docs" / "scene-files.md").read_text().splitlines()
                    if line.startswith("| `mesh` | `path` |"))
    for where, text in (("clrt render's description", render.description), ("README's MESH line", readme),
                        ("docs/scene-files.md's path row", path_row)):
        words = set(re.findall(r"\w+", text.upper()))
        missing = [ext for ext in SUPPORTED_EXTENSIONS if ext[1:].upper() not in words]
        assert not missing, f"{where} does not name {missing}"

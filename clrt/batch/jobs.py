"""What a batch is made of: sources found from the command's arguments, their
output names, the settings that decide whether an existing output is still
valid, and the tasks the views are cut into.  Plain Python: no Dask, no OpenCL.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from clrt.config import BATCH_FORMAT, BATCH_VIEWS_PER_TASK, DEFAULT_HEIGHT, DEFAULT_SAMPLES, DEFAULT_WIDTH
from clrt.output import WRITERS
from clrt.scene.load import SCENE_EXTENSION, SUPPORTED_EXTENSIONS

#: Files a folder argument contributes (any file named explicitly is tried).
SOURCE_SUFFIXES = SUPPORTED_EXTENSIONS + (SCENE_EXTENSION,)   # meshes and scene files
_GLOB_CHARS = "*?["


@dataclass(frozen=True)
class Source:
    """One file to render, or an argument that named none (``error`` says why)."""

    path: str                # absolute path, or the argument as given when it names nothing
    name: str = ""           # folder of its outputs under the output folder
    error: str = ""


def expand_sources(arguments) -> list[Source]:
    """Files, folders (their mesh and scene files, not recursive) and glob patterns
    -> sources in argument order, each file once.  An argument naming nothing is
    a Source with an ``error``."""
    found, seen = [], set()
    for arg in arguments:
        arg = str(arg)
        if any(c in arg for c in _GLOB_CHARS) and not os.path.lexists(arg):
            paths = sorted(p for p in glob.glob(os.path.expanduser(arg), recursive=True) if os.path.isfile(p))
            if not paths:
                found.append(Source(arg, error=f"{arg}: no file matches this pattern"))
        elif os.path.isdir(arg):
            paths = sorted(str(p) for p in Path(arg).iterdir()
                           if p.is_file() and p.suffix.lower() in SOURCE_SUFFIXES)
            if not paths:
                found.append(Source(arg, error=f"{arg}: folder has no mesh or scene files "
                                                f"({', '.join(SOURCE_SUFFIXES)})"))
        elif not os.path.exists(arg):
            found.append(Source(arg, error=f"{arg}: no such file"))
            continue
        else:
            paths = [arg]
        for p in paths:
            p = os.path.abspath(p)
            if p not in seen:
                seen.add(p)
                found.append(Source(p))
    return _named(found)


def _named(sources: list[Source]) -> list[Source]:
    """Output folder names: the file's stem, or -- where stems collide -- the stem
    and a hash of the path, so a name never depends on which other sources came along."""
    stems: dict[str, int] = {}
    for s in sources:
        if not s.error:
            stem = Path(s.path).stem
            stems[stem] = stems.get(stem, 0) + 1
    named = []
    for s in sources:
        if s.error:
            named.append(s)
            continue
        stem = Path(s.path).stem
        name = stem if stems[stem] == 1 else f"{stem}-{hashlib.sha1(s.path.encode()).hexdigest()[:8]}"
        named.append(Source(s.path, _safe(name)))
    return named


def _safe(name: str) -> str:
    name = "".join(c if c.isalnum() or c in "-_.+" else "_" for c in name).lstrip(".")
    return name or "source"


def output_path(name: str, view: int, suffix: str | None = None) -> str:
    """Relative path of a view's image: ``<source-stem>/view-0007.png``, or with
    the ``suffix`` of another format (default: BATCH_FORMAT's)."""
    return f"{name}/view-{view:04d}{suffix or WRITERS[BATCH_FORMAT].suffix}"


def settings_key(source: str, settings: dict) -> str:
    """A digest of everything that decides a source's images: the file's size and
    modification time, and the render settings.  An output recorded with another
    key is rendered again."""
    try:
        st = os.stat(source)
        stamp = [st.st_size, st.st_mtime_ns]
    except OSError:
        stamp = None
    text = json.dumps([stamp, settings], sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def camera_rays(source: str, scene: dict, camera: dict) -> int:
    """Camera rays of one view, width x height x samples^2, as far as they are
    known before rendering: the batch's options, else a scene file's [camera]
    and [render] values (its TOML alone is read, not its meshes), else the
    defaults.  It sizes a task's hang limit before any frame has finished
    (clrt.batch.watch.HangWatch); a file that cannot be read counts as the
    defaults (its task reports why)."""
    own = {}
    if source.lower().endswith(SCENE_EXTENSION):
        try:
            with open(source, "rb") as f:
                data = tomllib.load(f)
            own = {**data.get("camera", {}), **data.get("render", {})}
        except (OSError, ValueError, TypeError):   # TOML errors are ValueErrors
            pass

    def count(value, default):
        return value if isinstance(value, int) and not isinstance(value, bool) and value > 0 else default
    width = count(camera.get("width"), count(own.get("width"), DEFAULT_WIDTH))
    height = count(camera.get("height"), count(own.get("height"), DEFAULT_HEIGHT))
    samples = count(scene.get("samples"), count(own.get("samples"), DEFAULT_SAMPLES))
    return width * height * samples * samples


@dataclass
class Task:
    """Views of one source rendered by one call of the worker's render_task."""

    source: Source
    views: list
    replace: list = field(default_factory=list)   # views whose existing (outdated) image is replaced


def plan_tasks(source: Source, pending: list, replace: set, workers: int, sources: int) -> list[Task]:
    """Cut a source's pending views into tasks: enough to keep every worker busy
    when sources are few, at most BATCH_VIEWS_PER_TASK views each, and otherwise
    one task per source, so that each mesh's BVH is built on as few workers as
    possible (each keeps it for later views, clrt.batch.worker)."""
    if not pending:
        return []
    wanted = max(-(-max(workers, 1) // max(sources, 1)), -(-len(pending) // BATCH_VIEWS_PER_TASK))
    count = min(len(pending), wanted)
    size = -(-len(pending) // count)
    tasks = []
    for i in range(0, len(pending), size):
        views = pending[i:i + size]
        tasks.append(Task(source, views, [v for v in views if v in replace]))
    return tasks

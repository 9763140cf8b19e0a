"""Writing one file safely, whatever its format: through a temporary file in the
same folder and a rename, so that a reader never sees half a file and a failure
leaves none behind; and, for a file with no room for clrt's mark, a record of
its SHA-256 beside it (``.NAME.clrt``).  The formats themselves and the rule of
when a file may be replaced: clrt.output.writers."""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from pathlib import Path

from clrt.errors import OutputError

# Every image clrt writes carries this mark ("Software" in PNG and TIFF, a comment in
# JPEG and GIF, XMP in WebP, a header attribute in OpenEXR); an existing output is
# replaced without --force only if it carries the mark (or its record matches), so a
# re-run replaces its own render but never a user's file.
SOFTWARE_MARK = "clrt"
RECORD_PREFIX, RECORD_SUFFIX = ".", ".clrt"


def mark_text() -> str:
    """What clrt writes as its mark: ``clrt VERSION``."""
    from clrt import __version__
    return f"{SOFTWARE_MARK} {__version__}"


def record_path(path: Path) -> Path:
    """The record beside a file clrt cannot mark: ``dir/.NAME.clrt``."""
    path = Path(path)
    return path.with_name(f"{RECORD_PREFIX}{path.name}{RECORD_SUFFIX}")


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def matches_record(path: Path) -> bool:
    """Is ``path`` exactly the file that clrt recorded writing there?"""
    try:
        words = record_path(path).read_text(encoding="ascii", errors="replace").split()
        return (len(words) == 4 and words[0] == SOFTWARE_MARK and words[2] == "sha256"
                and words[3] == sha256(path))
    except OSError:
        return False


def _umask() -> int:
    """The process's umask, read without changing it: os.umask can only be read
    by setting it, and another thread creating a file or folder in between (the
    batch workers write images in threads) would get the temporary mask.  Linux
    lists it in /proc/self/status; elsewhere the set-and-restore is kept."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    with _UMASK_LOCK:
        umask = os.umask(0)
        os.umask(umask)
    return umask


_UMASK_LOCK = threading.Lock()


def _new_file_mode(path: Path) -> int:
    """The replaced file's permissions, else 0666 less the umask."""
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


def replace_atomically(path: Path, write, record: bool = False, by_name: bool = False) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it into
    place; with ``record``, also (re)write the record of its SHA-256 beside it.
    ``by_name``: ``write`` gets the temporary file's path instead (for writers
    that open files themselves)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        os.fchmod(fd, _new_file_mode(path))
        with os.fdopen(fd, "wb") as f:
            write(tmp if by_name else f)
        digest = sha256(Path(tmp)) if record else None
        os.replace(tmp, path)
        if record:   # after the file: a crash in between leaves a stale record, which refuses (safe)
            _write_record(path, digest)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, (OSError, ValueError, KeyError)):
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise OutputError(f"cannot write {path}: {reason}") from None
        raise


def _write_record(path: Path, digest: str) -> None:
    target = record_path(path)
    fd, tmp = tempfile.mkstemp(prefix=f"{target.name}.", dir=path.parent)
    try:
        os.fchmod(fd, _new_file_mode(target))
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(f"{mark_text()} sha256 {digest}\n")
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def remove_written(paths) -> None:
    """Remove files this run wrote (and their records), when a later step of the
    same output failed or was interrupted: a half-finished set of outputs (an
    image without its AOVs) is not left behind."""
    for path in paths:
        for p in (Path(path), record_path(Path(path))):
            try:
                p.unlink()
            except OSError:
                pass

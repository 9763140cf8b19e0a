"""Writing one file safely, whatever its format, and knowing it again by its
content: through a temporary file in the same folder and a rename, so that a
reader never sees half a file and a failure leaves none behind; and, beside
every file clrt writes, a record of its SHA-256 (``.NAME.clrt``).  The
formats themselves and the rule of when a file may be replaced:
clrt.output.writers.

**The record is what makes a file clrt's** (:func:`file_state`).  A file is
clrt's while its bytes are exactly those whose SHA-256 the record beside it
holds: a copy of the folder (``cp -r``, ``rsync -a``: the hidden records go
with the files) stays clrt's, while an edit, a truncation or another file put
in its place -- even one that keeps clrt's "Software" mark, as image editors
do -- no longer matches.  The mark that images still carry ("Software" in PNG
and TIFF, a comment in JPEG and GIF, XMP in WebP, a header attribute in
OpenEXR) says who made them; it decides nothing.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from pathlib import Path

from clrt.errors import OutputError

# The mark inside every image clrt writes (where the format has room), and the
# first word of every record.
SOFTWARE_MARK = "clrt"
RECORD_PREFIX, RECORD_SUFFIX = ".", ".clrt"

#: What :func:`file_state` finds at a path.
ABSENT, OURS, CHANGED, FOREIGN, NOT_A_FILE = "absent", "ours", "changed", "foreign", "not a file"


def mark_text() -> str:
    """What clrt writes as its mark: ``clrt VERSION``."""
    from clrt import __version__
    return f"{SOFTWARE_MARK} {__version__}"


def record_path(path: Path) -> Path:
    """The record beside a file clrt wrote: ``dir/.NAME.clrt``."""
    path = Path(path)
    return path.with_name(f"{RECORD_PREFIX}{path.name}{RECORD_SUFFIX}")


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def recorded_digest(path: Path) -> str | None:
    """The SHA-256 that the record beside ``path`` holds (``clrt VERSION sha256
    HEX``); None without a record, or with a file there that is not one."""
    try:
        words = record_path(path).read_text(encoding="ascii", errors="replace").split()
    except OSError:
        return None
    if len(words) == 4 and words[0] == SOFTWARE_MARK and words[2] == "sha256" and len(words[3]) == 64:
        return words[3]
    return None


def file_state(path: Path) -> str:
    """What is at ``path``, judged by its content -- the one rule of clrt render's
    overwrites and of a batch's resume (clrt.output.writers.check_replace,
    clrt.batch.resume):

    - ABSENT: nothing;
    - OURS: a regular file whose SHA-256 is the one its record holds: exactly
      what clrt wrote there;
    - CHANGED: a record says clrt wrote a file there, and the file is no longer
      that one -- cut short, edited, replaced by another, or unreadable;
    - FOREIGN: a file without a record: clrt did not write it (or its record
      was removed);
    - NOT_A_FILE: a folder, a pipe, a device: never replaced."""
    path = Path(path)
    if not os.path.lexists(path):
        return ABSENT
    if path.is_dir() or (path.exists() and not path.is_file()):
        return NOT_A_FILE
    digest = recorded_digest(path)
    if digest is None:
        return FOREIGN
    try:
        return OURS if sha256(path) == digest else CHANGED
    except OSError:
        return CHANGED


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


def replace_atomically(path: Path, write, by_name: bool = False) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it into
    place, with the record of its SHA-256 beside it.  ``by_name``: ``write``
    gets the temporary file's path instead (for writers that open files
    themselves).

    The record is written before the rename: a process killed in between leaves
    the new record beside the old file (CHANGED: refused by clrt render,
    rendered again by a batch) or beside no file (ABSENT), never a new file
    without its record, which would be FOREIGN and refused."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    old_record, recorded = None, False
    try:
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        os.fchmod(fd, _new_file_mode(path))
        with os.fdopen(fd, "wb") as f:
            write(tmp if by_name else f)
        digest = sha256(Path(tmp))
        old_record = _read_bytes(record_path(path))
        _write_record(path, digest)
        recorded = True
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if recorded:   # the old file stays, and so does its record (or its lack of one)
            _restore(record_path(path), old_record)
        if isinstance(exc, (OSError, ValueError, KeyError)):
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise OutputError(f"cannot write {path}: {reason}") from None
        raise


def _read_bytes(path: Path) -> bytes | None:
    try:
        return path.read_bytes()
    except OSError:
        return None


def _restore(record: Path, text: bytes | None) -> None:
    try:
        if text is None:
            record.unlink(missing_ok=True)
        elif _read_bytes(record) != text:
            record.write_bytes(text)
    except OSError:
        pass


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

"""The manifest of an output folder: one JSON line per output (and per bad
source), rewritten through a temporary file and a rename, so a reader never sees
half of it, with the record of its SHA-256 beside it (``.manifest.jsonl.clrt``,
clrt.output): a manifest.jsonl that clrt did not write is never read or replaced
without ``force``.  The images are the truth: an image is written atomically before it
is recorded, and one found without a record (the client stopped before it wrote
the manifest) is taken as done if clrt wrote it.

Fields of a line: ``path`` (relative to the folder; null for a bad source),
``source``, ``view``, ``views``, ``status`` ("done", "bad", "device", "failed": also an
image that could not be written),
``key`` (the settings it was made with, clrt.batch.jobs.settings_key),
``seconds``, ``worker``, ``device``, ``camera`` (eye, target, up, fov, width,
height) and ``error`` (one line).
"""

from __future__ import annotations

import fcntl
import json
import os
import time
from pathlib import Path

from clrt.config import BATCH_MANIFEST, BATCH_MANIFEST_SECONDS
from clrt.errors import OutputError
from clrt.output import check_replace, record_path, write_file, written_by_clrt


class Manifest:
    """The records of one output folder, keyed by output path (bad sources: by source).

    The manifest follows clrt's one overwrite rule (clrt.output): it is written
    with a record of its SHA-256 beside it (``.manifest.jsonl.clrt``), and an
    existing manifest is read and replaced only if it is the one clrt wrote --
    a user's file of that name is refused (OutputError) unless ``force``, and
    then replaced without being read (the images decide what is done)."""

    def __init__(self, folder: Path, force: bool = False):
        self.path = Path(folder) / BATCH_MANIFEST
        self.records: dict[str, dict] = {}
        self._written = 0.0
        self._dirty = False
        if not os.path.lexists(self.path):
            return
        if not written_by_clrt(self.path):
            if _manifest_before_records(self.path):
                self._dirty = True            # read, and rewritten with its record
            else:
                check_replace(self.path, force)   # before anything in the folder is written
                self._dirty = True                # with force: replaced, unread
                return
        with open(self.path, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                try:
                    record = json.loads(line)
                except ValueError:
                    continue   # damaged: the images decide
                if isinstance(record, dict):
                    self.records[_record_key(record)] = record

    def get(self, path: str) -> dict | None:
        return self.records.get(path)

    def add(self, record: dict) -> None:
        self.records[_record_key(record)] = record
        self._dirty = True

    def drop_bad(self, source: str) -> None:
        """Forget an earlier failure of ``source`` (it is being tried again)."""
        if self.records.pop(f"source:{source}", None) is not None:
            self._dirty = True

    def write(self, force: bool = True) -> None:
        """Rewrite the file if anything changed -- at most every
        BATCH_MANIFEST_SECONDS unless ``force``."""
        if not self._dirty or (not force and time.monotonic() - self._written < BATCH_MANIFEST_SECONDS):
            return
        lines = (json.dumps(r, sort_keys=True) for r in sorted(self.records.values(), key=_order))
        # force: the file there is the one read (or refused) when this Manifest was made
        write_file("".join(line + "\n" for line in lines), self.path, force=True)
        self._written, self._dirty = time.monotonic(), False


# Every line of a manifest clrt wrote has these fields.
_LINE_FIELDS = {"path", "source", "status", "key"}


def _manifest_before_records(path: Path) -> bool:
    """Is ``path`` a manifest that clrt wrote before manifests had a record beside
    them (2026-11-29): no record, and every line one of clrt's JSON lines?  Such
    a folder resumes as before; a record that no longer matches still refuses."""
    if record_path(path).exists() or not path.is_file():
        return False
    try:
        with open(path, encoding="utf-8") as fh:
            lines = [line for line in fh if line.strip()]
        records = [json.loads(line) for line in lines]
    except (OSError, ValueError):
        return False
    return bool(records) and all(isinstance(r, dict) and _LINE_FIELDS <= r.keys() for r in records)


def _record_key(record: dict) -> str:
    return record.get("path") or f"source:{record.get('source')}"


def _order(record: dict):
    return (record.get("path") is None, record.get("path") or "", str(record.get("source")))


class FolderLock:
    """An exclusive lock on an output folder, so two batches never write one manifest."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / ".clrt-batch.lock"
        self._fd = None

    def __enter__(self):
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise OutputError(f"cannot write {self.path.parent}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._fd)
            raise OutputError(f"another clrt batch is writing {self.path.parent}; wait for it "
                              "or choose another -o") from None
        return self

    def __exit__(self, *exc):
        os.close(self._fd)   # releases the lock; the file stays (removing it would race)

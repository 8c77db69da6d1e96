"""Atomic file writes, shared by every package: nothing half-written ever looks whole after a crash.

Temporary files and folders carry the writing process's id in their names (``.NAME.tmp-PID-XXXX.EXT``,
``.vtr-tmp-PID-XXXX/``). A ``kill -9`` leaves them behind, so every write first removes the leftovers in
its folder whose process is gone: no temporary file survives the next run, and a write in progress in
another live process is never touched.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

_LEFTOVER = re.compile(r"^\..*\.tmp-(\d+)-[^/]*$|^\.vtr-tmp-(\d+)-[^/]*$")


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def remove_leftovers(folder: str | os.PathLike[str]) -> list[Path]:
    """Delete temporary files/folders in ``folder`` left by writers that died; returns what was removed."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        match = _LEFTOVER.match(entry.name)
        if match is None or _alive(int(match.group(1) or match.group(2))):
            continue
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
            removed.append(Path(entry.path))
        except OSError:
            pass  # raced with another cleaner, or not ours to remove: harmless
    return removed


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path in `path`'s folder; on success it replaces `path`, on any error it is removed.

    The temporary name keeps `path`'s suffix, so writers that pick a format by extension (matplotlib,
    numpy's savez) behave as they would on the real name.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(path.parent)
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{path.name}.tmp-{os.getpid()}-", suffix=path.suffix, dir=path.parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, 0o644)  # mkstemp makes the file private; ours are ordinary files
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def temp_dir(folder: str | os.PathLike[str]) -> Iterator[Path]:
    """A scratch folder inside ``folder`` (same filesystem, so its files can be ``os.replace``d out),
    removed on exit; leftovers of dead writers are removed first."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    remove_leftovers(folder)
    with tempfile.TemporaryDirectory(prefix=f".vtr-tmp-{os.getpid()}-", dir=folder) as tmp:
        yield Path(tmp)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write `text` to `path` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write `data` to `path` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)

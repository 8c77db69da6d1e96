"""Paths given on a command line, checked before anything is read, opened or created: a refused start says
in one line which path is wrong and why (a folder where a file is wanted, a file where a folder is), and
leaves nothing behind (:class:`MadeFolders` removes the folders a failed start created)."""

from __future__ import annotations

import os
from pathlib import Path


def require_file(path: str | os.PathLike[str], what: str) -> str:
    """``path`` when it is a file; else FileNotFoundError or IsADirectoryError saying it is ``what``'s."""
    name = os.fspath(path)
    if os.path.isdir(name):
        raise IsADirectoryError(f"{name} is a folder, not a {what}; pass the file itself")
    if not os.path.isfile(name):
        raise FileNotFoundError(f"{what} {name!r} does not exist")
    return name


def check_output(path: str | os.PathLike[str], flag: str, folder: bool = False) -> Path:
    """Refuse an output ``path`` (``folder``: a folder to be written) that cannot be created, naming ``flag``;
    creates nothing. Missing folders above it are fine (the writer creates them)."""
    p = Path(path)
    if folder and p.exists() and not p.is_dir():
        raise ValueError(f"{flag} {p}: a file is in the way of the folder it names")
    if not folder and p.is_dir():
        raise ValueError(f"{flag} {p} is a folder; name a file in it")
    above = p.absolute().parent
    while not above.exists() and above != above.parent:
        above = above.parent
    if not above.is_dir():
        raise ValueError(f"{flag} {p}: {above} is a file, not a folder")
    if not os.access(above, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {p}: no permission to write in {above}")
    return p


class MadeFolders:
    """Create the folders above output paths, remembering which it made so that :meth:`remove` can take them
    away again (only those, only when empty) when the start fails."""

    def __init__(self) -> None:
        self.made: list[Path] = []

    def make(self, path: str | os.PathLike[str]) -> None:
        """Create the missing folders above ``path``."""
        missing = []
        above = Path(path).absolute().parent
        while not above.exists():
            missing.append(above)
            above = above.parent
        for folder in reversed(missing):
            folder.mkdir()
            self.made.append(folder)

    def remove(self) -> None:
        for folder in reversed(self.made):
            try:
                folder.rmdir()
            except OSError:
                pass  # something else was put there meanwhile: not ours to remove
        self.made = []

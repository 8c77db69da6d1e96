"""Size caps for ``.npz`` files (routes, datasets) and other zip archives (torch checkpoints) before anything is
decompressed.

A compressed ``.npz`` can expand a thousandfold (0.29 MB of zeros became 295 MB), and a ``.npy`` header can
declare a shape far larger than its data. :func:`check_npz` reads only the zip directory and each array's
header, and refuses a file whose arrays would take more than ``max_expansion`` times the file's size, whose
arrays hold Python objects (pickles: code), or whose members are not plain ``.npy`` arrays. ``np.load`` then
never allocates more than was checked: zipfile stops each member at its declared size. :func:`check_zip` is
the directory-only half, for archives whose members are not ``.npy`` (a torch checkpoint is a zip whose
reader allocates each member's declared size).
"""

from __future__ import annotations

import math
import os
import zipfile

import numpy as np
from numpy.lib import format as npy_format

#: Loading never takes more than this many times the file's size (arrays + zip member buffers).
MAX_EXPANSION = 4.0
#: More members than this is not one of our files.
MAX_MEMBERS = 64


class NpzTooLargeError(ValueError):
    """An .npz whose arrays exceed the cap or that is not a plain array archive; the message says why."""


def check_zip(
    path: str | os.PathLike[str],
    max_expansion: float = MAX_EXPANSION,
    max_members: int = MAX_MEMBERS,
    what: str = "an .npz archive",
) -> int:
    """Raise NpzTooLargeError unless ``path`` is a zip archive of at most ``max_members`` members whose
    declared sizes total at most ``max_expansion`` times the file size; returns that total in bytes. Reads
    the zip directory only."""
    path = os.fspath(path)
    size = os.path.getsize(path)
    try:
        with zipfile.ZipFile(path) as archive:
            members = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise NpzTooLargeError(f"{path}: not {what} ({exc})") from None
    if len(members) > max_members:
        raise NpzTooLargeError(f"{path}: {len(members)} members, more than {max_members}")
    total = sum(info.file_size for info in members)
    if total > max_expansion * size:
        raise NpzTooLargeError(
            f"{path}: its contents take {total / 1e6:.1f} MB, more than {max_expansion:g}x the file's "
            f"{size / 1e6:.2f} MB; refusing to decompress it"
        )
    return total


def check_npz(path: str | os.PathLike[str], max_expansion: float = MAX_EXPANSION) -> int:
    """Raise NpzTooLargeError unless every member is a plain .npy array and their total size is at most
    ``max_expansion`` times the file size (:func:`check_zip`); returns that total in bytes."""
    total = check_zip(path, max_expansion)
    path = os.fspath(path)
    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            nbytes = _array_bytes(archive, info, path)
            if nbytes > info.file_size:
                raise NpzTooLargeError(
                    f"{path}: {info.filename} declares {nbytes} bytes of data in a {info.file_size}-byte member"
                )
    return total


def _array_bytes(archive: zipfile.ZipFile, info: zipfile.ZipInfo, path: str) -> int:
    if not info.filename.endswith(".npy"):
        raise NpzTooLargeError(f"{path}: member {info.filename!r} is not a .npy array")
    try:
        with archive.open(info) as f:
            version = npy_format.read_magic(f)
            if version == (1, 0):
                shape, _, dtype = npy_format.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, _, dtype = npy_format.read_array_header_2_0(f)
            else:
                raise NpzTooLargeError(f"{path}: {info.filename} uses .npy format {version}, not 1.0/2.0")
    except NpzTooLargeError:
        raise
    except Exception as exc:  # a truncated or corrupt member: say so, never a traceback
        raise NpzTooLargeError(f"{path}: {info.filename} is not a readable .npy array ({exc})") from None
    if dtype.hasobject:
        raise NpzTooLargeError(f"{path}: {info.filename} holds Python objects (a pickle); refusing it")
    return math.prod(shape) * dtype.itemsize


def np_load_checked(
    path: str | os.PathLike[str], max_expansion: float = MAX_EXPANSION
) -> np.lib.npyio.NpzFile:
    """``np.load(path, allow_pickle=False)`` after :func:`check_npz`."""
    check_npz(path, max_expansion)
    return np.load(path, allow_pickle=False)

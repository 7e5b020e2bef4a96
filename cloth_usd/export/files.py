"""Output files of the exports: checked before any work, written whole or not at all."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Iterable

from ..errors import ArgumentError, OutputExistsError, OutputWriteError

__all__ = ["check_output_file", "check_output_dir", "write_atomic"]


def check_output_file(path: str | os.PathLike, *, force: bool, suffixes: Iterable[str], what: str = "-o") -> Path:
    """An output file path, validated: known suffix, existing folder, not a folder itself.

    Raises:
        ArgumentError: wrong suffix or missing folder. OutputExistsError: it exists, no ``force``.
    """
    path = Path(path)
    suffixes = tuple(suffixes)
    if path.suffix.lower() not in suffixes:
        raise ArgumentError(f"{what} {path}: must end in {', '.join(suffixes)}")
    if not path.parent.is_dir():
        raise ArgumentError(f"{what} {path}: folder '{path.parent}' does not exist")
    if path.is_dir():
        raise ArgumentError(f"{what} {path}: is a folder; name a file to write")
    if path.exists() and not force:
        raise OutputExistsError(f"{what} {path}: already exists; pass --force to replace it")
    return path


def check_output_dir(path: str | os.PathLike, *, force: bool, names: Iterable[str], what: str = "-o") -> Path:
    """An output folder (made if missing); without ``force`` none of ``names`` may exist in it.

    Raises:
        ArgumentError: it is a file, or its parent is missing. OutputExistsError: a file to
        be written exists and no ``force``.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ArgumentError(f"{what} {path}: is a file; name a folder for the textures, mesh and JSON")
    if not path.parent.is_dir():
        raise ArgumentError(f"{what} {path}: folder '{path.parent}' does not exist")
    taken = [n for n in names if (path / n).exists()]
    if taken and not force:
        raise OutputExistsError(f"{what} {path}: {taken[0]} already exists; pass --force to replace it")
    path.mkdir(exist_ok=True)
    return path


def write_atomic(path: Path, data: bytes) -> Path:
    """Write ``data`` to a temporary file beside ``path`` and rename it into place.

    Raises:
        OutputWriteError: the write or rename failed (the target is left as it was).
    """
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except OSError as exc:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        raise OutputWriteError(f"{path}: could not be written ({exc.strerror or exc}); check the folder's "
                               "permissions and free space; nothing was written") from None
    return path

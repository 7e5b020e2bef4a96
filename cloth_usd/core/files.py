"""Where shipped model files live, and file hashes for manifests and provenance."""

from __future__ import annotations

import hashlib
import json
import tomllib
from pathlib import Path
from typing import Any

from ..errors import ArgumentError

__all__ = ["models_dir", "file_sha256", "read_config"]


def models_dir() -> Path:
    """The shipped ``models/`` folder: ``cloth_usd/models`` when installed from a wheel,
    else the repository's ``models/`` (an editable install or a checkout)."""
    installed = Path(__file__).resolve().parents[1] / "models"
    return installed if installed.exists() else Path(__file__).resolve().parents[2] / "models"


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_config(path: str | Path, what: str, *, text: str | None = None) -> Any:
    """The content of a ``.toml`` file, or JSON for any other suffix.

    Args:
        what: what the file is, for error messages ("the data set config").
        text: the file's text when the caller has read it already.
    Raises:
        ArgumentError: unreadable or malformed, naming the file.
    """
    path = Path(path)
    try:
        text = path.read_text() if text is None else text
    except OSError as exc:
        raise ArgumentError(f"{path}: cannot read {what} ({exc.strerror})") from None
    try:
        return tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (ValueError, tomllib.TOMLDecodeError) as exc:
        raise ArgumentError(f"{path}: not valid {path.suffix[1:].upper() if path.suffix == '.toml' else 'JSON'} "
                            f"({exc})") from None


def check_keys(raw: Any, cls: type, where: str) -> dict:
    """``raw`` as the keyword arguments of the dataclass ``cls``, checked: a table (dict) whose
    keys are all fields of ``cls``.

    Raises:
        ArgumentError: naming ``where``, the unknown keys and the valid ones.
    """
    import dataclasses

    known = [f.name for f in dataclasses.fields(cls)]
    if not isinstance(raw, dict):
        raise ArgumentError(f"{where}: expected a table of {cls.__name__} keys ({', '.join(known)}), "
                            f"got {type(raw).__name__}")
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise ArgumentError(f"{where}: unknown keys {unknown} (valid: {', '.join(known)})")
    return dict(raw)
